"""Render the geometry of the squat wall S5 and of the terraced house S7 to docs/ (PNG, VTK offscreen).

Run: ``python docs/make_renders.py``. Uses only the public generators and ``dr_masonry.viz``.
"""
import os

from dr_masonry import Model, PlasticDamage
from dr_masonry.geometry import HouseParams, add_beam, add_foundation, add_wall, terraced_house
from dr_masonry.viz.render import render_model

HERE = os.path.dirname(os.path.abspath(__file__))


def squat_wall():
    model = Model()
    brick = PlasticDamage.reference()
    steel = PlasticDamage.elastic(210e9, 0.3, 7850.0)
    add_foundation(model, (-0.2, 0, -0.2), (4.4, 0.102, 0.2), steel)
    wall = add_wall(model, (0, 0, 0), 4.0, 2.75, brick)
    add_beam(model, (0, 0, wall.height), (wall.length, 0.102, 0.2), steel)
    return model


def house():
    model = Model()
    terraced_house(model, HouseParams(), PlasticDamage.reference(),
                   PlasticDamage.elastic(210e9, 0.3, 7850.0),
                   PlasticDamage.elastic(30e9, 0.2, 2500.0))
    return model


def main():
    for name, build, view in (("squat_wall_S5", squat_wall, "front"), ("house_S7", house, "iso")):
        model = build()
        out = render_model(model, os.path.join(HERE, f"{name}.png"), view=view, size=(1000, 750))
        print(f"{out.path} ({out.backend}): {model.summary()}")


if __name__ == "__main__":
    main()

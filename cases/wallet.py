"""S3 wallet: uniaxial compression of a small running-bond wall into softening.

Running-bond wallet 2 blocks long x 5 courses (440 x 405 x 102 mm) between rigid, lubricated
platens: the base is supported vertically, the top face moves down uniformly under displacement
control, and both faces may expand laterally (clamped platens confine the ends and raise the
peak by about 10 %). Reference (paper Fig. 11):
the peak stress follows the blocks' compressive curve (6.8 MPa), damage spreads over the wallet,
and the run passes the peak without diverging (here: to at least three times the peak strain).

Run: ``python cases/wallet.py [key=value ...]``; about a minute on 2 cores after compilation.
"""
import sys
from dataclasses import dataclass

import numpy as np

from dr_masonry import Displacement, JointLaw, Model, PlasticDamage, Simulation, Stage
from dr_masonry.cli import run_script
from dr_masonry.geometry import BrickSpec, add_wall, plane_nodes
from dr_masonry.scene import finish, scene_params, solver_options
from dr_masonry.units import MPa, kN, mm

PARAMS = dict(
    shortening=12.0 * mm,   # final platen displacement, m
    increments=120,
    nx=4, ny=2, nz=1,       # hexahedra per full block (length, thickness, height)
    tol=1e-4,
    damping="viscous",
    out="results/wallet",
)
#: the response curve (dr_masonry.study): platen force against shortening, compression positive
#: (the stress and strain of ``run`` divide by the wallet's area and height)
CURVE = dict(x="platen.uz", y="platen.fz", stage=None, xscale=-1 / mm, yscale=-1 / kN,
             xlabel="platen shortening (mm)", ylabel="platen force (kN)")


@dataclass(frozen=True)
class Wallet:
    """The scene data of the wallet, returned by :func:`build` and :func:`run`."""
    area: float     # m^2, the loaded (plan) area, length x thickness
    height: float   # m, the wallet's height


def build(params):
    """``(sim, stages, wallet)`` of the wallet compression test: the simulation, its stage and
    the :class:`Wallet` (plan area and height)."""
    model = Model()
    model.set_joint_law(JointLaw.reference())
    brick = BrickSpec(nx_along=params["nx"], ny_thick=params["ny"], nz_height=params["nz"])
    wall = add_wall(model, (0, 0, 0), 2 * brick.length, 5 * brick.height,
                    PlasticDamage.reference(), brick=brick)
    sim = Simulation(model, solver_options(params), output=params.get("h5"), config=params)
    base = plane_nodes(model, 2, 0.0)
    sim.fix(base, "z")
    sim.fix(base[:1], "xy")                       # no rigid-body motion in the plane
    sim.fix(base[np.argmax(model.nodes[base, 0])], "y")
    top = sim.node_set("platen", plane_nodes(model, 2, wall.height))
    press = Displacement(target=top, dof="z", to=-params["shortening"], name="press")
    wallet = Wallet(area=wall.length * wall.thickness, height=wall.height)
    return sim, [Stage("compression", params["increments"], [press])], wallet


def run(params):
    """Run; returns (simulation, strain (-), stress (Pa), :class:`Wallet`) with compression
    positive."""
    sim, stages, wallet = build(params)
    hist = sim.run(stages)
    return sim, -hist["platen.uz"] / wallet.height, -hist["platen.fz"] / wallet.area, wallet


def main(argv=None):
    params = scene_params(PARAMS, None, sys.argv[1:] if argv is None else argv, __doc__,
                          "wallet")
    sim, strain, stress, _ = run(params)
    finish(sim, params["out"], x=strain * 1e3, y=stress / MPa, xlabel="strain (per mille)",
           ylabel="compressive stress (MPa)", title="S3 wallet",
           reference=([0, strain[-1] * 1e3], [6.8, 6.8], "block strength 6.8 MPa"))
    k = int(np.argmax(stress))
    print(f"peak {stress[k] / MPa:.3f} MPa at strain {strain[k]:.2e}; final strain "
          f"{strain[-1]:.2e} = {strain[-1] / strain[k]:.1f} x peak strain")


if __name__ == "__main__":
    sys.exit(run_script(main))

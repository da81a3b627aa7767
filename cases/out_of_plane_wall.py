"""S6 out-of-plane wall: two-way bending of a 3.874 x 2.765 m wall under airbag pressure (COMP-11).

A 3.874 m long x 2.765 m high (34 courses) x 0.102 m running-bond wall of 220 x 81 x 102 mm bricks
on a fixed foundation block, a stiff steel beam on its top course, the joints of the calibrated
masonry law (also against the foundation and the beam). Supports of a two-way spanning wall:

* the beam carries the pre-compression (0.05 MPa x plan area with the self-weight, as in the S5
  rig) and holds the top against out-of-plane motion (beam ``x``, ``y``, ``ry``, ``rz`` held,
  ``rx`` free: a line support, around which the top joint may open);
* the nodes of both vertical edges (``x = 0`` and ``x = L``) are held in ``y``;
* the foundation is fixed.

Stage ``push``: a uniform pressure on the face ``y = 0`` of every wall brick (the airbag) whose
magnitude is the unknown of an indirect displacement control of the out-of-plane (``y``)
displacement of the node nearest the centre of the loaded face (the load factor ``lambda`` is
the total force, N): monotonic to 40 mm
(``protocol=monotonic``) or the cyclic amplitudes 2, 5, 10, 15, 20, 30 mm, one cycle each
(``protocol=cyclic``, :data:`dr_masonry.protocols.S6`; negative pressure = suction of the
reversed airbag). Output: total lateral force (pressure x loaded area) against the centre
displacement; crack and crushing maps of the wall's elevation at the points of ``maps``.

Reference (paper Fig. 20, after Graziotti et al. 2016): diagonal cracks running from the corners to
the centre and horizontal cracks at the base, at mid-height and at the top; the peak is followed
by a gentle softening, since the edges keep the cracked panel in two-way action.

Run: ``python cases/out_of_plane_wall.py [key=value ...]`` (or ``dr-masonry run
out_of_plane_wall``); ``mesh=coarse`` is one hexahedron per brick; ``fast=true`` runs a
0.88 x 0.81 m wall in a few increments (test suite). The full protocols' commands and measured
run times (hours): README, "Full protocols".
"""
import sys
from dataclasses import dataclass

import numpy as np

from dr_masonry import (Combined, Displacement, Indirect, JointLaw, PlasticDamage, Pressure,
                        Stage)
from dr_masonry.cases import squat_wall
from dr_masonry.cli import run_script
from dr_masonry.geometry import Wall, plane_nodes
from dr_masonry.loading import NodeSet
from dr_masonry.materials.joint import KC_PEN_FACTOR
from dr_masonry.model import quad_area_vector
from dr_masonry.postprocess import cycle_text, energy_per_cycle
from dr_masonry.protocols import S6, turning_points
from dr_masonry.scene import (RUN_PARAMS, at_floor, choice, compare_curve, equilibrium_text,
                              finish, peaks_text, run_stages, scene_params, solver_summary,
                              write_maps, write_run_pages)
from dr_masonry.units import MPa, kN, mm

PARAMS = dict(
    length=3.874,           # wall length, m (rounded down to whole half bricks)
    height=2.765,           # wall height, m (rounded to whole 81 mm courses)
    sigma=0.05 * MPa,       # vertical pre-compression on the wall's top, Pa
    protocol="monotonic",   # monotonic | cyclic
    target=S6.monotonic,    # monotonic target of the centre displacement, m
    increments=40,          # increments of the monotonic push
    grading=1.5,            # monotonic: i-th target = target * (i / increments) ** grading
    step=0.5 * mm,          # cyclic: largest displacement per increment, m (1 mm cut the peak
                            # inside the 2 mm cycle 15 % low: docs/validation.md, S6)
    quarter_increments=2,   # cyclic: fewest increments per quarter cycle
    n_amplitudes=0,         # cyclic: run only the first n amplitudes (0: all)
    pre_increments=4,       # increments of the pre-compression stage
    mesh="coarse",          # coarse (1 x 1 x 1 hexahedra per brick) | fine (4 x 1 x 2)
    kc_factor=KC_PEN_FACTOR,  # compression penalty of the joints / knn (its model error:
                            # docs/validation.md, "The compression penalty")
    gravity=True,
    beam_height=0.20,       # steel loading beam height, m
    **RUN_PARAMS,
    fast=False,             # preset FAST: tiny 0.88 x 0.81 m coarse wall, few increments
    out="results/out_of_plane_wall",
)
#: overrides of ``fast=true``: a 4 x 10 brick wall, a few increments (seconds)
FAST = dict(length=0.88, height=0.81, mesh="coarse", target=3 * mm, increments=6,
            pre_increments=2, step=1.0 * mm, n_amplitudes=2)
#: history columns of the curve (for studies): centre displacement, total lateral force
CURVE = dict(x="centre.uy", y="lambda", stage="push", xscale=1e3, yscale=1e-3,
             xlabel="centre displacement (mm)", ylabel="lateral force (kN)")
#: 3-D damage views (dr_masonry.viz.views.damage_view): the wall's front (loaded, y = 0) and back
#: faces, bricks by tensile damage, the damaged joints (paper Fig. 20)
VIEWS = {"view_front": dict(camera="elevation", field="dt"),
         "view_back": dict(camera="back", field="dt")}


@dataclass(frozen=True)
class OutOfPlaneWall:
    """The scene data of the S6 wall, returned by :func:`build` and :func:`run`."""
    wall: Wall            # the wall's geometry
    centre: NodeSet       # the control node, nearest the centre of the loaded face
    airbag: Combined      # the pressure's load pattern (factor 1 = 1 N lateral force in all)
    loaded_area: float    # m^2, area of the pressurised face


def build(params):
    """``(sim, stages, scene)``: the simulation, its stages and the :class:`OutOfPlaneWall`."""
    kind = choice(params, "protocol", ("monotonic", "cyclic"))
    sim, rig, pre = squat_wall.rig(params, JointLaw.reference(), PlasticDamage.reference())
    model, wall, beam = sim.model, rig.wall, rig.beam
    L, H = wall.length, wall.height
    bricks = [b for c in wall.courses for b in c]
    quads = np.concatenate([model.block_face(b, 2)[1] for b in bricks])  # faces y = 0
    loaded_area = float(np.linalg.norm(quad_area_vector(model.nodes[quads]), axis=1).sum())
    # factor 1 = 1 N in all: the load factor is the total lateral force
    airbag = Combined([(Pressure(quads, name="pressure"), 1.0 / loaded_area)], name="airbag")
    face = plane_nodes(model, 1, 0.0, blocks=bricks)  # the control node must carry pressure
    d2 = (model.nodes[face, 0] - 0.5 * L) ** 2 + (model.nodes[face, 2] - 0.5 * H) ** 2
    centre = sim.node_set("centre", face[[int(np.argmin(d2))]])
    edges = np.concatenate([plane_nodes(model, 0, 0.0, blocks=bricks),
                            plane_nodes(model, 0, L, blocks=bricks)])
    sim.node_set("edges", edges)
    pre += [Displacement(target=beam, dof=d, to=0.0) for d in ("x", "y", "ry", "rz")]
    pre.append(Displacement(target=sim.node_sets["edges"], dof="y", to=0.0))
    if kind == "monotonic":
        path = S6.monotonic_path(params["increments"], target=params["target"],
                                 grading=params["grading"])
    else:
        path = S6.path(step=params["step"], quarter_increments=params["quarter_increments"],
                       n_amplitudes=params["n_amplitudes"] or None)
    stages = [Stage("precompression", params["pre_increments"], pre,
                    frames=params["pre_increments"]),
              Stage("push", path.size, [Indirect(pattern=airbag, target=centre, dof="y",
                                                 path=path, name="airbag")],
                    frames=params["frames"], frame_at=turning_points(path))]
    return sim, stages, OutOfPlaneWall(wall, centre, airbag, loaded_area)


def run(params):
    """Run; returns (simulation, history with a ``lateral_force`` column (N), push mask,
    :class:`OutOfPlaneWall`)."""
    sim, stages, scene = build(params)
    hist = run_stages(sim, stages, params)
    push = hist["increment"] > stages[0].increments
    hist["lateral_force"] = np.where(push, hist["lambda"], 0.0)
    return sim, hist, push, scene


def report(sim, hist, push, scene):
    """One-line summary: peak lateral force (both directions' in a cyclic run) at its centre
    displacement, and as a pressure (``scene``: the :class:`OutOfPlaneWall`); damage, iterations
    per increment."""
    u, F = curve(hist, push)
    balance = equilibrium_text(F, support_reaction(sim, hist, push, scene),
                               at_floor(sim, hist, push))
    return (f"peak lateral force {peaks_text(u, F)} centre displacement (pressure "
            f"{peaks_text(u, F / scene.loaded_area, 1e3, 'kPa')}); {balance}; "
            + solver_summary(hist, push))


def support_reaction(sim, hist, rows, scene):
    """The out-of-plane reaction of the held edges, the top beam and the foundation (N) that
    balances the lateral force of the history rows ``rows``, less the airbag's pressure on the
    held edge nodes (node-set reactions leave out the load on their own nodes); ``scene``: the
    :class:`OutOfPlaneWall`."""
    P = sim.pattern_forces(scene.airbag)[0]
    direct = hist["lambda"][rows] * P[sim.node_sets["edges"].nodes, 1].sum()
    return -(hist["edges.fy"][rows] + hist["beam.fy"][rows] + hist["base.fy"][rows]) + direct


def curve(hist, rows):
    """Centre displacement and total lateral force (m, N) of the history rows ``rows`` (the load
    factor of the push is the lateral force)."""
    return hist["centre.uy"][rows], hist["lambda"][rows]


def main(argv=None):
    params = scene_params(PARAMS, FAST, sys.argv[1:] if argv is None else argv, __doc__,
                          "out_of_plane_wall")
    sim, hist, push, scene = run(params)
    cycles = (energy_per_cycle(hist, "centre.uy", push, force="lateral_force")
              if params["protocol"] == "cyclic" else None)
    x, y = curve(hist, push)
    finish(sim, params["out"], x=x / mm, y=y / kN, xlabel="centre displacement (mm)",
           ylabel="lateral force (kN)", title=f"S6 out-of-plane wall, {params['protocol']}",
           cycles=cycles, label=f"this run ({params['protocol']})",
           reaction=support_reaction(sim, hist, push, scene) / kN, floor=at_floor(sim, hist, push),
           reference=compare_curve(params, "pre_increments", curve))
    write_maps(sim, params, params["out"], squat_wall.MAPS, x, y, push, VIEWS, CURVE)
    write_run_pages(sim, params)
    print(report(sim, hist, push, scene))
    if cycles:
        print(cycle_text(cycles))


if __name__ == "__main__":
    sys.exit(run_script(main))

"""S5 squat wall: in-plane cyclic shear-compression of a 4.00 x 2.75 m wall (paper COMP-6).

A 4.00 m long x 2.75 m high (34 courses) x 0.102 m running-bond wall of 220 x 81 x 102 mm
expanded bricks stands on a fixed foundation block; a stiff steel loading beam (elastic,
E = 210 GPa) sits on its top course. All joints, including the wall-foundation and the wall-beam
bed joints, follow the calibrated masonry joint law (the test specimen has mortar bed joints
against both beams, so the beam may lift and slide like any bed joint; a tied joint would forbid
the top-course decompression that the test shows). The beam's nodes are tied to a reference point
at the centre of the wall's top face:

* stage 1 ``precompression``: gravity and a constant vertical force, so that the top of the wall
  carries 0.30 MPa x plan area (the beam's own weight is subtracted from the force); the beam's
  x, y, rx, rz DOFs are held, ry is free (cantilever) or held (``bc=double_clamped``);
* stage 2 ``push``: horizontal displacement of the beam, monotonic to 1.0 % drift
  (``protocol=monotonic``) or the cyclic protocol 0.025 ... 0.75 % drift, two cycles each
  (``protocol=cyclic``, :data:`dr_masonry.protocols.S5`).

``control=diagonal`` pushes the monotonic run with the wall's diagonal elongation held instead
of the beam's displacement (a diagonal transducer's control, :func:`diagonal_push`): the beam's
horizontal force is the unknown, the push ends at the row where the beam reaches the drift
target, and the drops where the diagonal crack extends, which displacement control jumps, are
followed row by row (BENCHMARKS.md, "Path-following controls").

Output: base shear (the actuator force ``beam.fx``) against top displacement (``beam.ux``); the
foundation's reactions are recorded as ``base.fx/fy/fz``; crack and crushing maps of the wall at
the points of ``maps``. Reference (paper Figs. 15-17): shear
failure with diagonal stair-stepped cracks through joints and blocks, peak base shear about
equal in the cyclic and monotonic runs. ``variant=PAR_A..PAR_E`` are the sensitivity analyses of
paper Fig. 18 (doubled ft and u_k; c and delta_k; tan(phi) and mu; block compressive strength and
its fracture energy; all of these), ``shear_damage=paper`` the literal eq. (7) of the paper.

Run: ``python cases/squat_wall.py [key=value ...]`` (or ``dr-masonry run squat_wall``). The
default, coarse monotonic run (one hexahedron per brick, 5260 nodes, 5036 contacts; 60 graded
increments to 1 % drift: 30 put the peak 5.4 % low) takes about 1 min 45 s alone on 2 cores (64
rows, no cut, 145,630 iterations), its 3-D views and run report about 5 s more;
``mesh=fine`` (CASES.md's 4 x 1 x 2 hexahedra per brick, 20000 nodes) costs about 3.4 times more
per iteration: 15 min 53 s on one thread with ``floor_tol=1e-3 stall_iter=3000`` (BENCHMARKS.md,
"Scene run times").
The energy balance error of these coarse increments reaches a few per cent (trapezoidal rule of
the external work over large steps; it shrinks with the step, see tests/test_walls.py).
``fast=true`` runs a 0.88 x 0.81 m coarse wall in a few increments (test suite). The full
protocols' commands and measured run times: README, "Full protocols".
"""
import sys
from dataclasses import dataclass

import numpy as np

from dr_masonry import (Displacement, Force, JointLaw, Load, Model, Opening, PlasticDamage,
                        Simulation, Stage, Until)
from dr_masonry.cli import run_script
from dr_masonry.geometry import BrickSpec, Wall, add_beam, add_foundation, add_wall, plane_nodes
from dr_masonry.loading import Gravity, NodeSet, PointLoad, RigidPoint
from dr_masonry.materials.joint import KC_PEN_FACTOR
from dr_masonry.params import ParameterError
from dr_masonry.postprocess import cycle_text, energy_per_cycle
from dr_masonry.protocols import S5, turning_points
from dr_masonry.scene import (RUN_PARAMS, at_floor, choice, compare_curve, equilibrium_text,
                              finish, peaks_text, run_stages, scene_params, solver_options,
                              solver_summary, with_penalty, write_maps,
                              write_run_pages)
from dr_masonry.units import MPa, kN, mm

PARAMS = dict(
    length=4.00,            # wall length, m
    height=2.75,            # wall height, m (rounded to whole 81 mm courses)
    sigma=0.30 * MPa,       # vertical pre-compression on the wall's top, Pa
    bc="cantilever",        # cantilever (beam rotation free) | double_clamped (held)
    protocol="monotonic",   # monotonic | cyclic
    drift=S5.monotonic,     # monotonic target, % of the height
    increments=60,          # increments of the monotonic push (30: peak 5.7 % low)
    control="displacement",  # displacement: the beam's x displacement follows the protocol |
                            # diagonal (monotonic only): the wall's diagonal elongation (the
                            # top-right minus the bottom-left corner brick, along the line joining
                            # them: a diagonal transducer) is held, the beam's force is the
                            # unknown, and the push ends at the drift target; softening that
                            # snaps under displacement control is traced (loading.Opening)
    diagonal_step=0.15 * mm,  # control=diagonal: diagonal elongation per increment, m
    opening_rate=1e-3,      # control=diagonal: loading.Opening rate (how fast the force follows)
    grading=1.5,            # monotonic: i-th target = drift * (i / increments) ** grading
    step=0.25 * mm,         # cyclic: largest displacement per increment, m (0.5 mm put the
                            # peak of the 0.1 % cycles 6 % low)
    quarter_increments=2,   # cyclic: fewest increments per quarter cycle
    n_amplitudes=0,         # cyclic: run only the first n amplitudes (0: all)
    pre_increments=4,       # increments of the pre-compression stage
    mesh="coarse",          # coarse (1 x 1 x 1 hexahedra per brick) | fine (4 x 1 x 2)
    shear_damage="calibrated",  # calibrated | paper (JointLaw.shear_damage)
    kc_factor=KC_PEN_FACTOR,    # compression penalty of the joints / knn (its model error:
                            # docs/validation.md, "The compression penalty")
    variant="reference",    # reference | PAR_A | PAR_B | PAR_C | PAR_D | PAR_E
    gravity=True,           # self-weight of wall and beam
    bricks="reference",     # reference (plastic-damage law) | elastic (the same E and nu: the
                            # bricks neither crack nor crush; joints alone fail)
    beam_z="load",          # load: the beam carries the constant vertical force N and moves up
                            # and down freely (the test's actuators) | held: its vertical
                            # displacement is held after the pre-compression (N then varies)
    beam_out_of_plane="held",   # held: the beam's out-of-plane displacement and rotations (y,
                            # rx, rz) held | free: its rotations rx, rz free (y stays held)
    beam_height=0.20,       # steel loading beam height, m
    **RUN_PARAMS,
    fast=False,             # preset FAST: tiny 0.88 x 0.81 m coarse wall, few increments
    out="results/squat_wall",
)
#: overrides of ``fast=true``: a 4 x 10 brick wall, a few increments (seconds)
FAST = dict(length=0.88, height=0.81, mesh="coarse", drift=0.2, increments=20, grading=1.5,
            pre_increments=2, step=0.4 * mm, n_amplitudes=2)
#: the response curve (dr_masonry.study): base shear (kN) against top displacement (mm) of the push
CURVE = dict(x="beam.ux", y="beam.fx", stage="push", xscale=1 / mm, yscale=1 / kN,
             xlabel="top displacement (mm)", ylabel="base shear (kN)")

STEEL = PlasticDamage.elastic(210e9, 0.3, 7850.0)       # loading beam
CONCRETE = PlasticDamage.elastic(30e9, 0.2, 2400.0)     # foundation (fixed)
MESHES = {"fine": BrickSpec(), "coarse": BrickSpec(nx_along=1, nz_height=1, ny_thick=1)}
#: sensitivity variants (paper Fig. 18): which parameter pairs are doubled
VARIANTS = {"reference": "", "PAR_A": "A", "PAR_B": "B", "PAR_C": "C", "PAR_D": "D",
            "PAR_E": "ABCD"}


def materials(variant="reference", shear_damage="calibrated"):
    """(JointLaw, brick PlasticDamage) of a sensitivity variant (paper Fig. 18).

    PAR_A doubles ft and u_k, PAR_B c and delta_k, PAR_C tan(phi) and mu, PAR_D the block's
    compressive strength and fracture energy (the compression table's stresses x 2 at the same
    inelastic strains, so its area doubles), PAR_E all of these.
    """
    if variant not in VARIANTS:
        raise ParameterError(f"parameter variant={variant!r}: valid values are {list(VARIANTS)}")
    law = JointLaw.reference(shear_damage=shear_damage)
    block = PlasticDamage.reference()
    which = VARIANTS[variant]
    if "A" in which:
        law = law.with_changes(ft=2 * law.ft, u_k=2 * law.u_k)
    if "B" in which:
        law = law.with_changes(c=2 * law.c, delta_k=2 * law.delta_k)
    if "C" in which:
        law = law.with_changes(tan_phi=2 * law.tan_phi, mu=2 * law.mu)
    if "D" in which:
        block = block.with_changes(compression=tuple((2 * s, e, d) for s, e, d in block.compression))
    return law, block


@dataclass(frozen=True)
class Rig:
    """The scene data of a wall in the loading rig (S4, S5, S6), returned by :func:`rig` and
    :func:`build`."""
    wall: Wall             # the wall's geometry (blocks, courses, length, height, thickness)
    beam: RigidPoint       # the loading beam's reference point (history ``beam.*``)
    base: NodeSet          # the foundation's top-face node set (reactions ``base.f*``)
    n_top: float           # N, the vertical force on the wall's top (sigma x plan area)
    weight_wall: float     # N, the wall's self-weight (0 without gravity)


def rig(params, law, block):
    """A wall on a fixed foundation under a stiff steel loading beam (S4, S5, S6).

    Uses ``length``, ``height``, ``mesh``, ``beam_height``, ``gravity``, ``sigma``, the
    solver options (``scene.OPTION_KEYS``), ``kc_factor`` (the joints' compression penalty, x knn)
    of ``params``. Returns
    ``(sim, rig, pre)``: the simulation, the :class:`Rig` (the wall, the beam's reference point at
    the centre of the wall's top face, the foundation's top-face node set, the top force and the
    wall's weight) and the pre-compression controls (gravity and the force ``N`` that makes the
    top of the wall carry ``sigma`` x plan area, the beam's weight subtracted; the base held).
    """
    if not params["sigma"] >= 0:
        raise ParameterError(f"parameter sigma={params['sigma']!r}: must be >= 0 Pa (compression)")
    brick = MESHES[choice(params, "mesh", tuple(MESHES))]
    model = Model()
    model.set_joint_law(with_penalty(law, params["kc_factor"]))
    if not (np.isfinite(params["height"]) and params["height"] >= 0.5 * brick.height):
        raise ParameterError(f"parameter height={params['height']!r}: must be at least half a "
                             f"course ({brick.height} m)")
    courses = int(round(params["height"] / brick.height))
    wall = add_wall(model, (0, 0, 0), params["length"], courses * brick.height, block,
                    brick=brick, fit="cut")
    L, t, H = wall.length, wall.thickness, wall.height
    esize = (brick.length / brick.nx_along, t / brick.ny_thick, brick.height / brick.nz_height)
    fnd = add_foundation(model, (0, 0, -0.2), (L, t, 0.2), CONCRETE, element_size=esize)
    hb = params["beam_height"]
    beam_block = add_beam(model, (0, 0, H), (L, t, hb), STEEL, element_size=esize)
    sim = Simulation(model, solver_options(params), output=params.get("h5"), config=params)
    beam = sim.rigid_point("beam", blocks=[beam_block], position=(0.5 * L, 0.5 * t, H))
    base = sim.node_set("base", plane_nodes(model, 2, 0.0, blocks=[fnd]))
    g = Gravity()
    weight_beam = STEEL.density * L * t * hb * g.g if params["gravity"] else 0.0
    weight_wall = block.density * L * t * H * g.g if params["gravity"] else 0.0
    n_top = params["sigma"] * L * t
    if n_top < weight_beam:
        raise ParameterError(f"parameter sigma={params['sigma']!r} Pa: the beam's weight alone "
                             f"({weight_beam / (L * t):.4g} Pa) exceeds the pre-compression")
    pre = [Force(target=beam, dof="z", to=-(n_top - weight_beam), name="N")]
    pre += [Displacement(target=base, dof=d, to=0.0) for d in "xyz"]
    if params["gravity"]:
        pre.append(Load(pattern=g, to=1.0))
    return sim, Rig(wall, beam, base, n_top, weight_wall), pre


def build(params, protocol=S5):
    """``(sim, stages, rig)`` of an in-plane wall test (S5 squat wall; S4 uses ``protocol=S4``):
    the simulation, its stages and the scene's :class:`Rig` (wall, beam, base, top force, wall
    weight)."""
    bc = choice(params, "bc", ("cantilever", "double_clamped"))
    kind = choice(params, "protocol", ("monotonic", "cyclic"))
    choice(params, "shear_damage", ("calibrated", "paper"))
    law, block = materials(params["variant"], params["shear_damage"])
    if choice(params, "bricks", ("reference", "elastic")) == "elastic":
        block = PlasticDamage.elastic(block.E, block.nu, block.density)
    hold_z = choice(params, "beam_z", ("load", "held")) == "held"
    out_of_plane = ("y",) + (("rx", "rz") if choice(params, "beam_out_of_plane",
                                                    ("held", "free")) == "held" else ())
    sim, scene, pre = rig(params, law, block)
    beam = scene.beam
    held = out_of_plane + (("ry",) if bc == "double_clamped" else ())
    pre += [Displacement(target=beam, dof="x", to=0.0, name="push")]
    pre += [Displacement(target=beam, dof=d, to=0.0) for d in held]
    H = scene.wall.height
    if kind == "monotonic":
        path = protocol.monotonic_path(params["increments"], H, params["drift"], params["grading"])
    else:
        path = protocol.path(H, step=params["step"],
                             quarter_increments=params["quarter_increments"],
                             n_amplitudes=params["n_amplitudes"] or None)
    beam_z = [Displacement(target=beam, dof="z", name="beam_z")] if hold_z else []
    stages = [Stage("precompression", params["pre_increments"], pre, frames=params["pre_increments"])]
    if choice(params, "control", ("displacement", "diagonal")) == "diagonal":
        if kind != "monotonic":
            raise ParameterError("parameter control='diagonal' drives a monotonic push: give "
                                 "protocol=monotonic (a cyclic half-cycle would need the other "
                                 "diagonal)")
        stages.append(diagonal_push(sim, scene, path[-1], params, beam_z))
    else:
        stages.append(Stage("push", path.size,
                            [Displacement(target=beam, dof="x", path=path, name="push")] + beam_z,
                            frames=params["frames"], frame_at=turning_points(path)))
    return sim, stages, scene


def corner_bricks(sim, wall, sense=1.0):
    """The node sets of the wall's bricks nearest the ends of the diagonal that a push in the
    sense of ``sense`` (+: x, -: -x) lengthens, bottom corner first (bottom-left and top-right
    for +x), and the unit vector (3,) from the first brick's centre to the second's."""
    m = sim.model
    cent = np.array([m.nodes[m.block_nodes([b])].mean(0) for b in range(m.n_blocks)])
    inside = np.flatnonzero((cent[:, 2] > 0) & (cent[:, 2] < wall.height))
    ends = (((0.0, 0.0), (wall.length, wall.height)) if sense > 0
            else ((wall.length, 0.0), (0.0, wall.height)))
    pick = [inside[np.argmin(np.hypot(cent[inside, 0] - x, cent[inside, 2] - z))]
            for x, z in ends]
    axis = cent[pick[1]] - cent[pick[0]]
    names = ("bottom_left", "top_right") if sense > 0 else ("bottom_right", "top_left")
    return (sim.node_set(names[0], m.block_nodes([pick[0]])),
            sim.node_set(names[1], m.block_nodes([pick[1]])), axis / np.linalg.norm(axis))


def diagonal_push(sim, scene, target, params, extra=()):
    """The push under opening control (``control=diagonal``): the wall's diagonal elongation
    (:func:`corner_bricks`) grows by ``diagonal_step`` per increment, the beam's horizontal force
    (a 1 kN pattern; history ``lambda`` in kN) found with ``Opening(rate=opening_rate)``; the
    stage ends at the increment where the beam reaches ``target`` m (its elongation's path runs
    to |target|: past the peak the diagonal opens about as fast as the beam moves)."""
    step = params["diagonal_step"]
    if not (np.isfinite(step) and 0.0 < step <= abs(target)):
        raise ParameterError(f"parameter diagonal_step={step!r}: must be a length in (0, "
                             f"{abs(target):.4g}] m (the push's target)")
    a, b, direction = corner_bricks(sim, scene.wall, np.sign(target))
    n = int(np.ceil(abs(target) / step))
    shear = PointLoad(target=scene.beam, dof="x", value=np.sign(target) * kN, name="shear")
    push = Opening(pattern=shear, a=a, b=b, direction=direction, dof="x", name="diagonal",
                   to=abs(target), rate=params["opening_rate"])
    return Stage("push", n, [push, Force(target=scene.beam, dof="x", to=0.0, name="beam_x"),
                             *extra],
                 frames=params["frames"], until=Until(scene.beam, "x", target))


def run(params, protocol=S5):
    """Run; returns (simulation, history, push-stage mask (bool array), :class:`Rig`)."""
    sim, stages, scene = build(params, protocol)
    hist = run_stages(sim, stages, params)
    return sim, hist, hist["increment"] > stages[0].increments, scene


def report(sim, hist, push):
    """One-line summary: peak base shear (both directions' in a cyclic run) at its top
    displacement, damage, iterations per increment."""
    u, V = curve(hist, push)
    return (f"peak base shear {peaks_text(u, V)} top displacement; "
            f"{equilibrium_text(V, base_reaction(hist, push), at_floor(sim, hist, push))}; "
            + solver_summary(hist, push))


def curve(hist, rows):
    """Top displacement and base shear (m, N) of the history rows ``rows``."""
    return hist["beam.ux"][rows], hist["beam.fx"][rows]


def base_reaction(hist, rows):
    """The foundation's horizontal reaction that balances the base shear (N) of the history
    rows ``rows``."""
    return -hist["base.fx"][rows]


#: crack maps of the wall's elevation: joint damage with block tensile, and with compressive damage
MAPS = {"cracks": dict(plane="xz", blocks="wall"),
        "crushing": dict(plane="xz", blocks="wall", element_field="dc")}
#: 3-D damage views (dr_masonry.viz.views.damage_view) of the wall's elevation: bricks by tensile,
#: and by compressive damage, the damaged joints on both
VIEWS = {"view_cracks": dict(camera="elevation", field="dt"),
         "view_crushing": dict(camera="elevation", field="dc")}


def main(argv=None, doc=__doc__, defaults=PARAMS, protocol=S5, title="S5 squat wall",
         scene="squat_wall"):
    params = scene_params(defaults, FAST, sys.argv[1:] if argv is None else argv, doc, scene)
    sim, hist, push, _ = run(params, protocol)
    cycles = (energy_per_cycle(hist, "beam.ux", push, force="beam.fx")
              if params["protocol"] == "cyclic" else None)
    x, y = curve(hist, push)
    finish(sim, params["out"], x=x / mm, y=y / kN, xlabel="top displacement (mm)",
           ylabel="base shear (kN)",
           title=f"{title}, {params['protocol']}, {params['bc']}, {params['variant']}",
           cycles=cycles, label=f"this run ({params['protocol']})",
           reaction=base_reaction(hist, push) / kN, floor=at_floor(sim, hist, push),
           reference=compare_curve(params, "pre_increments", curve))
    write_maps(sim, params, params["out"], MAPS, x, y, push, VIEWS, CURVE)
    write_run_pages(sim, params)
    print(report(sim, hist, push))
    if cycles:
        print(cycle_text(cycles))


if __name__ == "__main__":
    sys.exit(run_script(main))

"""S7 terraced house: quasi-static pushover of a two-storey masonry house (paper Sec. 5.3).

A parametric two-storey house after the TU Delft full-scale calcium-silicate test (Esposito et
al. 2019; paper Fig. 9), built by :func:`dr_masonry.geometry.terraced_house` (dimensions in
:class:`~dr_masonry.geometry.HouseParams`): two transversal (party) walls carry two floors of
precast concrete slabs; the front facade has one large opening per storey between a wide
(1.1 m) and a narrow (0.6 m) pier, toothed into the transversal walls. Half model by symmetry:
the mid-plane ``y = depth / 2`` (parallel to the facade and to the load) holds ``u_y = 0``; each
floor's slab is tied to a reference point (``floor1``, ``floor2``) whose ``y``, ``rx``, ``rz`` are
held by the symmetry. Masonry: the calibrated bricks and joints of MODEL.md section 4; slabs,
lintels and foundation elastic concrete (slab density scaled so that the slabs, rounded to whole
courses, weigh as 0.2 m slabs).

* stage ``gravity``: self-weight;
* stage ``push``: equal horizontal forces along the facade (``x``) at the two floors, their
  magnitude the unknown of an indirect displacement control of the top floor's ``x``
  displacement: monotonic to ``direction`` x 60 mm (``protocol=monotonic``) or the reduced
  cyclic protocol +/-2.5, 5, 10, 20, 30, 40, 50, 60 mm, one cycle each (``protocol=cyclic``,
  :data:`dr_masonry.protocols.S7`).

Output: base shear of the whole house (2 x the half model's: twice the floor force, two floors)
against the top-floor displacement (total reactions ``base.f*``); the vertical reaction of each wall and pier
(``base_W1.fz``, ``base_W2.fz``, ``base_P1.fz`` wide pier, ``base_P2.fz`` narrow pier, half model,
N) against it (paper Fig. 26, ``out_reactions.png``); crack maps of the facade and of each
transversal wall and the facade's crushing map at the points of ``maps``.

Reference (paper Figs. 22-26): in the positive direction (towards the narrow pier) a shear/
vertical crack opens in the wide pier, in the negative direction the piers rock; the peak base
shear differs between the directions; as the house sways, the vertical load moves between the
transversal walls and the piers (Fig. 26). The paper's implicit monotonic run took 2 h 09 min on
a 2-core laptop.

Run: ``python cases/terraced_house.py [key=value ...]`` (or ``dr-masonry run terraced_house``).
``mesh=coarse`` (default: one hexahedron per brick) or ``mesh=fine`` (4 x 1 x 2 per brick);
``fast=true`` runs a small coarse house of large blocks in a few increments (test suite). The
full protocols' commands and measured run times (hours): README, "Full protocols".
"""
import sys
from dataclasses import dataclass, replace

import numpy as np

from dr_masonry import (Combined, Displacement, Indirect, JointLaw, Load, Model, PlasticDamage,
                        PointLoad, Simulation, Stage)
from dr_masonry.cli import run_script
from dr_masonry.geometry import BrickSpec, HouseParams, terraced_house
from dr_masonry.loading import Gravity
from dr_masonry.materials.joint import KC_PEN_FACTOR
from dr_masonry.postprocess import cycle_text, energy_per_cycle
from dr_masonry.protocols import S7, turning_points
from dr_masonry.scene import (RUN_PARAMS, at_floor, choice, compare_curve, equilibrium_text,
                              finish, peaks_text, run_stages, scene_params, solver_options,
                              solver_summary, with_penalty, write_maps,
                              write_run_pages)
from dr_masonry.units import kN, mm
from dr_masonry.viz.plots import plot_history

PARAMS = dict(
    direction=1,            # +1: push towards the narrow pier (+x), -1: towards the wide pier
    protocol="monotonic",   # monotonic | cyclic
    target=S7.monotonic,    # monotonic target of the top-floor displacement, m
    increments=30,          # increments of the monotonic push
    grading=1.5,            # monotonic: i-th target = target * (i / increments) ** grading
    step=2.5 * mm,          # cyclic: largest displacement per increment, m
    quarter_increments=2,   # cyclic: fewest increments per quarter cycle
    n_amplitudes=0,         # cyclic: run only the first n amplitudes (0: all)
    gravity_increments=4,
    mesh="coarse",          # coarse (1 x 1 x 1 hexahedra per brick) | fine (4 x 1 x 2)
    slab_element=0.22,      # slab and foundation hexahedron size in plan, m
    kc_factor=KC_PEN_FACTOR,  # compression penalty of the joints / knn (its model error:
                            # docs/validation.md, "The compression penalty")
    **RUN_PARAMS,
    fast=False,             # preset FAST: small coarse house of large blocks, few increments
    out="results/terraced_house",
)
#: overrides of ``fast=true``
FAST = dict(mesh="tiny", target=3 * mm, increments=5, gravity_increments=2, step=2.0 * mm,
            n_amplitudes=1, slab_element=0.44)
#: history columns of the curve (for studies): top-floor displacement, base shear (half model)
CURVE = dict(x="floor2.ux", y="lambda", stage="push", xscale=1e3, yscale=4e-3,  # kN of the whole house: 2 floors x 2 halves
             xlabel="top displacement (mm)", ylabel="base shear, whole house (kN)")
#: 3-D damage views (dr_masonry.viz.views.damage_view): the facade, and the house from a corner with
#: the facade (the blocks whose centre is within a brick's thickness of y = 0) cut away so that the
#: transversal walls show (paper Figs. 24-25)
VIEWS = {"view_facade": dict(camera="facade", field="dt"),
         "view_inside": dict(camera="iso", field="dt", cut=(1, BrickSpec().thickness))}

CONCRETE = PlasticDamage.elastic(30e9, 0.2, 2400.0)
MESHES = {"coarse": BrickSpec(nx_along=1, nz_height=1, ny_thick=1), "fine": BrickSpec()}
#: reactions of the foundation on each wall and pier (paper Fig. 26): history name -> block group
REACTIONS = {"base_P1": "pier_wide", "base_P2": "pier_narrow", "base_W1": "transversal_wall_1",
             "base_W2": "transversal_wall_2"}


@dataclass(frozen=True)
class House:
    """The scene data of the S7 house, returned by :func:`build` and :func:`run`."""
    groups: dict          # the generator's block groups, name -> block ids (terraced_house)
    floors: list          # the slabs' reference points (RigidPoint), bottom first
    house_params: HouseParams   # the house's dimensions and mesh


def house_params(params):
    """The :class:`HouseParams` of a mesh choice (``tiny``: the scaled smoke-test house)."""
    mesh = choice(params, "mesh", (*MESHES, "tiny"))
    if mesh == "tiny":
        return replace(HouseParams().scaled(coarse=True), slab_element=params["slab_element"])
    return HouseParams(brick=MESHES[mesh], slab_element=params["slab_element"])


def build(params):
    """``(sim, stages, house)``: the simulation, its stages and the :class:`House` (block
    groups, floor reference points, HouseParams)."""
    choice(params, "direction", (1, -1))
    choice(params, "protocol", ("monotonic", "cyclic"))
    hp = house_params(params)
    lay = hp.layout()
    model = Model()
    model.set_joint_law(with_penalty(JointLaw.reference(), params["kc_factor"]))
    slab = CONCRETE.with_changes(density=CONCRETE.density * hp.slab_thickness / lay.slab_thickness)
    groups = terraced_house(model, hp, PlasticDamage.reference(), CONCRETE, slab)
    sim = Simulation(model, solver_options(params), output=params.get("h5"), config=params)
    floors = [sim.rigid_point(f"floor{i + 1}", blocks=groups[f"slabs_floor{i + 1}"])
              for i in range(hp.n_storeys)]
    tied = np.concatenate([f.nodes for f in floors])
    sym = np.setdiff1d(groups["symmetry_nodes"], tied)
    sim.fix(sym, "y")
    pre = [Load(pattern=Gravity(), to=1.0)]
    for f in floors:
        pre += [Displacement(target=f, dof=d, to=0.0) for d in ("y", "rx", "rz")]
    fnd = groups["foundation"]
    ids = model.block_nodes(fnd)
    base = sim.node_set("base", ids[np.isclose(model.nodes[ids, 2], 0.0)])
    pre += [Displacement(target=base, dof=d, to=0.0) for d in "xyz"]
    for name, group in REACTIONS.items():
        sim.contact_reaction(name, groups[group], fnd)
    pattern = Combined([(PointLoad(f, "x", 1.0, name=f"{f.name}_x"), 1.0) for f in floors],
                       name="floors")
    if params["protocol"] == "monotonic":
        path = params["direction"] * S7.monotonic_path(params["increments"],
                                                       target=params["target"],
                                                       grading=params["grading"])
    else:
        path = S7.path(step=params["step"], quarter_increments=params["quarter_increments"],
                       n_amplitudes=params["n_amplitudes"] or None,
                       start_negative=params["direction"] < 0)
    stages = [Stage("gravity", params["gravity_increments"], pre,
                    frames=params["gravity_increments"]),
              Stage("push", path.size, [Indirect(pattern=pattern, target=floors[-1], dof="x",
                                                 path=path, name="push")],
                    frames=params["frames"], frame_at=turning_points(path))]
    return sim, stages, House(groups, floors, hp)


def run(params):
    """Run; returns (simulation, history with ``base_shear`` (N, whole house), push mask,
    :class:`House`)."""
    sim, stages, house = build(params)
    hist = run_stages(sim, stages, params)
    push = hist["increment"] > stages[0].increments
    hist["base_shear"] = np.where(push, curve(hist, slice(None), len(house.floors))[1], 0.0)
    return sim, hist, push, house


def report(sim, hist, push, house):
    """One-line summary: peak base shear of the whole house (both directions' in a cyclic run)
    at its top displacement, damage, iterations per increment (``house``: the :class:`House`)."""
    u, V = curve(hist, push, len(house.floors))
    return (f"peak base shear (whole house) {peaks_text(u, V)} top displacement; "
            f"{equilibrium_text(V, base_reaction(hist, push), at_floor(sim, hist, push))}; "
            + solver_summary(hist, push))


def curve(hist, rows, floors=2):
    """Top-floor displacement and the whole house's base shear (m, N) of the history rows
    ``rows``: 2 x the half model's, whose floors' forces are each the load factor."""
    return hist[f"floor{floors}.ux"][rows], 2.0 * floors * hist["lambda"][rows]


def base_reaction(hist, rows):
    """The foundation's horizontal reaction that balances the base shear (N, whole house: 2 x
    the half model's) of the history rows ``rows``."""
    return -2.0 * hist["base.fx"][rows]


def maps(house):
    """Crack maps of the facade (piers, spandrels and lintels; x-z) and of each transversal wall
    (y-z) of the :class:`House` ``house``, joint damage with block tensile damage; the facade's
    crushing map."""
    g = house.groups
    facade = dict(plane="xz", blocks=np.concatenate([g["facade"], g["lintels"]]))
    return {"facade_cracks": facade, "facade_crushing": dict(facade, element_field="dc"),
            "wall1_cracks": dict(plane="yz", blocks=g["transversal_wall_1"]),
            "wall2_cracks": dict(plane="yz", blocks=g["transversal_wall_2"])}


def main(argv=None):
    params = scene_params(PARAMS, FAST, sys.argv[1:] if argv is None else argv, __doc__,
                          "terraced_house")
    sim, hist, push, house = run(params)
    top = f"{house.floors[-1].name}.ux"
    # cycles of the half model: its energies with its own base shear (half the house's)
    cycles = (energy_per_cycle(dict(hist, half_shear=0.5 * hist["base_shear"]), top, push,
                               force="half_shear") if params["protocol"] == "cyclic" else None)
    x, y = curve(hist, push, len(house.floors))
    out = params["out"]
    finish(sim, out, x=x / mm, y=y / kN, xlabel="top displacement (mm)",
           ylabel="base shear, whole house (kN)",
           title=f"S7 terraced house, {params['protocol']}, direction {params['direction']:+d}",
           cycles=cycles, label=f"this run ({params['protocol']})",
           reaction=base_reaction(hist, push) / kN, floor=at_floor(sim, hist, push),
           reference=compare_curve(
               params, "gravity_increments", lambda h, r: curve(h, r, len(house.floors))))
    if sim.output is not None:   # Fig. 26: the load moves between the walls and the piers
        plot_history(sim.output, top, [f"{k}.fz" for k in REACTIONS], out + "_reactions.png",
                     ylabel="vertical reaction, half model (kN)",
                     title="vertical reactions (paper Fig. 26): P1 wide pier, P2 narrow pier,\n"
                           "W1, W2 transversal walls")
    write_maps(sim, params, out, maps(house), x, y, push, VIEWS, CURVE)
    write_run_pages(sim, params)
    print(report(sim, hist, push, house))
    if cycles:
        print("cycles of the half model (base shear and energies half the house's):\n"
              + cycle_text(cycles))


if __name__ == "__main__":
    sys.exit(run_script(main))

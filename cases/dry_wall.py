"""Dry-joint block (or a stack of them) on a tilting table until it overturns or slides.

``courses`` blocks of ``width`` (b, along x) x ``depth`` x ``height`` (h each) stand on a clamped
base of the same footprint, every joint dry (``JointLaw.dry(mu)``); the blocks are stiff elastic
hexahedra. Self-weight, then a horizontal body force ``lam g`` along +x ramped by ``step``
(a table tilted by ``theta``, ``lam = tan(theta)``; :mod:`dr_masonry.collapse`).

Reference (rigid-block statics, the closed form of the tilting-table test): the stack overturns
about its toe at ``lam = b / H`` (H = courses x h: the base joint carries the largest moment; the
resultant of the weight and the body force leaves the base there) or slides at ``lam = mu``
(every joint carries the same ratio of shear to normal force), whichever is smaller.

Collapse is the run's diagnosis, not an error: past the factor there is no equilibrium, the
solver stops (after ``max_cuts`` halvings of the increment, or at once on a run-away
displacement) and the scene reports the last converged factor, the factor of the failed attempt,
the mode from that attempt's motion (slides: a joint's slip is at least half the top's
displacement; overturns otherwise) and the closed form. Outputs: ``out.png``/``.csv`` (tilt
factor against the top's horizontal displacement), ``out_mechanism.png``, ``out.h5``.

The base has the block's footprint by default, on purpose: a contact point sits at each node of
the slave face (the finer mesh), so a rocking block turns about the outermost slave node. On a
wider, coarser base the slave nodes are the base's, inside the footprint, and the block rocks
about one of them: ``base_overhang=0.1 base_nx=3`` (a 0.4 m base of three elements under the
0.2 x 0.4 m block, nodes at x = 0.033 and 0.167 m inside it) overturns at lam = 1/3 instead of
0.5 (docs/validation.md, "Arches and dry stone").

Run: ``python cases/dry_wall.py [key=value ...]`` or ``dr-masonry run dry_wall``; about a second
after compilation (2 cores, 2026-12-06).
"""
import os
import sys

import numpy as np

from dr_masonry import JointLaw, Model, PlasticDamage, Simulation
from dr_masonry.cli import run_script
from dr_masonry.collapse import draw_mechanism, run_to_collapse, tilt_stages
from dr_masonry.params import ParameterError
from dr_masonry.results import make_folder
from dr_masonry.scene import finish, scene_params, solver_options
from dr_masonry.units import mm

PARAMS = dict(
    width=0.2,              # b, along x (the tilt's direction), m
    height=0.4,             # h of one block, m
    depth=0.2,              # along y, m
    courses=1,              # blocks stacked (dry joints between them)
    mu=0.8,                 # friction coefficient of the dry joints
    young=10e9,             # Young's modulus of the blocks, Pa (stiff: nearly rigid)
    density=2000.0,         # kg/m^3
    nx=1, nz=1,             # hexahedra per block along x and z
    base_overhang=0.0,      # the base's length beyond the blocks on each side along x, m
    base_nx=0,              # hexahedra of the base along x (0: nx)
    lam_max=1.0,            # largest tilt factor tried
    step=0.01,              # tilt factor step; the solver's cuts refine it by 2^max_cuts
    tol=1e-4,               # relative residual tolerance (SolverOptions)
    max_iter=100_000,       # iterations before an increment is cut (SolverOptions)
    max_cuts=4,             # halvings of an increment before the run stops: the collapse
    stall_iter=10_000,      # iterations without progress before an attempt is cut
    out="results/dry_wall",
)


def closed_form(params):
    """(factor, mode) of rigid-block statics: ``min(b / H, mu)``, "overturns" or "slides"."""
    tip = params["width"] / (params["courses"] * params["height"])
    return (tip, "overturns") if tip <= params["mu"] else (params["mu"], "slides")


def build(params):
    """(simulation, stages, blocks bottom first, base) of the scene, with the contact reaction
    ``base`` (blocks on the base) and the rigid point ``top`` on the top block's top face."""
    b, h, d, k = params["width"], params["height"], params["depth"], params["courses"]
    for key in ("width", "height", "depth"):
        if not (np.isfinite(params[key]) and params[key] > 0):
            raise ParameterError(f"parameter {key}={params[key]!r}: must be a length > 0 m")
    if not (isinstance(k, int) and k >= 1):
        raise ParameterError(f"parameter courses={k!r}: must be an integer >= 1")
    stages = tilt_stages(params["lam_max"], params["step"])
    model = Model()
    model.set_joint_law(JointLaw.dry(params["mu"]))
    mat = PlasticDamage.elastic(params["young"], 0.2, params["density"])
    div = (params["nx"], 1, params["nz"])
    over = params["base_overhang"]
    if not (np.isfinite(over) and over >= 0):
        raise ParameterError(f"parameter base_overhang={over!r}: must be a length >= 0 m")
    base = model.add_box((-over, 0.0, -0.5 * h), (b + 2 * over, d, 0.5 * h), mat,
                         (params["base_nx"] or params["nx"], 1, 1), fixed=True, group="base")
    blocks = [model.add_box((0.0, 0.0, j * h), (b, d, h), mat, div, group="block")
              for j in range(k)]
    sim = Simulation(model, solver_options(params), output=params.get("h5"), config=params)
    sim.contact_reaction("base", blocks, [base])
    nodes = model.block_nodes(blocks[-1])
    sim.rigid_point("top", nodes=nodes[np.isclose(model.nodes[nodes, 2], k * h)])
    return sim, stages, blocks, base


def mode(model, blocks, base, motion):
    """"slides" if some joint's slip in ``motion`` (n_nodes, 3) m is at least half the top's
    horizontal displacement, else "overturns"."""
    def face_ux(b, top):
        nd = model.block_nodes(b)
        z = model.nodes[nd, 2]
        return motion[nd[np.isclose(z, z.max() if top else z.min())], 0].mean()
    below = [base] + list(blocks[:-1])
    slip = [face_ux(b, False) - face_ux(a, True) for a, b in zip(below, blocks)]
    return "slides" if np.abs(slip).max() >= 0.5 * abs(face_ux(blocks[-1], True)) else "overturns"


def run(params):
    """Run the scene; returns (simulation, blocks, base, Collapse, mode or None)."""
    sim, stages, blocks, base = build(params)
    res = run_to_collapse(sim, stages, "base")
    how = mode(sim.model, blocks, base, res.motion) if res.collapsed else None
    return sim, blocks, base, res, how


def main(argv=None):
    params = scene_params(PARAMS, None, sys.argv[1:] if argv is None else argv, __doc__,
                          "dry_wall")
    sim, blocks, base, res, how = run(params)
    ref, ref_mode = closed_form(params)
    head = (f"dry stack of {params['courses']} block(s) b/H = "
            f"{params['width'] / (params['courses'] * params['height']):.4f}, mu = {params['mu']}")
    if res.collapsed:
        print(f"{head}: {how} between lam = {res.factor:.4f} (last converged) and "
              f"{res.failed:.4f} (no equilibrium); closed form {ref:.4f} ({ref_mode})\n"
              f"  solver: {res.message}")
        from matplotlib.figure import Figure
        fig = Figure(figsize=(3.2, 3.6))
        ax = fig.subplots()
        H = params["courses"] * params["height"]
        draw_mechanism(ax, sim.model, [base] + blocks, sim.dyn.U, res.motion,
                       0.1 * H / max(np.abs(res.motion).max(), 1e-300))
        ax.set_aspect("equal")
        ax.set(xlabel="x (m)", ylabel="z (m)", title=f"{how} at lam = {res.factor:.3f}")
        fig.tight_layout()
        make_folder(os.path.dirname(params["out"]) or ".")
        fig.savefig(params["out"] + "_mechanism.png", dpi=100)
    else:
        print(f"{head}: stands at lam = {res.factor:.4f}; closed form {ref:.4f} ({ref_mode})")
    finish(sim, params["out"], x=np.asarray(sim.history["top.ux"]) / mm, y=res.factors,
           xlabel="top horizontal displacement (mm)", ylabel="tilt factor lam",
           title="dry-joint block on a tilting table")
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))

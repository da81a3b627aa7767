"""Voussoir arch of dry joints under self-weight and on a tilting table, against limit analysis.

A semicircular arch of ``n`` flat-faced voussoirs (centreline radius ``radius``, radial
``thickness``, ``depth`` along y; :func:`dr_masonry.geometry.add_arch`) stands on two clamped
abutments. Its joints are dry (``JointLaw.dry(mu)``, no tension, no cohesion) with ``mu`` high
enough that sliding does not govern; the voussoirs are stiff elastic hexahedra (one each), so
the arch is a chain of nearly rigid blocks, which is what the reference assumes:

* ``load=gravity``: self-weight only. Reference: the minimum thickness of the thrust-line lower
  bound (Heyman 1969, "The safety of masonry arches", Int. J. Mech. Sci. 11; Milankovitch's
  t/R = 0.1075 for the continuous arch), here the linear program of ``tests/limit_analysis.py``
  for the same n voussoirs (t_min/R = 0.1049 for n = 12). Thinner than that, the arch collapses
  under its own weight at any gravity.
* ``load=tilt`` (default): the tilting table, self-weight then a horizontal body force ``lam g``
  along +x ramped by ``step`` to ``lam_max`` (:mod:`dr_masonry.collapse`). Reference: the same LP's
  largest ``lam`` and its four hinges (n = 12: 0.1573 at t/R = 0.15, 0.2852 at t/R = 0.2).

Collapse is the run's diagnosis, not an error: past the collapse factor the increment has no
equilibrium, the solver cuts it ``max_cuts`` times and stops; the scene reports the last converged
factor (from the abutments' reaction, ``-R_x / R_z``), the factor of the failed attempt, the
solver's message and the mechanism (the relative rotation of the voussoirs at each joint in the
failed attempt: the hinges, on the intrados or the extrados). Outputs: ``out.png``/``.csv``
(tilt factor against the crown's horizontal displacement), ``out_mechanism.png``, ``out.h5``.

Run: ``python cases/arch.py [key=value ...]`` or ``dr-masonry run arch``; n = 12, 0.4-3 s after
compilation (2 cores, 2026-12-06). The runs of docs/validation.md:
``python docs/make_arch_figures.py``.
"""
import os
import sys

import numpy as np

from dr_masonry import JointLaw, Model, PlasticDamage, Simulation
from dr_masonry.cli import run_script
from dr_masonry.collapse import (block_rotations, draw_mechanism, gravity_stage, run_to_collapse,
                                 tilt_stages)
from dr_masonry.geometry import add_arch
from dr_masonry.params import ParameterError
from dr_masonry.results import make_folder
from dr_masonry.scene import choice, finish, scene_params, solver_options
from dr_masonry.units import mm

PARAMS = dict(
    radius=1.0,             # centreline radius R, m
    thickness=0.15,         # radial thickness t, m
    n=12,                   # voussoirs
    depth=0.25,             # depth of the ring along y, m
    abutment_height=0.3,    # height of the springings above the ground, m
    mu=1.0,                 # friction coefficient of the dry joints
    knn=75e9,               # normal stiffness of the dry joints, Pa/m (shear: a tenth of it)
    young=10e9,             # Young's modulus of the voussoirs, Pa (stiff: nearly rigid blocks)
    density=2000.0,         # kg/m^3
    load="tilt",            # gravity | tilt
    lam_max=0.6,            # tilt: largest factor tried (lam = tan of the table's angle)
    step=0.01,              # tilt: factor step; the solver's cuts refine it by 2^max_cuts
    hinge_share=0.1,        # a joint is a hinge where its rotation in the failed attempt is at
                            # least this fraction of the largest
    tol=1e-4,               # relative residual tolerance (SolverOptions)
    max_iter=100_000,       # iterations before an increment is cut (SolverOptions)
    max_cuts=4,             # halvings of an increment before the run stops: the collapse
    stall_iter=10_000,      # iterations without progress before an attempt is cut
    out="results/arch",
)


def build(params):
    """(simulation, stages, arch) of the scene: the arch, the abutments' contact reaction
    ``abutments`` and a rigid point ``crown`` on the extrados face of voussoir ``n // 2``."""
    R, t = params["radius"], params["thickness"]
    if not (np.isfinite(t) and 0 < t < R):
        raise ParameterError(f"parameter thickness={t!r}: must be in (0, radius={R!r}) m")
    choice(params, "load", ("gravity", "tilt"))
    stages = ([gravity_stage()] if params["load"] == "gravity" else
              tilt_stages(params["lam_max"], params["step"]))
    model = Model()
    mat = PlasticDamage.elastic(params["young"], 0.2, params["density"])
    ri = R - 0.5 * t
    arch = add_arch(model, mat, span=2 * ri, rise=ri, thickness=t, depth=params["depth"],
                    n=params["n"], abutment_height=params["abutment_height"],
                    joint=JointLaw.dry(params["mu"], knn=params["knn"],
                                       kss=0.1 * params["knn"]))
    sim = Simulation(model, solver_options(params), output=params.get("h5"), config=params)
    sim.contact_reaction("abutments", arch.voussoirs, arch.abutments)
    crown = model.block_nodes(arch.voussoirs[params["n"] // 2])
    xc, zc = arch.centre
    r = np.hypot(model.nodes[crown, 0] - xc, model.nodes[crown, 2] - zc)
    sim.rigid_point("crown", nodes=crown[np.isclose(r, ri + t)])
    return sim, stages, arch


def hinges(model, arch, u, motion, share):
    """Joints (0..n, left springing first) that hinge in ``motion`` (n_nodes, 3) m from the state
    ``u``, their faces (+1 extrados, -1 intrados) and every joint's relative rotation (rad): the
    right voussoir's rotation minus the left one's (abutments at rest); a joint is a hinge where
    that is at least ``share`` of the largest. A counter-clockwise relative rotation (seen from
    -y, x to the right) turns the right block about the joint's extrados edge."""
    rot = np.r_[0.0, block_rotations(model, arch.voussoirs, u, motion), 0.0]
    rel = np.diff(rot)
    big = np.abs(rel) >= share * np.abs(rel).max()
    idx = tuple(int(i) for i in np.flatnonzero(big))
    return idx, tuple(int(np.sign(rel[i])) for i in idx), rel


def mechanism_figure(model, arch, u, motion, hinge_idx, faces, path, title, marks=None):
    """``path`` (PNG): the arch (grey) and the failed attempt's motion scaled to a tenth of the
    radius (blue), its hinges (red dots); ``marks``: (joints, faces, label) drawn as open
    circles (a reference's hinges)."""
    from matplotlib.figure import Figure
    fig = Figure(figsize=(5, 3.4))
    ax = fig.subplots()
    scale = 0.1 * arch.radius / max(np.abs(motion).max(), 1e-300)
    draw_mechanism(ax, model, list(arch.voussoirs) + list(arch.abutments), u, motion, scale)
    xc, zc = arch.centre
    R, t = arch.radius, arch.thickness

    def face_point(i, f):
        a = arch.angles[i]
        return xc + (R + 0.5 * f * t) * np.cos(a), zc + (R + 0.5 * f * t) * np.sin(a)
    pts = np.array([face_point(i, f) for i, f in zip(hinge_idx, faces)]).reshape(-1, 2)
    ax.plot(pts[:, 0], pts[:, 1], "o", color="tab:red", ms=6, label="hinges (this code)")
    if marks is not None:
        ref = np.array([face_point(i, f) for i, f in zip(marks[0], marks[1])]).reshape(-1, 2)
        ax.plot(ref[:, 0], ref[:, 1], "o", mfc="none", mec="k", ms=11, label=marks[2])
    ax.set_aspect("equal")
    ax.set(xlabel="x (m)", ylabel="z (m)", title=title)
    ax.legend(loc="lower center", fontsize=7, frameon=False)
    fig.tight_layout()
    make_folder(os.path.dirname(path) or ".")
    fig.savefig(path, dpi=100)
    return path


def run(params):
    """Run the scene; returns (simulation, arch, :class:`~dr_masonry.collapse.Collapse`, hinges
    as :func:`hinges` gives them, or None when it stood)."""
    sim, stages, arch = build(params)
    res = run_to_collapse(sim, stages, "abutments")
    found = None
    if res.collapsed:
        found = hinges(sim.model, arch, sim.dyn.U, res.motion, params["hinge_share"])
    return sim, arch, res, found


def report(params, res, found):
    """The diagnosis in words."""
    t_R = params["thickness"] / params["radius"]
    head = f"arch n={params['n']} t/R={t_R:.4f}"
    if not res.collapsed:
        return (f"{head}: stands under self-weight" + (
            f" and tilt factor {res.factor:.4f}" if params["load"] == "tilt" else ""))
    where = ("collapses under its own weight" if res.stage == "gravity" else
             f"collapses on the tilting table between lam = {res.factor:.4f} (last converged; "
             f"{res.reaction[-1]:.4f} from the abutments' reaction) and {res.failed:.4f} (no "
             f"equilibrium)")
    faces = ", ".join(f"{i} ({'extrados' if f > 0 else 'intrados'})" for i, f in zip(*found[:2]))
    return f"{head}: {where}; hinges at joints {faces}\n  solver: {res.message}"


def main(argv=None):
    params = scene_params(PARAMS, None, sys.argv[1:] if argv is None else argv, __doc__,
                          "arch")
    sim, arch, res, found = run(params)
    print(report(params, res, found))
    hist = sim.history
    out = params["out"]
    if res.collapsed:
        t_R = params["thickness"] / params["radius"]
        mechanism_figure(sim.model, arch, sim.dyn.U, res.motion, found[0], found[1],
                         out + "_mechanism.png", f"t/R = {t_R:.3f}: mechanism of the failed attempt")
    if len(res.factors):
        finish(sim, out, x=np.asarray(hist["crown.ux"]) / mm, y=res.factors,
               xlabel="crown horizontal displacement (mm)", ylabel="tilt factor lam (applied)",
               title="voussoir arch on a tilting table")
    else:
        sim.close()
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))

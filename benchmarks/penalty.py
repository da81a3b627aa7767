"""The compression penalty ``kc_pen`` of the joints: its effect on accuracy and on the step.

The paper closes joints in compression with Lagrange multipliers (no deformability at a closed
joint); an explicit code needs a penalty, ``sigma = kc_pen u`` for u < 0 (MODEL.md section 2),
``JointLaw.kc_pen`` = ``KC_PEN_FACTOR`` x ``knn`` by default. A stiffer penalty is closer to the
paper but enters the Gershgorin bound of the fictitious masses of every node on a joint, so the
relaxation needs more iterations (about sqrt of the masses). This script sweeps the factor
``kc_pen / knn`` (every joint law of the scene) and reports, per scene and factor:

* ``mass``: median fictitious mass of the nodes on joints, relative to the default factor 10
  (kg when the sweep leaves 10 out; the step of the relaxation is fixed at 1, so a heavier node
  is a shorter stable step);
* ``iterations`` and ``wall_s`` of the run (iterations are exact, wall times noisy);
* ``peak``: largest |y| of the scene's curve, and ``k0``: the secant stiffness y / x at the
  first row of the loading stage;
* ``err_peak``, ``err_k0``: relative to the same quantities extrapolated to a rigid closed joint
  (the paper's), from the two stiffest factors of the sweep assuming an error proportional to
  1 / kc_pen (the compliance the penalty adds); a run the solver stopped (``status``) still gives
  the peak and ``k0`` of the rows it completed;
* ``compliance``: the penalty's compression compliance per course against the brick's,
  E / (kc_pen h), for the reference brick (E = 4.8 GPa, h = 81 mm) and joint (knn = 75 GPa/m):
  the error of a column of bricks loaded along its axis.

Scenes (``scenes``): ``s2`` the S2 triplet at ``sigma`` MPa; ``s5fast`` and
``s6fast``: the squat wall and the out-of-plane wall with their ``fast=true`` presets (S6 with
``s6_increments`` push increments: with the preset's 6 the peak load depends on where the
steps fall more than on the penalty); ``s5``:
the coarse 4.0 m squat wall of the main job to ``s5_drift`` % drift in ``s5_increments``
increments (slow: minutes per factor). Each setting runs in a process of its own.

Run: ``python benchmarks/penalty.py [factors=3,10,30,100 scenes=s2,s5fast,s6fast]``
(about 10 min); writes ``benchmarks/out/penalty<tag>.csv`` and ``.png``. docs/internals.md, "Decisions".
"""
import json
import os
import time
import warnings

import numpy as np

from common import OUT, ROOT, child_row, report, start  # noqa: I100  (script folder on sys.path)

PARAMS = dict(
    factors="3,10,30,100",   # kc_pen / knn
    scenes="s2,s5fast,s6fast",
    sigma=0.6,               # S2 pre-compression, MPa
    s5_drift=0.1,            # scene s5: drift of the push, %
    s5_increments=24,
    s6_increments=12,        # scene s6fast: push increments (its preset's 6 step over the sharp peak)
    tag="",
    mode="all",              # all | one (a single setting, used by the subprocesses)
    scene="s2",              # mode=one: the scene
    factor=10.0,             # mode=one: kc_pen / knn
)


REF_E, REF_KNN = 4.8e9, 75e9  # reference brick modulus (Pa) and joint knn (Pa/m), MODEL.md


def build(params):
    """(simulation, stages, x key, y key, y scale, loading stage) of one scene, no HDF5 output."""
    from dr_masonry.params import ParameterError
    scene = params["scene"]
    if scene == "s2":
        from dr_masonry.cases import triplet
        sim, stages = triplet.build(dict(triplet.PARAMS, h5=None), params["sigma"] * 1e6)
        return sim, stages, "push.ux", "push.fx", 1.0 / (2 * triplet.AREA), stages[-1].name
    if scene in ("s5fast", "s5"):
        from dr_masonry.cases import squat_wall
        p = dict(squat_wall.PARAMS, h5=None, progress=False)
        if scene == "s5fast":
            p.update(squat_wall.FAST, fast=True)
        else:
            p.update(drift=params["s5_drift"], increments=params["s5_increments"])
        sim, stages, _ = squat_wall.build(p)
        return sim, stages, "beam.ux", "beam.fx", 1.0, "push"
    if scene == "s6fast":
        from dr_masonry.cases import out_of_plane_wall
        p = dict(out_of_plane_wall.PARAMS, **out_of_plane_wall.FAST, fast=True, h5=None,
                 progress=False)
        p["increments"] = params["s6_increments"]
        sim, stages, _ = out_of_plane_wall.build(p)
        return sim, stages, "centre.uy", "lambda", 1.0, "push"
    raise ParameterError(f"parameter scene={scene!r}: valid values are s2, s5fast, s6fast, s5")


def one(params):
    """Run one (scene, factor) in this process; prints a JSON row."""
    from dr_masonry import SolverError
    from dr_masonry.geometry import BrickSpec
    sim, stages, xk, yk, scale, stage = build(params)
    f = params["factor"]
    sim.model.joint_laws[:] = [law.with_changes(kc_pen=f * law.knn) for law in sim.model.joint_laws]
    t0 = time.perf_counter()
    err = ""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        try:
            sim.run(stages)
        except SolverError as e:
            err = str(e)[:120]
    wall = time.perf_counter() - t0
    sim.close()
    on_joint = np.zeros(sim.dyn.U.shape[0], dtype=bool)
    c = sim.model.contacts
    on_joint[c.slave] = True
    on_joint[c.master.ravel()] = True
    h = {k: np.asarray(v) for k, v in sim.history.items()}
    first = sum(s.increments for s in stages[:[s.name for s in stages].index(stage)])
    load = h["increment"] > first
    x, y = h[xk][load], h[yk][load] * scale
    row = dict(scene=params["scene"], factor=f, mass=float(np.median(1.0 / sim.dyn.minv[on_joint])),
               iterations=int(h["iterations"].sum() + h.get("cut_iterations", np.zeros(1)).sum()),
               wall_s=wall, peak=float(np.max(np.abs(y))) if y.size else np.nan,
               k0=float(y[0] / x[0]) if y.size and x[0] != 0 else np.nan,
               rows=int(load.sum()), status=err or "ok",
               compliance=REF_E / (f * REF_KNN * BrickSpec().height))
    print(json.dumps(row), flush=True)


def extrapolated(rows, key):
    """Value of ``key`` at a rigid closed joint: linear in 1 / factor through the two stiffest."""
    r = sorted((r for r in rows if np.isfinite(r[key])), key=lambda r: r["factor"])[-2:]
    if len(r) < 2:
        return np.nan
    (f1, y1), (f2, y2) = [(q["factor"], q[key]) for q in r]
    return y2 + (y2 - y1) * (1 / f2) / (1 / f1 - 1 / f2)


def plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    for scene in dict.fromkeys(r["scene"] for r in rows):
        rs = [r for r in rows if r["scene"] == scene]
        f = [r["factor"] for r in rs]
        a1.loglog(f, [r["iterations"] for r in rs], "o-", label=scene)
        a2.loglog(f, [max(abs(r["err_peak"]), 1e-5) for r in rs], "o-", label=scene)
    a1.set(xlabel="kc_pen / knn", ylabel="iterations (whole run)")
    a2.set(xlabel="kc_pen / knn", ylabel="peak error against a rigid closed joint")
    for a in (a1, a2):
        a.grid(True, which="both", alpha=0.3)
        a.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(argv=None):
    params = start(PARAMS, __doc__, argv, "one", one)
    if params is None:
        return
    rows = []
    factors = [float(v) for v in params["factors"].split(",")]
    for scene in params["scenes"].split(","):
        got = []
        for f in factors:
            got.append(child_row(__file__, ["mode=one", f"scene={scene}", f"factor={f}"] + [
                f"{k}={params[k]}" for k in ("sigma", "s5_drift", "s5_increments", "s6_increments")]))
            print(f"  {scene} x{f:g}: {got[-1]['iterations']} iterations, {got[-1]['wall_s']:.1f} s, "
                  f"peak {got[-1]['peak']:.5g}", flush=True)
        ref_peak, ref_k0 = extrapolated(got, "peak"), extrapolated(got, "k0")
        m10 = [r["mass"] for r in got if r["factor"] == 10.0]
        for r in got:
            r["mass"] = r["mass"] / m10[0] if m10 else r["mass"]
            r["err_peak"] = r["peak"] / ref_peak - 1.0
            r["err_k0"] = r["k0"] / ref_k0 - 1.0
        rows += got
    report(rows, f"penalty{params['tag']}", "Compression penalty kc_pen / knn: step and accuracy")
    plot(rows, os.path.join(OUT, f"penalty{params['tag']}.png"))
    print(f"(plot {os.path.relpath(os.path.join(OUT, 'penalty' + params['tag'] + '.png'), ROOT)})")


if __name__ == "__main__":
    main()

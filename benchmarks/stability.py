"""Numerical stability stress test: time step, joint stiffness and block stiffness.

From the defaults, one change at a time:

* step: the mass-scaling ``safety`` (fictitious masses = safety x Gershgorin row sum / 4, stable
  for safety >= 1) set to each of ``safeties``. ``SolverOptions`` refuses safety < 1 unless
  ``allow_unstable=True``, which this script sets **on purpose**, to see what the solver does
  beyond the stable step;
* joints: ``knn``, ``kss`` and the compression penalty ``kc_pen`` of every joint law times each
  of ``factors`` (``JointLaw.with_changes``);
* blocks: Young's modulus ``E`` of every block material that is not ``stays_elastic`` (the
  masonry; loading beams and foundations keep theirs) times each of ``factors``
  (``PlasticDamage.with_changes``).

Scenes (``scenes``): ``s2`` the S2 triplet (``dr_masonry.cases.triplet``) at ``sigma`` MPa with
``s2_increments`` shear increments; ``s3`` the S3 wallet (``dr_masonry.cases.wallet``) shortened
by ``s3_shortening`` m in ``s3_increments`` increments; ``s5fast`` the squat wall with its
``fast=true`` preset (``squat_wall.FAST``: 0.88 x 0.81 m coarse wall, 2 + 20 increments).

Every setting runs in its own process (``mode=one``), killed after ``timeout`` s, so that a hang or
a crash of the interpreter is recorded rather than stopping the script; it writes its HDF5 result
to ``benchmarks/out/stability/``. The iteration cap is lowered to ``max_iter`` per increment with
``max_cuts`` halvings (bounded time); ``coarse`` sets ``SolverOptions.coarse``. Recorded per
setting: ``status`` (completed, stopped by an exception, timeout, crash), the exception type
and the first 120 characters of its message, ``guard`` (``unstable``: the non-finite/run-away
guard; ``step``: the unstable-step detector of the viscous damping; ``cap``: the increment did
not converge within the cap) with the residual ratio it reported, ``failed_after``: the
iterations of the increment that failed, ``nonfinite``: whether the history, the solver's displacements or the HDF5 file read
back by ``open_result`` (history and every frame) hold NaN or Inf (they must not), ``rows`` of
history written (converged increments, halves of cut increments included) against the
``planned`` increments, iterations, wall time (s).

Run: ``python benchmarks/stability.py [key=value ...]``; writes
``benchmarks/out/stability<tag>.csv``.
"""
import json
import os
import re
import subprocess
import sys
import time
import warnings

import numpy as np

from common import OUT, ROOT, report, start  # noqa: I100  (script folder on sys.path)

PARAMS = dict(
    scenes="s2,s5fast",      # s2 | s3 | s5fast (comma separated)
    safeties="1.0,0.9,0.7,0.5,0.3,0.1",
    factors="10,100,1e3,1e4",  # stiffness multipliers of the joints and of the blocks
    sigma=0.6,               # S2 pre-compression, MPa
    s2_increments=30,
    s3_shortening=0.003,     # m
    s3_increments=30,
    max_iter=50000,
    max_cuts=1,
    coarse=True,             # SolverOptions.coarse (two-level relaxation, the default)
    timeout=300,             # s per setting
    tag="",                  # suffix of the CSV name (keeps runs apart)
    mode="all",              # all | one (a single setting, used by the subprocesses)
    scene="s2",              # mode=one: the scene
    change="default",        # mode=one: default | safety | joints | blocks
    value=1.0,               # mode=one: the safety factor or the stiffness multiplier
)
H5 = os.path.join(OUT, "stability")


def build(params):
    """(simulation, stages) of ``params["scene"]`` writing to ``out/stability/<label>.h5``."""
    from dr_masonry.params import ParameterError
    h5 = os.path.join(H5, f"{params['scene']}_{params['change']}_{params['value']:g}.h5")
    if params["scene"] == "s2":
        from dr_masonry.cases import triplet
        return triplet.build(dict(triplet.PARAMS, increments=params["s2_increments"], h5=h5),
                             params["sigma"] * 1e6)
    if params["scene"] == "s3":
        from dr_masonry.cases import wallet
        return wallet.build(dict(wallet.PARAMS, shortening=params["s3_shortening"],
                                 increments=params["s3_increments"], h5=h5))[:2]
    if params["scene"] == "s5fast":
        from dr_masonry.cases import squat_wall
        return squat_wall.build(dict(squat_wall.PARAMS, **squat_wall.FAST, fast=True, h5=h5))[:2]
    raise ParameterError(f"parameter scene={params['scene']!r}: valid values are s2, s3, s5fast")


def apply_change(sim, change, value):
    """Change the step, the joint stiffnesses or the block modulus before the arrays are built."""
    from dr_masonry.params import ParameterError
    m = sim.model
    if change == "safety":
        sim.options = sim.options.replace(safety=value, allow_unstable=True)
    elif change == "joints":
        m.joint_laws[:] = [law.with_changes(knn=value * law.knn, kss=value * law.kss,
                                            kc_pen=value * law.kc_pen) for law in m.joint_laws]
    elif change == "blocks":
        m.materials[:] = [mt if mt.stays_elastic else mt.with_changes(E=value * mt.E)
                          for mt in m.materials]
    elif change != "default":
        raise ParameterError(f"parameter change={change!r}: valid values are default, safety, "
                             f"joints, blocks")


def finite_result(path):
    """(opens, finite): the HDF5 file opens with ``open_result``; its history and frames are finite."""
    from dr_masonry.results import open_result
    try:
        res = open_result(path)
    except Exception as e:  # the point is to see whether a stopped run left a readable file
        return f"no ({type(e).__name__})", True
    ok = all(np.all(np.isfinite(v)) for v in res.history.values())
    for i in range(res.n_frames):
        ok &= all(np.all(np.isfinite(v)) for v in res.frame(i).values()
                  if np.issubdtype(np.asarray(v).dtype, np.floating))
    return "yes", bool(ok)


def one(params):
    """Run one setting in this process; prints a JSON row."""
    sim, stages = build(params)
    apply_change(sim, params["change"], params["value"])
    sim.options.increments.max_iter = params["max_iter"]
    sim.options.increments.max_cuts = params["max_cuts"]
    sim.options.coarse.enabled = params["coarse"]
    exc, msg = "", ""
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # energy-balance warnings
        try:
            sim.run(stages)
        except Exception as e:  # what is raised, and how, is the result
            exc, msg = type(e).__name__, str(e)
    wall = time.perf_counter() - t0
    sim.close()
    hist = {k: np.asarray(v) for k, v in sim.history.items()}
    finite = all(np.all(np.isfinite(v)) for v in hist.values())
    if getattr(sim, "dyn", None) is not None:
        finite &= bool(np.all(np.isfinite(sim.dyn.U)))
    opens, h5_finite = finite_result(sim.output)
    ratio = re.search(r"residual ratio ([-+0-9.eE]+|nan|inf)", msg)
    guard = ("unstable" if re.search(r"non-finite|run-away", msg) else
             "step" if "unstable time step" in msg else
             "cap" if "did not converge" in msg else "")
    spent = re.search(r"after (\d+) iterations", msg)
    print(json.dumps(dict(
        status="stopped" if exc else "completed", exception=exc, message=msg[:120], guard=guard,
        resid_ratio=float(ratio.group(1)) if ratio else float("nan"),
        nonfinite="NO" if finite and h5_finite else "YES", h5_opens=opens,
        rows=len(hist.get("increment", [])), planned=sum(s.increments for s in stages),
        failed_after=int(spent.group(1)) if spent else 0,
        iterations=int(hist["iterations"].sum()) if "iterations" in hist else 0, wall_s=wall)))


def settings(params):
    out = [("default", 1.0)]
    out += [("safety", float(v)) for v in params["safeties"].split(",")]
    for change in ("joints", "blocks"):
        out += [(change, float(v)) for v in params["factors"].split(",")]
    return out


def run_all(params, argv):
    rows = []
    keep = [a for a in argv if a.partition("=")[0] not in ("mode", "scene", "change", "value")]
    for scene in params["scenes"].split(","):
        for change, value in settings(params):
            cmd = [sys.executable, __file__, "mode=one", f"scene={scene}", f"change={change}",
                   f"value={value!r}"] + keep
            row = dict(scene=scene, change=change, value=value)
            t0 = time.perf_counter()
            try:
                p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True,
                                   timeout=params["timeout"])
                lines = p.stdout.strip().splitlines()
                if p.returncode == 0 and lines:
                    row.update(json.loads(lines[-1]))
                else:
                    tail = (p.stderr.strip().splitlines() or ["(no output)"])[-1]
                    row.update(status=f"CRASH rc {p.returncode}", message=tail[:120])
            except subprocess.TimeoutExpired:
                row.update(status=f"TIMEOUT > {params['timeout']} s")
            row["process_s"] = time.perf_counter() - t0
            rows.append(row)
            print(f"  {scene} {change} {value:g}: {row['status']} {row.get('guard', '')} "
                  f"{row.get('message', '')[:90]} ({row['process_s']:.1f} s)", flush=True)
    keys = ["scene", "change", "value", "status", "exception", "message", "guard", "resid_ratio",
            "nonfinite", "h5_opens", "rows", "planned", "iterations", "failed_after", "wall_s",
            "process_s"]
    blank = dict(resid_ratio=float("nan"), rows=0, iterations=0, failed_after=0,
                 wall_s=float("nan"))
    rows = [{k: r.get(k, blank.get(k, "")) for k in keys} for r in rows]
    report(rows, "stability" + params["tag"],
           "Stability stress test (one change at a time from the defaults)")
    print("\n" + conclusion(rows))


def conclusion(rows):
    """One paragraph summarising the table."""
    bad = [r for r in rows if r["nonfinite"] == "YES" or r["status"] not in ("completed", "stopped")
           or (r["status"] == "stopped" and r["exception"] != "SolverError")]
    lines = [f"{len(rows)} settings: {sum(r['status'] == 'completed' for r in rows)} completed, "
             f"{sum(r['status'] == 'stopped' for r in rows)} stopped by an exception "
             f"({sum(r['guard'] == 'unstable' for r in rows)} by the non-finite/run-away guard, "
             f"{sum(r['guard'] == 'step' for r in rows)} by the unstable-step detector, "
             f"{sum(r['guard'] == 'cap' for r in rows)} at the iteration cap)."]
    if bad:
        lines.append("NOT caught cleanly: " + "; ".join(
            f"{r['scene']} {r['change']} {r['value']:g}: {r['status']} {r['exception']} "
            f"nonfinite={r['nonfinite']}" for r in bad) + ".")
    else:
        lines.append("Every failure was a SolverError with its diagnosis; no result holds NaN or "
                     "Inf and every HDF5 file opens.")
    stalled = [r for r in rows if r["change"] == "safety" and r["guard"] == "cap"
               and r["resid_ratio"] >= 1.0]
    if stalled:
        lines.append(f"{len(stalled)} runs with safety < 1 did not diverge: they stalled with a "
                     f"residual ratio >= 1 until the iteration cap, and the message reports "
                     f"non-convergence, not the step.")
    for scene in dict.fromkeys(r["scene"] for r in rows):
        base = next((r for r in rows if r["scene"] == scene and r["change"] == "default"), None)
        for change in ("safety", "joints", "blocks"):
            sel = [r for r in rows if r["scene"] == scene and r["change"] == change]
            done = [f"{r['value']:g}" for r in sel if r["status"] == "completed"]
            its = [f"x{r['value']:g}: {r['iterations']}" for r in sel if r["status"] == "completed"]
            failed = [f"{r['value']:g} ({r['guard'] or r['status']}, residual ratio "
                      f"{r['resid_ratio']:.2g})" for r in sel if r["status"] != "completed"]
            lines.append(f"{scene} {change}: completed at {', '.join(done) or 'none'}"
                         + (f" (iterations {'; '.join(its)}; default {base['iterations']})"
                            if change != "safety" and its and base else "")
                         + (f"; stopped at {', '.join(failed)}" if failed else "") + ".")
    return " ".join(lines)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    params = start(PARAMS, __doc__, argv, "one", one)
    if params is None:
        return
    os.makedirs(H5, exist_ok=True)
    run_all(params, argv)


if __name__ == "__main__":
    main()

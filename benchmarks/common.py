"""Shared helpers of the benchmark scripts: output folder, machine line, timing, tables, CSV."""
import csv
import json
import os
import platform
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
OUT = os.path.join(HERE, "out")
if ROOT not in sys.path:  # ``cases`` is imported from the repository root
    sys.path.insert(0, ROOT)


def divisions(text, what):
    """``"4x2x1"`` -> (4, 2, 1): three integers >= 1 (hexahedra along x, y, z); a ParameterError
    naming the parameter ``what`` and the value otherwise."""
    from dr_masonry.params import ParameterError
    try:
        out = tuple(int(v) for v in text.lower().split("x"))
    except ValueError:
        out = ()
    if len(out) != 3 or min(out) < 1:
        raise ParameterError(f"{what} {text!r}: expected three integers >= 1 like 4x2x1")
    return out


def machine():
    """One line describing the machine and its load at the time of the run."""
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    import numba
    return (f"{platform.processor() or platform.machine()}, {os.cpu_count()} logical cores, "
            f"load average {load:.2f} at start, Python {platform.python_version()}, "
            f"numba {numba.__version__}")


def report(rows, name, title):
    """Print ``rows`` (list of dicts, same keys) as a markdown table and write ``out/<name>.csv``."""
    os.makedirs(OUT, exist_ok=True)
    keys = list(rows[0])
    print(f"\n### {title}\n")
    print("| " + " | ".join(keys) + " |")
    print("|" + "---|" * len(keys))
    for r in rows:
        print("| " + " | ".join(_fmt(r[k]) for k in keys) + " |")
    path = os.path.join(OUT, f"{name}.csv")
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    print(f"\n(written {os.path.relpath(path, ROOT)})", flush=True)


def _fmt(v):
    if isinstance(v, float):
        return f"{v:.4g}" if abs(v) < 1e4 else f"{v:,.0f}"
    return str(v)


def child_row(script, overrides, env=None):
    """Run the benchmark file ``script`` with ``overrides`` (``key=value`` strings) in a fresh
    interpreter (its own threads, environment and compiled state); returns the dict of the JSON
    line it prints last. A failing child raises RuntimeError with the end of its stderr."""
    res = subprocess.run([sys.executable, os.path.abspath(script)] + list(overrides), env=env,
                         capture_output=True, text=True)
    if res.returncode:
        raise RuntimeError(f"{os.path.basename(script)} {' '.join(overrides)}: {res.stderr[-2000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def driven(history):
    """(mask of the driven rows, driven axis 0-2) of a run's ``history``: the rows with a finite
    driving force ``drive.f*`` (not a gravity or pre-compression stage) and the axis of the
    largest |driving force| over them; (empty mask, -1) when no row is driven."""
    n = len(history["iterations"])
    drive = np.column_stack([np.asarray(history.get(f"drive.f{a}", np.full(n, np.nan)))
                             for a in "xyz"])
    rows = np.isfinite(drive).any(axis=1)
    if not rows.any():
        return rows, -1
    return rows, int(np.argmax(np.where(np.isfinite(drive[rows]), np.abs(drive[rows]), -1.0)
                               .max(axis=0)))


def built_scene(scene, args, name):
    """(simulation, stages) of scene ``scene`` built (not run) with its parameters ``args``
    (space-separated ``key=value`` overrides of the case's ``PARAMS``), writing its results to
    ``out/<name>.h5`` and no maps or progress bar."""
    from dr_masonry.cli import import_case
    from dr_masonry.scene import scene_params
    mod = import_case(scene)
    run = scene_params(mod.PARAMS, getattr(mod, "FAST", None),
                       [f"out={os.path.join(OUT, name)}", "maps=", "report=false"] + args.split(),
                       mod.__doc__, scene)
    run["progress"] = False
    return mod.build(run)[:2]      # a scene with its own data returns it third


def stored_run(scene, path, name):
    """(simulation, stages, copy) of scene ``scene`` set up from ``copy`` = ``out/<name>.h5``, a
    copy of its result file ``path``, with the parameters stored in it (not yet resumed:
    ``sim.resume(copy)`` loads the checkpoint, and running then continues the stored run without
    touching the original). A ParameterError names a missing file."""
    import shutil
    from dr_masonry.cli import import_case
    from dr_masonry.params import ParameterError
    from dr_masonry.results import open_result
    if not os.path.isfile(path):
        raise ParameterError(f"parameter file={path!r}: no such result file")
    mod = import_case(scene)
    os.makedirs(OUT, exist_ok=True)
    copy = os.path.join(OUT, f"{name}.h5")
    shutil.copy(path, copy)
    stored = open_result(copy).config
    run = {**mod.PARAMS, **stored, "h5": copy, "progress": False}  # keys newer than the file: defaults
    sim, stages = mod.build(run)[:2]
    return sim, stages, copy


def start(defaults, doc, argv, child_mode=None, child=None):
    """Parameters of a benchmark script's ``main`` (``key=value`` overrides of ``defaults``);
    ``None`` after running ``child(params)`` when ``params["mode"]`` is ``child_mode`` (the
    script called by itself for one setting), else the parameters with the machine line printed
    (scripts without such a mode pass neither)."""
    from dr_masonry.params import parse_overrides
    params = parse_overrides(defaults, sys.argv[1:] if argv is None else argv, doc)
    if child is not None and params["mode"] == child_mode:
        child(params)
        return None
    print(f"machine: {machine()}")
    return params


def timed(fn, args, repeats, min_time):
    """(best, median) seconds per call of ``fn(*args)`` over ``repeats`` batches of >= ``min_time``
    s each (after one untimed call); ``min_time`` 0: one call per batch."""
    fn(*args)
    n = 1
    while True:
        t0 = time.perf_counter()
        for _ in range(n):
            fn(*args)
        dt = time.perf_counter() - t0
        if dt >= min_time:
            break
        n = max(2 * n, int(n * 1.2 * min_time / max(dt, 1e-9)))
    per = [dt / n]
    for _ in range(repeats - 1):
        t0 = time.perf_counter()
        for _ in range(n):
            fn(*args)
        per.append((time.perf_counter() - t0) / n)
    return min(per), float(np.median(per))


def relax_args(sim, iters, alpha=1.0, ring=None):
    """Arguments of ``kernels.relaxation.relax`` on ``sim``: viscous damping ``alpha`` (0: no
    Rayleigh-quotient damping), ring damping ``ring`` (default the options'), no load factor or
    control, tol 0 (it runs all ``iters`` iterations), run-away limit half the model's size."""
    from dr_masonry.kernels import relaxation as R
    ring = sim.options.damping.ring if ring is None else ring
    crit = R.Criteria(0.0, float(sim.ref_floor), 0.0, 0.0, 10, 0, 0.5 * sim.size, 0.0, int(iters))
    return [sim.mesh, sim.cont, sim.dyn, np.zeros(1), np.zeros(3, dtype=np.int64), 1.0,
            float(alpha), float(ring), crit, R.start_progress(), R.no_constraint()]


def check_ran(out):
    """Raise unless the ``relax`` call that returned ``out`` ran all its iterations."""
    from dr_masonry.kernels.relaxation import ST_MAXITER
    if out[0].status != ST_MAXITER:
        raise RuntimeError(f"relax stopped early (status {out[0].status}); the steps were not all "
                           f"taken, so the timing would be wrong")

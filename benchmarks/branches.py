"""How much the converged curve depends on how it was solved: one scene (default the S5 main
job) run under solver settings and increment sizes that change how the path is relaxed, not the
problem.

A run is a pair (scene arguments, solver variant): every set of ``args`` (``|``-separated sets of
space-separated ``key=value`` scene parameters, e.g. ``increments=30|increments=60``; empty: the
scene's defaults) with every item of ``variants`` (``name:option=value[+option=value...]``,
``option`` a flat ``SolverOptions`` name among :data:`OPTIONS`; ``default`` changes nothing).
Every run is compared with the ``reference`` run (``<args>/<variant>``; default the first args
set with ``default``): the force at the reference's rows interpolated in the run's curve (by the
control displacement, history column ``x``), its largest and RMS difference in % of the
reference's peak, before and after that peak. A row converged to tol with every block balanced
is an equilibrium of its increment; if each increment had one, the variants of one args set would
agree to within their tolerance. Also reported: rows, whether every row converged, peak, end
force, iterations (with cut attempts). Runs go in their own processes (one thread each), ``jobs``
at a time; each run's curve is kept in ``benchmarks/out/branches_<key>.json`` (keyed on the scene,
its arguments and every solver option) and reused (``refresh=true`` runs it again).

Run: ``python benchmarks/branches.py [variants=... args=... reference=...]`` (the main job: 1-5
min per run on one core); writes ``benchmarks/out/branches.csv``.
"""
import json
import os
import sys
import zlib
from concurrent.futures import ThreadPoolExecutor

import numpy as np

import common

DEFAULTS = dict(mode="all", scene="squat_wall", args="", x="beam.ux", jobs=2, refresh=False,
                reference="", variant="default",
                variants="default,tol5:tol=5e-5,tol2:tol=2.5e-5,tol1:tol=1e-5,alpha:alpha=0.7,"
                         "ring:ring=0.5,safety:safety=1.3,check:check_every=5,gap:gap_tol=0.005")
#: the options a variant may set: flat name -> (group of ``SolverOptions``, attribute, type)
OPTIONS = dict(alpha=("damping", "alpha", float), ring=("damping", "ring", float),
               safety=("damping", "safety", float), tol=("convergence", "tol", float),
               check_every=("convergence", "check_every", int),
               gap_tol=("convergence", "gap_tol", float),
               block_tol=("convergence", "block_tol", float),
               stall_iter=("increments", "stall_iter", int),
               adapt=("increments", "adapt", lambda v: {"true": True, "false": False}[v]),
               coarse=("coarse", "enabled", lambda v: {"true": True, "false": False}.get(v, v)),
               coarse_test=("coarse", "test", str))


def parse(item):
    """``name:option=value[+option=value...]`` (or ``default``) -> (name, {option: value})."""
    from dr_masonry.params import ParameterError
    if item == "default":
        return item, {}
    try:
        name, settings = item.split(":")
        change = {}
        for setting in settings.split("+"):
            key, value = setting.split("=")
            change[key] = OPTIONS[key][2](value)
        return name, change
    except (ValueError, KeyError):
        raise ParameterError(f"parameter variants: {item!r} is not name:option=value[+...] with "
                             f"options among {sorted(OPTIONS)}") from None


def settings(item):
    """The solver options of variant ``item`` with every default filled in, as text: what a
    kept curve is keyed on (a run made under other defaults is not reused)."""
    from dr_masonry import SolverOptions
    return json.dumps(SolverOptions(**parse(item)[1]).as_dict(), sort_keys=True)


def one(params):
    """Run one variant (``mode=one``) and print its rows as a JSON line."""
    name, change = parse(params["variant"])
    sim, stages = common.built_scene(params["scene"], params["args"],   # (a file per run)
                                     f"branches_{name}_{zlib.crc32(params['args'].encode()):08x}")
    for key, value in change.items():
        group, attr, _ = OPTIONS[key]
        setattr(getattr(sim.options, group), attr, value)
    from dr_masonry.results.reader import above_tol
    hist = sim.run(stages)
    driven, axis = common.driven(hist)
    tol = sim.options.convergence.tol
    print(json.dumps(dict(x=hist[params["x"]][driven].tolist(),
                          force=hist[f"drive.f{'xyz'[axis]}"][driven].tolist(),
                          iterations=float(np.sum(hist["iterations"]) +
                                           np.nansum(hist["cut_iterations"])),
                          converged=not above_tol(hist["residual"], tol).any(), tol=tol)))


def compare(name, got, ref):
    """The table row of run ``name`` (``got``) against the reference run (``ref``): differences of
    the force at the reference's rows, interpolated in the run's curve (a cut increment adds
    rows), in % of the reference's peak."""
    x, f = np.array(got["x"]), np.abs(np.array(got["force"]))
    rx, rf = np.array(ref["x"]), np.abs(np.array(ref["force"]))
    peak = int(np.argmax(rf))
    order = np.argsort(x)   # a monotonic push: the control displacement grows row by row
    d = (np.interp(rx, x[order], f[order]) - rf) / rf[peak]
    pre = np.arange(rx.size) <= peak

    def stats(v):
        return (100 * float(np.max(np.abs(v))) if v.size else float("nan"),
                100 * float(np.sqrt(np.mean(v * v))) if v.size else float("nan"))
    pre_max, pre_rms = stats(d[pre])
    post_max, post_rms = stats(d[~pre])
    return dict(variant=name, rows=len(x), all_converged=got["converged"],
                peak_kN=float(f.max()) / 1e3, end_kN=float(f[-1]) / 1e3, pre_max_pct=pre_max,
                pre_rms_pct=pre_rms, post_max_pct=post_max, post_rms_pct=post_rms,
                iterations=int(got["iterations"]))


def main(argv=None):
    params = common.start(DEFAULTS, __doc__, argv, child_mode="one", child=one)
    if params is None:
        return
    from dr_masonry.params import ParameterError
    sets = params["args"].split("|")
    items = params["variants"].split(",")
    for item in items:
        parse(item)
    runs = [(a, i) for a in sets for i in items]
    ref = tuple(params["reference"].split("/")) if params["reference"] else (sets[0], "default")
    if len(ref) != 2:
        raise ParameterError(f"parameter reference={params['reference']!r}: expected "
                             f"<scene args>/<variant>, e.g. increments=120/tol1:tol=1e-5")
    parse(ref[1])
    if ref not in runs:
        runs.insert(0, ref)
    env = dict(os.environ, NUMBA_NUM_THREADS="1")

    def run(what):   # a run's rows, kept in out/branches_<key>.json
        args, item = what
        key = zlib.crc32(f"{params['scene']} {args} {settings(item)}".encode())
        path = os.path.join(common.OUT, f"branches_{key:08x}.json")
        if params["refresh"] or not os.path.isfile(path):
            got = common.child_row(__file__, ["mode=one", f"variant={item}",
                                              f"scene={params['scene']}", f"args={args}",
                                              f"x={params['x']}"], env=env)
            with open(path, "w") as f:
                json.dump(got, f)
        with open(path) as f:
            return json.load(f)
    with ThreadPoolExecutor(int(params["jobs"])) as pool:
        got = dict(zip(runs, pool.map(run, runs)))
    rows = []
    for args, item in runs:
        row = compare(parse(item)[0], got[(args, item)], got[ref])
        rows.append(dict(args=args or "-", **row))
    common.report(rows, "branches", f"{params['scene']}: against {ref[0] or '-'} "
                                    f"{parse(ref[1])[0]}")


if __name__ == "__main__":
    sys.exit(main())

"""Command line: ``dr-masonry run | study | vtk | info | pack | animate | report | list``.

Also ``python -m dr_masonry``.

``run <case> [key=value ...]``  run ``dr_masonry.cases.<case>`` with parameter overrides
``study <case> [--vary key=v1,v2 ...] [--set key=value ...]``  a parameter study through Dask
``vtk <result.h5> [out_dir]``   write the VTK time series (.vtu + .pvd)
``info <result.h5> [--peak KEY ...]``  model size, configuration, increments, frames, last row
``pack <result.h5> <copy.h5> [--frames ...]``  a compressed copy a run can be continued from
``animate <result.h5> [out.gif|out.mp4]``  the damaged structure beside the curve, frame by frame
``report <result.h5> [out.html]``  one self-contained HTML page of the run
``list``                        the cases available

Case scripts parse their ``key=value`` arguments with :func:`dr_masonry.params.parse_overrides`.
"""
from __future__ import annotations

import argparse
import importlib
import json
import os
import pkgutil
import sys
import warnings

import numpy as np

from .interrupts import Terminated
from .params import ParameterError


def available_cases():
    """Names of the case modules in ``dr_masonry.cases``, sorted."""
    import dr_masonry.cases as cases
    return sorted(m.name for m in pkgutil.iter_modules(cases.__path__)
                  if not m.name.startswith("_"))


def import_case(name):
    """The module ``dr_masonry.cases.<name>``; ParameterError naming the valid cases if unknown."""
    try:
        return importlib.import_module(f"dr_masonry.cases.{name}")
    except ModuleNotFoundError as e:
        if e.name != f"dr_masonry.cases.{name}":
            raise
        raise ParameterError(f"unknown case {name!r}; available: "
                             f"{', '.join(available_cases()) or '(none)'}") from None


def _cmd_run(args):
    name = args.case
    mod = import_case(name)
    if not hasattr(mod, "main"):
        raise ParameterError(f"case {name!r} has no main(argv)")
    return mod.main(list(args.overrides))


def _key_value(opt, spec):
    key, sep, text = spec.partition("=")
    if not sep or not key.strip() or not text.strip():
        raise ParameterError(f"{opt} {spec!r}: expected key=value")
    return key.strip(), text.strip()


def _cmd_study(args):
    from .study import grid, run_study
    axes, base = {}, {}
    for spec in args.vary:
        key, text = _key_value("--vary", spec)
        if key in axes:
            raise ParameterError(f"--vary {key}: given twice")
        axes[key] = [v.strip() for v in text.split(",") if v.strip()]
    for spec in args.set:
        key, text = _key_value("--set", spec)
        if key in axes:
            raise ParameterError(f"parameter {key!r} is both varied (--vary) and set (--set)")
        base[key] = text
    res = run_study(args.case, grid(**axes), base=base,
                    out=args.out or f"results/study_{args.case}", scheduler=args.scheduler,
                    n_workers=args.workers, threads_per_worker=args.threads)
    return 1 if res.failed else 0


def _cmd_vtk(args):
    from dr_masonry.viz.vtk_series import export_vtk
    print(export_vtk(args.result, args.out_dir, warp=args.warp))
    return 0


def _cmd_info(args):
    from dr_masonry.results import CHECKPOINT, ResultsError, open_result
    r = open_result(args.result)
    print(f"file:      {r.path}")
    print(f"code:      dr_masonry {r.attrs['code_version']}, schema {r.attrs['schema_version']}, "
          f"created {r.attrs['created']}, {len(r.attrs['restarts'])} restart(s)")
    print(f"model:     {r.summary()}")
    print("groups:    " + ", ".join(f"{k} ({len(v)})" for k, v in r.groups.items()))
    print(f"config:    {json.dumps(r.config, indent=2, sort_keys=True)}")
    for k, rs in enumerate(r.attrs["restarts"], 1):
        changed = _changed(r.config, rs.get("config", {}))
        print(f"restart {k}: {rs.get('time', '?')}, dr_masonry {rs.get('code_version', '?')}: "
              + (", ".join(f"{key} {old!r} -> {new!r}" for key, (old, new) in changed.items())
                 or "same parameters"))
    print(f"history:   {r.n_history} rows (numbered from 1 below, as in the run's messages), "
          f"columns {list(r.history)}")
    for line in certificate(r):
        print(line)
    ids = r.frame_ids
    print(f"frames:    {r.n_frames}" + (f" (increments {ids[0]} .. {ids[-1]})" if ids else ""))
    try:
        ck = r.frame_increment(CHECKPOINT)
        print(f"checkpoint: increment {ck}" + (" (after the last frame; frame 'checkpoint' reads "
                                               "its fields)" if not ids or ck > ids[-1] else ""))
    except ResultsError:
        print("checkpoint: none")
    kept = r.kept_checkpoints
    if kept:
        print(f"kept checkpoints: increments {', '.join(map(str, kept))} (resume_from=INCREMENT)")
    if r.n_history:
        print("last row:  " + ", ".join(f"{k}={v}" for k, v in last_row(r).items()))
        unknown = [k for k in args.peak if k not in r.history]
        if unknown:
            raise ParameterError(f"info --peak: no history column {unknown}; columns are "
                             f"{list(r.history)}")
        for k in args.peak or r.history:
            v = r.history[k]
            i, j = int(np.argmax(v)), int(np.argmin(v))
            print(f"peak {k}: max {v[i]:.6g} (row {i + 1}), min {v[j]:.6g} (row {j + 1})")
    return 0


def _curve_arg(text):
    """``--curve X,Y`` (history columns) as a curve dict, or None."""
    if text is None:
        return None
    cols = [c.strip() for c in text.split(",")]
    if len(cols) != 2 or not all(cols):
        raise ParameterError(f"--curve {text!r}: expected two history columns X,Y")
    return {"x": cols[0], "y": cols[1], "stage": None}


def _cmd_animate(args):
    from dr_masonry.viz.animation import animate
    print(animate(args.result, args.out, case=args.case, curve=_curve_arg(args.curve),
                  field=args.field, camera=args.camera, fps=args.fps))
    return 0


def _cmd_report(args):
    from dr_masonry.viz.report import write_report
    print(write_report(args.result, args.out, case=args.case, curve=_curve_arg(args.curve)))
    return 0


def _cmd_pack(args):
    from .results import pack
    frames = args.frames
    if frames != ["all"]:
        try:
            frames = [int(i) for i in frames]
        except ValueError:
            raise ParameterError(f"pack --frames {' '.join(frames)}: give increments (integers) "
                                 f"or 'all'") from None
    else:
        frames = "all"
    size, packed = pack(args.result, args.copy, frames)
    print(f"{args.copy}: {packed / 2**20:.2f} MiB ({args.result}: {size / 2**20:.2f} MiB); "
          f"continue the run with out={os.path.splitext(args.copy)[0]} resume=true")
    return 0


def _flat(d, prefix=""):
    """A nested configuration dict as {"a.b": value}."""
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def _changed(config, later):
    """{key: (value at creation, value at a restart)} for the keys a restart's configuration sets
    to another value (``resume``, ``resume_from`` left out; ``solver.X`` left out where ``X``
    says the same)."""
    a, b = _flat(config), _flat(later)
    diff = {k: (a.get(k), v) for k, v in b.items()
            if k not in ("resume", "resume_from") and a.get(k) != v}

    def echoed(k, new):   # solver.X set to the value X is set to
        top = k.removeprefix("solver.")
        return top != k and top in diff and diff[top][1] == new
    return {k: v for k, v in diff.items() if not echoed(k, v[1])}


def certificate(r):
    """The lines of ``dr-masonry info`` on what the rows of result ``r`` can be trusted for: the
    rows accepted above the run's tolerance (:func:`_above_tol`), the energy balance, every
    block's balance and the joints' overhang (:func:`_checks`); ``dr-masonry report`` prints
    the same lines."""
    return [_above_tol(r)] + _checks(r)


def last_row(r):
    """``{column: "%.6g" text}`` of the last history row of result ``r``, as ``info`` prints
    it (empty for a file without rows)."""
    return {k: f"{v[-1]:.6g}" for k, v in r.history.items()} if r.n_history else {}


def _above_tol(r):
    """One line: the rows of result ``r`` whose residual ratio is above the run's ``tol``
    (accepted at a floor, ``SolverOptions.floor_tol``), or that there are none."""
    tol, rows = r.rows_above_tol()
    res = r.history.get("residual")
    if tol is None or not len(res):
        return "residual:  (no solver tolerance or residual column recorded)"
    if not rows.size:
        return f"residual:  every row converged to tol {tol:g}"
    shown = ", ".join(str(i + 1) for i in rows[:12]) + (", ..." if rows.size > 12 else "")
    return (f"residual:  {rows.size} of {len(res)} rows accepted above tol {tol:g} (floor_tol; "
            f"largest ratio {np.max(res):.3g}): rows {shown}")


def _largest(r, column):
    """(largest |value|, its row counted from 1) of a history column, NaN rows (not recorded)
    left out; None where the column is missing or holds no value."""
    v = np.abs(np.asarray(r.history.get(column, []), dtype=float))
    if not np.isfinite(v).any():
        return None
    i = int(np.nanargmax(v))
    return float(v[i]), i + 1


def _checks(r):
    """Lines on what a reader should trust the run's rows for: the energy balance, every block's
    balance (``SolverOptions.block_tol``) and how far joint nodes slid off their faces."""
    solver = r.config.get("solver") or {}
    lines = []
    e = _largest(r, "balance_error")
    if e is not None:
        etol = solver.get("energy_tol")
        n = "" if etol is None else (
            f"; {int(np.sum(np.abs(r.history['balance_error']) > etol))} rows above energy_tol "
            f"{etol:g}")
        lines.append(f"energy:    balance error at most {e[0]:.3g} of the gross work (row "
                     f"{e[1]}){n}")
    b = _largest(r, "block_imbalance")
    if b is not None:
        btol = solver.get("block_tol")
        n = "" if not btol else (
            f"; {int(np.sum(np.asarray(r.history['block_imbalance']) > btol))} rows above "
            f"block_tol {btol:g}")
        lines.append(f"blocks:    largest block imbalance ratio {b[0]:.3g} (row {b[1]}){n}")
    elif r.n_history:
        lines.append("blocks:    no block_imbalance column (written before 2026-12-02: loose "
                     "blocks were not checked; docs/validation.md, S5 cyclic)")
    o = _largest(r, "max_overhang")
    if o is not None:
        lines.append(f"overhang:  joint nodes slid at most {o[0] * 1e3:.3g} mm off their master "
                     f"faces (row {o[1]})")
    return lines


def _cmd_list(args):
    for name in available_cases():
        try:
            mod = importlib.import_module(f"dr_masonry.cases.{name}")
            first = (mod.__doc__ or "").strip().splitlines()
            print(f"{name:<20} {first[0] if first else ''}")
        except Exception as e:  # a broken case must not hide the others
            print(f"{name:<20} (cannot import: {type(e).__name__}: {e})")
    return 0


def _parser():
    p = argparse.ArgumentParser(prog="dr-masonry", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser("run", help="run a case: run <case> [key=value ...] (run <case> --help)",
                       add_help=False)
    s.add_argument("case")
    s.add_argument("overrides", nargs=argparse.REMAINDER)
    s.set_defaults(func=_cmd_run)
    s = sub.add_parser("study", help="run a case once per parameter variant (Dask); one CSV "
                       "table and one overlay plot; exit status 1 if a variant failed",
                       description="Run a case once per combination of the --vary values "
                       "(cartesian product), with the --set values in every run, as Dask tasks. "
                       "Values convert to the type of the case's defaults (dr-masonry run <case> "
                       "--help lists them). Writes <out>/<label>.h5 per variant, <out>/study.csv "
                       "and <out>/study.png.")
    s.add_argument("case")
    s.add_argument("--vary", action="append", default=[], metavar="KEY=V1,V2,...",
                   help="an axis of the grid (repeatable)")
    s.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a parameter of every variant (repeatable)")
    s.add_argument("--scheduler", metavar="ADDR",
                   help="address of a running Dask scheduler (tcp://host:8786), or 'synchronous' "
                   "(no Dask, one run after another here); default: local worker processes")
    s.add_argument("--workers", type=int, metavar="N",
                   help="local worker processes (default: cores / threads, at most one per "
                   "variant)")
    s.add_argument("--threads", type=int, default=1, metavar="N",
                   help="Numba threads per run (default 1)")
    s.add_argument("--out", metavar="DIR", help="study directory (default results/study_<case>)")
    s.set_defaults(func=_cmd_study)
    s = sub.add_parser("vtk", help="write the VTK time series of a results file")
    s.add_argument("result")
    s.add_argument("out_dir", nargs="?")
    s.add_argument("--warp", type=float, default=1.0, help="displacement scale (0: reference)")
    s.set_defaults(func=_cmd_vtk)
    s = sub.add_parser("info", help="summary of a results file")
    s.add_argument("result")
    s.add_argument("--peak", nargs="*", default=[], metavar="KEY",
                   help="history columns to report max/min of (default all)")
    s.set_defaults(func=_cmd_info)
    s = sub.add_parser("pack", help="compressed copy of a results file (history, last "
                       "checkpoint, chosen frames) that a run can be continued from",
                       description="Copy a results file with its datasets compressed: the "
                       "configuration, model, history and last checkpoint, and only the frames "
                       "named by --frames. A run continues from the copy as from the file "
                       "(resume=true, out naming the copy): the way to carry a long run to "
                       "another machine.")
    s.add_argument("result")
    s.add_argument("copy")
    s.add_argument("--frames", nargs="*", default=[], metavar="INCREMENT",
                   help="increments of the frames to keep, or 'all' (default: none)")
    s.set_defaults(func=_cmd_pack)
    for name, what in (("animate", "an animation (GIF, or MP4 with ffmpeg) of the damaged "
                                   "structure beside the force-displacement curve"),
                       ("report", "one self-contained HTML page of a run: parameters, curve, "
                                  "damage views, equilibrium certificate, cycles, run time")):
        s = sub.add_parser(name, help=what)
        s.add_argument("result")
        s.add_argument("out", nargs="?", help="output file (default next to the result: "
                       + ("<stem>.gif)" if name == "animate" else "<stem>_report.html)"))
        s.add_argument("--case", help="the scene (default: the case whose parameters the "
                       "file's configuration holds)")
        s.add_argument("--curve", metavar="X,Y", help="history columns of the curve (default "
                       "the scene's CURVE)")
        if name == "animate":
            s.add_argument("--field", default="dt", choices=["dt", "dc"],
                           help="brick colouring (default dt)")
            s.add_argument("--camera", help="elevation, back, facade or iso (default the "
                           "scene's first view)")
            s.add_argument("--fps", type=float, default=2.0, help="frames per second")
        s.set_defaults(func=_cmd_animate if name == "animate" else _cmd_report)
    s = sub.add_parser("list", help="list the cases")
    s.set_defaults(func=_cmd_list)
    return p


def main(argv=None):
    """Entry point of ``dr-masonry``; returns the exit status (see :func:`guarded`)."""
    args = _parser().parse_args(argv)
    return guarded(f"dr-masonry {args.command}", args.func, args)


def run_script(main):
    """``main()`` of a case script run as ``python cases/NAME.py key=value ...``, guarded as
    ``dr-masonry run NAME`` is (the script's ``__main__`` block: ``sys.exit(run_script(main))``)."""
    return guarded(os.path.basename(sys.argv[0]), main)


def guarded(command, func, *args):
    """``func(*args)`` as the command ``command``; returns the exit status: the function's int
    result (0 otherwise), 1 when a run stops on a :class:`~dr_masonry.solver.SolverError` and 2
    on bad input (the message, no traceback), 130 after Ctrl-C and 143 after SIGTERM (where the
    results are, no traceback). Warnings print as one line ``command: Category: message``
    (Python's format adds the file, line and source line of the ``warnings.warn`` call)."""
    def one_line(message, category, filename, lineno, line=None):
        return f"{command}: {category.__name__}: {message}\n"
    python_format, warnings.formatwarning = warnings.formatwarning, one_line
    try:
        rc = func(*args)
        return rc if isinstance(rc, int) else 0
    except KeyboardInterrupt as e:   # Ctrl-C, SIGTERM: where the results are, not a traceback
        term = isinstance(e, Terminated)
        print("\n".join([f"{command}: " + ("terminated (SIGTERM)" if term else "interrupted")]
                        + getattr(e, "__notes__", [])), file=sys.stderr)
        return 143 if term else 130
    except ValueError as e:
        if not type(e).__module__.startswith("dr_masonry"):   # not one of the project's input
            raise                                              # errors: keep the traceback
        # ParameterError, ResultsError, ModelError, ...: the message says what is wrong
        print(f"{command}: error: {e}", file=sys.stderr)
        return 2
    except RuntimeError as e:
        from .solver import SolverError   # not at the top: `info` and `list` need no Numba
        if not isinstance(e, SolverError):
            raise
        # a run that did not converge or became unstable: its diagnosis and where its rows are
        print("\n".join([f"{command}: stopped: {e}"] + getattr(e, "__notes__", [])),
              file=sys.stderr)
        return 1
    finally:
        warnings.formatwarning = python_format

"""Parameter studies through Dask: one scene, many parameter variants, one table and one plot.

A study runs a case of :mod:`dr_masonry.cases` once per variant (a label and a dict of parameter
overrides, e.g. from :func:`grid`) as independent Dask tasks:

* ``scheduler=None``: a :class:`distributed.LocalCluster` of worker processes on this machine
  (``threads_per_worker`` Numba threads each), closed at the end;
* ``scheduler="tcp://host:port"``: the workers of an existing cluster (``dask scheduler`` and
  ``dask worker`` started elsewhere; they need dr_masonry installed and, for the result files, a
  file system shared with this machine);
* ``scheduler="synchronous"``: no Dask at all, the variants run one after the other in this
  process (tests, debugging).

Every task writes ``<out>/<label>.h5`` (the label made a file name) and returns a small summary: wall time, increments,
iterations, peak of the scene's curve and the abscissa at the peak, final value and the curve
itself. A variant that raises (bad parameter, solver failure) or whose worker dies is reported
with status ``failed`` and its error; the others go on. The summaries are gathered into
``<out>/study.csv`` (one row per variant) and ``<out>/study.png`` (the curves overlaid).

The curve of a case is declared by its module attribute ``CURVE``: a dict with ``x`` and ``y``
(history columns), ``stage`` (name of the stage whose history rows form the curve, None for all
rows), ``xscale``/``yscale`` (factors from SI to the plotted units, signed so that the response
of interest is positive: the peak is the largest scaled ``y``) and ``xlabel``/``ylabel``. The
history has no stage column; the rows of a stage are found from the result file's frames: every
stage writes a frame at its last increment, and each frame records its stage name and the number
of history rows written (``history_rows``), so the rows of a stage are those after the last frame
of the previous stage up to the stage's last frame. This stays exact when the solver cuts an
increment into sub-increments (each one a history row).
"""
import csv
import itertools
import os
import re
import time
import traceback
import warnings
from dataclasses import dataclass, field

import numpy as np

from .params import ParameterError, _coerce, check_protocol_keys, with_preset
from .results import ResultsError, make_folder

#: keys the study sets itself in every variant's parameters
_RESERVED = ("out", "h5", "progress", "scene")


@dataclass
class StudyResult:
    """Gathered results of :func:`run_study`.

    Attributes
    ----------
    scene : str
        the case name.
    rows : list of dict
        one per variant, in the order given: ``label``, ``overrides`` (dict), ``status`` ("ok" or
        "failed"), ``error`` ("" when ok), ``wall_s`` (s), ``increments`` (history rows),
        ``iterations`` (total), ``peak``, ``x_at_peak``, ``final`` (curve units), ``x``, ``y``
        ((n,) curve arrays), ``h5`` (result path, "" if none was written), ``warnings`` (the
        run's warning messages, e.g. the energy audit) and, for a run that raised, ``traceback``.
    curve : dict
        the case's ``CURVE``.
    csv, png : str
        paths of the table and of the overlay plot.
    base : dict
        the overrides common to all variants (also part of each row's ``overrides``).
    """
    scene: str
    rows: list
    curve: dict
    csv: str
    png: str
    base: dict = field(default_factory=dict)

    @property
    def failed(self):
        """The rows of the variants that failed."""
        return [r for r in self.rows if r["status"] != "ok"]

    def table(self):
        """The rows as an aligned text table (errors of failed variants below it)."""
        c = self.curve
        head = ("label", "status", "incr", "iter", "wall (s)", f"peak {c['ylabel']}",
                f"at {c['xlabel']}", "final")
        body = []
        for r in self.rows:
            ok = r["status"] == "ok"
            body.append((r["label"], r["status"], str(r.get("increments", "")),
                         str(r.get("iterations", "")), f"{r['wall_s']:.1f}",
                         f"{r['peak']:.4g}" if ok else "-", f"{r['x_at_peak']:.4g}" if ok else "-",
                         f"{r['final']:.4g}" if ok else "-"))
        w = [max(len(s[i]) for s in (head, *body)) for i in range(len(head))]
        lines = ["  ".join(s.ljust(n) for s, n in zip(line, w)).rstrip() for line in (head, *body)]
        lines.insert(1, "  ".join("-" * n for n in w))
        lines += [f"{r['label']}: {r['error']}" for r in self.failed]
        return "\n".join(lines)


def grid(**axes):
    """Variants of the cartesian product of parameter values.

    Parameters
    ----------
    **axes : list
        parameter name -> values, e.g. ``variant=["reference", "PAR_B"], tol=[1e-3, 1e-4]``.

    Returns
    -------
    list of (str, dict)
        ``(label, overrides)`` per combination, the last axis varying fastest; labels read
        ``"variant=PAR_B,tol=0.001"``. No axes give the single variant ``("base", {})``.
    """
    for k, v in axes.items():
        if isinstance(v, (str, bytes)) or not hasattr(v, "__iter__") or len(v) == 0:
            raise ParameterError(f"grid axis {k}={v!r}: expected a non-empty list of values")
    if not axes:
        return [("base", {})]
    keys = list(axes)
    return [(",".join(f"{k}={v}" for k, v in zip(keys, combo)), dict(zip(keys, combo)))
            for combo in itertools.product(*axes.values())]


def load_case(scene):
    """The module ``dr_masonry.cases.<scene>``; ParameterError if unknown or without ``CURVE``."""
    from .cli import import_case
    mod = import_case(scene)
    missing = [a for a in ("PARAMS", "run", "CURVE") if not hasattr(mod, a)]
    if missing:
        raise ParameterError(f"case {scene!r} cannot run in a study: it has no {missing} "
                             f"(a study needs PARAMS, run(params) -> (sim, ...) and CURVE)")
    return mod


def check_overrides(mod, overrides, scene="case"):
    """Overrides checked against the case's PARAMS; strings are converted to the default's type.

    Raises ParameterError for an unknown key, a key the study sets itself (out, h5, progress),
    ``fast`` on a case without a ``FAST`` preset, or a value that does not convert.
    """
    out = {}
    for k, v in overrides.items():
        if k in _RESERVED:
            raise ParameterError(f"parameter {k!r} is set by the study (one result per variant "
                                 f"under the study's out directory)")
        if k not in mod.PARAMS:
            raise ParameterError(f"unknown parameter {k!r} of case {scene!r}; valid keys: "
                                 f"{', '.join(x for x in mod.PARAMS if x not in _RESERVED)}")
        out[k] = _coerce(k, v, mod.PARAMS[k]) if isinstance(v, str) else v
    if out.get("fast") and not hasattr(mod, "FAST"):
        raise ParameterError(f"parameter fast=True: case {scene!r} has no FAST preset")
    return out


def safe_label(label):
    """``label`` as a file name: characters other than letters, digits and ``_.,=+-`` become _."""
    return re.sub(r"[^A-Za-z0-9_.,=+-]", "_", str(label)) or "_"


def stage_rows(h5, stage, n_rows):
    """Slice of the history rows of stage ``stage`` in result file ``h5`` (None: all rows).

    Uses the frames' ``stage`` and ``history_rows`` attributes (a stage always writes a frame at
    its last increment). Raises ValueError if no frame of ``stage`` exists.
    """
    if stage is None:
        return slice(0, n_rows)
    from .results import open_result
    r = open_result(h5)
    attrs = [r.frame_attrs(i) for i in range(r.n_frames)]
    mine = [i for i, a in enumerate(attrs) if a.get("stage") == stage]
    if not mine:
        raise ResultsError(f"{h5}: no frame of stage {stage!r} (stages with frames: "
                           f"{sorted({str(a.get('stage')) for a in attrs})})")
    start = attrs[mine[0] - 1]["history_rows"] if mine[0] > 0 else 0
    return slice(int(start), int(attrs[mine[-1]]["history_rows"]))


def run_variant(scene, label, overrides, out, threads=1):
    """Run one variant (the Dask task); never raises.

    Parameters
    ----------
    scene : str
        case name.
    label : str
        the variant's label.
    overrides : dict
        checked parameter overrides (:func:`check_overrides`); ``fast=True`` applies the case's
        FAST preset first, the overrides on top.
    out : str
        result path without extension: writes ``out + ".h5"``.
    threads : int
        Numba threads of the run (at most the process's NUMBA_NUM_THREADS).

    Returns
    -------
    dict
        a row of :attr:`StudyResult.rows`; status "failed" with ``error`` "Type: message" and
        ``traceback`` if the run raised.
    """
    import numba
    h5 = out + ".h5"
    row = dict(label=label, overrides=dict(overrides), status="ok", error="", h5=h5)
    t0 = time.perf_counter()
    before = numba.get_num_threads()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
            mod = load_case(scene)
            params = with_preset(mod.PARAMS, getattr(mod, "FAST", None), overrides.get("fast"))
            params.update(overrides, out=out, h5=h5, progress=False, scene=scene)
            make_folder(os.path.dirname(out) or ".")
            sim = mod.run(params)[0]
            sim.close()
            row.update(_summary(sim.history, mod.CURVE, h5))
        except Exception as e:
            row.update(status="failed", error=f"{type(e).__name__}: {e}",
                       traceback=traceback.format_exc())
        finally:
            numba.set_num_threads(before)
    row["wall_s"] = time.perf_counter() - t0
    row["warnings"] = "; ".join(dict.fromkeys(str(w.message) for w in caught))
    if not os.path.exists(h5):
        row["h5"] = ""
    return row


def _summary(history, curve, h5):
    """Increments, iterations and the curve (scaled; peak = largest y) of a finished run."""
    hist = {k: np.asarray(v, dtype=float) for k, v in history.items()}
    n = hist["increment"].size
    rows = stage_rows(h5, curve.get("stage"), n)
    x = hist[curve["x"]][rows] * curve.get("xscale", 1.0)
    y = hist[curve["y"]][rows] * curve.get("yscale", 1.0)
    if y.size == 0:
        raise ResultsError(f"the curve (stage {curve.get('stage')!r}) has no history rows")
    k = int(np.argmax(y))
    return dict(increments=n, iterations=int(hist["iterations"].sum()), peak=float(y[k]),
                x_at_peak=float(x[k]), final=float(y[-1]), x=x, y=y)


def _failed(label, overrides, error):
    return dict(label=label, overrides=dict(overrides), status="failed", error=error, h5="",
                wall_s=float("nan"), warnings="")


def run_study(scene, variants, base=None, out="results/study", scheduler=None, n_workers=None,
              threads_per_worker=1, processes=True, verbose=True):
    """Run every variant of a case through Dask; write ``<out>/study.csv`` and ``study.png``.

    Parameters
    ----------
    scene : str
        case name in :mod:`dr_masonry.cases` with ``PARAMS``, ``run`` and ``CURVE``.
    variants : list of (str, dict)
        ``(label, overrides)`` per variant (:func:`grid`); string values are converted to the
        type of the case's default (as on the command line).
    base : dict, optional
        overrides common to all variants (the variant's own win).
    out : str
        directory of the study: ``<out>/<label>.h5`` per variant, ``study.csv``, ``study.png``.
        Made absolute here (on a cluster, a path the workers can write).
    scheduler : None, "synchronous" or str
        None: a LocalCluster of ``n_workers`` processes (closed at the end); "synchronous": run
        in this process, one variant after another; otherwise the address of a running
        scheduler, e.g. ``"tcp://10.0.0.5:8786"``.
    n_workers : int, optional
        LocalCluster workers (default: cores // threads_per_worker, at most one per variant).
    threads_per_worker : int
        Numba threads per run (the LocalCluster sets NUMBA_NUM_THREADS of its workers to it).
    processes : bool
        LocalCluster of processes (default) or of threads in this process.
    verbose : bool
        print a line per finished variant and the table.

    Returns
    -------
    StudyResult

    Raises
    ------
    ParameterError
        unknown case, unknown parameter or bad value (before any run starts), duplicate labels.

    Notes
    -----
    The LocalCluster starts its workers as fresh processes (spawn): a script that calls this
    function must do so under ``if __name__ == "__main__":``. The workers load the compiled
    kernels from Numba's cache (``cache=True``), a few seconds each, and compile only if the
    cache is missing or stale.
    """
    mod = load_case(scene)
    base = check_overrides(mod, dict(base or {}), scene)
    variants = [(str(label), dict(base, **check_overrides(mod, dict(ov), scene)))
                for label, ov in variants]
    if not variants:
        raise ParameterError("run_study: no variants")
    for label, ov in variants:
        try:
            check_protocol_keys(dict(mod.PARAMS, **ov), set(ov))
        except ParameterError as e:
            raise ParameterError(f"variant {label!r}: {e}") from None
    names = [safe_label(label) for label, _ in variants]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ParameterError(f"run_study: variant labels {dup} are not unique (as file names)")
    if int(threads_per_worker) < 1:
        raise ParameterError(f"threads_per_worker={threads_per_worker!r}: must be >= 1")
    if n_workers is not None and int(n_workers) < 1:
        raise ParameterError(f"n_workers={n_workers!r}: must be >= 1 (None: one per core)")
    out = os.path.abspath(out)
    make_folder(out)
    paths = [os.path.join(out, n) for n in names]
    say = print if verbose else (lambda *a, **k: None)

    def done(row, i):
        say(f"[{i}/{len(variants)}] {row['label']}: {row['status']}"
            + (f", {row['wall_s']:.1f} s" if row["status"] == "ok" else f": {row['error']}"),
            flush=True)

    rows = []
    if scheduler == "synchronous":
        for (label, ov), path in zip(variants, paths):
            rows.append(run_variant(scene, label, ov, path, threads_per_worker))
            done(rows[-1], len(rows))
    else:
        rows = _run_dask(scene, variants, paths, scheduler, n_workers, int(threads_per_worker),
                         processes, say, done)
    order = {label: i for i, (label, _) in enumerate(variants)}
    rows.sort(key=lambda r: order[r["label"]])
    result = StudyResult(scene, rows, dict(mod.CURVE), os.path.join(out, "study.csv"),
                         os.path.join(out, "study.png"), base)
    write_csv(result)
    plot_overlay(result)
    say(result.table())
    say(f"wrote {result.csv} and {result.png}")
    return result


def _run_dask(scene, variants, paths, scheduler, n_workers, threads, processes, say, done):
    """Submit the variants to a LocalCluster (scheduler None) or a scheduler address; gather."""
    from distributed import Client, LocalCluster, as_completed
    cluster = None
    if scheduler is None:
        n = n_workers or max(1, (os.cpu_count() or 1) // threads)
        n = max(1, min(int(n), len(variants)))
        kw = dict(env={"NUMBA_NUM_THREADS": str(threads)}) if processes else {}
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=processes,
                               dashboard_address=None, **kw)
        client = Client(cluster)
        say(f"LocalCluster: {n} worker {'processes' if processes else 'threads'}, "
            f"{threads} Numba thread(s) each")
    else:
        try:
            client = Client(scheduler)
        except (OSError, ValueError) as e:
            raise ParameterError(f"scheduler={scheduler!r}: cannot connect ({e})") from None
        say(f"scheduler {scheduler}: {len(client.scheduler_info()['workers'])} workers")
    rows = []
    try:
        futures = {client.submit(run_variant, scene, label, ov, path, threads, pure=False):
                   (label, ov) for (label, ov), path in zip(variants, paths)}
        for fut in as_completed(futures):
            label, ov = futures[fut]
            try:
                rows.append(fut.result())
            except Exception as e:   # the worker died (KilledWorker) or the task was lost
                rows.append(_failed(label, ov, f"{type(e).__name__}: {e}"))
            done(rows[-1], len(rows))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return rows


def write_csv(result):
    """One row per variant: label, status, ``param.<key>`` per override, summary, h5, error.

    ``wall_s`` in s, ``increments`` = history rows (sub-increments of cut increments included),
    ``peak``, ``x_at_peak`` and ``final`` in the units of the case's CURVE labels.
    """
    keys = list(dict.fromkeys(k for r in result.rows for k in r["overrides"]))
    stats = ["wall_s", "increments", "iterations", "peak", "x_at_peak", "final", "h5", "error",
             "warnings"]
    with open(result.csv, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["label", "status", *(f"param.{k}" for k in keys), *stats])
        for r in result.rows:
            w.writerow([r["label"], r["status"], *(r["overrides"].get(k, "") for k in keys),
                        f"{r['wall_s']:.3f}", *(r.get(k, "") for k in stats[1:])])
    return result.csv


def plot_overlay(result):
    """The curves of the finished variants on one axes, labelled; returns the PNG path."""
    from matplotlib.figure import Figure   # no pyplot: the caller's back end is untouched
    c = result.curve
    ok = [r for r in result.rows if r["status"] == "ok"]
    fig = Figure(figsize=(7, 4.5))
    ax = fig.subplots()
    for r in ok:
        ax.plot(r["x"], r["y"], "o-", ms=2, lw=1.2, label=r["label"])
    ax.set(xlabel=c["xlabel"], ylabel=c["ylabel"],
           title=f"{result.scene}: {len(ok)} of {len(result.rows)} variants")
    ax.grid(alpha=0.3)
    if ok:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(result.png, dpi=120)
    return result.png

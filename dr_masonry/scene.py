"""What every scene script does around its run: parse its parameters, summarise the solver's
work, close the result and write the curve (PNG + CSV) and VTK."""
import os
import warnings

import numpy as np

from .options import SolverOptions
from .params import ParameterError, check_protocol_keys, output_path, parse_overrides, with_preset
from .results import above_tol, make_folder, open_result
from .solver import SolverError
from .units import kN, mm


def scene_params(defaults, fast, argv, doc, scene):
    """Parameters of a scene's ``main``: ``key=value`` overrides of ``defaults``, on top of the
    ``fast`` preset when ``fast=true`` (``fast`` None: a scene without that parameter); ``h5``
    next to ``out``, the progress bar on and ``scene``, the case's name (stored with the
    configuration: ``dr-masonry report`` and ``animate`` find the scene's curve and views by
    it)."""
    params = parse_overrides(defaults, argv, doc)
    if params.get("fast"):              # the preset first, explicit overrides on top
        params = parse_overrides(with_preset(defaults, fast, True), argv, doc)
    check_protocol_keys(params, {a.partition("=")[0].strip() for a in argv})
    params["h5"] = output_path(params) + ".h5"
    params["progress"] = True
    params["scene"] = scene
    return params


#: scene parameters that are :class:`~dr_masonry.options.SolverOptions` fields of the same (flat)
#: name: their defaults and meaning are the options' (docs/solver.md)
OPTION_KEYS = ("tol", "damping", "alpha", "coarse", "max_dissipation", "redetect", "max_iter",
               "max_cuts", "stall_iter", "adapt", "floor_tol", "gap_tol", "block_tol",
               "coarse_test")
#: the solver and output parameters of the wall and house scenes, with their defaults (a scene's
#: ``PARAMS`` spreads them: ``dict(..., **RUN_PARAMS)``): the :data:`OPTION_KEYS` with the
#: options' defaults, and
RUN_PARAMS = dict(
    {k: v for k, v in SolverOptions.defaults().items() if k in OPTION_KEYS},
    frames=5,               # write a field frame every this many increments (and at each
                            # turning point of a cyclic path)
    resume=False,           # continue the run stored in out.h5 from its last checkpoint
    resume_from=0,          # with resume: from the checkpoint kept after this increment instead
    replot=False,           # write the outputs (curve, CSV, VTK) of the run stored in out.h5, as
                            # far as it went (a stopped run, or one still writing), without running
    maps="peak,end",        # crack and crushing maps and 3-D damage views (PNG) at these
                            # points: peak (the frame nearest the largest |force|; both ways
                            # of a cyclic run), peak+, peak-, end, increment numbers; "": none
    report=True,            # write out_report.html: curve, views at the peaks and the end,
                            # equilibrium certificate, energies, cycles, run time (the page of
                            # `dr-masonry report`)
    animate=False,          # write out.gif: the damaged structure beside the curve, one picture
                            # per stored frame (the file of `dr-masonry animate`)
    compare="",             # results file of another run of the scene drawn on the curve (e.g.
                            # the monotonic run on the cyclic one), or a CSV of the curve's two
                            # columns in its plotted units (measured or published points)
)
#: parameters that may differ when a run is continued: how it is solved and written, not what
SOLVER_KEYS = {"resume", "resume_from", "replot", "maps", "report", "animate", "compare",
               "progress", "out", "h5", "frames", "solver", *OPTION_KEYS}


def choice(params, key, options):
    """``params[key]``, checked to be one of ``options`` (a ParameterError names the valid ones)."""
    if params[key] not in options:
        raise ParameterError(f"parameter {key}={params[key]!r}: valid values are {list(options)}")
    return params[key]


#: the scene parameter ``coarse`` as written on a command line (the option takes True, False or
#: "auto")
COARSE_WORDS = {"true": True, "on": True, "yes": True, "1": True, "false": False, "off": False,
                "no": False, "0": False, "auto": "auto"}


def solver_options(params):
    """The :class:`SolverOptions` of a scene: its ``OPTION_KEYS`` parameters (those it has) and
    the progress bar."""
    given = {k: params[k] for k in OPTION_KEYS if k in params}
    if isinstance(given.get("coarse"), str):
        word = given["coarse"].strip().lower()
        if word not in COARSE_WORDS:
            raise ParameterError(f"parameter coarse={given['coarse']!r}: valid values are "
                                 f"true, false, auto")
        given["coarse"] = COARSE_WORDS[word]
    return SolverOptions(**given, progress=params.get("progress", False))


def with_penalty(law, factor):
    """``law`` (JointLaw) with the compression penalty ``factor`` x knn: the scene parameter
    ``kc_factor`` (default ``KC_PEN_FACTOR``; its effect: docs/internals.md, "Decisions")."""
    if not (isinstance(factor, (int, float)) and np.isfinite(factor) and factor > 0):
        raise ParameterError(f"parameter kc_factor={factor!r}: must be a positive multiple of knn")
    return law.with_changes(kc_pen=factor * law.knn)


def _stored_run(params, key):
    """The :class:`~dr_masonry.results.Result` of ``params["h5"]`` for ``key``=true (``resume``
    or ``replot``), checked to exist and to have been run with ``params`` apart from
    :data:`SOLVER_KEYS`."""
    from .results import open_result
    path = params["h5"]
    if not os.path.exists(path):
        raise ParameterError(f"parameter {key}=true: no result file {path} to "
                             + ("continue" if key == "resume" else "draw"))
    result = open_result(path)
    stored = result.config
    changed = sorted(k for k in set(stored) & set(params) - SOLVER_KEYS if stored[k] != params[k])
    if changed:
        raise ParameterError(f"parameter {key}=true: {path} was run with "
                             + ", ".join(f"{k}={stored[k]!r}" for k in changed)
                             + "; give the same parameters")
    return result


def run_stages(sim, stages, params):
    """``sim.run(stages)``; with ``params["resume"]``, continue ``params["h5"]`` from its last
    checkpoint instead, or from the one kept after increment ``params["resume_from"]`` (when
    not 0; ``dr-masonry info`` lists them); with ``params["replot"]``, run nothing and return
    the stored history as far as it goes (``sim.history`` set to it, for :func:`finish`). The
    stored run's parameters must equal ``params`` apart from :data:`SOLVER_KEYS`. A Ctrl-C or
    SIGTERM (KeyboardInterrupt, :class:`~dr_masonry.interrupts.Terminated`) goes on up with a
    note saying where the rows so far are and how to continue (``dr-masonry`` and the case
    scripts print just that note); a :class:`~dr_masonry.solver.SolverError` gets a note naming
    the file of the rows so far."""
    map_points(params)   # the output parameters are checked before hours of running, not after
    _compare_path(params)
    if params.get("resume_from") and not params.get("resume"):
        raise ParameterError(f"parameter resume_from={params['resume_from']!r} continues a stored "
                             f"run: add resume=true (without it the run starts again and "
                             f"overwrites {params.get('h5')})")
    if params.get("replot"):
        if params.get("resume"):
            raise ParameterError("parameters replot=true and resume=true: replot draws the stored "
                                 "run without running, resume continues it; give one")
        sim.history = {k: np.asarray(v) for k, v in _stored_run(params, "replot").history.items()}
        sim.output = params["h5"]
        return dict(sim.history)
    if params.get("resume"):
        path = params["h5"]
        result = _stored_run(params, "resume")
        if result.complete and not params.get("resume_from"):
            raise ParameterError(f"parameter resume=true: {path} is complete "
                                 f"({len(result.history.get('increment', ()))} rows, the end of "
                                 f"its last stage): nothing to continue (resume_from=INCREMENT "
                                 f"goes on from a kept checkpoint; `dr-masonry info` lists them)")
        sim.resume(path, params.get("resume_from") or None)
    try:
        return sim.run(stages)
    except KeyboardInterrupt as e:
        h5 = params.get("h5")
        e.add_note(f"interrupted in row {sim.increment + 1}" + (
            f": the rows so far are in {h5}; add resume=true to the same command to continue, "
            f"or replot=true to write their curve, CSV and VTK" if h5 else ""))
        raise
    except SolverError as e:
        if params.get("h5"):
            e.add_note(f"{sim.increment} rows written to {params['h5']}")
        raise


def two_sided(force):
    """Whether ``force`` (one per push row) was taken both ways, as in a cyclic run: its most
    negative value above a quarter of its largest, positive one."""
    force = np.asarray(force, dtype=float)
    return bool(force.size) and -force.min() > 0.25 * force.max() > 0.0


def peaks_text(x, force, unit=kN, unit_name="kN"):
    """"F kN at u mm" of the largest |force| (N) against displacement ``x`` (m); for a force
    taken both ways (:func:`two_sided`) the largest and the most negative, "+F1 kN at u1 mm, -F2
    kN at u2 mm"."""
    x, force = np.asarray(x, dtype=float), np.asarray(force, dtype=float)
    if not force.size:
        return "no push row"
    if two_sided(force):
        ks = (int(np.argmax(force)), int(np.argmin(force)))
        return ", ".join(f"{force[k] / unit:+.2f} {unit_name} at {x[k] / mm:+.2f} mm" for k in ks)
    k = int(np.argmax(np.abs(force)))
    return f"{force[k] / unit:.2f} {unit_name} at {x[k] / mm:.2f} mm"


def equilibrium_text(force, reaction, at_floor, unit=kN, unit_name="kN"):
    """How far a curve's force and the supports' reaction that should balance it part (N, one
    of each per row), as one phrase: the largest and the median gap on the rows accepted at the
    residual floor (``at_floor``, bool mask) and the largest on the converged rows. Their gap is
    the resultant of the out-of-balance (inertia and damping) forces a row was left with: the
    residual ratio, a norm over every node against loads dominated by gravity, can pass a
    resultant of several per cent of a lateral load, so a row at the floor is only as exact as
    this gap."""
    gap = np.abs(np.asarray(force, dtype=float) - np.asarray(reaction, dtype=float))
    at_floor = np.asarray(at_floor, dtype=bool)
    parts = []
    if at_floor.any():
        g = gap[at_floor]
        parts.append(f"at most {g.max() / unit:.2f} {unit_name} (median {np.median(g) / unit:.2f})"
                     f" on the {g.size} rows accepted at the residual floor")
    if (~at_floor).any():
        parts.append(f"at most {gap[~at_floor].max() / unit:.2f} {unit_name} on the "
                     f"{int((~at_floor).sum())} converged rows")
    return "force and support reaction part by " + ", ".join(parts) if parts else "no row"


def at_floor(sim, hist, rows):
    """Bool mask of the history rows ``rows`` accepted above the solver's tolerance (at the
    residual floor, ``SolverOptions.floor_tol``)."""
    return above_tol(np.asarray(hist["residual"])[rows], sim.options.convergence.tol)


def solver_summary(hist, rows):
    """Damage maxima at the end, iterations per increment over ``rows`` (bool mask), the
    relaxation time of a run's history and the work lost in attempts that were cut, as one
    phrase."""
    cut_it = np.nansum(hist.get("cut_iterations", np.zeros(1)))
    cut_s = np.nansum(hist.get("cut_s", np.zeros(1)))
    cuts = (f" (+ {cut_it:.0f} iterations, {cut_s:.1f} s in attempts cut in two)"
            if cut_it else "")
    return (f"max joint damage {hist['max_joint_damage'][-1]:.2f}, block dt "
            f"{hist['max_dt'][-1]:.2f}, dc {hist['max_dc'][-1]:.2f}; iterations per increment "
            f"{np.mean(hist['iterations'][rows]):.0f} (max {np.max(hist['iterations'][rows]):.0f});"
            f" relaxation time {np.sum(hist['time_s']):.1f} s{cuts}")


#: the named points of parameter ``maps``: the rows of the largest |force|, the largest and the
#: most negative force, the end
MAP_NAMES = ("peak", "peak+", "peak-", "end")


def map_points(params):
    """The points of scene parameter ``maps`` ("peak,end": comma-separated names of
    :data:`MAP_NAMES` and increment numbers; "" or "none": no map) as a list of names and ints;
    "peak" of a run loaded both ways means both peaks (:func:`write_maps`)."""
    value = params.get("maps", "")
    tokens = [t.strip() for t in str(value).split(",") if t.strip()]
    if tokens == ["none"]:
        return []
    points = []
    for t in tokens:
        if t in MAP_NAMES:
            points.append(t)
        elif t.isdigit():
            points.append(int(t))
        else:
            raise ParameterError(f"parameter maps={value!r}: {t!r} is not one of "
                                 f"{', '.join(MAP_NAMES)} or an increment number (comma-"
                                 "separated; \"\" or none: no map)")
    return points


def peak_increments(increments, force):
    """{"peak", "peak+", "peak-": increment} of the largest |force|, largest and most negative
    ``force`` (one per entry of ``increments``; empty: {})."""
    if not len(increments):
        return {}
    return {name: int(increments[k]) for name, k in (
        ("peak", np.argmax(np.abs(force))), ("peak+", np.argmax(force)),
        ("peak-", np.argmin(force)))}


def map_frames(result, points, named, two_sided=False, among=None):
    """(tag, frame) of each of ``points`` (:func:`map_points`) in ``result``: the frame nearest
    the increment of a name in ``named`` ({name: increment}; tag: the name) or of an increment
    number (tag: the frame's increment), the later of two as near, and for "end" the last frame,
    or the last checkpoint where the run stopped after it ("checkpoint"); with ``two_sided`` (a
    cyclic run) "peak" stands for "peak+" and "peak-"; ``among``: the increments whose frames a
    peak or a numbered point may take (the rows of the curve, so that a peak of the push is not
    drawn from a frame of the pre-compression before it; None, or none of them framed: any
    frame); points without a stored state are left out."""
    from .results import CHECKPOINT, ResultsError
    ids = np.asarray(result.frame_ids)
    pick = np.flatnonzero(np.isin(ids, among)) if among is not None else ids[:0]
    if not pick.size:
        pick = np.arange(ids.size)
    try:
        ck = result.frame_increment(CHECKPOINT)
    except ResultsError:
        ck = None
    out = []
    for p in points:
        if p == "end":
            if ck is not None and (not ids.size or ck > ids[-1]):
                out.append(("end", CHECKPOINT))
            elif ids.size:
                out.append(("end", ids.size - 1))
            continue
        for q in (("peak+", "peak-") if two_sided and p == "peak" else (p,)):
            inc = q if isinstance(q, int) else named.get(q)
            if ids.size and inc is not None:
                d = np.abs(ids[pick] - inc)
                k = int(pick[np.flatnonzero(d == d.min())[-1]])
                out.append((str(ids[k]) if isinstance(q, int) else q, k))
    return out


def write_maps(sim, params, out, maps, x, force, rows, views=None, curve=None):
    """Crack and crushing maps ``{out}_{name}_{tag}.png`` of ``maps`` ({name: keyword arguments
    of :func:`dr_masonry.viz.plots.crack_map`}) and 3-D damage views ``{out}_{name}_{tag}.png``
    of ``views`` ({name: keyword arguments of :func:`dr_masonry.viz.views.damage_view}`, a
    scene's ``VIEWS``; ``curve``: its ``CURVE``, for the views' titles) at the points of
    ``params["maps"]``; the peaks (:data:`MAP_NAMES`) are those of ``force`` (N) against the
    control displacement ``x`` (m), one of each per row of ``rows`` (a bool mask of the
    history); each map's title gives the frame's increment and displacement, and the peak's
    where the nearest frame is another increment. Returns the written paths (none without a
    results file)."""
    points = map_points(params)
    if not points or sim.output is None:
        return []
    from .results import open_result
    from .viz.plots import crack_map
    result = open_result(sim.output)
    force = np.asarray(force, dtype=float)
    inc = np.asarray(sim.history["increment"])[rows].astype(int)
    named = peak_increments(inc, force)
    at_inc = dict(zip(inc.tolist(), np.asarray(x, dtype=float).tolist()))

    def where(k):
        return f"increment {k}" + (f", {at_inc[k] / mm:.2f} mm" if k in at_inc else "")
    paths = []
    frames = map_frames(result, points, named, two_sided(force), among=inc)
    for tag, frame in frames:
        k = result.frame_increment(frame)
        at = f"{tag}: {where(k)}" + (f" (the peak: {where(named[tag])})"
                                     if tag in named and named[tag] != k else "")
        paths += [crack_map(result, frame, f"{out}_{name}_{tag}.png",
                            title=f"{os.path.basename(out)} {name.replace('_', ' ')}, {at}", **kw)
                  for name, kw in maps.items()]
    if views:
        from .viz.views import write_views
        paths += write_views(result, out, frames, views, curve=curve)
    return paths


def write_run_pages(sim, params):
    """With scene parameter ``report`` the run report ``{out}_report.html``
    (:func:`dr_masonry.viz.report.write_report`), with ``animate`` the animation ``{out}.gif``
    (:func:`dr_masonry.viz.animation.animate`) of the closed results file, for the scene
    ``params["scene"]``. Returns the written paths (none without a results file)."""
    if sim.output is None or not (params.get("report") or params.get("animate")):
        return []
    from .results import ResultsError
    paths = []
    try:
        if params.get("report"):
            from .viz.report import write_report
            paths.append(write_report(sim.output, params["out"] + "_report.html",
                                      case=params.get("scene")))
        if params.get("animate"):
            from .viz.animation import animate
            paths.append(animate(sim.output, params["out"] + ".gif", case=params.get("scene")))
    except ResultsError as e:   # e.g. a packed copy without the frames that name its stages
        warnings.warn(f"no run report or animation written: {e}", RuntimeWarning, stacklevel=2)
    return paths


def _compare_path(params):
    """The results file or CSV of scene parameter ``compare`` (None when empty), checked to
    exist."""
    path = params.get("compare")
    if path and not os.path.exists(path):
        raise ParameterError(f"parameter compare={path!r}: no such "
                             + ("file" if path.lower().endswith(".csv") else "results file"))
    return path or None


def _reference_csv(path):
    """(x, y, label) of a reference curve stored as CSV: ``#`` comment lines (the source), a
    header line, then two columns in the plotted units (mm, kN); label: the file's name."""
    with open(path) as f:
        rows = [ln for ln in f if ln.strip() and not ln.lstrip().startswith("#")][1:]
    try:
        xy = np.loadtxt(rows, delimiter=",", ndmin=2) if rows else np.empty((0, 2))
    except ValueError as e:
        raise ParameterError(f"parameter compare={path!r}: not a CSV of numbers ({e})") from None
    if xy.shape[1] != 2 or len(xy) < 2:
        raise ParameterError(f"parameter compare={path!r}: needs two columns (x, y in the "
                             f"plotted units) and at least 2 rows after its header, has "
                             f"{len(xy)} rows of {xy.shape[1]} columns")
    bad = np.flatnonzero(~np.all(np.isfinite(xy), axis=1))
    if bad.size:
        raise ParameterError(f"parameter compare={path!r}: data row {bad[0] + 1} is "
                             f"{rows[bad[0]].strip()!r}, not finite")
    return xy[:, 0], xy[:, 1], os.path.basename(path)


def compare_curve(params, first_stage, curve, xscale=1.0 / mm, yscale=1.0 / kN):
    """The reference line (x, y, label) of scene parameter ``compare`` (None when empty): the
    results file's push rows (increment above its parameter ``first_stage``, the increments of
    the stage before the push) through ``curve(history, rows) -> (x, y)`` (SI), times
    ``xscale``, ``yscale`` (default mm and kN); a ``.csv`` file: its points as they are
    (:func:`_reference_csv`)."""
    from .results import open_result
    path = _compare_path(params)
    if path is None:
        return None
    if path.lower().endswith(".csv"):
        return _reference_csv(path)
    r = open_result(path)
    if first_stage not in r.config:
        raise ParameterError(f"parameter compare={path!r}: not a run of this scene (its "
                             f"parameters have no {first_stage})")
    h = r.history
    x, y = curve(h, np.asarray(h["increment"]) > r.config[first_stage])
    return x * xscale, y * yscale, f"{os.path.basename(path)} ({r.config.get('protocol', 'run')})"


def finish(sim, out, x, y, xlabel, ylabel, title, reference=None, vtk=True, cycles=None,
           label="dr_masonry", reaction=None, floor=None):
    """Write ``out.png`` (curve ``label``, optional reference (x, y, label) and, thin, the
    supports' reaction ``reaction`` (y of the same x) that balances the curve's force: where the
    two part, rows stopped short of equilibrium; the rows of bool mask ``floor``, accepted at
    the residual floor, as open circles), ``out.csv``,
    ``out_vtk/`` and, for a cyclic run, ``out_cycles.csv`` and the bars of ``out_cycles.png``
    (``cycles``: the list of :func:`dr_masonry.postprocess.energy_per_cycle`; displacements m,
    forces N, energies J).

    ``sim`` is closed first so that the HDF5 result is complete. Returns the written paths.
    """
    from matplotlib.figure import Figure   # no pyplot: the caller's back end is untouched

    sim.close()
    make_folder(os.path.dirname(out) or ".")
    fig = Figure(figsize=(6, 4))
    ax = fig.subplots()
    if reference is not None:
        ax.plot(reference[0], reference[1], "k--", lw=1, label=reference[2])
    line, = ax.plot(x, y, "o-", ms=2, label=label)
    if floor is not None and np.any(floor):
        ax.plot(np.asarray(x)[floor], np.asarray(y)[floor], "o", ms=4, mfc="none",
                color=line.get_color(), label=f"{int(np.sum(floor))} rows at the residual floor")
    if reaction is not None:
        ax.plot(x, reaction, "-", color="0.6", lw=0.8, label="support reaction")
    ax.set(xlabel=xlabel, ylabel=ylabel, title=title)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out + ".png", dpi=120)
    hist = sim.history
    keys = list(hist)
    np.savetxt(out + ".csv", np.column_stack([hist[k] for k in keys]), delimiter=",",
               header=",".join(keys), comments="")
    paths = [out + ".png", out + ".csv"]
    if cycles:
        cols = list(cycles[0])
        np.savetxt(out + "_cycles.csv", np.array([[c[k] for k in cols] for c in cycles]),
                   delimiter=",", header=",".join(cols), comments="")
        from .viz.plots import cycle_energy_plot
        paths += [out + "_cycles.csv", cycle_energy_plot(cycles, out + "_cycles.png", title)]
    if vtk and sim.output is not None:
        from .viz.vtk_series import export_vtk
        n_frames = open_result(sim.output).n_frames
        if n_frames:
            paths.append(export_vtk(sim.output, out + "_vtk"))
        else:   # a packed copy keeps only the frames named at packing
            warnings.warn(f"{sim.output} has no frames: no VTK written (`dr-masonry pack "
                          f"--frames` keeps frames in a packed copy)", RuntimeWarning,
                          stacklevel=2)
    return paths

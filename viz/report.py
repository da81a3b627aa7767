"""One self-contained HTML page of a run (``dr-masonry report FILE``): what an engineer attaches to
a calculation note.

The page holds the scene and its parameters, the response curve, the 3-D damage views
(:mod:`dr_masonry.viz.views`) at the curve's peaks and at the end, the equilibrium certificate
(the lines of ``dr-masonry info``: :func:`dr_masonry.cli.certificate`), the energies and the
dissipation by mechanism at the last row (as ``info``'s last row prints them), the cycle table of
a cyclic run and the run's rows, iterations and relaxation time. The figures are embedded as
base64 PNG: the page needs no other file.

The scene of a result is its configuration's ``scene`` where the file records it, else the case
of :mod:`dr_masonry.cases` whose parameters the configuration holds (of several, the one with the
most values at its defaults, e.g. ``out``); the scene gives the curve (its ``CURVE``) and the views
(its ``VIEWS``).
"""
from __future__ import annotations

import base64
import html
import importlib
import json
import os
import tempfile

import numpy as np

from dr_masonry.results import Result, ResultsError, open_result

from .plots import PlotError, plot_history
from .views import write_views

#: configuration keys a run adds to its scene's parameters
_ADDED = {"h5", "progress", "solver", "scene"}
#: views of a scene that declares none
DEFAULT_VIEWS = {"view": dict(camera="iso", field="dt")}
#: the energy columns of the history (J) the page lists at the last row, with what they are
ENERGIES = {"W_ext": "external work", "E_stored": "stored elastic energy",
            "D_blocks": "dissipated in the bricks (plastic damage)",
            "D_joints": "dissipated in the joints", "D_joint_damage": "joints: cohesive damage",
            "D_joint_friction": "joints: friction",
            "E_damped": "absorbed by the relaxation's damping", "E_kinetic": "kinetic energy left",
            "balance_error": "balance error (of the gross work)"}


def scene_of(result, case=None):
    """(name, module) of the scene of ``result`` (a Result): ``case`` if given, else the
    configuration's ``scene``, else the case whose parameters the configuration holds; (None,
    None) when none fits."""
    from dr_masonry.cli import available_cases, import_case
    name = case or result.config.get("scene")
    if name:
        return name, import_case(name)
    keys = set(result.config) - _ADDED
    best, score = (None, None), -1
    for name in available_cases():
        try:
            mod = importlib.import_module(f"dr_masonry.cases.{name}")
        except ImportError:
            continue
        params = getattr(mod, "PARAMS", None)
        if not isinstance(params, dict) or set(params) != keys:
            continue
        same = sum(params[k] == result.config[k] for k in keys)
        if same > score:
            best, score = (name, mod), same
    return best


def curve_rows(result, curve):
    """Bool mask (n_rows,) of the history rows of the curve's stage (``curve["stage"]``: the
    rows of that stage, :func:`dr_masonry.study.stage_rows`; None: all rows)."""
    from dr_masonry.study import stage_rows
    mask = np.zeros(result.n_history, bool)
    mask[stage_rows(result.path, curve.get("stage"), result.n_history)] = True
    return mask


def peak_frames(result, curve, rows, points=("peak", "end")):
    """(tag, frame) of the frames nearest the curve's peaks (both ways where it was loaded both
    ways) and of the end (:func:`dr_masonry.scene.map_frames`)."""
    from dr_masonry.scene import map_frames, peak_increments, two_sided
    y = np.asarray(result.history[curve["y"]], dtype=float)[rows] * curve.get("yscale", 1.0)
    inc = np.asarray(result.history["increment"])[rows].astype(int)
    return map_frames(result, list(points), peak_increments(inc, y), two_sided(y), among=inc)


def _png(path):
    with open(path, "rb") as f:
        return base64.b64encode(f.read()).decode("ascii")


def _table(rows, head=None):
    """An HTML table of ``rows`` (lists of cells, escaped), ``head`` its header cells."""
    out = ["<table>"]
    if head:
        out.append("<tr>" + "".join(f"<th>{html.escape(str(c))}</th>" for c in head) + "</tr>")
    out += ["<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in rows]
    return "\n".join(out + ["</table>"])


def _figure(path, caption):
    return (f'<figure><img src="data:image/png;base64,{_png(path)}" alt="{html.escape(caption)}">'
            f"<figcaption>{html.escape(caption)}</figcaption></figure>")


def _cycles(r, curve, rows):
    """Lines of the cycle table of a cyclic run (:func:`dr_masonry.postprocess.cycle_text`): the
    force's peaks and xi_eq where the curve's force is a history force column (``*.f?``),
    else the amplitude and the energies."""
    from dr_masonry.postprocess import cycle_text, energy_per_cycle
    y = curve["y"]
    force = y if y.rsplit(".", 1)[-1] in ("fx", "fy", "fz") else None
    return cycle_text(energy_per_cycle(r.history, curve["x"], rows, force=force))


def write_report(h5_path, html_path=None, case=None, curve=None, size=(1000, 750)):
    """Write the run report of a results file.

    Parameters
    ----------
    h5_path : str or Result
    html_path : str, optional
        default ``<file stem>_report.html`` next to the file.
    case : str, optional
        the scene (a case name); default :func:`scene_of`.
    curve : dict, optional
        the curve (history columns ``x``, ``y``, optional ``stage``, ``xscale``, ``yscale``,
        ``xlabel``, ``ylabel``); default the scene's ``CURVE``.
    size : (width, height)
        pixels of each 3-D view.

    Returns
    -------
    str
        the page's path.
    """
    r = h5_path if isinstance(h5_path, Result) else open_result(h5_path)
    from dr_masonry.cli import certificate, last_row
    name, mod = scene_of(r, case)
    curve = curve or getattr(mod, "CURVE", None)
    if curve is None:
        raise ResultsError(f"report: the scene of {r.path} is not known (no case's parameters "
                           f"match its configuration): give the curve's history columns "
                           f"(--curve X,Y)")
    for k in ("x", "y"):
        if curve[k] not in r.history:
            raise ResultsError(f"report: {r.path} has no history column {curve[k]!r} (the "
                               f"curve's {k}); columns are {list(r.history)}")
    html_path = html_path or os.path.splitext(r.path)[0] + "_report.html"
    rows = curve_rows(r, curve)
    h = r.history
    doc = (mod.__doc__ or "").strip().splitlines() if mod is not None else []
    title = f"{os.path.basename(r.path)}: {name or 'run'}" + (f", {doc[0]}" if doc else "")
    body = [f"<h1>{html.escape(title)}</h1>",
            _table([["file", r.path], ["scene", name or "(unknown)"],
                    ["code", f"dr_masonry {r.attrs['code_version']}, schema "
                             f"{r.attrs['schema_version']}"],
                    ["created", r.attrs["created"]], ["restarts", len(r.attrs["restarts"])],
                    ["model", r.summary()],
                    ["groups", ", ".join(f"{k} ({len(v)})" for k, v in r.groups.items())]])]
    params = {k: v for k, v in r.config.items() if k != "solver"}
    body += ["<h2>Parameters</h2>",
             _table([[k, json.dumps(v)] for k, v in params.items()], ["parameter", "value"])]
    if isinstance(r.config.get("solver"), dict):
        body += ["<h3>Solver options</h3>",
                 _table([[k, json.dumps(v)] for k, v in r.config["solver"].items()],
                        ["option", "value"])]
    with tempfile.TemporaryDirectory() as tmp:
        body.append("<h2>Response</h2>")
        try:
            png = plot_history(r, curve["x"], curve["y"], os.path.join(tmp, "curve.png"),
                               xscale=curve.get("xscale", 1.0), yscale=curve.get("yscale", 1.0),
                               xlabel=curve.get("xlabel"), ylabel=curve.get("ylabel"), title=title)
            body.append(_figure(png, f"{curve.get('ylabel', curve['y'])} against "
                                     f"{curve.get('xlabel', curve['x'])}, every history row"))
        except PlotError as e:
            body.append(f"<p>No curve: {html.escape(str(e))}</p>")
        frames = peak_frames(r, curve, rows) if r.n_frames and rows.any() else []
        views = getattr(mod, "VIEWS", None) or DEFAULT_VIEWS
        body.append("<h2>Damage at the peaks and at the end</h2>")
        if frames:
            for path in write_views(r, os.path.join(tmp, "v"), frames, views, curve=curve,
                                    size=size):
                tag = os.path.basename(path)[2:-4]
                body.append(_figure(path, tag.replace("_", " ")))
        else:
            body.append("<p>No frame stored: no view.</p>")
    tol, above = r.rows_above_tol()
    n = r.n_history
    summary = [["history rows", n]]
    if tol is not None:
        summary += [["converged to tol", f"{n - above.size} (tol {tol:g})"],
                    ["accepted at a floor (above tol)", above.size],
                    ["largest residual ratio", f"{np.max(h['residual']):.3g}" if n else "-"]]
    body += ["<h2>Equilibrium certificate</h2>", _table(summary),
             "<ul class=certificate>"
             + "".join(f"<li><code>{html.escape(line)}</code></li>" for line in certificate(r))
             + "</ul>"]
    last = last_row(r)
    energies = [[k, what, last[k]] for k, what in ENERGIES.items() if k in last]
    if energies:
        body += ["<h3>Energy balance and dissipation by mechanism at the last row (J)</h3>",
                 _table(energies, ["column", "what", "value"])]
    if r.config.get("protocol") == "cyclic" and rows.any():
        body += ["<h2>Cycles</h2>", "<pre>" + html.escape("\n".join(_cycles(r, curve, rows)))
                 + "</pre>"]
    work = [["rows", n]]
    for k, what in (("iterations", "relaxation iterations"),
                    ("cut_iterations", "iterations of attempts cut in two"),
                    ("time_s", "relaxation time (s)"), ("cut_s", "time of attempts cut (s)")):
        if k in h:
            work.append([what, f"{np.nansum(h[k]):.6g}"])
    if "iterations" in h and n:
        work.append(["iterations per row: mean, max",
                     f"{np.mean(h['iterations']):.0f}, {np.max(h['iterations']):.0f}"])
    body += ["<h2>Run time and iterations</h2>", _table(work)]
    page = ("<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8>"
            f"<title>{html.escape(title)}</title><style>"
            "body{font-family:sans-serif;max-width:1100px;margin:auto}"
            "table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #bbb;"
            "padding:2px 6px;text-align:left}img{max-width:100%}</style></head><body>\n"
            + "\n".join(body) + "\n</body></html>\n")
    with open(html_path, "w", encoding="utf-8") as f:
        f.write(page)
    return html_path

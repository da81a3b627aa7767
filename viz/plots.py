"""Curves from the history of one or several runs, and 2-D crack maps of walls.

Drawn on bare matplotlib ``Figure`` objects (no pyplot, so the caller's back end is untouched).
"""
from __future__ import annotations

import os

import numpy as np
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.figure import Figure

from dr_masonry.loading import is_number
from dr_masonry.model import id_array

from .render import HEX_EDGES, output_file
from .vtk_series import as_result, block_corner_nodes, positions

#: in-plane axes of an elevation: plane name -> (horizontal, vertical) coordinate indices
PLANES = {"xz": (0, 2), "yz": (1, 2), "xy": (0, 1)}
#: unit names of common scale factors from SI
_UNITS = {"m": {1.0: "m", 1e3: "mm"}, "N": {1.0: "N", 1e-3: "kN", 1e-6: "MN"}}


class PlotError(ValueError):
    """Bad arguments to a plotting function."""


def _unit(scale, kind):
    return _UNITS[kind].get(float(scale), f"x{scale:g} SI")


def plot_history(results, x_key, y_key, png, xscale=1e3, yscale=1e-3, label=None, xlabel=None,
                 ylabel=None, title=None):
    """Plot history column(s) ``y_key`` against ``x_key`` for one run or overlay several.

    Parameters
    ----------
    results : str, Result or list of them
        the run(s).
    x_key : str
        history column (SI).
    y_key : str or list of str
        history column(s) (SI); several give one line each (e.g. the reactions of each wall).
    png : str
        output file (its extension gives the format; its folder is created).
    xscale, yscale : float
        non-zero factors applied to the SI values (default m -> mm and N -> kN).
    label : str or list of str, optional
        legend entries (default: the file names). Rows accepted above the run's tolerance (at a
        residual floor, ``SolverOptions.floor_tol``) are marked with open circles.
    xlabel, ylabel, title : str, optional
        default labels are the keys with the units of the scales.

    Returns
    -------
    str
        ``png``.
    """
    for name, scale in (("xscale", xscale), ("yscale", yscale)):
        if not (is_number(scale) and scale != 0):
            raise PlotError(f"plot_history: {name}={scale!r} must be a finite non-zero number")
    runs = [as_result(r) for r in (results if isinstance(results, (list, tuple)) else [results])]
    if not runs:
        raise PlotError("plot_history: results is empty; give at least one run")
    labels = label if isinstance(label, (list, tuple)) else [label] * len(runs)
    if len(labels) != len(runs):
        raise PlotError(f"plot_history: {len(labels)} labels for {len(runs)} runs")
    ys = list(y_key) if isinstance(y_key, (list, tuple)) else [y_key]
    if not ys:
        raise PlotError("plot_history: y_key is empty; give at least one history column")
    png = output_file("plot_history", png, error=PlotError)
    fig = Figure(figsize=(6.4, 4.8))
    ax = fig.add_subplot()
    for r, lab in zip(runs, labels):
        for key in [x_key] + ys:
            if key not in r.history:
                raise PlotError(f"plot_history: {r.path} has no history column {key!r}; "
                                f"columns are {list(r.history)}")
        if not r.n_history:
            raise PlotError(f"plot_history: {r.path} has no history rows to plot")
        tol, floor = r.rows_above_tol()
        name = lab or os.path.basename(r.path)
        for j, key in enumerate(ys):
            x, y = r.history[x_key] * xscale, r.history[key] * yscale
            line, = ax.plot(x, y, lw=1.2, label=f"{name}: {key}" if len(ys) > 1 else name)
            if floor is not None and floor.size:   # one legend entry per run
                ax.plot(x[floor], y[floor], "o", ms=4, mfc="none", color=line.get_color(),
                        label=(f"{name}: {floor.size} rows accepted above tol {tol:g} (open)"
                               if j == 0 else "_nolegend_"))
    ax.set_xlabel(xlabel or f"{x_key} [{_unit(xscale, 'm')}]")
    ax.set_ylabel(ylabel or f"{', '.join(ys)} [{_unit(yscale, 'N')}]")
    if title:
        ax.set_title(title)
    ax.grid(True, lw=0.4, alpha=0.5)
    ax.axhline(0.0, color="k", lw=0.5)
    ax.axvline(0.0, color="k", lw=0.5)
    ax.legend(fontsize="small" if len(ax.get_legend_handles_labels()[1]) > 4 else None)
    fig.tight_layout()
    fig.savefig(png, dpi=150)
    return png


def crack_map(result, frame, png, threshold=0.5, field="D", plane="xz", blocks=None, warp=0.0,
              title=None, element_field="dt"):
    """Elevation of a wall: block outlines, joint points with damage above ``threshold``, and
    element damage shaded (tensile "dt", or compressive "dc" for a crushing map).

    Parameters
    ----------
    result : str or Result
    frame : int or "checkpoint"
        frame position (negative from the end), or the last checkpoint (a run stopped between
        frames).
    png : str
        output file (its extension gives the format; its folder is created).
    threshold : float
        contact points with ``field`` above it (a finite number >= 0) are drawn, coloured by
        its value.
    field : str
        contact field of the frame to map (default joint damage "D").
    plane : {"xz", "yz", "xy"}
        projection plane (x-z: a wall along x).
    blocks : array_like of int or str, optional
        block ids or a block group name to draw (default all).
    warp : float
        displacement magnification (0: reference positions).
    element_field : {"dt", "dc"}
        element damage to shade.

    Returns
    -------
    str
        ``png``.
    """
    r = as_result(result)
    if element_field not in ("dt", "dc"):
        raise PlotError(f"crack_map: element_field must be 'dt' or 'dc', got {element_field!r}")
    if plane not in PLANES:
        raise PlotError(f"crack_map: plane must be one of {sorted(PLANES)}, got {plane!r}")
    if not (is_number(threshold) and threshold >= 0):
        raise PlotError(f"crack_map: threshold={threshold!r} must be a finite number >= 0")
    a, b = PLANES[plane]
    arrays = r.model_arrays
    nb = len(arrays["block_divisions"])
    if blocks is None:
        sel = np.arange(nb)
    elif isinstance(blocks, str):
        if blocks not in r.groups:
            raise PlotError(f"crack_map: no block group {blocks!r}; groups are {r.group_names}")
        sel = r.groups[blocks]
    else:
        sel = id_array("crack_map: blocks", blocks, nb, PlotError)
    keep = np.zeros(nb, bool)
    keep[sel] = True
    fields = r.frame(frame)
    joint = sorted(k for k, v in r.locations(frame).items()
                   if v == "contact" and np.ndim(fields.get(k)) == 1)
    # a model without joints has no contact field: the default "D" then draws none
    if not isinstance(field, str) or field not in joint and (joint or field != "D"):
        raise PlotError(f"crack_map: field={field!r} is not a contact field of frame {frame!r}; "
                        f"its contact fields are {joint}")
    png = output_file("crack_map", png, error=PlotError)
    x = positions(arrays["nodes"], fields, warp)
    fig = Figure(figsize=(8, 6))
    ax = fig.add_subplot()
    ax.set_aspect("equal")
    dt = fields.get(element_field)
    if dt is not None:
        elem = np.flatnonzero(keep[arrays["element_block"]] & (dt > 1e-3))
        elem = elem[np.argsort(dt[elem])]          # most damaged drawn last
        xe = x[arrays["elements"][elem]][:, :, [a, b]]
        faces = xe[:, [0, 1, 5, 4]] if plane == "xz" else (
            xe[:, [1, 2, 6, 5]] if plane == "yz" else xe[:, [0, 1, 2, 3]])
        pc = PolyCollection(faces, array=dt[elem], cmap="Greys", clim=(0.0, 1.0),
                            edgecolors="none")
        ax.add_collection(pc)
        kind = "tensile" if element_field == "dt" else "compressive"
        fig.colorbar(pc, ax=ax, shrink=0.6, label=f"block {kind} damage {element_field}")
    corners = block_corner_nodes(arrays)[keep]
    seg = x[corners[:, HEX_EDGES]][:, :, :, [a, b]].reshape(-1, 2, 2)
    ax.add_collection(LineCollection(seg, colors="0.3", linewidths=0.5))
    con = r.contacts(frame)
    if con is not None and field in joint:
        v = fields[field]
        on = (v > threshold) & keep[con["blocks"][:, 0]]
        xs = x[con["slave"][on]]
        order = np.argsort(v[on])
        sc = ax.scatter(xs[order, a], xs[order, b], c=v[on][order], s=6, cmap="Reds",
                        vmin=threshold, vmax=1.0 if field == "D" else None, zorder=3)
        fig.colorbar(sc, ax=ax, shrink=0.6, label=f"joint {field} > {threshold:g}")
    ax.autoscale_view()
    ax.set_xlabel(f"{plane[0]} [m]")
    ax.set_ylabel(f"{plane[1]} [m]")
    inc = r.frame_increment(frame)
    ax.set_title(title or f"{os.path.basename(r.path)}: increment {inc}")
    fig.tight_layout()
    fig.savefig(png, dpi=150)
    return png


def cycle_energy_plot(cycles, png, title=None):
    """Energy dissipated per cycle, stacked joints over blocks (J, bars), and the equivalent
    viscous damping ratio (line, right axis) where the cycles have it.

    Parameters
    ----------
    cycles : list of dict
        :func:`dr_masonry.postprocess.energy_per_cycle` (``cycle``, ``D_joints``, ``D_blocks``,
        optional ``xi_eq`` and ``complete``); a partial last cycle is drawn hatched.
    png : str
        output file (its extension gives the format; its folder is created).
    title : str, optional

    Returns
    -------
    str
        ``png``.
    """
    cycles = list(cycles) if isinstance(cycles, (list, tuple)) else None
    if not cycles or not all(isinstance(c, dict) and {"cycle", "D_joints", "D_blocks"} <= set(c)
                             for c in cycles):
        raise PlotError("cycle_energy_plot: cycles must be the non-empty list energy_per_cycle "
                        "returns")
    png = output_file("cycle_energy_plot", png, error=PlotError)
    n = np.array([c["cycle"] for c in cycles])
    dj = np.array([c["D_joints"] for c in cycles])
    db = np.array([c["D_blocks"] for c in cycles])
    partial = np.array([not c.get("complete", True) for c in cycles])
    fig = Figure(figsize=(6.4, 4.0))
    ax = fig.add_subplot()
    hatch = ["//" if p else "" for p in partial]
    ax.bar(n, dj, color="tab:red", label="joints", hatch=hatch)
    ax.bar(n, db, bottom=dj, color="0.4", label="blocks", hatch=hatch)
    ax.set_xlabel("cycle" + (" (hatched: partial)" if partial.any() else ""))
    ax.set_ylabel("energy dissipated in the cycle (J)")
    ax.set_xticks(n)
    ax.legend(loc="upper left")
    if all("xi_eq" in c for c in cycles):
        ax2 = ax.twinx()
        ax2.plot(n, [100.0 * c["xi_eq"] for c in cycles], "ko-", ms=3)
        ax2.set_ylabel("equivalent viscous damping (%), line")
        ax2.set_ylim(bottom=0.0)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    fig.savefig(png, dpi=150)
    return png

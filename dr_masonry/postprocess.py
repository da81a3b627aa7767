"""Quantities derived from a run's history: cycles of a cyclic protocol and the energy dissipated
in each (what an engineer compares between cycles and between models)."""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from .loading import is_number


class PostprocessError(ValueError):
    """A history that does not hold what was asked for."""


#: history columns of the solver's work per row (:func:`energy_per_cycle` sums them per cycle)
WORK_COLUMNS = ("iterations", "cut_iterations", "time_s", "cut_s")


def cycle_bounds(u):
    """Row ranges of the full cycles of a cyclic displacement history.

    A cycle starts at rest or where ``u`` turns positive again after a negative excursion (the
    protocols go 0 -> +a -> -a -> 0, the return to zero ends the cycle; a protocol started
    negative, 0 -> -a -> +a -> 0, is handled by the sign of its first move).

    Parameters
    ----------
    u : (n,) float64
        control displacement per history row, m.

    Returns
    -------
    list of (start, stop)
        row slices ``u[start:stop]`` of each cycle (the last one may be partial).
    """
    u = np.asarray(u, dtype=np.float64)
    if u.ndim != 1 or u.size == 0 or not np.all(np.isfinite(u)):
        raise PostprocessError("cycle_bounds: u must be a non-empty finite 1-D array")
    moved = np.flatnonzero(u != 0.0)
    if moved.size == 0:
        return [(0, u.size)]
    s = np.sign(u[moved[0]])
    v = s * u
    starts, went_negative = [0], False
    for i in range(1, u.size):
        if v[i] > 0.0 and v[i - 1] <= 0.0 and went_negative:
            starts.append(i)
            went_negative = False
        went_negative |= v[i] < 0.0
    ends = starts[1:] + [u.size]
    return list(zip(starts, ends))


def energy_per_cycle(history, key, rows=None, force=None):
    """Energy dissipated in each cycle of the control displacement ``history[key]``.

    Parameters
    ----------
    history : dict of (n,) arrays, Result or Simulation
        a run's history (``Simulation.history`` or ``Result.history``, or the run itself).
    key : str
        the control displacement column (e.g. ``"beam.ux"``).
    rows : (n,) bool, optional
        the rows of the cyclic stage (default all).
    force : str, optional
        the force column that goes with ``key`` (e.g. ``"beam.fx"``): adds the cycle's peaks and
        its equivalent viscous damping ratio.

    Returns
    -------
    list of dict
        per cycle: ``cycle`` (1-based), ``amplitude`` (max |u|, m), ``D_blocks``, ``D_joints``
        and ``D_total`` (J dissipated during the cycle), ``W_ext`` (J, net external work of
        the cycle), ``complete`` (False for a last cycle that has not gone both ways and back
        to zero: a run stopped inside it). With ``force``: ``u_max``, ``u_min`` (m, extreme
        displacements), ``F_max``, ``F_min`` (largest and smallest force of the cycle, the
        column's unit) and ``xi_eq``, the equivalent viscous damping ratio ``D_total / (pi
        (|F(u_max) u_max| + |F(u_min) u_min|))`` (Jacobsen's ``E_D / (4 pi E_so)`` with the
        strain energy ``E_so`` of each half cycle at its peak displacement; NaN for a cycle
        without displacement). The energies are those of the whole model: give the force acting
        on it (a half model's own, not the whole building's). With the solver's columns in the
        history (``WORK_COLUMNS``), what the cycle cost: ``rows``, ``iterations`` and
        ``cut_iterations`` (relaxation iterations of its rows and of the attempts cut in two),
        ``solve_s`` (s of relaxation, cut attempts included).
    """
    if not isinstance(history, Mapping) and isinstance(getattr(history, "history", None), Mapping):
        history = history.history
    if not isinstance(history, Mapping):
        raise PostprocessError(f"energy_per_cycle: history must be a dict of columns (a run's "
                               f".history) or the run, got {type(history).__name__}")
    for name, k in (("key", key), ("force", force)):
        if not isinstance(k, str) and (name == "key" or k is not None):
            raise PostprocessError(f"energy_per_cycle: {name}={k!r} must be a history column name")
    need = (key, "D_blocks", "D_joints", "W_ext") + ((force,) if force is not None else ())
    for k in need:
        if k not in history:
            raise PostprocessError(f"energy_per_cycle: no history column {k!r}")
    lengths = {k: len(history[k]) for k in need}
    if len(set(lengths.values())) > 1:
        raise PostprocessError(f"energy_per_cycle: history columns of different lengths: "
                               f"{', '.join(f'{k!r} {n}' for k, n in lengths.items())}")
    sel = np.ones(len(history[key]), bool) if rows is None else np.asarray(rows, bool)
    if sel.shape != (len(history[key]),):
        raise PostprocessError(f"energy_per_cycle: rows has shape {sel.shape}, the history has "
                               f"{len(history[key])} rows")
    if not sel.any():
        raise PostprocessError("energy_per_cycle: rows selects no row of the history")
    rows_used = np.flatnonzero(sel)
    first = rows_used[0]
    for k in need:   # the rows used (and the energies' row before the first)
        used = rows_used
        if k in ("D_blocks", "D_joints", "W_ext") and first > 0:
            used = np.r_[first - 1, used]
        v = np.asarray(history[k], dtype=np.float64)[used]
        if not np.all(np.isfinite(v)):
            j = int(np.argmax(~np.isfinite(v)))
            raise PostprocessError(f"energy_per_cycle: history column {k!r} row {used[j] + 1} "
                                   f"(from 1) is {float(v[j])}, not a finite number")
    u = np.asarray(history[key])[sel]
    cum = {k: np.asarray(history[k])[sel] for k in ("D_blocks", "D_joints", "W_ext")}
    f = np.asarray(history[force])[sel] if force is not None else None
    work = ({k: np.nan_to_num(np.asarray(history[k], dtype=np.float64)[sel]) for k in WORK_COLUMNS}
            if all(k in history and len(history[k]) == sel.size for k in WORK_COLUMNS) else None)
    before = {k: (np.asarray(history[k])[first - 1] if first > 0 else 0.0) for k in cum}
    out = []
    bounds = cycle_bounds(u)
    moved = u[u != 0.0]
    signed = u * (np.sign(moved[0]) if moved.size else 1.0)   # the protocol's first move positive
    for i, (a, b) in enumerate(bounds):
        row = {"cycle": i + 1, "amplitude": float(np.abs(u[a:b]).max()),
               "complete": bool(i < len(bounds) - 1 or (signed[a:b].min() < 0.0
                                                              and signed[b - 1] >= 0.0))}
        for k, v in cum.items():
            start = v[a - 1] if a > 0 else before[k]
            row[k] = float(v[b - 1] - start)
        row["D_total"] = row["D_blocks"] + row["D_joints"]
        if work:
            row.update(rows=b - a, iterations=int(work["iterations"][a:b].sum()),
                       cut_iterations=int(work["cut_iterations"][a:b].sum()),
                       solve_s=float(work["time_s"][a:b].sum() + work["cut_s"][a:b].sum()))
        if f is not None:
            hi, lo = a + int(np.argmax(u[a:b])), a + int(np.argmin(u[a:b]))
            row.update(u_max=float(u[hi]), u_min=float(u[lo]), F_max=float(f[a:b].max()),
                       F_min=float(f[a:b].min()))
            strain = abs(f[hi] * u[hi]) + abs(f[lo] * u[lo])
            row["xi_eq"] = float(row["D_total"] / (np.pi * strain)) if strain > 0 else float("nan")
        out.append(row)
    return out


def cycle_text(cycles, u_unit=1e-3, f_unit=1e3):
    """Per-cycle table of :func:`energy_per_cycle` as text lines: displacements in ``u_unit`` m
    (default mm), forces in ``f_unit`` (default kN), energies J. Cycles without ``force`` give
    the amplitude instead of the peaks, forces and xi_eq; with the solver's work (rows,
    iterations, minutes of relaxation) where the cycles carry it; a cycle a run stopped inside
    (``complete`` False) is marked ``(partial)``."""
    for name, v in (("u_unit", u_unit), ("f_unit", f_unit)):
        if not (is_number(v) and v > 0):
            raise PostprocessError(f"cycle_text: {name}={v!r} must be a finite number > 0")
    cycles = list(cycles)
    peaks = all("u_max" in c for c in cycles)
    need = ("cycle", "D_total", "D_joints", "D_blocks") + (
        ("u_max", "u_min", "F_max", "F_min", "xi_eq") if peaks else ("amplitude",))
    for i, c in enumerate(cycles):
        missing = [k for k in need if k not in c]
        if missing:
            raise PostprocessError(f"cycle_text: cycle {i} lacks {missing}; give the list "
                                   "energy_per_cycle returns")

    work = all("iterations" in c for c in cycles)

    def tail(c):
        cost = (f"  {c['rows']:5d} {c['iterations']:11d} {c['cut_iterations']:10d} "
                f"{c['solve_s'] / 60:7.1f}" if work else "")
        return cost + ("" if c.get("complete", True) else " (partial)")
    cost = "   rows  iterations    in cuts     min" if work else ""
    if not peaks:
        return "\n".join(["cycle  amplitude  dissipated (joints / blocks) J" + cost] + [
            f"{c['cycle']:5d} {c['amplitude'] / u_unit:10.2f}  {c['D_total']:10.2f} "
            f"({c['D_joints']:.2f} / {c['D_blocks']:.2f}){tail(c)}" for c in cycles])
    lines = ["cycle  u_max  u_min   F_max   F_min  dissipated (joints / blocks) J  xi_eq" + cost]
    for c in cycles:
        lines.append(f"{c['cycle']:5d} {c['u_max'] / u_unit:6.2f} {c['u_min'] / u_unit:6.2f} "
                     f"{c['F_max'] / f_unit:7.2f} {c['F_min'] / f_unit:7.2f}  {c['D_total']:10.2f} "
                     f"({c['D_joints']:.2f} / {c['D_blocks']:.2f})   {c['xi_eq']:.3f}{tail(c)}")
    return "\n".join(lines)

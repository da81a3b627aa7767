"""Quantities derived from a run's history: cycles of a cyclic protocol and the energy dissipated
in each (what an engineer compares between cycles and between models)."""
from __future__ import annotations

import numpy as np


class PostprocessError(ValueError):
    """A history that does not hold what was asked for."""


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


def energy_per_cycle(history, key, rows=None):
    """Energy dissipated in each cycle of the control displacement ``history[key]``.

    Parameters
    ----------
    history : dict of (n,) arrays
        a run's history (``Simulation.history`` or ``Result.history``).
    key : str
        the control displacement column (e.g. ``"beam.ux"``).
    rows : (n,) bool, optional
        the rows of the cyclic stage (default all).

    Returns
    -------
    list of dict
        per cycle: ``cycle`` (1-based), ``amplitude`` (max |u|, m), ``D_blocks``, ``D_joints``
        and ``D_total`` (J dissipated during the cycle), ``W_ext`` (J, net external work of
        the cycle).
    """
    for k in (key, "D_blocks", "D_joints", "W_ext"):
        if k not in history:
            raise PostprocessError(f"energy_per_cycle: no history column {k!r}")
    sel = np.ones(len(history[key]), bool) if rows is None else np.asarray(rows, bool)
    u = np.asarray(history[key])[sel]
    cum = {k: np.asarray(history[k])[sel] for k in ("D_blocks", "D_joints", "W_ext")}
    first = np.flatnonzero(sel)[0]
    before = {k: (np.asarray(history[k])[first - 1] if first > 0 else 0.0) for k in cum}
    out = []
    for i, (a, b) in enumerate(cycle_bounds(u)):
        row = {"cycle": i + 1, "amplitude": float(np.abs(u[a:b]).max())}
        for k, v in cum.items():
            start = v[a - 1] if a > 0 else before[k]
            row[k] = float(v[b - 1] - start)
        row["D_total"] = row["D_blocks"] + row["D_joints"]
        out.append(row)
    return out

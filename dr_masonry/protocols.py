"""Loading protocols of the reference scenes (CASES.md) as data, and their displacement paths.

A :class:`Protocol` lists the cyclic amplitudes of a scene, the cycles per amplitude and the
monotonic target, either as drifts in percent of a height (in-plane walls S4, S5) or as
displacements in m (S6, S7). :meth:`Protocol.path` turns it into one target value per increment
with :func:`dr_masonry.loading.cyclic_path`, refining each amplitude so that no increment moves
more than ``step`` (m).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .loading import LoadingError, check_increments, cyclic_path
from .units import mm


@dataclass(frozen=True)
class Protocol:
    """A cyclic protocol and its monotonic counterpart.

    Attributes
    ----------
    name : str
    amplitudes : tuple of float
        cyclic amplitudes, increasing; in percent drift (``unit="drift"``) or m (``unit="m"``).
    cycles : int
        full cycles 0 -> +a -> -a -> 0 per amplitude.
    monotonic : float
        target of the monotonic run (same unit).
    unit : {"drift", "m"}
    """
    name: str
    amplitudes: tuple
    cycles: int
    monotonic: float
    unit: str = "drift"

    def _scale(self, height):
        if self.unit == "m":
            return 1.0
        if height is None or not (math.isfinite(height) and height > 0):
            raise LoadingError(f"protocol {self.name}: drift protocol needs a height > 0 m, "
                               f"got {height!r}")
        return 0.01 * float(height)

    def amplitudes_m(self, height=None):
        """Amplitudes in m ((n,) array); ``height`` (m) converts percent drifts."""
        return np.asarray(self.amplitudes, dtype=np.float64) * self._scale(height)

    def path(self, height=None, step=0.5 * mm, quarter_increments=2, n_amplitudes=None,
             start_negative=False):
        """Cyclic displacement targets (m), one per increment.

        Each quarter cycle of amplitude ``a`` gets ``max(quarter_increments, ceil(a / step))``
        increments, so small cycles are still resolved and large ones move at most ``step`` per
        increment (a peak inside a cycle needs steps well below its displacement).
        ``n_amplitudes`` keeps only the first amplitudes (None: all).
        """
        if not (math.isfinite(step) and step > 0):
            raise LoadingError(f"protocol {self.name}: step must be > 0 m, got {step!r}")
        if int(quarter_increments) < 1:
            raise LoadingError(f"protocol {self.name}: quarter_increments must be >= 1, got "
                               f"{quarter_increments!r}")
        amps = self.amplitudes_m(height)
        if n_amplitudes is not None:
            if not 1 <= int(n_amplitudes) <= amps.size:
                raise LoadingError(f"protocol {self.name}: n_amplitudes must be in 1..{amps.size}, "
                                   f"got {n_amplitudes!r}")
            amps = amps[:int(n_amplitudes)]
        quarter = [max(int(quarter_increments), math.ceil(a / step - 1e-9)) for a in amps]
        check_increments(4 * self.cycles * sum(quarter), f"protocol {self.name} with step "
                         f"{step!r} m")
        parts = [cyclic_path([a], self.cycles, k, start_negative) for a, k in zip(amps, quarter)]
        return np.concatenate(parts)

    def monotonic_path(self, increments, height=None, target=None, grading=1.0):
        """Monotonic targets (m): ``target`` (default the protocol's, same unit) reached in
        ``increments`` steps, the i-th at ``target * (i / n) ** grading`` (grading > 1 refines
        the start, where the response bends most)."""
        n = int(increments)
        if n < 1:
            raise LoadingError(f"protocol {self.name}: increments must be >= 1, got {increments!r}")
        check_increments(n, f"protocol {self.name}")
        if not (math.isfinite(grading) and grading > 0):
            raise LoadingError(f"protocol {self.name}: grading must be > 0, got {grading!r}")
        goal = self.monotonic if target is None else float(target)
        if not math.isfinite(goal) or goal == 0.0:
            raise LoadingError(f"protocol {self.name}: the monotonic target must be a finite "
                               f"nonzero value (its sign sets the direction), got {target!r}")
        return goal * self._scale(height) * (np.arange(1, n + 1) / n) ** grading


def turning_points(path):
    """Increments (counted from 1) at which a path of targets turns back: its cyclic peaks,
    where the crack maps of the paper's figures are drawn (``Stage.frame_at``)."""
    d = np.diff(np.asarray(path, dtype=np.float64))
    return tuple(int(k) + 1 for k in np.flatnonzero(d[:-1] * d[1:] < 0.0) + 1)


#: S4 slender wall: drift (%) of the 2.75 m wall, two cycles each, monotonic to 2.5 %.
S4 = Protocol("S4", (0.05, 0.1, 0.2, 0.3, 0.5, 0.75, 1.0, 1.5, 2.0), 2, 2.5)
#: S5 squat wall: drift (%), two cycles each, monotonic to 1.0 %.
S5 = Protocol("S5", (0.025, 0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.75), 2, 1.0)
#: S6 out-of-plane wall: centre displacement (m), one cycle each, monotonic to 40 mm.
S6 = Protocol("S6", tuple(a * mm for a in (2, 5, 10, 15, 20, 30)), 1, 40 * mm, unit="m")
#: S7 terraced house: top displacement (m), one cycle each, monotonic to 60 mm.
S7 = Protocol("S7", tuple(a * mm for a in (2.5, 5, 10, 20, 30, 40, 50, 60)), 1, 60 * mm, unit="m")

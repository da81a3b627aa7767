"""Observers of a run: small objects that ``rows.commit`` hands every committed history row
(``row(sim, row)``), like PyFR's plug-ins. The progress bar is also told while an increment
relaxes (``working``) and when one is done (``increment_done``)."""
from __future__ import annotations

import time


class ProgressBar:
    """A tqdm bar of the run's increments, its text the stage, row, residual and iterations
    (``SolverOptions.progress``; a disabled bar costs nothing)."""

    def __init__(self, total, enabled):
        from tqdm.auto import tqdm
        self._bar = tqdm(total=total, disable=not enabled, unit="incr")
        self._t = 0.0   # when the text was last changed within an increment (perf_counter, s)

    def working(self, sim, residual, done):
        """During an increment: its residual ratio and iterations so far, at most once a
        second."""
        if time.perf_counter() - self._t > 1.0:
            self._t = time.perf_counter()
            self._bar.set_postfix_str(f"{sim.stage_name} row {sim.increment + 1} res="
                                      f"{residual:.1e} it={done}...")

    def row(self, sim, row):
        """Every row, so that the halves of a cut increment show too."""
        self._bar.set_postfix_str(f"{sim.stage_name} row {sim.increment} res="
                                  f"{row['residual']:.1e} it={int(row['iterations'])}")

    def increment_done(self):
        self._bar.update(1)

    def close(self):
        self._bar.close()


class Idle:
    """The progress observer outside ``run`` (nothing to show)."""

    def working(self, sim, residual, done):
        pass

    def row(self, sim, row):
        pass

    def increment_done(self):
        pass

    def close(self):
        pass


class RowWriter:
    """Appends every row to the result file's ``/history`` (``results.ResultWriter``)."""

    def __init__(self, writer):
        self.writer = writer

    def row(self, sim, row):
        self.writer.append_history(row)

"""Test helper: simulate an interrupted run (Ctrl-C) at a chosen committed increment."""
from dr_masonry.solver import Simulation


def interrupt_after(monkeypatch, increment):
    """Make runs raise KeyboardInterrupt once ``increment`` has been committed (an interrupt)."""
    commit = Simulation._commit

    def stop(self, *args):
        commit(self, *args)
        if self.increment == increment:
            raise KeyboardInterrupt
    monkeypatch.setattr(Simulation, "_commit", stop)

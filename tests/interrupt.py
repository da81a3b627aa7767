"""Test helper: simulate an interrupted run (Ctrl-C) at a chosen committed increment."""
from dr_masonry.solver import increments

#: the commit of an accepted increment, as the increment loop calls it
COMMIT = increments.commit


def interrupt_after(monkeypatch, increment):
    """Make runs raise KeyboardInterrupt once ``increment`` has been committed (an interrupt);
    ``monkeypatch.setattr(increments, "commit", COMMIT)`` undoes it."""
    def stop(sim, *args):
        COMMIT(sim, *args)
        if sim.increment == increment:
            raise KeyboardInterrupt
    monkeypatch.setattr(increments, "commit", stop)

"""Stopping a run from outside without losing what it wrote.

Ctrl-C (SIGINT) raises :class:`KeyboardInterrupt` in Python; a batch scheduler's or ``kill``'s
stop (SIGTERM) would end the process at once. During a run, :func:`terminate_as_interrupt` turns
SIGTERM into :class:`Terminated` (a KeyboardInterrupt), so both take the same path: the run
stops between two compiled calls, its file keeps every row, frame and the last checkpoint, and
the scenes say how to continue. :func:`uninterrupted` holds either signal back while a write to
the results file is under way (a checkpoint half replaced could not be resumed) and raises it
when the write is complete. Inside :func:`terminate_as_interrupt` it also holds them while Numba
compiles: an exception raised in the compiler's Python code (LLVM's object-code callback, for
one) would leave a half-built function and end the run with a Numba traceback instead of the
stop it asked for (a run's first minute is its cold compile).

Handlers can only be set in the main thread: elsewhere (a Dask worker's thread) both context
managers do nothing, and the process's owner decides what its signals do. A signal the process
ignores (SIGINT of a job started in the background) stays ignored.
"""
from __future__ import annotations

import signal
import threading
from contextlib import ExitStack, contextmanager


class Terminated(KeyboardInterrupt):
    """A run stopped by SIGTERM (``kill``, a scheduler's time limit or pre-emption)."""


def _raise_terminated(signum, frame):
    raise Terminated("SIGTERM")


def _in_main_thread():
    return threading.current_thread() is threading.main_thread()


#: Numba events during which signals are held: a compilation, and LLVM's code generation
COMPILE_EVENTS = ("numba:compile", "numba:llvm_lock")


def _compile_hold():
    """A Numba event listener that holds SIGINT and SIGTERM (:func:`uninterrupted`) from the
    start of the outermost compile event to its end, where a held signal is raised."""
    from numba.core import event   # here: `dr-masonry info` and `list` need no Numba

    class CompileHold(event.Listener):
        def __init__(self):
            self.depth, self.hold = 0, None

        def on_start(self, ev):
            if self.depth == 0:
                self.hold = uninterrupted()
                self.hold.__enter__()
            self.depth += 1

        def on_end(self, ev):
            self.depth -= 1
            if self.depth == 0:
                hold, self.hold = self.hold, None
                hold.__exit__(None, None, None)   # raises a signal held meanwhile

    return event, CompileHold()


@contextmanager
def terminate_as_interrupt():
    """Within the block, SIGTERM raises :class:`Terminated` (unless another handler than the
    default one is set: the process's owner handles it then), and SIGINT and SIGTERM wait for the
    end of a Numba compilation under way (module docstring)."""
    if not _in_main_thread() or signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL:
        yield
        return
    event, hold = _compile_hold()
    signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        with ExitStack() as stack:
            for kind in COMPILE_EVENTS:
                stack.enter_context(event.install_listener(kind, hold))
            yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


@contextmanager
def uninterrupted():
    """Within the block, SIGINT and SIGTERM whose handlers raise in Python are recorded, not
    raised; at its end the first one recorded is raised by its own handler. Nests: an inner
    block's recorded signal goes to the outer block's record."""
    if not _in_main_thread():
        yield
        return
    pending = []
    saved = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        handler = signal.getsignal(sig)
        if callable(handler):
            saved[sig] = handler
            signal.signal(sig, lambda signum, frame: pending.append(signum))
    try:
        yield
    finally:
        for sig, handler in saved.items():
            signal.signal(sig, handler)
    if pending:
        saved[pending[0]](pending[0], None)

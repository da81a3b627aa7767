"""Stopping a run from outside: SIGTERM as Ctrl-C, no half-written results file."""
import os
import signal
import subprocess
import sys
import threading
import time

import h5py
import numpy as np
import pytest
from numba import njit
from numba.core import event

from dr_masonry.interrupts import Terminated, terminate_as_interrupt, uninterrupted
from dr_masonry.results import CHECKPOINT_NEW, ResultWriter, open_result
from conftest import gravity, tiny_wall, write_fake_result
from dr_masonry.kernels import relaxation as R


@pytest.fixture(autouse=True)
def _sigint_raises():
    """SIGINT raises KeyboardInterrupt here even where pytest was started in the background,
    which ignores it (and :mod:`dr_masonry.interrupts` leaves an ignored signal ignored)."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


def _signal_self(sig):
    os.kill(os.getpid(), sig)
    time.sleep(0.01)   # the handler runs at the next bytecode after delivery


def test_uninterrupted_defers_sigint_to_the_end_of_the_block():
    done = []
    with pytest.raises(KeyboardInterrupt):
        with uninterrupted():
            _signal_self(signal.SIGINT)
            done.append(1)   # still runs: the interrupt waits for the block's end
    assert done == [1]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    with uninterrupted():   # nothing pending: nothing raised
        pass


def test_sigterm_stops_a_run_only_inside_terminate_as_interrupt():
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    with pytest.raises(Terminated):
        with terminate_as_interrupt():
            _signal_self(signal.SIGTERM)
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    # deferred inside a write, then raised as Terminated (a KeyboardInterrupt)
    with pytest.raises(KeyboardInterrupt) as e:
        with terminate_as_interrupt(), uninterrupted():
            _signal_self(signal.SIGTERM)
    assert isinstance(e.value, Terminated)


def test_outside_the_main_thread_both_do_nothing():
    errors = []

    def work():
        try:
            with terminate_as_interrupt(), uninterrupted():
                pass
        except BaseException as e:   # pragma: no cover - the failure this test looks for
            errors.append(e)
    t = threading.Thread(target=work)
    t.start()
    t.join()
    assert errors == [] and signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


class _SignalAtCompile(event.Listener):
    """A Numba listener that sends ``sig`` to this process when a compilation starts."""

    def __init__(self, sig):
        self.sig = sig

    def on_start(self, ev):
        _signal_self(self.sig)

    def on_end(self, ev):
        pass


@pytest.mark.parametrize("sig, raised", [(signal.SIGTERM, Terminated),
                                         (signal.SIGINT, KeyboardInterrupt)])
def test_a_signal_during_a_numba_compile_waits_for_its_end(sig, raised):
    """Ctrl-C or SIGTERM while Numba compiles (a run's cold start) is raised once the function
    is compiled: raised inside the compiler (in LLVM's object-code callback, for one) it left a
    half-built function and a Numba traceback instead of a stop."""
    @njit   # not cached: compiles here
    def add_one(x):
        return x + 1
    with pytest.raises(raised):
        with terminate_as_interrupt(), event.install_listener("numba:compile",
                                                              _SignalAtCompile(sig)):
            add_one(1)
    with event.install_recorder("numba:compile") as rec:   # compiled completely before the
        assert add_one(1) == 2                              # signal was raised: no second compile
    assert not rec.buffer and signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


class _SignalOnRead:
    """An array that sends ``sig`` to this process when it is converted (mid-write)."""

    def __init__(self, sig, value):
        self.sig, self.value = sig, np.asarray(value)

    def __array__(self, dtype=None, copy=None):
        _signal_self(self.sig)
        return self.value


def test_a_checkpoint_interrupted_while_written_is_complete(tmp_path):
    p = tmp_path / "r.h5"
    write_fake_result(p)
    w = ResultWriter(p, None, {}, mode="a")
    w.write_checkpoint(3, {"U": np.zeros((2, 3))}, {"n": 3})
    arrays = {"U": np.ones((2, 3)), "V": _SignalOnRead(signal.SIGTERM, [1.0, 2.0]),
              "s_joints": np.full(4, 7.0)}
    with pytest.raises(Terminated):
        with terminate_as_interrupt():
            w.write_checkpoint(4, arrays, {"n": 4})
    w.close()
    inc, got, meta = open_result(p).checkpoint()
    assert inc == 4 and meta == {"n": 4}
    assert np.array_equal(got["U"], np.ones((2, 3))) and np.array_equal(got["s_joints"],
                                                                        np.full(4, 7.0))


def test_a_kill_while_a_checkpoint_is_replaced_leaves_one(tmp_path):
    """Killed while writing the new checkpoint: the old one is read and the stale new one is
    replaced by the next write; killed between removing the old and renaming the new one: the
    complete new one is read, and a restart renames it."""
    p = tmp_path / "r.h5"
    write_fake_result(p)
    w = ResultWriter(p, None, {}, mode="a")
    w.write_checkpoint(3, {"U": np.zeros((2, 3))}, {"n": 3})
    w.close()
    with h5py.File(p, "a") as f:   # an incomplete new checkpoint (no "complete" attribute)
        f.create_group(CHECKPOINT_NEW).create_dataset("U", data=np.ones(1))
    assert open_result(p).checkpoint()[0] == 3
    w = ResultWriter(p, None, {}, mode="a")
    w.write_checkpoint(5, {"U": np.full((2, 3), 5.0)}, {"n": 5})
    w.close()
    with h5py.File(p, "a") as f:   # the old one removed, the new one not yet renamed
        assert CHECKPOINT_NEW not in f
        f.move("checkpoint", CHECKPOINT_NEW)
    assert open_result(p).checkpoint()[0] == 5
    ResultWriter(p, None, {}, mode="a").close()
    with h5py.File(p, "r") as f:
        assert "checkpoint" in f and CHECKPOINT_NEW not in f


def test_a_signal_while_a_relaxation_returns_stops_the_run(monkeypatch):
    """SIGTERM while Numba boxes the ``Exit`` a relaxation call returns (by calling its class:
    Python code, where the handler runs) stops the run with :class:`Terminated`: raised there it
    ended the process with a segmentation fault (without the fix this test crashes pytest)."""
    new, sent = R.Exit.__new__, []

    def signal_once(cls, *fields):
        if not sent:
            sent.append(1)
            os.kill(os.getpid(), signal.SIGTERM)
        return new(cls, *fields)
    sim = tiny_wall()
    monkeypatch.setattr(R.Exit, "__new__", staticmethod(signal_once))
    with pytest.raises(Terminated):
        with terminate_as_interrupt():
            sim.run(gravity())
    assert sent == [1] and sim.increment == 0


def _rows(path):
    """History rows of a results file another process is writing (0 while it cannot be read)."""
    try:
        with h5py.File(path, "r", locking=False) as f:
            return f["history/increment"].shape[0]
    except (OSError, KeyError):
        return 0


def test_sigterm_stops_a_scene_and_resume_finishes_it(tmp_path):
    """``kill`` (SIGTERM) of ``dr-masonry run``: exit status 143, a note saying where the rows
    are, a file that holds them with its checkpoint, and ``resume=true`` runs it to its end."""
    out = tmp_path / "s4"
    cmd = [sys.executable, "-m", "dr_masonry", "run", "slender_wall", "fast=true",
           f"out={out}", "frames=1", "maps=", "report=false"]
    env = dict(os.environ)
    env.pop("OMP_WAIT_POLICY", None)
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True,
                            env=env)
    h5 = f"{out}.h5"
    t0 = time.time()
    while _rows(h5) < 6 and proc.poll() is None and time.time() - t0 < 240:
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    err = proc.communicate(timeout=120)[1]
    assert proc.returncode == 143, err
    assert "terminated (SIGTERM)" in err and "resume=true" in err and "Traceback" not in err
    r = open_result(h5)
    n = r.n_history
    assert 6 <= n < 22
    # frames=1: the checkpoint is the last row's, or the one before when the signal came
    # between a row and its frame (resume then computes that row again)
    assert r.checkpoint()[0] in (n - 1, n)
    assert np.array_equal(r.history["increment"], np.arange(1, n + 1))
    done = subprocess.run(cmd + ["resume=true"], capture_output=True, text=True, env=env,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert np.array_equal(open_result(h5).history["increment"], np.arange(1, 23))


def test_nested_uninterrupted_blocks_raise_at_the_outer_end():
    done = []
    with pytest.raises(KeyboardInterrupt):
        with uninterrupted():
            with uninterrupted():
                _signal_self(signal.SIGINT)
            done.append(1)   # the inner block's end hands the signal on, it does not raise
    assert done == [1] and signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_an_ignored_sigint_stays_ignored():
    """A job started in the background ignores SIGINT: held blocks leave it so, raising nothing."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with uninterrupted():
        _signal_self(signal.SIGINT)
    assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN

"""The cold start's second process (``dr_masonry.precompile``): used only when the force kernel
is in no cache, switched off by its environment variable, and a failing worker costs nothing but
a warning."""
import json
import os
import subprocess
import sys
import textwrap
import warnings

import pytest

from dr_masonry import precompile as P

from conftest import gravity, tiny_wall


@pytest.fixture
def no_worker(monkeypatch):
    """Fail the test if a worker process is started."""
    def popen(*a, **k):
        raise AssertionError("a compile worker was started")
    monkeypatch.setattr(P.subprocess, "Popen", popen)


def test_warm_kernels_start_no_worker(no_worker):
    sim = tiny_wall()
    sim.run(gravity())   # compiled (or loaded) in this process
    assert P.ensure_compiled(sim.mesh, sim.cont, sim.dyn) is False


def test_switched_off_by_the_environment(monkeypatch, no_worker):
    sim = tiny_wall()
    sim.build()
    monkeypatch.setattr(P, "_cached", lambda name, sig: False)   # as if the cache were cold
    monkeypatch.setenv(P.ENV_SWITCH, "0")
    assert P.ensure_compiled(sim.mesh, sim.cont, sim.dyn) is False


def test_a_failing_worker_is_reported_and_the_run_goes_on(monkeypatch):
    sim = tiny_wall()
    sim.build()
    monkeypatch.setattr(P, "_cached", lambda name, sig: False)
    monkeypatch.setattr(P.sys, "executable", "false")   # exits 1 at once
    with pytest.warns(RuntimeWarning, match="compile worker failed"):
        assert P.ensure_compiled(sim.mesh, sim.cont, sim.dyn) is True
    monkeypatch.undo()
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        sim.run(gravity())
    assert sim.history["increment"] == [1] and sim.history["residual"][0] <= sim.options.convergence.tol


def test_no_worker_without_compilation():
    """``NUMBA_DISABLE_JIT=1`` (debugging): the kernels are plain functions, nothing to compile."""
    script = textwrap.dedent(f"""\
        import sys
        sys.path.insert(0, {os.path.dirname(__file__)!r})
        from conftest import tiny_wall
        from dr_masonry import precompile
        sim = tiny_wall()
        sim.build()
        print(precompile.ensure_compiled(sim.mesh, sim.cont, sim.dyn))
        """)
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True,
                         check=True, timeout=300)
    assert out.stdout.strip().splitlines()[-1] == "False"


@pytest.mark.slow
def test_cold_start_compiles_the_force_kernel_in_the_worker_only(tmp_path):
    """Empty cache: the run's process compiles ``relax`` and the node passes, never the force
    kernel or the return mapping (the worker's), so the signatures agree with ``relax``'s."""
    script = textwrap.dedent(f"""\
        import json, sys
        from numba.core import event
        sys.path.insert(0, {os.path.dirname(__file__)!r})
        from conftest import gravity, tiny_wall
        sim = tiny_wall()
        with event.install_recorder("numba:compile") as rec:
            sim.run(gravity())
        print(json.dumps(sorted({{ev.data["dispatcher"].py_func.__qualname__
                                  for _, ev in rec.buffer if ev.is_start}})))
        """)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    env.pop(P.ENV_SWITCH, None)
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True,
                         check=True, timeout=600)
    compiled = set(json.loads(out.stdout.strip().splitlines()[-1]))
    assert {"relax", "gather_residual", "update_nodes"} <= compiled
    assert not compiled & {"element_and_contact_forces", "gp_update", "offset_forces"}

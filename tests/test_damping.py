"""FIRE damping (``SolverOptions(damping="fire")``): the compiled iteration against a plain numpy
FIRE, and the answers of the small scenes against viscous damping (every scheme against a direct
sparse solve: test_relaxation_kernels.py); the viscous iteration, splitting into calls and the
thread count."""
import importlib

import numba
import numpy as np
import pytest

from dr_masonry import Force, Model, PlasticDamage, Simulation, SolverOptions, Stage
from dr_masonry.kernels import relaxation as R
from dr_masonry.solver import relaxing

from naive_relaxation import (column as _column, fire_reference, loaded_column as _loaded_column,
                              relax_call, viscous_reference)

@pytest.mark.parametrize("ring", [0.0, 1.0])
def test_viscous_iteration_matches_numpy_reference(ring):
    """300 iterations of the compiled viscous loop equal the numpy iteration step by step, with
    and without ring damping; with it, some DOFs were ring-damped (the column's stiff modes
    ring from rest) and the motion differs from the one without."""
    n_iter = 300
    ref, _ = _loaded_column()
    rung = viscous_reference(ref, n_iter, 1.0, ring)
    sim, _ = _loaded_column()
    out = relax_call(sim, "viscous", 1.0, 1e-300, n_iter, 0, check_every=10 ** 9, ring=ring)[0]
    assert out.iterations == n_iter and out.status == R.ST_MAXITER
    scale = np.abs(ref.dyn.U).max()
    assert scale > 1e-7
    assert np.allclose(sim.dyn.U, ref.dyn.U, rtol=0, atol=1e-9 * scale)
    assert np.allclose(sim.dyn.rpU, ref.dyn.rpU, rtol=0, atol=1e-9 * np.abs(ref.dyn.rpU).max())
    if ring:
        assert rung > 0
        plain, _ = _loaded_column()
        assert viscous_reference(plain, n_iter, 1.0, 0.0) == 0
        assert not np.allclose(plain.dyn.U, ref.dyn.U, rtol=0, atol=1e-9 * scale)


def test_ring_damping_is_validated():
    for bad in (-0.1, 2.0, float("nan")):
        with pytest.raises(ValueError, match="ring"):
            SolverOptions(ring=bad)


def test_fire_iteration_matches_numpy_reference():
    """300 iterations of the compiled FIRE loop (stops and step growth included) equal the
    numpy FIRE step by step, rigid point included."""
    n_iter = 300
    ref, _ = _loaded_column()
    fire_reference(ref, n_iter, 0.1)
    sim, _ = _loaded_column()
    out = relax_call(sim, "fire", 0.1, 1e-300, n_iter, 0, check_every=10 ** 9)[0]
    assert out.iterations == n_iter and out.status == R.ST_MAXITER
    assert np.abs(ref.dyn.rpU).max() > 1e-6  # it moved
    scale = np.abs(ref.dyn.U).max()
    assert np.allclose(sim.dyn.U, ref.dyn.U, rtol=0, atol=1e-9 * scale)
    assert np.allclose(sim.dyn.rpU, ref.dyn.rpU, rtol=0, atol=1e-9 * np.abs(ref.dyn.rpU).max())
    assert out.damped > 0.0


def _peak(case, damping):
    mod = importlib.import_module(f"dr_masonry.cases.{case}")
    if case == "couplet":
        _, hist = mod.run(dict(mod.PARAMS, increments=30, h5=None, damping=damping))
        return hist["platen.fz"].max() / (mod.L * mod.T)
    if case == "triplet":
        _, _, tau = mod.run(dict(mod.PARAMS, increments=30, h5=None, damping=damping), 0.6e6)
        return tau.max()
    _, _, stress, _ = mod.run(dict(mod.PARAMS, shortening=0.003, increments=15, h5=None,
                                   damping=damping))
    return stress.max()


@pytest.mark.parametrize("case", ["couplet", "triplet", "wallet"])
def test_fire_scene_peaks_match_viscous(case):
    """S1-S3 (coarse increments): FIRE converges at every increment to the peak of the viscous
    run within 0.5 % (different damping, same equilibrium path)."""
    assert _peak(case, "fire") == pytest.approx(_peak(case, "viscous"), rel=0.005)


def test_fire_is_a_known_scheme():
    assert SolverOptions(damping="fire").damping.alpha == 0.1
    with pytest.raises(ValueError, match="damping"):
        SolverOptions(damping="FIRE")


def test_dissipation_bound_is_validated():
    for bad in (-0.1, np.nan, np.inf):
        with pytest.raises(ValueError, match="max_dissipation"):
            SolverOptions(max_dissipation=bad)


def test_stall_rule_counts_iterations_without_progress():
    """A free block under a constant force accelerates undamped: its residual ratio stays 1 and
    never falls (by STALL_DROP), so ``stall_iter`` = 500 stops the loop at the first check (every 10
    iterations) 500 iterations after the first one, also when the increment is relaxed in two
    calls (300 + the rest: the count carries over); ``stall_iter`` = 0 never stops."""
    m = Model()
    m.add_box((0, 0, 0), (0.22, 0.102, 0.081), PlasticDamage.elastic(5e9, 0.2, 2000.0), (1, 1, 1))
    for stall, calls, status, total in ((500, (1000,), R.ST_STALLED, 510),
                                        (500, (300, 1000), R.ST_STALLED, 510),
                                        (0, (1000,), R.ST_MAXITER, 1000)):
        sim = Simulation(m, SolverOptions(coarse=False))
        sim.build()
        sim.dyn.fext[:, 0] = 10.0   # N per node, far above the reference floor
        done, pr = 0, None
        for iters in calls:
            out, pr, _ = relax_call(sim, "viscous", 0.0, 1e-300, iters, stall, pr=pr)
            done += out.iterations
        assert out.status == status
        assert done == total
        assert out.residual == pytest.approx(1.0, rel=1e-9)


@pytest.mark.parametrize("scheme, alpha", [("viscous", 1.0), ("fire", 0.1), ("kinetic", 0.0),
                                           ("local", 0.8)])
def test_relaxation_split_into_calls_is_the_same_relaxation(scheme, alpha):
    """Calls that continue a span (``Progress.seg``: the span's iterations so far) give the
    iterates of one uninterrupted call: the same iteration count, status and displacements bit
    for bit, with the stall and budget rules on, for every damping scheme (FIRE's step and
    mixing and kinetic damping's peak test carry over); the convergence checks fall on the
    span's multiples of check_every also when a call's length is not one (25)."""
    def run(calls_of):
        sim, _ = _loaded_column()
        done, pr, state = 0, None, None
        while True:
            out, pr, state = relax_call(sim, scheme, alpha, 1e-8, calls_of,
                                        200 if scheme == "viscous" else 0, pr=pr, state=state,
                                        left=100_000 - done)
            done += out.iterations
            if out.status != R.ST_MAXITER:
                return out.status, done, sim.dyn.rpU.copy(), sim.dyn.U.copy()

    status, n, rpu, u = run(100_000)
    assert status == R.ST_CONVERGED and n > 500
    for calls_of in (25, 250):
        s, m, rpv, v = run(calls_of)
        assert (s, m) == (status, n)
        np.testing.assert_array_equal(rpv, rpu)
        np.testing.assert_array_equal(v, u)


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs two threads")
@pytest.mark.parametrize("scheme", ["viscous", "fire"])
def test_relaxation_does_not_depend_on_the_thread_count(scheme):
    """The node passes add their sums chunk by chunk in a fixed order: one and two threads give
    the same iterates bit for bit (a column of 8 blocks: 288 nodes, two node chunks)."""
    runs = []
    for threads in (1, 2):
        numba.set_num_threads(threads)
        try:
            sim, _ = _loaded_column(8)
            assert sim.dyn.U.shape[0] > R.NODE_CHUNK
            out = relax_call(sim, scheme, 1.0 if scheme == "viscous" else 0.1, 1e-300, 400, 0)
        finally:
            numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        runs.append((sim.dyn.U.copy(), sim.dyn.rpU.copy(), out))
    (u1, r1, i1), (u2, r2, i2) = runs
    assert np.abs(u1).max() > 0.0
    np.testing.assert_array_equal(u1, u2)
    np.testing.assert_array_equal(r1, r2)
    assert i1 == i2


def test_small_models_relax_on_one_thread():
    """Below ``SERIAL_NODES`` the solver relaxes on one thread and gives the threads back after
    (also when the relaxation raises); larger models keep the threads as set."""
    before = numba.get_num_threads()
    with relaxing.threads_for(relaxing.SERIAL_NODES - 1):
        assert numba.get_num_threads() == 1
    assert numba.get_num_threads() == before
    with pytest.raises(KeyboardInterrupt):
        with relaxing.threads_for(10):
            raise KeyboardInterrupt
    assert numba.get_num_threads() == before
    with relaxing.threads_for(relaxing.SERIAL_NODES):
        assert numba.get_num_threads() == before


def test_solver_splits_long_spans_without_changing_the_answer(monkeypatch):
    """``relaxing.relax_increment`` with compiled calls of 40 iterations instead of 2,000: the
    same increments, iterations and displacements (plain and two-level relaxation)."""
    for coarse in (False, True):
        runs = []
        for call in (relaxing.CALL_ITERATIONS, 40):
            monkeypatch.setattr(relaxing, "CALL_ITERATIONS", call)
            m = _column(6)
            sim = Simulation(m, SolverOptions(coarse=coarse))
            X = m.nodes
            sim.fix(np.nonzero(np.isclose(X[:, 2], 0.0))[0])
            rp = sim.rigid_point("tip", nodes=np.nonzero(np.isclose(X[:, 2], 6 * 0.081))[0])
            sim.run([Stage("push", 3, [Force(target=rp, dof="x", to=2e4)])])
            runs.append((sim.history["iterations"], sim.dyn.U.copy()))
        assert runs[0][0] == runs[1][0] and sum(runs[0][0]) > 3 * 40
        np.testing.assert_array_equal(runs[0][1], runs[1][1])


def test_stall_rule_does_not_touch_a_converging_relaxation():
    """On a relaxation that keeps converging the rule only observes: the same iterations and the
    same displacements with and without it."""
    runs = []
    for stall in (0, 200):
        sim, _ = _loaded_column()
        out = relax_call(sim, "viscous", 1.0, 1e-8, 100_000, stall)[0]
        assert out.status == R.ST_CONVERGED
        runs.append((out.iterations, sim.dyn.rpU.copy()))
    assert runs[0][0] == runs[1][0] > 200
    np.testing.assert_array_equal(runs[0][1], runs[1][1])


def test_slow_rule_cuts_what_cannot_finish_within_the_budget():
    """The loaded column converges steadily to 1e-8 in N iterations. Windows of N/4 iterations:
    with a budget of N/2 the rate of the first window puts tol out of reach and the loop stops
    with ST_SLOW at that window's end; with a budget of 2 N, or none known (``left`` = 0), the
    rule only observes: the same iterations and displacements as without it."""
    def run(stall, left):
        sim, _ = _loaded_column()
        out = relax_call(sim, "viscous", 1.0, 1e-8, 100_000, stall, left=left)[0]
        return out.status, out.iterations, sim.dyn.rpU.copy()

    status, n, u = run(0, 0)
    assert status == R.ST_CONVERGED and n > 400
    window = 10 * (n // 40)
    for left in (2 * n, 0):
        s, m, v = run(window, left)
        assert (s, m) == (R.ST_CONVERGED, n)
        np.testing.assert_array_equal(v, u)
    s, m, _ = run(window, n // 2)
    assert s == R.ST_SLOW and window <= m <= window + 10


def test_reachable_decrease_extrapolates_a_shrinking_rate():
    """Hand sums: a decrease that halves per window reaches 0.25 + 0.125 + 0.0625 in 3 more
    windows after 1.0 then 0.5; a steady or growing one (or an unknown previous window) reaches
    ``d`` per window. On the S6 attempt that hovered above tol (best
    residual ratio at the ends of 10,000-iteration windows, 200,000-iteration budget) the
    extrapolation keeps the windows ending at 21,400 and 31,400 iterations and gives up at
    41,400, where 158,600 iterations cannot bring 1.148e-3 down to tol 1e-4."""
    assert R.reachable_decrease(0.5, 1.0, 3.0) == pytest.approx(0.4375, rel=1e-12)
    for d_prev in (0.0, 0.5, 0.4):
        assert R.reachable_decrease(0.5, d_prev, 3.0) == pytest.approx(1.5, rel=1e-12)
    best = {11_400: 4.444e-3, 21_400: 2.711e-3, 31_400: 1.699e-3, 41_400: 1.148e-3}
    ends = sorted(best)
    verdicts = []
    for k in range(1, len(ends)):
        d = np.log(best[ends[k - 1]] / best[ends[k]])
        d_prev = np.log(best[ends[k - 2]] / best[ends[k - 1]]) if k >= 2 else 0.0
        left = (200_000 - ends[k]) / 10_000
        verdicts.append(R.reachable_decrease(d, d_prev, left) < np.log(best[ends[k]] / 1e-4))
    assert verdicts == [False, False, True]

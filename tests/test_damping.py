"""FIRE damping (``SolverOptions(damping="fire")``): the compiled iteration against a plain numpy
FIRE, and the answers of the small scenes against viscous damping (every scheme against a direct
sparse solve: test_relaxation_kernels.py); the viscous iteration, splitting into calls and the
thread count."""
import importlib

import numba
import numpy as np
import pytest

from dr_masonry import Force, JointLaw, Model, PlasticDamage, Simulation, SolverOptions, Stage
from dr_masonry.kernels import relaxation as R

DOFS = ("x", "y", "z", "rx", "ry", "rz")



def _column(n_blocks=3, H=0.081):
    m = Model()
    m.set_joint_law(JointLaw.tied(2e10, 8e9))
    mat = PlasticDamage.elastic(5e9, 0.2, 2000.0)
    for k in range(n_blocks):
        m.add_box((0.0, 0.0, k * H), (0.22, 0.102, H), mat, (3, 2, 2))
    return m


def _loaded_column(n_blocks=3):
    """Glued column, base clamped, top face tied to a rigid point loaded on all 6 DOFs."""
    m = _column(n_blocks)
    sim = Simulation(m, SolverOptions(damping="fire"))
    X = m.nodes
    sim.fix(np.nonzero(np.isclose(X[:, 2], 0.0))[0])
    rp = sim.rigid_point("tip", nodes=np.nonzero(np.isclose(X[:, 2], 3 * 0.081))[0])
    sim.build()
    sim.dyn.rpf[0] = 3e4 * np.array([3.0, 2.0, -5.0, 0.0, 0.0, 0.4])
    return sim, rp


def fire_reference(sim, n_iter, alpha):
    """Plain numpy FIRE (Bitzek et al. 2006, semi-implicit Euler, half step back on a stop) on the
    free node DOFs and rigid-point DOFs of ``sim``, forces from the kernels' internal forces."""
    d = sim.dyn
    free = d.free > 0
    rpfree = d.rpfree > 0
    minv = np.concatenate([np.broadcast_to(d.minv[:, None], d.U.shape)[free], d.rpminv[rpfree]])
    rpres = np.zeros((d.rpX.shape[0], 6))
    dt, a, n_pos = 0.5, alpha, 0
    R.place_rigid_nodes(d)
    for _ in range(n_iter):
        R.internal_forces(sim.mesh, sim.cont, d)
        R.residual(d, 0.0, rpres)
        f = np.concatenate([d.res[free], rpres[rpfree]])
        v = np.concatenate([d.V[free], d.rpV[rpfree]])
        x = np.concatenate([d.U[free], d.rpU[rpfree]])
        power = f @ v
        if power < 0:
            x -= 0.5 * dt * v
            v[:] = 0.0
            dt, a, n_pos = 0.5 * dt, alpha, 0
        else:
            n_pos += 1
            if n_pos > 5:
                dt, a = min(1.1 * dt, 1.0), 0.99 * a
            vnorm = np.sqrt(v @ (v / minv))          # |v|_M
            fnorm = np.sqrt(f @ (minv * f))          # |M^-1 f|_M
            v = (1 - a) * v + a * vnorm / fnorm * minv * f
        v += dt * minv * f
        x += dt * v
        nf = free.sum()
        d.V[free], d.rpV[rpfree] = v[:nf], v[nf:]
        d.U[free], d.rpU[rpfree] = x[:nf], x[nf:]
        R.place_rigid_nodes(d)


def viscous_reference(sim, n_iter, alpha, ring):
    """Plain numpy viscous damping (Underwood's coefficient from the Rayleigh quotient of the
    motion, capped at 1.9; none in the first iteration) with ring damping: a node DOF whose
    decaying count of velocity reversals exceeds ``R.RING_COUNT`` gets the coefficient ``ring``
    when that is larger. Returns how many DOF-iterations were ring-damped."""
    d = sim.dyn
    free = d.free > 0
    rpfree = d.rpfree > 0
    m = np.broadcast_to(1.0 / d.minv[:, None], d.U.shape)
    rpres = np.zeros((d.rpX.shape[0], 6))
    count = np.zeros(d.U.shape)
    fprev = d.fint.copy()
    rung = 0
    R.place_rigid_nodes(d)
    for it in range(n_iter):
        R.internal_forces(sim.mesh, sim.cont, d)
        R.residual(d, 0.0, rpres)
        num = (d.V * (d.fint - fprev))[free].sum() if it else 0.0
        den = (d.V ** 2 * m)[free].sum()
        c = min(alpha * 2.0 * np.sqrt(num / den), 1.9) if den > 0 and num > 0 else 0.0
        fprev = d.fint.copy()
        ci = np.where((count > R.RING_COUNT) & (ring > c), ring, c)
        rung += int(((ci > c) & free).sum())
        vn = ((2.0 - ci) * d.V + 2.0 * d.res / m) / (2.0 + ci)
        count = np.where(free, R.RING_MEMORY * count + (vn * d.V < 0), count)
        d.V[free] = vn[free]
        d.rpV[rpfree] = (((2.0 - c) * d.rpV + 2.0 * d.rpminv * rpres) / (2.0 + c))[rpfree]
        d.U[free] += d.V[free]
        d.rpU[rpfree] += d.rpV[rpfree]
        R.place_rigid_nodes(d)
    return rung


def _relax(sim, scheme, alpha, tol, iters, stall, info, check_every=10, ring=1.0):
    """``R.relax`` on ``sim`` with no load factor or control, run-away limit 1 m."""
    R.relax(sim.mesh, sim.cont, sim.dyn, np.zeros(1), np.zeros(3, np.int64), 1.0, scheme, alpha,
            ring, tol, sim.ref_floor, iters, check_every, stall, 1.0, info)


@pytest.mark.parametrize("ring", [0.0, 1.0])
def test_viscous_iteration_matches_numpy_reference(ring):
    """300 iterations of the compiled viscous loop equal the numpy iteration step by step, with
    and without ring damping; with it, some DOFs were ring-damped (the column's stiff modes
    ring from rest) and the motion differs from the one without."""
    n_iter = 300
    ref, _ = _loaded_column()
    rung = viscous_reference(ref, n_iter, 1.0, ring)
    sim, _ = _loaded_column()
    info = np.zeros(R.N_INFO)
    _relax(sim, R.DAMP_VISCOUS, 1.0, 1e-300, n_iter, 0, info, check_every=10 ** 9, ring=ring)
    assert info[R.I_ITERS] == n_iter and info[R.I_STATUS] == R.ST_MAXITER
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
    info = np.zeros(R.N_INFO)
    _relax(sim, R.DAMP_FIRE, 0.1, 1e-300, n_iter, 0, info, check_every=10 ** 9)
    assert info[R.I_ITERS] == n_iter and info[R.I_STATUS] == R.ST_MAXITER
    assert np.abs(ref.dyn.rpU).max() > 1e-6  # it moved
    scale = np.abs(ref.dyn.U).max()
    assert np.allclose(sim.dyn.U, ref.dyn.U, rtol=0, atol=1e-9 * scale)
    assert np.allclose(sim.dyn.rpU, ref.dyn.rpU, rtol=0, atol=1e-9 * np.abs(ref.dyn.rpU).max())
    assert info[R.I_DAMPED] > 0.0


def _peak(case, damping):
    mod = importlib.import_module(f"dr_masonry.cases.{case}")
    if case == "couplet":
        _, hist = mod.run(dict(mod.PARAMS, increments=30, h5=None, damping=damping))
        return hist["platen.fz"].max() / (mod.L * mod.T)
    if case == "triplet":
        _, _, tau = mod.run(dict(mod.PARAMS, increments=30, h5=None, damping=damping), 0.6e6)
        return tau.max()
    _, _, stress = mod.run(dict(mod.PARAMS, shortening=0.003, increments=15, h5=None,
                                damping=damping))
    return stress.max()


@pytest.mark.parametrize("case", ["couplet", "triplet", "wallet"])
def test_fire_scene_peaks_match_viscous(case):
    """S1-S3 (coarse increments): FIRE converges at every increment to the peak of the viscous
    run within 0.5 % (different damping, same equilibrium path)."""
    assert _peak(case, "fire") == pytest.approx(_peak(case, "viscous"), rel=0.005)


def test_fire_is_a_known_scheme():
    assert SolverOptions(damping="fire").alpha == 0.1
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
        info = np.zeros(R.N_INFO)
        done = 0
        for iters in calls:
            _relax(sim, R.DAMP_VISCOUS, 0.0, 1e-300, iters, stall, info)
            done += int(info[R.I_ITERS])
        assert int(info[R.I_STATUS]) == status
        assert done == total
        assert info[R.I_RESID] == pytest.approx(1.0, rel=1e-9)


@pytest.mark.parametrize("scheme, alpha", [(R.DAMP_VISCOUS, 1.0), (R.DAMP_FIRE, 0.1),
                                           (R.DAMP_KINETIC, 0.0), (R.DAMP_LOCAL, 0.8)],
                         ids=["viscous", "fire", "kinetic", "local"])
def test_relaxation_split_into_calls_is_the_same_relaxation(scheme, alpha):
    """Calls that continue a span (``I_SEG``: the span's iterations so far) give the iterates of
    one uninterrupted call: the same iteration count, status and displacements bit for bit, with
    the stall and budget rules on, for every damping scheme (FIRE's step and mixing and kinetic
    damping's peak test carry over); the convergence checks fall on the span's multiples of
    check_every also when a call's length is not one (25)."""
    def run(calls_of):
        sim, _ = _loaded_column()
        info = np.zeros(R.N_INFO)
        done = 0
        while True:
            info[R.I_LEFT] = 100_000 - done
            _relax(sim, scheme, alpha, 1e-8, calls_of, 200 if scheme == R.DAMP_VISCOUS else 0,
                   info)
            done += int(info[R.I_ITERS])
            info[R.I_SEG] += info[R.I_ITERS]
            if int(info[R.I_STATUS]) != R.ST_MAXITER:
                return int(info[R.I_STATUS]), done, sim.dyn.rpU.copy(), sim.dyn.U.copy()

    status, n, rpu, u = run(100_000)
    assert status == R.ST_CONVERGED and n > 500
    for calls_of in (25, 250):
        s, m, rpv, v = run(calls_of)
        assert (s, m) == (status, n)
        np.testing.assert_array_equal(rpv, rpu)
        np.testing.assert_array_equal(v, u)


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs two threads")
@pytest.mark.parametrize("scheme", [R.DAMP_VISCOUS, R.DAMP_FIRE])
def test_relaxation_does_not_depend_on_the_thread_count(scheme):
    """The node passes add their sums chunk by chunk in a fixed order: one and two threads give
    the same iterates bit for bit (a column of 8 blocks: 288 nodes, two node chunks)."""
    runs = []
    for threads in (1, 2):
        numba.set_num_threads(threads)
        try:
            sim, _ = _loaded_column(8)
            assert sim.dyn.U.shape[0] > R.NODE_CHUNK
            info = np.zeros(R.N_INFO)
            _relax(sim, scheme, 1.0 if scheme == R.DAMP_VISCOUS else 0.1, 1e-300, 400, 0, info)
        finally:
            numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        runs.append((sim.dyn.U.copy(), sim.dyn.rpU.copy(), info.copy()))
    (u1, r1, i1), (u2, r2, i2) = runs
    assert np.abs(u1).max() > 0.0
    np.testing.assert_array_equal(u1, u2)
    np.testing.assert_array_equal(r1, r2)
    np.testing.assert_array_equal(i1, i2)


def test_small_models_relax_on_one_thread():
    """Below ``SERIAL_NODES`` the solver relaxes on one thread and gives the threads back after
    (also when the relaxation raises); larger models keep the threads as set."""
    from dr_masonry import solver
    before = numba.get_num_threads()
    with solver._threads_for(solver.SERIAL_NODES - 1):
        assert numba.get_num_threads() == 1
    assert numba.get_num_threads() == before
    with pytest.raises(KeyboardInterrupt):
        with solver._threads_for(10):
            raise KeyboardInterrupt
    assert numba.get_num_threads() == before
    with solver._threads_for(solver.SERIAL_NODES):
        assert numba.get_num_threads() == before


def test_solver_splits_long_spans_without_changing_the_answer(monkeypatch):
    """``Simulation._relax`` with compiled calls of 40 iterations instead of 2,000: the same
    increments, iterations and displacements (plain and two-level relaxation)."""
    import dr_masonry.solver as S
    for coarse in (False, True):
        runs = []
        for call in (S.CALL_ITERATIONS, 40):
            monkeypatch.setattr(S, "CALL_ITERATIONS", call)
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
        info = np.zeros(R.N_INFO)
        _relax(sim, R.DAMP_VISCOUS, 1.0, 1e-8, 100_000, stall, info)
        assert int(info[R.I_STATUS]) == R.ST_CONVERGED
        runs.append((int(info[R.I_ITERS]), sim.dyn.rpU.copy()))
    assert runs[0][0] == runs[1][0] > 200
    np.testing.assert_array_equal(runs[0][1], runs[1][1])


def test_slow_rule_cuts_what_cannot_finish_within_the_budget():
    """The loaded column converges steadily to 1e-8 in N iterations. Windows of N/4 iterations:
    with a budget of N/2 the rate of the first window puts tol out of reach and the loop stops
    with ST_SLOW at that window's end; with a budget of 2 N, or none known (``I_LEFT`` = 0), the
    rule only observes: the same iterations and displacements as without it."""
    def run(stall, left):
        sim, _ = _loaded_column()
        info = np.zeros(R.N_INFO)
        info[R.I_LEFT] = left
        _relax(sim, R.DAMP_VISCOUS, 1.0, 1e-8, 100_000, stall, info)
        return int(info[R.I_STATUS]), int(info[R.I_ITERS]), sim.dyn.rpU.copy()

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
    ``d`` per window. On the S6 attempt that hovered above tol (BENCHMARKS.md section 15: best
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

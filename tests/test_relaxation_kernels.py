"""Plain reference tests of the relaxation kernels (kernels/relaxation.py) and of ``quad_shape``
(kernels/contact_frame.py) that had none: every damping scheme of ``SolverOptions.damping``
against a direct sparse solve, the kinetic and local (Cundall) damping iterations against plain
numpy iterations step by step, ``norms``, ``worst_place`` and ``stored_energy`` against
hand values (and 0.5 u.K u), ``rotation_matrix`` against scipy's rotation vectors,
``place_rigid_nodes`` and ``rp_residual`` against numpy (the latter through virtual work)."""
from collections import namedtuple

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from dr_masonry import Force, Simulation, SolverOptions, Stage
from dr_masonry.kernels import balance as B
from dr_masonry.kernels import relaxation as R
from dr_masonry.kernels.contact_frame import quad_dshape, quad_shape
from dr_masonry.options import DAMPING
from dr_masonry.solver.arrays import Dyn

import linear_reference as LR
from naive_relaxation import DOFS, relax_call
from naive_relaxation import column as _column
from naive_relaxation import loaded_column as _loaded_column


# ------------------------------------------------------------------ numpy references
def place_np(d):
    """Tied nodes at u_p + R(theta_p) a - a, a = X_i - X_p, R from scipy's rotation vector."""
    for p in range(d.rpX.shape[0]):
        nodes = d.rpnodes[d.rpptr[p]:d.rpptr[p + 1]]
        a = d.X[nodes] - d.rpX[p]
        rot = Rotation.from_rotvec(d.rpU[p, 3:]).as_matrix()
        d.U[nodes] = d.rpU[p, :3] + a @ rot.T - a


def rpres_np(d, res, lam):
    """Generalised out-of-balance forces of the reference points: their loads plus the tied
    nodes' residual forces and moments r x f about the point's current position."""
    out = np.zeros((d.rpX.shape[0], 6))
    for p in range(d.rpX.shape[0]):
        nodes = d.rpnodes[d.rpptr[p]:d.rpptr[p + 1]]
        arm = d.X[nodes] + d.U[nodes] - d.rpX[p] - d.rpU[p, :3]
        out[p] = d.rpf[p] + lam * d.rpP[p]
        out[p, :3] += res[nodes].sum(axis=0)
        out[p, 3:] += np.cross(arm, res[nodes]).sum(axis=0)
    return out


def _forces(sim):
    """Node residuals (load factor 0) and reference-point residuals of the current state, the
    internal forces from the force kernel (tested on its own in test_hex8 / test_joint_law)."""
    d = sim.dyn
    R.internal_forces(sim.mesh, sim.cont, d)
    res = d.fext - d.fint
    return res, rpres_np(d, res, 0.0)


def kinetic_reference(sim, n_iter):
    """Plain numpy kinetic damping (unit step): v += M^-1 r; when the kinetic energy (node and
    reference-point DOFs) falls below the previous iteration's, the energy is counted as
    damped, the state moved back half the old velocity (U* = U - (v - M^-1 r) / 2) and every
    velocity zeroed; then U += v. Returns (damped energy, number of resets)."""
    d = sim.dyn
    free, rpfree = d.free > 0, d.rpfree > 0
    minv = np.broadcast_to(d.minv[:, None], d.U.shape)
    ke_prev, damped, resets = 0.0, 0.0, 0
    place_np(d)
    for _ in range(n_iter):
        res, rpres = _forces(sim)
        d.V[free] += (minv * res)[free]
        d.rpV[rpfree] += (d.rpminv * rpres)[rpfree]
        ke = (0.5 * (d.V ** 2 / minv)[free].sum()
              + 0.5 * (d.rpV ** 2 / d.rpminv)[rpfree].sum())
        if ke < ke_prev:
            damped += ke
            resets += 1
            d.U[free] -= 0.5 * (d.V - minv * res)[free]
            d.rpU[rpfree] -= 0.5 * (d.rpV - d.rpminv * rpres)[rpfree]
            d.V[:] = 0.0
            d.rpV[:] = 0.0
            ke = 0.0
        ke_prev = ke
        d.U[free] += d.V[free]
        d.rpU[rpfree] += d.rpV[rpfree]
        place_np(d)
    return damped, resets


def local_reference(sim, n_iter, alpha):
    """Plain numpy local non-viscous damping (Cundall): the force on each DOF reduced by
    alpha |r| against the sign of its velocity, masses raised by 1 + alpha:
    v += M^-1 (r - alpha |r| sign(v)) / (1 + alpha), U += v. Returns the energy removed at the
    node DOFs, sum of alpha |r| |v_mid|, and the number of velocity reversals of free node DOFs."""
    d = sim.dyn
    free, rpfree = d.free > 0, d.rpfree > 0
    minv = np.broadcast_to(d.minv[:, None], d.U.shape)
    damped, reversals = 0.0, 0
    place_np(d)
    for _ in range(n_iter):
        res, rpres = _forces(sim)
        vn = d.V + minv * (res - alpha * np.abs(res) * np.sign(d.V)) / (1.0 + alpha)
        damped += (alpha * np.abs(res) * 0.5 * np.abs(d.V + vn))[free].sum()
        reversals += int((vn * d.V < 0)[free].sum())
        d.V[free] = vn[free]
        rpvn = d.rpV + d.rpminv * (rpres - alpha * np.abs(rpres) * np.sign(d.rpV)) / (1.0 + alpha)
        d.rpV[rpfree] = rpvn[rpfree]
        d.U[free] += d.V[free]
        d.rpU[rpfree] += d.rpV[rpfree]
        place_np(d)
    return damped, reversals


# ------------------------------------------------------------------ 1. damping schemes
@pytest.mark.parametrize("damping", sorted(DAMPING))
def test_every_damping_scheme_solves_the_linear_column(damping):
    """Every scheme of ``SolverOptions.damping``: the glued elastic column of test_damping (base
    clamped, tip loaded on all 6 DOFs of a rigid point) relaxed to tol 1e-10 gives the nodal
    and rigid-point displacements of spsolve(K, f) (tests/linear_reference.py) within 1e-6; the
    half difference of +F and -F removes the geometric nonlinearity (~6e-5 one-sided)."""
    m = _column()
    sim = Simulation(m, SolverOptions(tol=1e-10, damping=damping))
    X = m.nodes
    base = np.nonzero(np.isclose(X[:, 2], 0.0))[0]
    sim.fix(base)
    rp = sim.rigid_point("tip", nodes=np.nonzero(np.isclose(X[:, 2], 3 * 0.081))[0])
    F = 30.0 * np.array([3.0, 2.0, -5.0, 0.0, 0.0, 0.4])
    stages = [Stage(f"s{s}", 1, [Force(target=rp, dof=d, to=s * v) for d, v in zip(DOFS, F)])
              for s in (1, -1)]
    sim.run(stages[:1])
    u_plus, q_plus = sim.dyn.U.copy(), sim.dyn.rpU.copy()
    hist = sim.run(stages[1:])
    u_lin = 0.5 * (u_plus - sim.dyn.U)
    q_lin = 0.5 * (q_plus - sim.dyn.rpU)
    fixed = np.isin(np.arange(m.n_nodes), base)[:, None].repeat(3, 1)
    U, Q = LR.solve(m, fixed, np.zeros((m.n_nodes, 3)), [(rp.nodes, rp.position, F)])
    assert np.abs(U).max() > 1e-6
    assert np.linalg.norm(u_lin - U) / np.linalg.norm(U) < 1e-6
    assert np.allclose(q_lin, Q, rtol=0, atol=1e-6 * np.abs(Q).max())
    assert np.all(hist["residual"] <= 1e-10)
    assert np.all(hist["iterations"] > 10)


def _compiled_like(ref, scheme, alpha, n_iter):
    """``n_iter`` iterations of the compiled loop with ``scheme`` on a fresh loaded column, checked
    against the numpy-iterated ``ref`` (node and rigid-point displacements to 1e-9 of their
    scale); returns (simulation, the call's Exit, displacement scale)."""
    sim, _ = _loaded_column()
    info = relax_call(sim, scheme, alpha, 1e-300, n_iter, 0, check_every=10 ** 9)[0]
    assert info.iterations == n_iter and info.status == R.ST_MAXITER
    scale = np.abs(ref.dyn.U).max()
    assert scale > 1e-7
    assert np.allclose(sim.dyn.U, ref.dyn.U, rtol=0, atol=1e-9 * scale)
    assert np.allclose(sim.dyn.rpU, ref.dyn.rpU, rtol=0, atol=1e-9 * np.abs(ref.dyn.rpU).max())
    return sim, info, scale


def test_kinetic_damping_iteration_matches_numpy_reference():
    """300 iterations of the compiled kinetic-damping loop equal the numpy iteration step by
    step (resets, the step back to the peak, the rigid point's DOFs); the energy it reports as
    damped is the kinetic energy at the resets."""
    n_iter = 300
    ref, _ = _loaded_column()
    damped, resets = kinetic_reference(ref, n_iter)
    assert resets >= 3
    sim, info, _ = _compiled_like(ref, "kinetic", 0.0, n_iter)
    assert np.allclose(sim.dyn.V, ref.dyn.V, rtol=0, atol=1e-9 * np.abs(ref.dyn.V).max())
    assert info.damped == pytest.approx(damped, rel=1e-9)


def test_local_damping_iteration_matches_numpy_reference():
    """100 iterations of the compiled local-damping loop (alpha 0.8) equal the numpy iteration
    step by step, rigid point included, with velocity reversals (both signs of the damping
    force); the damped energy is the numpy sum; with alpha 0 the same loop is undamped and
    differs (the damping does something). Not longer: the sign switch makes the damped motion
    sensitive to rounding (a 1e-15 change of the load grows to 1e-7 in 300 iterations, numpy
    against numpy), while the two agree to 1e-12 at 100."""
    n_iter = 100
    ref, _ = _loaded_column()
    damped, reversals = local_reference(ref, n_iter, 0.8)
    assert damped > 0.0 and reversals > 0
    sim, info, scale = _compiled_like(ref, "local", 0.8, n_iter)
    assert info.damped == pytest.approx(damped, rel=1e-9)
    plain, _ = _loaded_column()
    local_reference(plain, n_iter, 0.0)
    assert not np.allclose(plain.dyn.U, ref.dyn.U, rtol=0, atol=1e-3 * scale)


# ------------------------------------------------------------------ 2. norms, largest, energy
def _dyn(n, nr, n_tied):
    """A ``Dyn`` of zeros with the solver's dtypes: n nodes, nr reference points, n_tied tied."""
    z = np.zeros((n, 3))
    return Dyn(z.copy(), z.copy(), z.copy(), np.ones(n), np.ones((n, 3)),
               np.full(n, -1, np.int64), z.copy(), z.copy(), z.copy(), z.copy(),
               np.zeros((nr, 3)), np.zeros((nr, 6)), np.zeros((nr, 6)), np.ones((nr, 6)),
               np.ones((nr, 6)), np.zeros((nr, 6)), np.zeros((nr, 6)),
               np.zeros(nr + 1, np.int64), np.zeros(n_tied, np.int64), np.ones(nr), z.copy(),
               np.array([0, n], np.int64), np.zeros(1), z.copy(), np.zeros((nr, 6)),
               np.zeros((4, 3)))


def test_norms_hand_values():
    """Free DOFs: residual into the residual norm, load into the reference; supported DOFs
    (not free, not tied): load and reaction into the reference; tied nodes: nothing (they count
    through their point); point moments divided by the radius (2 m).

    lam 2: node loads fext + 2 P = [1,2,0], [0,2,0], [2,0,5]; residuals [3,0,4], [1,2,2],
    [7,7,7]. Node 0 free: rf 9+16, ref 1+4. Node 1 x free: rf 1; y, z supported: ref
    (4+4) + (0+4). Node 2 tied: none. Point: load [0,0,3,0,0,4] + 2 [1,0,0,0,0,0] scaled to
    [2,0,3,0,0,2], residual [1,0,0,2,0,6] scaled to [1,0,0,1,0,3], rz supported: rf 1+1,
    ref 4+9 + (4+9). rf = 28, ref = 5+8+4+13+13 = 43."""
    d = _dyn(3, 1, 1)
    d.fext[:] = [[1, 0, 0], [0, 2, 0], [0, 0, 5]]
    d.P[:] = [[0, 1, 0], [0, 0, 0], [1, 0, 0]]
    d.res[:] = [[3, 0, 4], [1, 2, 2], [7, 7, 7]]
    d.free[:] = [[1, 1, 1], [1, 0, 0], [0, 0, 0]]
    d.tied[2] = 0
    d.rpptr[1] = 1
    d.rpnodes[0] = 2
    d.rpradius[0] = 2.0
    d.rpf[0] = [0, 0, 3, 0, 0, 4]
    d.rpP[0] = [1, 0, 0, 0, 0, 0]
    d.rpfree[0] = [1, 1, 1, 1, 1, 0]
    rpres = np.array([[1.0, 0, 0, 2, 0, 6]])
    rf, ref = R.norms(d, 2.0, rpres)
    assert rf == pytest.approx(np.sqrt(28.0), rel=1e-15)
    assert ref == pytest.approx(np.sqrt(43.0), rel=1e-15)


def test_resultant_hand_values():
    """Node 0 free (x, y), z supported; node 1 driven in x by a prescribed motion (gnode),
    otherwise supported; node 2 tied to the point, whose x is free and y driven (grp); pattern
    P on node 0 and the point, lam 2; x and y driven, z not.

    Resultant (free residuals): x 3 (node 0) + 1 (point) = 4, y -2 (node 0), z 5 (point).
    Driving force: x -(-6) (node 1's reaction) + 2 (1 + 2) (pattern) = 12; y -(4) (point) +
    2 (0 + 1) = -2, its largest so far 8. Ratios x 4 / 12, y 2 / 8; z not driven."""
    d = _dyn(3, 1, 1)
    d.res[:] = [[3, -2, 9], [-6, 5, 5], [7, 7, 7]]
    d.free[:] = [[1, 1, 0], [0, 0, 0], [0, 0, 0]]
    d.gnode[1, 0] = 1.0
    d.P[0] = [1, 0, 0]
    d.rpP[0] = [2, 1, 0, 0, 0, 0]
    d.tied[2] = 0
    d.rpfree[0] = [1, 0, 1, 0, 0, 0]
    d.grp[0, 1] = 1.0
    d.gspec[0] = [1, 1, 0]
    d.gspec[1] = [0, 8, 0]
    rpres = np.array([[1.0, 4, 5, 0, 0, 0]])
    ratio, axis = R.resultant(d, 2.0, rpres)
    np.testing.assert_allclose(d.gspec[2], [4, -2, 5], rtol=1e-15)
    np.testing.assert_allclose(d.gspec[3, :2], [12, -2], rtol=1e-15)
    assert ratio == pytest.approx(1 / 3, rel=1e-15) and axis == 0
    d.gspec[1, 1] = 4.0   # y's ratio 2 / 4 now the larger
    ratio, axis = R.resultant(d, 2.0, rpres)
    assert ratio == pytest.approx(0.5, rel=1e-15) and axis == 1
    d.gspec[0] = 0.0      # nothing driven
    assert R.resultant(d, 2.0, rpres)[0] == 0.0


def test_block_imbalance_hand_values():
    """Blocks {0, 1}, {2}, {3}: block 0 free in x and y on both nodes, node 1 supported in z (z
    drops out of its net force); block 1 all free; block 2 supported (nothing counts, ratio 0).
    The scale is the joints' forces at the block's nodes (contact rows 0 at node 0, 1 at node 2,
    2 at node 3) and its loads; the nodal internal forces (which cancel at a node in balance)
    do not count.

    lam 1: loads fext + P = [0,0,-3], [0,4,0], [0,0,0], [1,0,0]. Block 0: net residual
    [1+2, 2-2] = [3, 0] (z: 5 + 9 not counted), joints 5, loads 3 + 4: 3 / 12. Block 1: net
    |[0, 6, 8]| = 10, joints 12, no load: 10 / 12. Block 2: 0."""
    d = _dyn(4, 0, 0)._replace(bstart=np.array([0, 2, 3, 4], np.int64))
    d.fext[:] = [[0, 0, -3], [0, 2, 0], [0, 0, 0], [1, 0, 0]]
    d.P[:] = [[0, 0, 0], [0, 2, 0], [0, 0, 0], [0, 0, 0]]
    d.fint[:] = 1e9
    d.res[:] = [[1, 2, 5], [2, -2, 9], [0, 6, 8], [4, 4, 4]]
    d.free[:] = [[1, 1, 1], [1, 1, 0], [1, 1, 1], [0, 0, 0]]
    joints = namedtuple("Joints", "fbuf ptr rows")(
        np.array([[3.0, 0, 4], [0, 12, 0], [0, 0, 7]]), np.array([0, 1, 1, 2, 3]),
        np.array([0, 1, 2]))
    ratio = np.full(3, np.nan)
    worst, at = R.block_imbalance(joints, d, 1.0, ratio)
    np.testing.assert_allclose(ratio, [3 / 12, 10 / 12, 0.0], rtol=1e-15)
    assert (worst, at) == (pytest.approx(10 / 12, rel=1e-15), 1)


def test_worst_place_hand_values():
    """``worst_place`` (which replaced ``largest_displacement``), by its docstring. All finite:
    the largest |U| of a free node DOF or a free reference-point translation (larger values at
    supported DOFs and at rotations are ignored). Else the first non-finite value, searched in
    the node displacements (any DOF), then the points' displacements, then the internal
    forces, then the load factor."""
    d = _dyn(4, 2, 1)
    d.U[:] = [[0.1, -0.2, 0.0], [0.0, 0.3, 9.0], [-0.7, 0.0, 0.5], [0.0, 0.6, 0.0]]
    d.free[1, 2] = 0.0
    d.rpU[0] = [0.0, 0.0, 3.0, 0.0, 0.0, 0.0]
    d.rpfree[0, 2] = 0.0
    d.rpU[1] = [0.0, -0.9, 0.0, 5.0, 0.0, 0.0]
    assert R.worst_place(d, 1.0) == (0.9, R.WHERE_RP, 1)
    d.rpU[1, 1] = 0.5
    assert R.worst_place(d, 1.0) == (0.7, R.WHERE_NODE, 2)
    d.free[:] = 0.0
    d.rpfree[:] = 0.0
    d.U[1, 2] = np.nan   # at a supported DOF
    d.U[3, 0] = np.inf
    d.rpU[1, 4] = -np.inf
    d.fint[2, 1] = np.nan
    value, kind, where = R.worst_place(d, np.inf)
    assert np.isnan(value) and (kind, where) == (R.WHERE_NODE, 1)
    d.U[1, 2] = 0.0
    assert R.worst_place(d, np.inf) == (np.inf, R.WHERE_NODE, 3)
    d.U[3, 0] = 0.0
    assert R.worst_place(d, np.inf) == (-np.inf, R.WHERE_RP, 1)
    d.rpU[1, 4] = 0.0
    value, kind, where = R.worst_place(d, np.inf)
    assert np.isnan(value) and (kind, where) == (R.WHERE_NODE, 2)
    d.fint[2, 1] = 0.0
    assert R.worst_place(d, -np.inf) == (-np.inf, R.WHERE_LOAD, 0)


def test_stored_energy_hand_values():
    """Sum of the energies of the active hexahedra only, plus every contact point's psi."""
    sim = Simulation(_column(1))
    sim.build()
    ne, nc = sim.mesh.energy.shape[0], sim.cont.psi.shape[0]
    assert ne >= 3 and nc == 0
    energy = np.zeros(ne)
    energy[:3] = [1.0, 2.0, 4.0]
    mesh = sim.mesh._replace(energy=energy, active=np.array([0, 2], np.int64))
    assert R.stored_energy(mesh, sim.cont) == 5.0
    sim2 = Simulation(_column(2))
    sim2.build()
    psi = np.zeros(sim2.cont.psi.shape[0])
    psi[:2] = [0.5, 0.25]
    energy = np.zeros(sim2.mesh.energy.shape[0])
    energy[-1] = 8.0
    mesh = sim2.mesh._replace(energy=energy, active=np.array([energy.size - 1], np.int64))
    assert R.stored_energy(mesh, sim2.cont._replace(psi=psi)) == 8.75


def test_stored_energy_is_the_quadratic_form_of_the_stiffness():
    """Glued column (hexahedra and joint springs) at a small random displacement u: the stored
    energy after a force evaluation is 0.5 u.K u with K assembled independently
    (tests/linear_reference.py); the mean of +u and -u cancels the odd geometric terms. The
    value returned by ``internal_forces`` is the same."""
    m = _column()
    sim = Simulation(m)
    sim.build()
    K = LR.hex_matrix(m) + LR.contact_matrix(m)
    u = 1e-7 * np.random.default_rng(3).standard_normal((m.n_nodes, 3))
    e = []
    for sign in (1.0, -1.0):
        sim.dyn.U[:] = sign * u
        e_ret = R.internal_forces(sim.mesh, sim.cont, sim.dyn)
        e.append(R.stored_energy(sim.mesh, sim.cont))
        assert e_ret == e[-1]
        assert sim.cont.psi.sum() > 0.0
    quad = 0.5 * u.ravel() @ (K @ u.ravel())
    assert 0.5 * (e[0] + e[1]) == pytest.approx(quad, rel=1e-8)


# ------------------------------------------------------------------ 3. rigid points
rotvecs = st.lists(st.floats(-7.0, 7.0), min_size=3, max_size=3).map(np.array)


@settings(max_examples=200, deadline=None)
@given(rotvecs, st.sampled_from([1.0, 1e-3, 1e-9]))
def test_rotation_matrix_is_scipy_rotation_vector(th, scale):
    """Rodrigues of a rotation vector (angle |th| about th / |th|): scipy's from_rotvec, small
    and large (beyond pi) rotations; orthogonal, det 1, the axis is fixed."""
    th = np.ascontiguousarray(th * scale)
    rot = np.empty((3, 3))
    B.rotation_matrix(th, rot)
    assert np.allclose(rot, Rotation.from_rotvec(th).as_matrix(), rtol=0, atol=1e-13)
    assert np.allclose(rot.T @ rot, np.eye(3), rtol=0, atol=1e-13)
    assert np.linalg.det(rot) == pytest.approx(1.0, abs=1e-13)
    assert np.allclose(rot @ th, th, rtol=0, atol=1e-13 * max(1.0, np.abs(th).max()))


def test_rotation_matrix_hand_values():
    """A quarter turn about z takes x to y; the zero vector gives the identity; a rotation of
    2 pi is the identity."""
    rot = np.full((3, 3), np.nan)
    B.rotation_matrix(np.array([0.0, 0.0, 0.5 * np.pi]), rot)
    assert np.allclose(rot, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], rtol=0, atol=1e-15)
    B.rotation_matrix(np.zeros(3), rot)
    np.testing.assert_array_equal(rot, np.eye(3))
    B.rotation_matrix(2.0 * np.pi * np.array([0.6, 0.0, 0.8]), rot)
    assert np.allclose(rot, np.eye(3), rtol=0, atol=1e-15)


def _two_points(rng):
    """Six nodes: 0-1 tied to point 0, 3-5 to point 1, node 2 free; random positions."""
    d = _dyn(6, 2, 5)
    d.X[:] = rng.uniform(-1.0, 1.0, (6, 3))
    d.rpX[:] = rng.uniform(-1.0, 1.0, (2, 3))
    d.rpptr[:] = [0, 2, 5]
    d.rpnodes[:] = [0, 1, 3, 4, 5]
    d.tied[:] = [0, 0, -1, 1, 1, 1]
    return d


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 2 ** 32 - 1), st.floats(0.0, 3.0))
def test_place_rigid_nodes_against_numpy(seed, angle):
    """Tied node i of point p moves to X_p + u_p + R(theta_p)(X_i - X_p), R scipy's rotation
    of the rotation vector theta_p (any angle); untied nodes keep their displacement."""
    rng = np.random.default_rng(seed)
    d = _two_points(rng)
    d.rpU[:, :3] = rng.uniform(-0.1, 0.1, (2, 3))
    axis = rng.standard_normal((2, 3))
    d.rpU[:, 3:] = angle * axis / np.linalg.norm(axis, axis=1)[:, None]
    d.U[:] = rng.uniform(-1.0, 1.0, (6, 3))
    u_free = d.U[2].copy()
    R.place_rigid_nodes(d)
    for p, nodes in ((0, [0, 1]), (1, [3, 4, 5])):
        rot = Rotation.from_rotvec(d.rpU[p, 3:]).as_matrix()
        x_new = d.rpX[p] + d.rpU[p, :3] + (d.X[nodes] - d.rpX[p]) @ rot.T
        assert np.allclose(d.X[nodes] + d.U[nodes], x_new, rtol=0, atol=1e-14)
        # rigid: distances to the point and between tied nodes are kept
        x0 = d.X[nodes]
        assert np.allclose(np.linalg.norm(x_new[:, None] - x_new[None], axis=2),
                           np.linalg.norm(x0[:, None] - x0[None], axis=2), rtol=0, atol=1e-14)
    np.testing.assert_array_equal(d.U[2], u_free)


def test_rp_residual_hand_value():
    """One node tied 1 m along x from the point (current positions) with out-of-balance force
    2 N along y: the point gets 2 N along y and a moment (1, 0, 0) x (0, 2, 0) = 2 N m about z,
    plus its own load 3 (rpf) + lam 2 x 0.5 (rpP) on rx; the untied node adds nothing."""
    d = _dyn(2, 1, 1)
    d.X[:] = [[0.5, 0.0, 0.0], [5.0, 5.0, 5.0]]
    d.U[0] = [0.2, 0.3, 0.4]
    d.rpX[0] = [-0.1, 0.1, 0.2]
    d.rpU[0, :3] = [-0.2, 0.2, 0.2]   # current point position (-0.3, 0.3, 0.4) = node - (1, 0, 0)
    d.res[:] = [[0.0, 2.0, 0.0], [7.0, 7.0, 7.0]]
    d.rpf[0, 3] = 3.0
    d.rpP[0, 3] = 0.5
    d.rpptr[1] = 1
    rpres = np.full((1, 6), np.nan)
    R.rp_residual(d, 2.0, rpres)
    assert np.allclose(rpres, [[0.0, 2.0, 0.0, 4.0, 0.0, 2.0]], rtol=0, atol=1e-15)


@pytest.mark.parametrize("seed", range(5))
def test_rp_residual_is_the_virtual_work_of_the_tied_nodes(seed):
    """The generalised residual of a point is conjugate to its rigid motion: for a virtual
    motion (du, dtheta) the tied nodes move du + dtheta x a_i (a_i from the point's current
    position to the node's), and rpres . (du, dtheta) equals the work of the tied nodes'
    residuals plus that of the point's loads rpf + lam rpP; numpy, each of the 6 unit motions."""
    rng = np.random.default_rng(seed)
    d = _two_points(rng)
    d.U[:] = rng.uniform(-0.2, 0.2, (6, 3))
    d.rpU[:] = rng.uniform(-0.2, 0.2, (2, 6))
    d.res[:] = rng.standard_normal((6, 3))
    d.rpf[:] = rng.standard_normal((2, 6))
    d.rpP[:] = rng.standard_normal((2, 6))
    lam = 1.7
    rpres = np.zeros((2, 6))
    R.rp_residual(d, lam, rpres)
    for p, nodes in ((0, [0, 1]), (1, [3, 4, 5])):
        arm = d.X[nodes] + d.U[nodes] - d.rpX[p] - d.rpU[p, :3]
        for k, dq in enumerate(np.eye(6)):
            du = dq[:3] + np.cross(dq[3:], arm)
            work = (d.res[nodes] * du).sum() + (d.rpf[p] + lam * d.rpP[p]) @ dq
            assert rpres[p, k] == pytest.approx(work, rel=1e-13, abs=1e-13)
    assert np.allclose(rpres, rpres_np(d, d.res, lam), rtol=0, atol=1e-13)


def test_rp_rayleigh_against_numpy():
    """Rayleigh sums of the free point DOFs: num = V . (g - gprev), den = V . M V, where g =
    rpf + lam rpP - rpres is the points' generalised internal force; gprev takes g (every
    DOF, free or held)."""
    rng = np.random.default_rng(4)
    d = _two_points(rng)
    d.rpV[:] = rng.standard_normal((2, 6))
    d.rpminv[:] = rng.uniform(0.5, 2.0, (2, 6))
    d.rpfree[:] = 1.0
    d.rpfree[1, 2] = 0.0                      # a held DOF: not in the sums
    d.rpf[:] = rng.standard_normal((2, 6))
    d.rpP[:] = rng.standard_normal((2, 6))
    rpres = rng.standard_normal((2, 6))
    gprev = rng.standard_normal((2, 6))
    old = gprev.copy()
    lam = 0.7
    num, den = R.rp_rayleigh(d, lam, rpres, gprev)
    g = d.rpf + lam * d.rpP - rpres
    free = d.rpfree > 0
    assert num == pytest.approx((d.rpV * (g - old))[free].sum(), rel=1e-13)
    assert den == pytest.approx((d.rpV ** 2 / d.rpminv)[free].sum(), rel=1e-13)
    np.testing.assert_array_equal(gprev, g)


# ------------------------------------------------------------------ 4. quad_shape
CORNERS = np.array([(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)])


def test_quad_shape_hand_value_and_corners():
    """(r, s) = (0.5, -0.25): N = (0.5 1.25, 1.5 1.25, 1.5 0.75, 0.5 0.75) / 4, compiled and
    ``py_func``; N_a(corner b) = delta_ab."""
    hand = [0.15625, 0.46875, 0.28125, 0.09375]
    np.testing.assert_allclose(quad_shape(0.5, -0.25), hand, rtol=1e-15)
    np.testing.assert_allclose(quad_shape.py_func(0.5, -0.25), hand, rtol=1e-15)
    for b, (r, s) in enumerate(CORNERS):
        np.testing.assert_array_equal(quad_shape(r, s), np.eye(4)[b])


def test_quad_shape_partition_of_unity_and_bilinear_interpolation():
    """On a grid over [-1.5, 1.5]^2 (``py_func`` on arrays, as the numpy code calls it, and the
    compiled function point by point): the functions sum to 1 and reproduce r, s and r s from
    the corners' values; a quad's corners interpolate to a hand value at (0.5, -0.25)."""
    r, s = (g.ravel() for g in np.meshgrid(np.linspace(-1.5, 1.5, 7), np.linspace(-1.5, 1.5, 7)))
    N = np.column_stack(quad_shape.py_func(r, s))
    assert N.shape == (r.size, 4)
    np.testing.assert_allclose(N.sum(axis=1), 1.0, rtol=0, atol=1e-15)
    np.testing.assert_allclose(N @ CORNERS[:, 0], r, rtol=0, atol=1e-15)
    np.testing.assert_allclose(N @ CORNERS[:, 1], s, rtol=0, atol=1e-15)
    np.testing.assert_allclose(N @ (CORNERS[:, 0] * CORNERS[:, 1]), r * s, rtol=0, atol=1e-15)
    for q in range(r.size):
        np.testing.assert_array_equal(quad_shape(r[q], s[q]), N[q])
    # corners (0,0,0), (4,0,0), (4,2,0), (0,2,8): z = 8 N3 = 8 x 0.09375
    xq = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [4.0, 2.0, 0.0], [0.0, 2.0, 8.0]])
    np.testing.assert_allclose(np.array(quad_shape(0.5, -0.25)) @ xq, [3.0, 0.75, 0.75],
                               rtol=1e-15)


def test_quad_dshape_is_the_derivative_of_quad_shape():
    """Central differences of ``quad_shape`` (exact for a bilinear function up to rounding)."""
    h = 1e-4
    for r, s in ((0.5, -0.25), (-1.0, 1.0), (0.3, 0.9)):
        dr, ds = quad_dshape(r, s)
        fd_r = (np.array(quad_shape(r + h, s)) - np.array(quad_shape(r - h, s))) / (2 * h)
        fd_s = (np.array(quad_shape(r, s + h)) - np.array(quad_shape(r, s - h))) / (2 * h)
        np.testing.assert_allclose(dr, fd_r, rtol=0, atol=1e-11)
        np.testing.assert_allclose(ds, fd_s, rtol=0, atol=1e-11)


# ------------------------------------------------------------------ 4. held constraint
def test_constraint_force_and_hold_against_numpy():
    """``constraint_force`` adds c mu to the residual with mu = -c.M^-1 r / c.M^-1 c (so that
    M^-1 (r + c mu) has no component along c), and ``hold`` moves U and V onto c.U = target,
    c.V = 0 along M^-1 c; no entries: nothing changes."""
    rng = np.random.default_rng(3)
    d = _dyn(6, 0, 0)
    d.minv[:] = rng.uniform(0.5, 2.0, 6)
    d.res[:] = rng.normal(size=(6, 3))
    d.U[:] = rng.normal(size=(6, 3))
    d.V[:] = rng.normal(size=(6, 3))
    con = R.Constraint(np.array([1, 4, 5]), np.array([0, 0, 2]), np.array([-0.5, 0.25, 0.25]),
                       0.3, 0.0, 0.0)
    c = np.zeros((6, 3))
    c[con.node, con.dof] = con.coef
    mi = d.minv[:, None]
    mu = -(c * mi * d.res).sum() / (c * c * mi).sum()
    expect = d.res + c * mu
    got, norm = R.constraint_force(d, con)
    assert got == pytest.approx(mu, rel=1e-12)
    assert norm == pytest.approx(abs(mu) * np.linalg.norm(con.coef), rel=1e-12)
    np.testing.assert_allclose(d.res, expect, rtol=1e-12, atol=1e-14)
    assert abs((c * mi * d.res).sum()) < 1e-12
    R.hold(d, con)
    assert (c * d.U).sum() == pytest.approx(0.3, abs=1e-12)
    assert abs((c * d.V).sum()) < 1e-12
    before = (d.U.copy(), d.res.copy())
    assert R.constraint_force(d, R.no_constraint()) == (0.0, 0.0)
    R.hold(d, R.no_constraint())
    np.testing.assert_array_equal(d.U, before[0])
    np.testing.assert_array_equal(d.res, before[1])


def test_adapt_gain_cuts_on_slow_reversals_only():
    """``adapt_gain`` by hand, settle 1000 iterations: reactions within tolerance change nothing
    but the count; the first reaction above it sets the sign; a reversal after 1000 iterations at
    the full gain (or 2000 at half) halves the gain, one sooner (the structure's vibration) does
    not, and either restarts the count."""
    f = R.adapt_gain
    assert f(3.0, 5.0, 1.0, 0.0, 0.0, 1000.0, 10.0) == (1.0, 0.0, 10.0)
    assert f(-30.0, 5.0, 1.0, 0.0, 10.0, 1000.0, 10.0) == (1.0, -1.0, 20.0)
    assert f(30.0, 5.0, 1.0, -1.0, 990.0, 1000.0, 10.0) == (R.GAIN_CUT, 1.0, 0.0)
    assert f(30.0, 5.0, 1.0, -1.0, 980.0, 1000.0, 10.0) == (1.0, 1.0, 0.0)
    assert f(30.0, 5.0, 0.5, -1.0, 1500.0, 1000.0, 10.0) == (0.5, 1.0, 0.0)
    assert f(-30.0, 5.0, 0.5, 1.0, 1990.0, 1000.0, 10.0) == (0.25, -1.0, 0.0)
    assert f(30.0, 5.0, 0.5, 1.0, 1990.0, 1000.0, 10.0) == (0.5, 1.0, 2000.0)

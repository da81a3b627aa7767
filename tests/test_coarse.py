"""The coarse correction of dynamic relaxation (dr_masonry.coarse): interpolations, the Galerkin
coarse matrix against an independently assembled T^T K T, and its effect on a run."""
import numpy as np
import pytest

from dr_masonry import (Gravity, JointLaw, Load, Model, PlasticDamage, Simulation,
                        SolverOptions, Stage)
from dr_masonry.coarse import BlockCoarse, affine_stiffness, affine_t, rigid_t
from dr_masonry.kernels import relaxation as R
from dr_masonry.solver import controls

import linear_reference as LR

RNG = np.random.default_rng(7)


def test_interpolations():
    d = RNG.normal(size=(5, 3))
    q = RNG.normal(size=12)
    a, B = q[:3], q[3:].reshape(3, 3)
    assert np.allclose(affine_t(d) @ q, a + d @ B.T, rtol=1e-14)
    u, th = q[:3], q[3:6]
    assert np.allclose(rigid_t(d) @ q, u + np.cross(th, d), rtol=1e-14)


def test_affine_stiffness_is_strain_energy():
    lam, mu = 2.1e9, 1.7e9
    K = affine_stiffness(lam, mu)
    B = RNG.normal(size=(3, 3))
    eps = 0.5 * (B + B.T)
    energy = 0.5 * (lam * np.trace(eps) ** 2 + 2 * mu * np.sum(eps * eps))
    assert 0.5 * B.ravel() @ K @ B.ravel() == pytest.approx(energy, rel=1e-12)
    W = B - B.T                                   # a rotation costs nothing
    assert np.abs(K @ W.ravel()).max() < 1e-6 * np.abs(K).max()


def _column(n_blocks, kc=None):
    m = Model()
    m.set_joint_law(JointLaw.tied(7.5e10, 3e10, kc))
    mat = PlasticDamage.elastic(4.8e9, 0.17, 1800.0)
    m.add_box((0, 0, -0.1), (0.22, 0.102, 0.1), mat, (1, 1, 1), fixed=True)
    for k in range(n_blocks):
        m.add_box((0.0, 0, 0.081 * k), (0.22, 0.102, 0.081), mat, (2, 1, 2))
    return m


def test_coarse_matrix_is_galerkin_projection():
    """At rest, the coarse matrix equals T^T (K_hex + K_joints) T with K assembled by the
    independent linear reference of the verification tests and T the affine map of each block."""
    m = _column(3)
    sim = Simulation(m)
    sim.build()
    co = BlockCoarse(sim)
    g, nbg = co.groups()
    dof, ndof = co.dof_map(nbg, 0)
    Kc = co.matrix(g, nbg, dof, ndof).toarray()
    K = (LR.hex_matrix(m) + LR.contact_matrix(m)).toarray()
    nodes = np.nonzero(g[m.node_block] >= 0)[0]
    T = np.zeros((3 * m.n_nodes, ndof))
    Tn = affine_t(m.nodes[nodes] - co.centre[m.node_block[nodes]])
    for i, node in enumerate(nodes):
        T[3 * node:3 * node + 3, dof[g[m.node_block[node]]]] = Tn[i]
    ref = T.T @ K @ T
    assert np.abs(Kc - ref).max() < 1e-9 * np.abs(ref).max()


def _loaded(kc, coarse):
    """A column of 30 blocks compressed by 1000 g (displacements ~0.1 mm), set up for one
    increment."""
    sim = Simulation(_column(30, kc), SolverOptions(tol=1e-5, coarse=coarse))
    sim.build()
    ctl = Load(pattern=Gravity(), to=1000.0)
    controls.apply(sim, ctl, 1000.0)
    controls.assemble_loads(sim, None)
    return sim, Stage("g", 1, [ctl])


def _coarse_at_rest(kc):
    """The loaded column of :func:`_loaded` at rest, its forces and residual computed, and its
    coarse correction."""
    sim, _ = _loaded(kc, True)
    R.internal_forces(sim.mesh, sim.cont, sim.dyn)
    R.residual(sim.dyn, 0.0, np.zeros((0, 6)))
    return sim, BlockCoarse(sim)


def _correct(co):
    """One coarse correction without load-factor control (True if accepted)."""
    return co.correct(np.zeros(1), np.zeros((0, 6)), np.zeros(3, np.int64))


@pytest.mark.parametrize("kc", [None, 7.5e11])
def test_one_correction_from_rest(kc):
    """One coarse correction from rest lands within 3 % of the converged displacement field
    (affine blocks represent their own compression, so a stiff compression penalty does not
    make the coarse model too stiff); the relaxed answer is the same with and without it, in a
    fraction of the iterations, and the row counts the corrections it accepted."""
    plain = Simulation(_column(30, kc), SolverOptions(tol=1e-5, coarse=False))
    hist = plain.run([Stage("g", 1, [Load(pattern=Gravity(), to=1000.0)])])
    exact = plain.dyn.U.copy()
    sim, co = _coarse_at_rest(kc)
    assert _correct(co)
    assert np.linalg.norm(sim.dyn.U - exact) < 0.03 * np.linalg.norm(exact)
    sim, stage = _loaded(kc, True)
    hist_c = sim.run([stage])
    assert np.abs(sim.dyn.U - exact).max() < 1e-3 * np.abs(exact).max()
    assert hist_c["iterations"][0] < 0.3 * hist["iterations"][0]
    assert hist_c["coarse_accepted"][0] >= 1 and hist["coarse_accepted"][0] == 0
    assert hist["coarse_rejected"][0] == 0


def test_residual_test_accepts_the_step_short_of_equilibrium():
    """``coarse_test="residual"``: from rest, the loaded column's coarse step leaves a residual
    that still works along the step (positive), the same step 2.5 x as long has passed the
    equilibrium along its line (negative work), and the correction lands where the energy
    test's does, within 3 % of the relaxed field."""
    plain = Simulation(_column(30), SolverOptions(tol=1e-5, coarse=False))
    plain.run([Stage("g", 1, [Load(pattern=Gravity(), to=1000.0)])])
    exact = plain.dyn.U.copy()
    sim, co = _coarse_at_rest(None)
    sim.options.coarse.test = "residual"
    d = sim.dyn
    op = co.operator(np.zeros(3, np.int64))
    du, drp = co.prolong(op, op["solve"](co.project(op, d.res, np.zeros((0, 6)))[op["idx"]]))
    nodes = op["nodes"]
    works = []
    for scale in (0.0, 1.0, 2.5):
        d.U[:] = 0.0
        d.U[nodes] += scale * du
        works.append(co.residual_work(0.0, nodes, du, drp))
    assert works[0] > 0.0 and works[1] > 0.0 > works[2]
    d.U[:] = 0.0
    R.internal_forces(sim.mesh, sim.cont, d)
    R.residual(d, 0.0, np.zeros((0, 6)))
    assert _correct(co)
    assert np.linalg.norm(d.U - exact) < 0.03 * np.linalg.norm(exact)


def test_joint_stiffness_secant_only_where_it_slides():
    """A block on a fixed foundation, every joint point closed with slip 1 mm under tau = 0.2 MPa
    in the direction (0.6, 0.8) of its face's frame: while the points stick, the coarse stiffness
    of the block's translation is kss A in both tangential directions (the unloading stiffness);
    once the trial state slides (plastic slip moving) it is the secant tau / slip A along the
    traction and still kss A across it (a slip across the traction turns it on the yield circle),
    kn A normal to the joint, with the frame of the contact-frame kernel."""
    from dr_masonry.kernels.contact_frame import contact_frame
    from dr_masonry.kernels.joint_law import JS_DP1
    m = Model()
    m.set_joint_law(JointLaw.dry(0.6))
    mat = PlasticDamage.elastic(10e9, 0.2, 2000.0)
    m.add_box((0.0, 0.0, -0.1), (0.2, 0.1, 0.1), mat, (2, 1, 1), fixed=True)
    blk = m.add_box((0.0, 0.0, 0.0), (0.2, 0.1, 0.1), mat, (4, 1, 1))
    sim = Simulation(m)
    sim.build()
    c = sim.cont
    c.gaps[:] = [-1e-6, 0.6e-3, 0.8e-3]
    c.trac[:] = [-1e5, 1.2e5, 1.6e5]
    co = BlockCoarse(sim)
    g, nbg = co.groups()
    dof, ndof = co.dof_map(nbg, 0)
    ix = dof[g[blk], :3]
    area = c.area.sum()
    assert area == pytest.approx(0.02)
    frame, xm = np.empty((3, 3)), np.empty(3)
    contact_frame(m.nodes[c.master[0]], c.xi[0, 0], c.xi[0, 1], xm, frame)
    n, t1, t2 = frame
    law = m.joint_laws[0]
    kn = 1e5 / 1e-6
    stick = co.matrix(g, nbg, dof, ndof)[ix][:, ix].toarray()
    ref = area * (kn * np.outer(n, n) + law.kss * (np.eye(3) - np.outer(n, n)))
    assert np.allclose(stick, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
    c.s_new[:, JS_DP1] = c.s_old[:, JS_DP1] + 1e-4
    slide = co.matrix(g, nbg, dof, ndof)[ix][:, ix].toarray()
    e = 0.6 * t1 + 0.8 * t2
    ref += area * (2e5 / 1e-3 - law.kss) * np.outer(e, e)
    assert np.allclose(slide, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
    assert e @ slide @ e == pytest.approx(2e5 / 1e-3 * area, rel=1e-12)
    across = np.cross(n, e)
    assert across @ slide @ across == pytest.approx(law.kss * area, rel=1e-12)


def test_trust_radius_rejects_a_long_step():
    """A coarse step that would move a node by more than the trust radius (a quarter of the
    median block's smallest extent: 81 mm blocks, 20.25 mm) is undone, even where it lowers the
    potential (a nearly singular operator lets a block held by sliding or cracked joints fly
    kilometres: S7 cyclic row 248); the same step within the radius is taken."""
    sim, co = _coarse_at_rest(None)
    assert co.trust == pytest.approx(0.25 * 0.081, rel=1e-12)
    assert _correct(co)
    step = np.abs(sim.dyn.U).max()
    assert 0.0 < step < co.trust
    sim, co = _coarse_at_rest(None)
    co.trust = 0.2 * step      # the halved steps (1/2, 1/4) are still too long
    assert not _correct(co)
    assert not sim.dyn.U.any()
    co.trust = 0.3 * step      # a quarter step fits
    assert _correct(co)
    assert np.abs(sim.dyn.U).max() == pytest.approx(0.25 * step, rel=1e-9)

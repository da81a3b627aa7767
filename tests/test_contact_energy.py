"""The contact kernel's forces against the gradient of the joints' stored energy.

Two bricks, the upper one shifted along x so that the faces overlap only in part: the slave
nodes inside the master face pair with gap0 = 0, those outside it (their tributary area still
overlapping) with a tangential offset gap0 (``contact_search``). In compression, below the
joints' strength (no damage, no slip: the state does not evolve), the internal force of a point
on its five nodes must be d psi / d x, psi its stored energy, and its forces must carry no net
moment (action and reaction on one line). The fictitious masses rest on Gershgorin bounds of the
assembled stiffness: ``contact_rowsum`` must bound it there as well.
"""
import numpy as np
import pytest

from dr_masonry import JointLaw, Model, PlasticDamage
from dr_masonry.contact_search import detect_contacts
from dr_masonry.kernels.contact_forces import contact_rowsum
from dr_masonry.kernels.forces import contact_forces
from dr_masonry.kernels.joint_law import NJS

MAT = PlasticDamage.elastic(10e9, 0.2, 2000.0)


@pytest.fixture(scope="module")
def pair():
    """Contact set of two 0.22 x 0.10 x 0.05 m bricks, the upper one shifted 0.03 m along x, and a
    compressed state of the joint (upper brick 3 um down, nodes jiggled by 0.2 um)."""
    m = Model()
    m.set_joint_law(JointLaw.reference())
    m.add_box((0.0, 0.0, 0.0), (0.22, 0.1, 0.05), MAT, (2, 1, 1))
    upper = m.add_box((0.03, 0.0, 0.05), (0.22, 0.1, 0.05), MAT, (2, 1, 1))
    cs = detect_contacts(m)
    X = m.nodes.copy()
    U = np.random.default_rng(3).normal(scale=2e-7, size=X.shape)
    U[m.block_nodes(upper), 2] -= 3e-6
    return cs, X, U


def evaluate(cs, X, U):
    """(psi (nc,) J, forces (nc, 5, 3) N, local gaps (nc, 3) m) at displacements U."""
    nc = cs.slave.size
    lp = np.ascontiguousarray(JointLaw.reference().params_array()[None, :])
    law = np.zeros(nc, np.int64)
    s_old = np.zeros((nc, NJS))
    s_new = s_old.copy()
    gaps, trac, fb, psi = np.zeros((nc, 3)), np.zeros((nc, 3)), np.zeros((nc * 5, 3)), np.zeros(nc)
    contact_forces(X, U, cs.slave, cs.master, cs.xi, cs.area, law, lp, cs.gap0, s_old, s_new,
                   gaps, trac, fb, psi)
    return psi, fb.reshape(nc, 5, 3), gaps


def energy_gradient(cs, X, U, c, h=1e-10):
    """d psi_c / d x of point c on its slave and four master nodes (5, 3), central differences."""
    nodes = np.concatenate([[cs.slave[c]], cs.master[c]])
    out = np.zeros((5, 3))
    for r, n in enumerate(nodes):
        for k in range(3):
            up, um = U.copy(), U.copy()
            up[n, k] += h
            um[n, k] -= h
            out[r, k] = (evaluate(cs, X, up)[0][c] - evaluate(cs, X, um)[0][c]) / (2.0 * h)
    return out


def net_moment(cs, X, U, f, c):
    nodes = np.concatenate([[cs.slave[c]], cs.master[c]])
    return np.cross(X[nodes] + U[nodes], f[c]).sum(axis=0)


def test_the_pair_has_points_on_and_off_their_faces(pair):
    cs, X, U = pair
    off = np.abs(cs.gap0).max(axis=1) > 1e-9
    assert 0 < off.sum() < off.size
    psi, f, gaps = evaluate(cs, X, U)
    assert np.all(gaps[:, 0] < 0.0)   # every point compressed: no damage, no slip


def test_forces_are_the_energy_gradient_on_the_face(pair):
    """Points whose slave node lies on its master face: forces = d psi / d x to 1e-5, and no net
    moment beyond the gap's own lever arm (um)."""
    cs, X, U = pair
    psi, f, _ = evaluate(cs, X, U)
    on = np.nonzero(np.abs(cs.gap0).max(axis=1) <= 1e-9)[0]
    for c in on:
        g = energy_gradient(cs, X, U, c)
        np.testing.assert_allclose(f[c], g, atol=1e-5 * np.abs(f[c]).max())
        assert np.linalg.norm(net_moment(cs, X, U, f, c)) < 1e-4 * np.abs(f[c]).max() * 0.05


def test_forces_are_the_energy_gradient_off_the_face(pair):
    """Points whose slave node lies off its master face (gap0 = 0.03 m): the frame's turning
    over the offset is part of the forces (``offset_forces``); without it they were 27 % off the
    gradient and carried a couple gap0 x F of 84-92 N m."""
    cs, X, U = pair
    psi, f, _ = evaluate(cs, X, U)
    off = np.nonzero(np.abs(cs.gap0).max(axis=1) > 1e-9)[0]
    for c in off:
        g = energy_gradient(cs, X, U, c)
        np.testing.assert_allclose(f[c], g, atol=1e-5 * np.abs(f[c]).max())
        assert np.linalg.norm(net_moment(cs, X, U, f, c)) < 1e-4 * np.abs(f[c]).max() * 0.05


def test_rowsum_bounds_the_contact_stiffness(pair):
    """Absolute row sums of the assembled contact stiffness (central differences of the nodal
    forces) against ``contact_rowsum`` with the points' lever (the bound without it is exceeded
    at the masters of the off-face points: 1.27 x)."""
    cs, X, U = pair
    kb = np.full(cs.slave.size, JointLaw.reference().stiffness_bound())
    bound = contact_rowsum(cs.slave, cs.master, cs.xi, cs.area, kb, X.shape[0], X, cs.gap0)
    nodes = np.column_stack([cs.slave, cs.master]).ravel()

    def forces(u):
        out = np.zeros_like(X)
        np.add.at(out, nodes, evaluate(cs, X, u.reshape(X.shape))[1].reshape(-1, 3))
        return out.ravel()

    h = 1e-10
    K = np.empty((X.size, X.size))
    for j in range(X.size):
        du = np.zeros(X.size)
        du[j] = h
        K[:, j] = (forces(U.ravel() + du) - forces(U.ravel() - du)) / (2.0 * h)
    rows = np.abs(K).sum(axis=1).reshape(X.shape).max(axis=1)
    assert np.all(rows <= bound * (1.0 + 1e-4))   # tight for a lone compressed spring

"""Race-free assembly and the fused force kernel of one relaxation iteration: ``gather_pair``
against numpy's unbuffered ``np.add.at``, and ``element_and_contact_forces`` (hexahedra and
contact points as interleaved tasks of one parallel region) against its calls on each set
alone (``hex_forces``, ``contact_forces``: the other set empty, no interleaving)."""
import numpy as np
import pytest

from dr_masonry import JointLaw, Model, PlasticDamage, Simulation
from dr_masonry.kernels import relaxation as R
from dr_masonry.kernels.assembly import gather_pair, node_row_map
from dr_masonry.kernels.forces import contact_forces, hex_forces
from dr_masonry.kernels.hex8 import CHUNK

RNG = np.random.default_rng(11)


def test_gather_pair_sums_both_buffers_per_node():
    n = 9   # node 8 belongs to no item: its row must be overwritten with zeros
    items_a = RNG.integers(0, 8, size=(6, 8))
    items_b = RNG.integers(-1, 8, size=(13, 5))   # -1: no node
    buf_a = RNG.normal(size=(items_a.size, 3))
    buf_b = RNG.normal(size=(items_b.size, 3))
    ref = np.zeros((n, 3))
    np.add.at(ref, items_a.ravel(), buf_a)
    keep = items_b.ravel() >= 0
    np.add.at(ref, items_b.ravel()[keep], buf_b[keep])
    out = np.full((n, 3), np.nan)
    gather_pair(buf_a, *node_row_map(items_a, n), buf_b, *node_row_map(items_b, n), out)
    assert np.allclose(out, ref, rtol=1e-14, atol=1e-14)
    assert np.all(out[8] == 0.0)


def _wall(n_blocks):
    """A column of bricks on a fixed base: ``n_blocks`` x 12 hexahedra, every third brick
    elastic (corotational elements between damaging ones: runs of slots in the force tasks)."""
    m = Model()
    m.set_joint_law(JointLaw.reference())
    m.add_box((0.0, 0.0, -0.05), (0.21, 0.1, 0.05), PlasticDamage.reference(), (1, 1, 1),
              fixed=True)
    for k in range(n_blocks):
        mat = PlasticDamage.elastic(2e9, 0.2, 1800.0) if k % 3 == 2 else PlasticDamage.reference()
        m.add_box((0.0, 0.0, 0.05 * k), (0.21, 0.1, 0.05), mat, (3, 2, 2))
    sim = Simulation(m)
    sim.build()
    return sim


@pytest.mark.parametrize("n_blocks", [1, 6, 13])
def test_fused_forces_equal_the_two_kernels(n_blocks):
    """Every hexahedron task and every contact task runs once: the fused kernel's outputs are
    bit for bit those of ``hex_forces`` then ``contact_forces`` (each set alone), with strains
    that crack and crush some Gauss points and open some joints."""
    sim = _wall(n_blocks)
    m, c, d = sim.mesh, sim.cont, sim.dyn
    assert (m.active.size > CHUNK) == (n_blocks > 5)
    d.U[:] = RNG.normal(scale=2e-4, size=d.U.shape) * (d.free > 0)
    R.element_and_contact_forces(d.X, d.U, m, c)
    outputs = (m.fbuf, m.energy, m.s_new, c.fbuf, c.psi, c.trac, c.s_new)
    fused = [a.copy() for a in outputs]
    # inactive elements are never written (their zero forces are gathered), nor the Gauss-point
    # states of elastic elements
    damaging = m.active[m.kid[m.active] < 0]
    for a in outputs:
        if a is m.s_new:
            a[damaging] = np.nan
        elif a.shape[0] == m.conn.shape[0]:
            a[m.active] = np.nan
        else:
            a[:] = np.nan
    hex_forces(d.U, m.conn, m.active, m.dN, m.geo, m.wdet, m.h, m.emat, m.mparams, m.s_old,
               m.s_new, m.pristine, m.dirty, m.fbuf, m.energy,
               corot=(m.ke, m.kbt, m.kxo, m.kdn, m.kid))
    contact_forces(d.X, d.U, c.slave, c.master, c.xi, c.area, c.law, c.lparams, c.gap0, c.s_old,
                   c.s_new, c.gaps, c.trac, c.fbuf, c.psi)
    for a, b in zip(fused, outputs):
        np.testing.assert_array_equal(a[m.active] if a.shape[0] == m.conn.shape[0] else a,
                                      b[m.active] if b.shape[0] == m.conn.shape[0] else b)
    assert np.any(c.s_new[:, 0] > 0.0)      # some joints damaged: the softening branch ran
    # internal_forces: the gathered nodal forces and the total stored energy
    e = R.internal_forces(m, c, d)
    ref = np.zeros_like(d.fint)
    np.add.at(ref, m.conn[m.active].ravel(), m.fbuf[m.active].reshape(-1, 3))
    nodes = np.column_stack([c.slave, c.master]).ravel()
    np.add.at(ref, nodes, c.fbuf)
    assert np.allclose(d.fint, ref, rtol=1e-12, atol=1e-9 * np.abs(ref).max())
    assert e == pytest.approx(m.energy[m.active].sum() + c.psi.sum(), rel=1e-12)


def test_single_set_calls_run_the_compiled_kernel_of_a_run():
    """``hex_forces`` (with tables) and ``contact_forces`` pass the force kernel tuples of the
    same Numba types as a run's, with the other set empty: they call its compiled code, compile
    nothing new."""
    from numba import typeof
    from dr_masonry.kernels.forces import (NO_CONTACTS, NO_ELEMENTS, contact_only_args,
                                            hex_only_args)
    sim = _wall(2)
    m, c = sim.mesh, sim.cont
    assert typeof(NO_CONTACTS) == typeof(c) and typeof(NO_ELEMENTS) == typeof(m)
    assert typeof(hex_only_args(sim.dyn.U, *m[:12], m.fbuf, m.energy, m[12:17])[2]) == typeof(m)
    assert typeof(contact_only_args(sim.dyn.X, sim.dyn.U, *c[:13])[3]) == typeof(c)

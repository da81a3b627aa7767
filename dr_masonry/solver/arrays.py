"""The arrays a run works on: the nodal state :data:`Dyn`, the hexahedra and contact points
(``kernels.forces.Mesh``, ``Cont``), the fictitious masses from Gershgorin row sums, and their
update after finite sliding re-paired contact points."""
from __future__ import annotations

from collections import namedtuple

import numpy as np

from .. import loading as L
from ..kernels.assembly import node_row_map
from ..kernels.contact_forces import contact_rowsum
from ..kernels.forces import Cont, Mesh
from ..kernels.hex8 import corot_tables, hex_geometry_shared, lumped_mass, pristine_elements
from ..kernels.hex8 import stiffness_rowsum
from ..kernels.plastic_damage import MP_HMAX
from ..materials import JointLaw, PlasticDamage
from ..model import ModelError
from ..options import COARSE_MIN_BLOCKS

#: nodal state (n_nodes, 3) unless noted: X reference coordinates m, U displacements m, V velocities
#: (m per unit fictitious step), minv (n_nodes,) inverse fictitious masses, free 1/0 per DOF, tied
#: (n_nodes,) reference point or -1, fext constant loads N, P indirect pattern N per unit factor,
#: fint internal forces N, res out-of-balance N; reference points (n_rp, 6) rpU/rpV/rpminv/rpfree,
#: rpf applied and rpP pattern generalised forces, rpX (n_rp, 3) m, rpptr/rpnodes CSR of tied
#: nodes, rpradius (n_rp,) m radius of gyration (moment scale); ring (n_nodes, 3) velocity-reversal
#: counts of the ring damping (``R.relax``); bstart (n_blocks + 1,) first node of each block,
#: bratio (n_blocks,) each block's imbalance ratio at the end of the last relaxation; gnode
#: (n_nodes, 3) and grp (n_rp, 6) 1.0 at the DOFs whose prescribed motion drives the increment,
#: gspec (4, 3) the driven axes, their largest driving force so far, the out-of-balance resultant
#: and the driving force (``R.resultant``)
Dyn = namedtuple("Dyn", "X U V minv free tied fext P fint res rpX rpU rpV rpminv rpfree rpf rpP "
                        "rpptr rpnodes rpradius ring bstart bratio gnode grp gspec")


class SolverError(RuntimeError):
    """A run stopped: the message says where (increment, node/block) and which quantity."""


def reaction_rows(pairs, blocks, support):
    """Contact rows (slave side, master side) by which blocks ``support`` act on ``blocks``,
    from the (slave block, master block) ``pairs`` (nc, 2) of the contact set."""
    a, b = np.isin(pairs, blocks), np.isin(pairs, support)
    return np.nonzero(a[:, 1] & b[:, 0])[0], np.nonzero(a[:, 0] & b[:, 1])[0]


def shortest_edge(q):
    """Shortest edge (m) of each quad with corners ``q`` (nc, 4, 3)."""
    return np.linalg.norm(q[:, [1, 2, 3, 0]] - q, axis=2).min(axis=1)


def check_materials(model):
    """ModelError naming the first block whose material is not a PlasticDamage or the first
    joint law (and a block using it) that is not a JointLaw: the model container takes any
    object, the solver needs these."""
    for b, k in enumerate(model.block_material):
        if not isinstance(model.materials[k], PlasticDamage):
            raise ModelError(f"block {b}: material must be a PlasticDamage, got "
                             f"{model.materials[k]!r}")
    for k, law in enumerate(model.joint_laws):
        if not isinstance(law, JointLaw):
            users = np.flatnonzero(np.asarray(model.block_joint) == k)
            which = f"block {users[0]}'s joint" if users.size else "the default joint law"
            raise ModelError(f"{which} must be a JointLaw, got {law!r}")


def build_arrays(sim):
    """Build ``sim.mesh``, ``sim.cont``, ``sim.dyn``, the physical and fictitious masses, the
    contact-face tables of the overhang check, ``sim.sliding`` and ``sim.use_coarse``."""
    m = sim.model
    o = sim.options
    X = m.nodes
    conn = m.elements
    n = m.n_nodes
    dN, geo, wdet, h = hex_geometry_shared(X, conn)
    emat = m.block_material[m.element_block]
    mats = m.materials
    mparams = np.ascontiguousarray(np.vstack([mt.params_array() for mt in mats]))
    for i, mt in enumerate(mats):  # crack band: refuse elements too large for the softening
        on = emat == i
        if on.any() and not mt.stays_elastic:
            mt.check_element_size(float(h[on].max()))
    rho = np.array([mt.density for mt in mats])[emat]
    E = np.array([mt.E for mt in mats])[emat]
    nu = np.array([mt.nu for mt in mats])[emat]
    tied = np.full(n, -1, dtype=np.int64)
    for p, rp in enumerate(sim.rigid_points):
        tied[rp.nodes] = p
    # elements of fixed blocks, and elements moving rigidly with one reference point, have no
    # strain: no force computation, and no stiffness in the fictitious masses
    et = tied[conn]
    rigid = (et[:, 0] >= 0) & np.all(et == et[:, :1], axis=1)
    active = np.nonzero(~m.block_fixed[m.element_block] & ~rigid)[0].astype(np.int64)
    s0 = np.stack([mt.initial_state() for mt in mats])[emat]
    s_old = np.ascontiguousarray(np.repeat(s0[:, None, :], 8, axis=1))
    ptr, rows = node_row_map(conn, n)
    sim._s_virgin = s0
    # corotational elements (one stiffness and strain table per brick shape and material)
    corot = corot_tables(X, conn, dN, geo, wdet, emat, mparams, active)
    sim.mesh = Mesh(conn, active, dN, geo, wdet, h, emat, mparams, s_old, s_old.copy(),
                    np.zeros(conn.shape[0], np.uint8), np.zeros(conn.shape[0], np.uint8),
                    *corot, np.zeros((conn.shape[0], 8, 3)), np.zeros(conn.shape[0]), ptr, rows)
    mark_pristine(sim)
    sim.mass = lumped_mass(conn, wdet, rho, n)  # physical, kg
    a = active
    sim._rowsum_solid = stiffness_rowsum(conn[a], dN, geo[a], wdet[a], E[a], nu[a], n)
    c = m.contacts
    laws = m.joint_laws
    sim._kbound = np.array([lw.stiffness_bound() for lw in laws])   # per law, Pa/m
    if c.n:
        lparams = np.ascontiguousarray(np.vstack([lw.params_array() for lw in laws]))
        js0 = np.stack([lw.initial_state() for lw in laws])[c.law]
    else:
        from ..kernels.joint_law import NJP, NJS
        lparams = np.zeros((1, NJP))
        js0 = np.zeros((0, NJS))
    cptr, crows = node_row_map(np.column_stack([c.slave, c.master]), n)
    nc = c.n
    from ..contact_search import master_sides, overhang
    sim._sides = master_sides(m, c)
    sim._overhang0 = overhang(m.nodes, c.slave, sim._sides)  # partial overlaps at the start
    sim._side_size = shortest_edge(m.nodes[sim._sides])
    # copies: finite sliding re-pairs points in place, ``model.contacts`` stays as detected
    sim.cont = Cont(c.slave, c.master.copy(), c.xi.copy(), c.area.copy(), c.law.copy(), lparams,
                    c.gap0.copy(), np.ascontiguousarray(js0), js0.copy(), np.zeros((nc, 3)),
                    np.zeros((nc, 3)), np.zeros((nc * 5, 3)), np.zeros(nc), cptr, crows)
    rs = rowsum(sim)
    free_nodes = ~sim._fixed.all(axis=1) & (tied < 0)
    if np.any(rs[free_nodes] <= 0):
        bad = int(np.nonzero(free_nodes & (rs <= 0))[0][0])
        raise SolverError(f"node {bad} (block {m.node_block[bad]}) has no stiffness: it belongs to "
                          f"no active element and no contact")
    if sim._fixed.all():
        raise ModelError("Simulation: every node is fixed (every block is fixed=True or "
                         "fixed by Simulation.fix): nothing can move")
    free = (~sim._fixed).astype(np.float64)
    nr = len(sim.rigid_points)
    rpX = np.zeros((nr, 3))
    rpptr = np.zeros(nr + 1, dtype=np.int64)
    for p, rp in enumerate(sim.rigid_points):
        if sim._fixed[rp.nodes].any():
            raise L.LoadingError(f"rigid point {rp.name!r} ties nodes that are also fixed")
        free[rp.nodes] = 0.0
        rpX[p] = rp.position
        rpptr[p + 1] = rpptr[p] + rp.nodes.size
    minv, rpminv, rpradius = masses(sim, rs)
    rpnodes = (np.concatenate([rp.nodes for rp in sim.rigid_points]) if nr
               else np.zeros(0, np.int64))
    z = np.zeros((n, 3))
    sim.dyn = Dyn(X, z.copy(), z.copy(), minv, free, tied, z.copy(), z.copy(), z.copy(), z.copy(),
                  rpX, np.zeros((nr, 6)), np.zeros((nr, 6)), rpminv, np.ones((nr, 6)),
                  np.zeros((nr, 6)), np.zeros((nr, 6)), rpptr, rpnodes, rpradius, z.copy(),
                  np.ascontiguousarray(m.block_node_start, np.int64), np.zeros(m.n_blocks),
                  z.copy(), np.zeros((nr, 6)), np.zeros((4, 3)))
    from ..sliding import Sliding
    sim.sliding = Sliding(sim) if (o.sliding.redetect and nc) else None
    movable = int((~m.block_fixed).sum())
    sim.use_coarse = (o.coarse.enabled is True
                      or (o.coarse.enabled == "auto" and movable >= COARSE_MIN_BLOCKS))
    sim.size = float(np.max(np.ptp(X, axis=0)))
    sim.ref_floor = 1e-9 * float(rs.max()) * sim.size


def mark_pristine(sim):
    """After the blocks' committed state changed (start, commit, checkpoint): the elements
    still in their virgin state, and trial states equal to the committed ones."""
    m = sim.mesh
    m.pristine[:] = pristine_elements(m.s_old, sim._s_virgin, m.h, m.mparams[m.emat, MP_HMAX])
    m.dirty[:] = 0


def rowsum(sim):
    """Gershgorin row sums (n_nodes,) N/m of the elements and the current contact set."""
    c = sim.cont
    if c.slave.size == 0:
        return sim._rowsum_solid
    return sim._rowsum_solid + contact_rowsum(c.slave, c.master, c.xi, c.area,
                                              sim._kbound[c.law], sim.model.n_nodes,
                                              sim.model.nodes, c.gap0)


def masses(sim, rs):
    """Inverse fictitious masses from the row sums ``rs`` (n_nodes,) N/m: of the nodes
    (n_nodes,) 1/kg, of the reference points (n_rp, 6) and their radii of gyration (n_rp,) m
    (the tied nodes' masses and their second moment about the point)."""
    fict = np.where(rs > 0, sim.options.damping.safety * rs / 4.0, 1.0)
    nr = len(sim.rigid_points)
    rpminv = np.ones((nr, 6))
    rpradius = np.ones(nr)
    for p, rp in enumerate(sim.rigid_points):
        w = fict[rp.nodes] * (rs[rp.nodes] > 0)
        mt = w.sum()
        if mt <= 0.0:
            raise L.LoadingError(f"rigid point {rp.name!r}: its nodes touch no deformable element "
                                 f"and no contact, so nothing resists its motion")
        jr = (w * ((sim.model.nodes[rp.nodes] - rp.position) ** 2).sum(axis=1)).sum()
        rpminv[p, :3] = 1.0 / mt
        rpminv[p, 3:] = 1.0 / max(jr, 1e-300)
        rpradius[p] = np.sqrt(max(jr / mt, 1e-300))
    return 1.0 / fict, rpminv, rpradius


def contacts_changed(sim):
    """After :mod:`dr_masonry.sliding` re-paired points: the gather's node map, the masses,
    the faces of the overhang check, the rows of the contact reactions and the coarse
    operator follow the new set."""
    from ..contact_search import master_sides
    c, d, m = sim.cont, sim.dyn, sim.model
    ptr, rows = node_row_map(np.column_stack([c.slave, c.master]), m.n_nodes)
    c.ptr[:], c.rows[:] = ptr, rows
    minv, rpminv, rpradius = masses(sim, rowsum(sim))
    d.minv[:], d.rpminv[:], d.rpradius[:] = minv, rpminv, rpradius
    sides = master_sides(m, sim.sliding.contact_set())
    new = np.any(sides != sim._sides, axis=1)
    sim._sides = sides
    sim._overhang0[new] = 0.0
    sim._side_size[new] = shortest_edge(m.nodes[sides[new]])
    for name, pair in sim._reaction_blocks.items():
        sim.contact_reactions[name] = reaction_rows(sim.sliding.blocks, *pair)
    sim.coarse = None

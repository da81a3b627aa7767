"""The increment loop: builds the arrays, marches every load increment to rest, records results.

Physics lives in ``kernels/``; this module only orchestrates: fictitious masses from Gershgorin
bounds, constraints and controls per increment, convergence checks, increment cutting, commit of
history variables, energy audit, guards and output (through ``dr_masonry.results``).
"""
from __future__ import annotations

import os
import time
import warnings
from collections import namedtuple
from contextlib import contextmanager
from dataclasses import asdict

import numba
import numpy as np

from . import loading as L
from .interrupts import terminate_as_interrupt
from .kernels import relaxation as R
from .kernels.assembly import node_row_map
from .kernels.contact_forces import contact_rowsum
from .kernels.forces import Cont, Mesh
from .kernels.hex8 import (corot_tables, hex_geometry_shared, inverted_element, lumped_mass,
                           pristine_elements, stiffness_rowsum)
from .kernels.joint_law import JS_D, JS_DISS, JS_DISSF
from .kernels.plastic_damage import FLAG_RETURN, MP_HMAX, MS_DC, MS_DISS, MS_DT, MS_FLAG, NMS
from .materials import JointLaw, PlasticDamage
from .model import Model, ModelError, id_array, quad_area_vector
from .options import COARSE_MIN_BLOCKS, DAMPING, OptionsError, SolverOptions
from .precompile import ensure_compiled
from .results import (ResultsError, ResultWriter, check_stored, ends_run, make_folder, open_result,
                      require_kept, state_fields)

#: energies of an increment at its current state (:meth:`Simulation._energies`)
Energies = namedtuple("Energies", "stored f_tot dw ratio diss element_diss joint_diss")
#: a row's overall balance (:meth:`Simulation._resultant`): the reference points' generalised
#: out-of-balance forces ``rpres`` (n_rp, 6), the out-of-balance resultant ``gap`` (3,) N, the
#: driving force ``drive`` (3,) N (NaN on the axes no control drives), their largest ratio and
#: its axis (0-2)
Balance = namedtuple("Balance", "rpres gap drive ratio axis")
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

#: most iterations of one compiled ``relax`` call (rounded down to a multiple of check_every):
#: Python regains control at least this often (progress bar, Ctrl-C: seconds, not the tens of
#: minutes one long increment of S6 or S7 runs)
CALL_ITERATIONS = 2000
#: models with fewer nodes relax on one thread: below it the second thread's wake-ups in the three
#: parallel regions of an iteration cost more than it computes (BENCHMARKS.md section 36); a run
#: is the same on any thread count, so this changes the run time only
SERIAL_NODES = 500
#: warn (once per run) when a joint node has slid off its master block's face by more than this
#: fraction of the face's shortest edge: contact points are paired in the reference configuration
OVERHANG_WARN = 0.05
#: the predictor does not continue the motion of a block that an accepted increment leaves out of
#: balance by more than this fraction of the forces on it (``kernels.relaxation.block_imbalance``)
LOOSE_BLOCK = 0.1
#: warn (once per run) beyond this imbalance of a block: with SolverOptions.block_tol a converged
#: increment leaves none above block_tol, so only a row accepted at the residual floor can
BLOCK_IMBALANCE_WARN = 0.5
#: load-step control: a half step that dissipates this fraction of its whole step's dissipation
#: or more holds a jump (smooth softening gives about one half) and is not cut again
JUMP = 0.75
#: most warnings per run (per process) that name where an increment moved the energy balance
BALANCE_JUMPS = 3


@contextmanager
def _threads_for(n_nodes):
    """Numba threads for relaxing a model of ``n_nodes`` nodes: one below ``SERIAL_NODES``, else
    as set; restored afterwards."""
    threads = numba.get_num_threads()
    if n_nodes < SERIAL_NODES:
        numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(threads)


def _reaction_rows(pairs, blocks, support):
    """Contact rows (slave side, master side) by which blocks ``support`` act on ``blocks``,
    from the (slave block, master block) ``pairs`` (nc, 2) of the contact set."""
    a, b = np.isin(pairs, blocks), np.isin(pairs, support)
    return np.nonzero(a[:, 1] & b[:, 0])[0], np.nonzero(a[:, 0] & b[:, 1])[0]


def _shortest_edge(q):
    """Shortest edge (m) of each quad with corners ``q`` (nc, 4, 3)."""
    return np.linalg.norm(q[:, [1, 2, 3, 0]] - q, axis=2).min(axis=1)


def _check_materials(model):
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


class SolverError(RuntimeError):
    """A run stopped: the message says where (increment, node/block) and which quantity."""


class Simulation:
    """A model with supports, reference points and options, ready to run stages.

    Parameters
    ----------
    model : Model
        the block assembly; contacts are detected here if the model has none yet.
    options : SolverOptions
    output : str or None
        HDF5 result path (None keeps results in memory only).
    config : dict
        the scene's input parameters, stored in the result file.

    Attributes
    ----------
    monitors : list of callables ``monitor(sim, info, done)``, called after every compiled call of
        the relaxation (at most ``CALL_ITERATIONS`` iterations): ``info`` the kernel's status
        array (``R.I_RESID``: residual ratio, ``R.I_STATUS``, ...), ``done`` the iterations of the
        attempt so far (row ``sim.increment + 1``). For diagnostics (``benchmarks/
        slow_increment.py``); an exception raised by a monitor stops the run, rows so far kept.
    """

    def __init__(self, model, options=None, output=None, config=None):
        from .contact_search import detect_contacts
        if not isinstance(model, Model):
            raise ModelError(f"Simulation: model must be a Model, got {model!r}")
        if not (output is None or isinstance(output, (str, os.PathLike))):
            raise ResultsError(f"Simulation: output must be a file path or None, got {output!r}")
        if not (config is None or isinstance(config, dict)):
            raise OptionsError(f"Simulation: config must be a dict of the input parameters, got "
                               f"{config!r}")
        self.model = model
        self.options = options or SolverOptions()
        self.output = output if output is None else os.fspath(output)
        self.config = dict(config or {})
        if not isinstance(self.options, SolverOptions):
            raise OptionsError(f"Simulation: options must be a SolverOptions, got "
                               f"{type(self.options).__name__}")
        if model.n_blocks == 0:
            raise ModelError("Simulation: the model has no blocks")
        _check_materials(model)
        if model.contacts is None:
            detect_contacts(model)
        self.rigid_points = []
        self.node_sets = {}
        self.contact_reactions = {}
        self._reaction_blocks = {}   # name -> (blocks, support), to re-select rows after sliding
        self._fixed = np.zeros((model.n_nodes, 3), dtype=bool)
        fixed_blocks = np.nonzero(model.block_fixed)[0]
        self._fixed[model.block_nodes(fixed_blocks)] = True
        self._built = False
        self.writer = None   # the results file's writer, opened by build
        self._closed = False   # close() was called: no more rows can be written
        self.coarse = None
        self._resuming = False
        self._checkpoint_stage = None
        self._checkpoint_inside = False   # the checkpoint resumed from is inside a cut increment
        self._checkpoint_time = time.perf_counter()
        self._kept_time = self._checkpoint_time   # when a checkpoint was last kept
        self._resume_increment = None
        # after each increment: (stage, its increments done, the controls' start values as
        # [[key, value]], stages of the run call, increments of the stage); stored in checkpoints
        self.stage_position = None
        self._warned = set()
        self._balance = None   # [error (J) after the last increment, balance jumps reported]
        self.history = {}
        self.increment = 0
        # iterations and relaxation seconds of attempts cut in two since the last committed row
        self._cut_work = [0, 0.0]
        self.monitors = []
        self._bar = None   # progress bar of a running ``run`` call
        self._bar_t = 0.0  # when its text was last changed within an increment (perf_counter, s)

    # ------------------------------------------------------------------ set-up API
    def node_set(self, name, nodes):
        """Register a named node set (int array of node ids)."""
        self._before_run(f"node set {name!r}")
        self._check_name(name)
        nodes = self._nodes(f"node set {name!r}", nodes)
        ns = L.NodeSet(name, nodes)
        self.node_sets[name] = ns
        return ns

    def contact_reaction(self, name, blocks, support):
        """Record the force (N, global axes) that the blocks ``support`` exert through their joints
        on the blocks ``blocks`` (history ``<name>.fx/fy/fz``; the sign of a node-set reaction:
        a wall standing on a foundation gives a positive ``fz``).

        Splits the reaction of one support (a foundation under several walls) by wall, exactly:
        the joint forces are summed per contact, whatever the meshes of the two sides.
        """
        self._before_run(f"contact reaction {name!r}")
        self._check_name(name)
        nb = self.model.n_blocks
        pair = (id_array(f"contact reaction {name!r}: blocks", blocks, nb, L.LoadingError),
                id_array(f"contact reaction {name!r}: support", support, nb, L.LoadingError))
        on_slave, on_master = _reaction_rows(self.model.contacts.blocks, *pair)
        if not (on_slave.size or on_master.size):
            raise L.LoadingError(f"contact reaction {name!r}: no joint between the two block sets")
        self.contact_reactions[name] = (on_slave, on_master)
        self._reaction_blocks[name] = pair

    def _before_run(self, what):
        """LoadingError: ``what`` changes the arrays that the first run built."""
        if self._built:
            raise L.LoadingError(f"{what} must be set before the first run (its arrays are built "
                                 f"then)")

    def _check_name(self, name):
        if not (isinstance(name, str) and name):   # history columns are "<name>.ux" ...
            raise L.LoadingError(f"names of node sets, rigid points and contact reactions must "
                                 f"be non-empty strings, got {name!r}")
        if name in self.contact_reactions:
            raise L.LoadingError(f"a contact reaction named {name!r} exists already")
        if name in self.node_sets or any(rp.name == name for rp in self.rigid_points):
            raise L.LoadingError(f"a node set or rigid point named {name!r} exists already; names "
                                 f"identify controls in the history and on restart")

    def fix(self, nodes, dofs="xyz"):
        """Clamp DOFs (any of 'x', 'y', 'z') of the given nodes (supports, symmetry planes)."""
        self._before_run("fix")
        nodes = self._nodes("fix", nodes)
        if not (isinstance(dofs, str) and dofs):
            raise L.LoadingError(f"fix: dofs={dofs!r} must be a string of 'x', 'y', 'z'")
        for d in dofs:
            self._fixed[nodes, L.dof_index(d, rotations=False)] = True

    def _nodes(self, what, nodes):
        """``nodes`` as sorted unique node ids; LoadingError naming ``what`` when the set is
        empty (e.g. a ``plane_nodes`` that found no node) or an id is not a node."""
        nodes = np.unique(id_array(what, nodes, self.model.n_nodes, L.LoadingError))
        if nodes.size == 0:
            raise L.LoadingError(f"{what}: no nodes given (an empty node set)")
        return nodes

    def rigid_point(self, name, blocks=None, nodes=None, position=None):
        """Tie the nodes of ``blocks`` (or ``nodes``) rigidly to a reference point with 6 DOFs.

        ``position`` defaults to the centroid of the nodes. Returns the :class:`RigidPoint`.
        """
        self._before_run(f"rigid point {name!r}")
        self._check_name(name)
        if (nodes is None) == (blocks is None):
            raise L.LoadingError(f"rigid point {name!r}: give blocks or nodes (one of them)")
        if nodes is None:
            nodes = self.model.block_nodes(blocks)
        nodes = self._nodes(f"rigid point {name!r}", nodes)
        for rp in self.rigid_points:
            if np.intersect1d(rp.nodes, nodes).size:
                raise L.LoadingError(f"rigid point {name!r} shares nodes with {rp.name!r}")
        pos = (self.model.nodes[nodes].mean(axis=0) if position is None
               else L.finite_vector(f"rigid point {name!r}: position", position, 3))
        rp = L.RigidPoint(name, nodes, pos, len(self.rigid_points))
        self.rigid_points.append(rp)
        return rp

    # ------------------------------------------------------------------ arrays
    def build(self):
        """Build the arrays (done by the first :meth:`run`; call it to inspect them first)."""
        m = self.model
        o = self.options
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
        for p, rp in enumerate(self.rigid_points):
            tied[rp.nodes] = p
        # elements of fixed blocks, and elements moving rigidly with one reference point, have no
        # strain: no force computation, and no stiffness in the fictitious masses
        et = tied[conn]
        rigid = (et[:, 0] >= 0) & np.all(et == et[:, :1], axis=1)
        active = np.nonzero(~m.block_fixed[m.element_block] & ~rigid)[0].astype(np.int64)
        s0 = np.stack([mt.initial_state() for mt in mats])[emat]
        s_old = np.ascontiguousarray(np.repeat(s0[:, None, :], 8, axis=1))
        ptr, rows = node_row_map(conn, n)
        self._s_virgin = s0
        # corotational elements (one stiffness and strain table per brick shape and material)
        corot = corot_tables(X, conn, dN, geo, wdet, emat, mparams, active)
        self.mesh = Mesh(conn, active, dN, geo, wdet, h, emat, mparams, s_old, s_old.copy(),
                         np.zeros(conn.shape[0], np.uint8), np.zeros(conn.shape[0], np.uint8),
                         *corot, np.zeros((conn.shape[0], 8, 3)), np.zeros(conn.shape[0]), ptr,
                         rows)
        self._mark_pristine()
        self.mass = lumped_mass(conn, wdet, rho, n)  # physical, kg
        a = active
        self._rowsum_solid = stiffness_rowsum(conn[a], dN, geo[a], wdet[a], E[a], nu[a], n)
        c = m.contacts
        laws = m.joint_laws
        self._kbound = np.array([lw.stiffness_bound() for lw in laws])   # per law, Pa/m
        if c.n:
            lparams = np.ascontiguousarray(np.vstack([lw.params_array() for lw in laws]))
            js0 = np.stack([lw.initial_state() for lw in laws])[c.law]
        else:
            from .kernels.joint_law import NJP, NJS
            lparams = np.zeros((1, NJP))
            js0 = np.zeros((0, NJS))
        cptr, crows = node_row_map(np.column_stack([c.slave, c.master]), n)
        nc = c.n
        from .contact_search import master_sides, overhang
        self._sides = master_sides(m, c)
        self._overhang0 = overhang(m.nodes, c.slave, self._sides)  # partial overlaps at the start
        self._side_size = _shortest_edge(m.nodes[self._sides])
        # copies: finite sliding re-pairs points in place, ``model.contacts`` stays as detected
        self.cont = Cont(c.slave, c.master.copy(), c.xi.copy(), c.area.copy(), c.law.copy(),
                         lparams, c.gap0.copy(), np.ascontiguousarray(js0), js0.copy(),
                         np.zeros((nc, 3)), np.zeros((nc, 3)), np.zeros((nc * 5, 3)), np.zeros(nc),
                         cptr, crows)
        rowsum = self._rowsum()
        free_nodes = ~self._fixed.all(axis=1) & (tied < 0)
        if np.any(rowsum[free_nodes] <= 0):
            bad = int(np.nonzero(free_nodes & (rowsum <= 0))[0][0])
            raise SolverError(f"node {bad} (block {m.node_block[bad]}) has no stiffness: it belongs to "
                              f"no active element and no contact")
        if self._fixed.all():
            raise ModelError("Simulation: every node is fixed (every block is fixed=True or "
                             "fixed by Simulation.fix): nothing can move")
        free = (~self._fixed).astype(np.float64)
        nr = len(self.rigid_points)
        rpX = np.zeros((nr, 3))
        rpptr = np.zeros(nr + 1, dtype=np.int64)
        for p, rp in enumerate(self.rigid_points):
            if self._fixed[rp.nodes].any():
                raise L.LoadingError(f"rigid point {rp.name!r} ties nodes that are also fixed")
            free[rp.nodes] = 0.0
            rpX[p] = rp.position
            rpptr[p + 1] = rpptr[p] + rp.nodes.size
        minv, rpminv, rpradius = self._masses(rowsum)
        rpnodes = (np.concatenate([rp.nodes for rp in self.rigid_points]) if nr
                   else np.zeros(0, np.int64))
        z = np.zeros((n, 3))
        self.dyn = Dyn(X, z.copy(), z.copy(), minv, free, tied, z.copy(), z.copy(), z.copy(),
                       z.copy(), rpX, np.zeros((nr, 6)), np.zeros((nr, 6)), rpminv,
                       np.ones((nr, 6)), np.zeros((nr, 6)), np.zeros((nr, 6)), rpptr, rpnodes,
                       rpradius, z.copy(), np.ascontiguousarray(m.block_node_start, np.int64),
                       np.zeros(m.n_blocks), z.copy(), np.zeros((nr, 6)), np.zeros((4, 3)))
        from .sliding import Sliding
        self.sliding = Sliding(self) if (o.redetect and nc) else None
        movable = int((~m.block_fixed).sum())
        self.use_coarse = (o.coarse is True
                           or (o.coarse == "auto" and movable >= COARSE_MIN_BLOCKS))
        self.size = float(np.max(np.ptp(X, axis=0)))
        self.ref_floor = 1e-9 * float(rowsum.max()) * self.size
        self.lam = np.zeros(1)
        self.rp_force = np.zeros((nr, 6))  # Force-control values on reference-point DOFs
        self.values = {}       # control key -> current value
        self.factors = {}      # pattern name -> current factor (load-controlled)
        self.patterns = {}     # pattern name -> (pattern, P (n,3), rpP (nr,6))
        self.presc = {}        # (node set name, dof) -> (nodes, dof)
        self.energy = dict(W_ext=0.0, E_damped=0.0)
        self.f_prev = np.zeros((n, 3))
        self.du_prev = None
        self.dctl_prev = 0.0
        self.writer = None
        self._u_committed = np.zeros((n, 3))
        if self.output is not None:
            make_folder(os.path.dirname(os.path.abspath(self.output)))
            cfg = dict(self.config, solver=asdict(self.options))
            self.writer = ResultWriter(self.output, m, cfg, mode="a" if self._resuming else "w")
        self._built = True
        if self._resuming:
            self._load_checkpoint()

    def _mark_pristine(self):
        """After the blocks' committed state changed (start, commit, checkpoint): the elements
        still in their virgin state, and trial states equal to the committed ones."""
        m = self.mesh
        m.pristine[:] = pristine_elements(m.s_old, self._s_virgin, m.h, m.mparams[m.emat, MP_HMAX])
        m.dirty[:] = 0

    def _rowsum(self):
        """Gershgorin row sums (n_nodes,) N/m of the elements and the current contact set."""
        c = self.cont
        if c.slave.size == 0:
            return self._rowsum_solid
        return self._rowsum_solid + contact_rowsum(c.slave, c.master, c.xi, c.area,
                                                   self._kbound[c.law], self.model.n_nodes,
                                                   self.model.nodes, c.gap0)

    def _masses(self, rowsum):
        """Inverse fictitious masses from the row sums ``rowsum`` (n_nodes,) N/m: of the nodes
        (n_nodes,) 1/kg, of the reference points (n_rp, 6) and their radii of gyration (n_rp,) m
        (the tied nodes' masses and their second moment about the point)."""
        fict = np.where(rowsum > 0, self.options.safety * rowsum / 4.0, 1.0)
        nr = len(self.rigid_points)
        rpminv = np.ones((nr, 6))
        rpradius = np.ones(nr)
        for p, rp in enumerate(self.rigid_points):
            w = fict[rp.nodes] * (rowsum[rp.nodes] > 0)
            mt = w.sum()
            if mt <= 0.0:
                raise L.LoadingError(f"rigid point {rp.name!r}: its nodes touch no deformable element "
                                     f"and no contact, so nothing resists its motion")
            jr = (w * ((self.model.nodes[rp.nodes] - rp.position) ** 2).sum(axis=1)).sum()
            rpminv[p, :3] = 1.0 / mt
            rpminv[p, 3:] = 1.0 / max(jr, 1e-300)
            rpradius[p] = np.sqrt(max(jr / mt, 1e-300))
        return 1.0 / fict, rpminv, rpradius

    def _contacts_changed(self):
        """After :mod:`dr_masonry.sliding` re-paired points: the gather's node map, the masses,
        the faces of the overhang check, the rows of the contact reactions and the coarse
        operator follow the new set."""
        from .contact_search import master_sides
        c, d, m = self.cont, self.dyn, self.model
        ptr, rows = node_row_map(np.column_stack([c.slave, c.master]), m.n_nodes)
        c.ptr[:], c.rows[:] = ptr, rows
        minv, rpminv, rpradius = self._masses(self._rowsum())
        d.minv[:], d.rpminv[:], d.rpradius[:] = minv, rpminv, rpradius
        sides = master_sides(m, self.sliding.contact_set())
        new = np.any(sides != self._sides, axis=1)
        self._sides = sides
        self._overhang0[new] = 0.0
        self._side_size[new] = _shortest_edge(m.nodes[sides[new]])
        for name, pair in self._reaction_blocks.items():
            self.contact_reactions[name] = _reaction_rows(self.sliding.blocks, *pair)
        self.coarse = None

    # ------------------------------------------------------------------ patterns
    def pattern_forces(self, pat):
        """(P (n_nodes, 3) N, rpP (n_rp, 6)) of a load pattern per unit factor, cached by name."""
        known = self.patterns.get(pat.name)
        if known is not None:
            if known[0] is pat or isinstance(known[0], L.StoredPattern):
                if known[0] is not pat:  # a pattern restored from a checkpoint, named again
                    self.patterns[pat.name] = (pat,) + known[1:]
                return known[1:]
            raise L.LoadingError(f"two different load patterns are named {pat.name!r}; give each "
                                 f"pattern a distinct name")
        m = self.model
        n = m.n_nodes
        P = np.zeros((n, 3))
        rpP = np.zeros((len(self.rigid_points), 6))
        if isinstance(pat, (L.Gravity, L.BodyForce)):
            acc = np.array([0.0, 0.0, -pat.g]) if isinstance(pat, L.Gravity) else np.asarray(pat.accel, float)
            blocks = getattr(pat, "blocks", None)
            blocks = np.nonzero(~m.block_fixed)[0] if blocks is None else np.asarray(blocks)
            nodes = m.block_nodes(blocks)
            P[nodes] = self.mass[nodes, None] * acc[None, :]
        elif isinstance(pat, L.Pressure):
            q = np.asarray(pat.quads, dtype=np.int64)
            if q.size and q.max() >= n:
                raise L.LoadingError(f"Pressure {pat.name!r}: node id {q.max()} in quads, the "
                                     f"model has {n} nodes")
            x = m.nodes[q]
            av = quad_area_vector(x)   # outward (corners counter-clockwise seen from outside)
            flat = np.flatnonzero(np.linalg.norm(av, axis=1) == 0.0)
            if flat.size:
                raise L.LoadingError(f"Pressure {pat.name!r}: quad {flat[0]} {q[flat[0]].tolist()} "
                                     "has zero area")
            for a in range(4):
                np.add.at(P, q[:, a], -0.25 * av)
        elif isinstance(pat, L.PointLoad):
            self._own(pat.target, f"PointLoad {pat.name!r}")
            k = L.dof_index(pat.dof, rotations=isinstance(pat.target, L.RigidPoint))
            if isinstance(pat.target, L.RigidPoint):
                rpP[pat.target.index, k] = pat.value
            else:
                P[pat.target.nodes, k] = pat.value / pat.target.nodes.size
        elif isinstance(pat, L.Combined):
            for part, w in pat.parts:
                p1, r1 = self.pattern_forces(part)
                P += w * p1
                rpP += w * r1
        else:
            raise L.LoadingError(f"unknown load pattern {pat!r}")
        self.patterns[pat.name] = (pat, P, rpP)
        return P, rpP

    # ------------------------------------------------------------------ controls
    def _key(self, ctl):
        if isinstance(ctl, (L.Displacement, L.Force, L.Indirect)):
            t = ctl.target   # a RigidPoint or NodeSet: checked when the control was made
            return (type(ctl).__name__ == "Force", t.name,
                    L.dof_index(ctl.dof, isinstance(t, L.RigidPoint)))
        return ("load", ctl.pattern.name)

    def _check_controls(self, stage):
        """LoadingError when two controls of ``stage`` act on one DOF (a Force and a
        Displacement too) or on one pattern's factor (a Load and an Indirect): the last would
        silently win."""
        seen = {}
        for ctl in stage.controls:
            if hasattr(ctl, "target"):
                self._own(ctl.target, f"control {ctl.label}")
            moves = np.any(ctl.path) if ctl.path is not None else bool(ctl.to)
            if isinstance(ctl, L.Displacement) and isinstance(ctl.target, L.NodeSet) and moves:
                k = L.dof_index(ctl.dof, rotations=False)
                held = ctl.target.nodes[self._fixed[ctl.target.nodes, k]]
                if held.size:   # (a zero displacement there records the support's reaction)
                    raise L.LoadingError(f"control {ctl.label}: node {held[0]} (block "
                                         f"{self.model.node_block[held[0]]}) is fixed in "
                                         f"{ctl.dof} (a fixed block or Simulation.fix): a "
                                         f"non-zero prescribed displacement would move a support")
            if isinstance(ctl, L.Load):
                P, rpP = self.pattern_forces(ctl.pattern)
                if not (np.any(P[~self._fixed]) or np.any(rpP)):
                    raise L.LoadingError(f"control {ctl.label}: pattern {ctl.pattern.name!r} "
                                         f"puts no force on any free DOF (its blocks, faces or "
                                         f"nodes are fixed, or it is empty)")
            acts = [self._key(ctl)[1:]]    # (target, dof) or (pattern,)
            if isinstance(ctl, L.Indirect):
                acts.append((ctl.pattern.name,))
            for what in acts:
                if what in seen:
                    on = (f"DOF {what[1]} of {what[0]!r}" if len(what) == 2
                          else f"the factor of pattern {what[0]!r}")
                    raise L.LoadingError(f"stage {stage.name!r}: controls {seen[what].label} and "
                                         f"{ctl.label} both act on {on}")
                seen[what] = ctl

    def _own(self, target, what):
        """LoadingError naming ``what`` unless ``target`` is one of this simulation's rigid
        points or node sets (one of another simulation would act on the point of that index)."""
        if isinstance(target, L.RigidPoint):
            ok = 0 <= target.index < len(self.rigid_points) and \
                self.rigid_points[target.index] is target
        else:
            ok = self.node_sets.get(target.name) is target
        if not ok:
            kind = "rigid point" if isinstance(target, L.RigidPoint) else "node set"
            raise L.LoadingError(f"{what}: {kind} {target.name!r} is not one of this "
                                 f"simulation's (made by another Simulation's rigid_point or "
                                 f"node_set, or by hand)")

    def _apply(self, ctl, value):
        """Impose one control value on the arrays (before relaxing an increment)."""
        d = self.dyn
        if isinstance(ctl, (L.Displacement, L.Indirect)):
            k = L.dof_index(ctl.dof, isinstance(ctl.target, L.RigidPoint))
            if isinstance(ctl.target, L.RigidPoint):
                d.rpfree[ctl.target.index, k] = 0.0
                d.rpU[ctl.target.index, k] = value
                d.rpV[ctl.target.index, k] = 0.0
            else:
                nodes = ctl.target.nodes
                if (d.tied[nodes] >= 0).any():
                    raise L.LoadingError(f"control {ctl.label}: nodes are tied to a rigid point")
                d.free[nodes, k] = 0.0
                d.U[nodes, k] = value
                d.V[nodes, k] = 0.0
        elif isinstance(ctl, L.Force):
            k = L.dof_index(ctl.dof)
            if not isinstance(ctl.target, L.RigidPoint):
                raise L.LoadingError(f"control {ctl.label}: Force acts on a RigidPoint; use Load with "
                                     f"a PointLoad pattern for node sets")
            d.rpfree[ctl.target.index, k] = 1.0
            self.rp_force[ctl.target.index, k] = value
        elif isinstance(ctl, L.Load):
            self.pattern_forces(ctl.pattern)
            self.factors[ctl.pattern.name] = value

    def _assemble_loads(self, indirect):
        d = self.dyn
        d.fext[:] = 0.0
        d.P[:] = 0.0
        d.rpP[:] = 0.0
        rpf_loads = np.zeros_like(d.rpf)
        for name, fac in self.factors.items():
            if indirect is not None and name == indirect.pattern.name:
                continue
            P, rpP = self.patterns[name][1:]
            d.fext[:] += fac * P
            rpf_loads += fac * rpP
        d.rpf[:] = self.rp_force * d.rpfree + rpf_loads
        if indirect is not None:
            P, rpP = self.pattern_forces(indirect.pattern)
            d.P[:] = P
            d.rpP[:] = rpP

    # ------------------------------------------------------------------ running
    def run(self, stages):
        """Run the stages; returns the history (dict of arrays). Raises SolverError on failure,
        KeyboardInterrupt on Ctrl-C and :class:`~dr_masonry.interrupts.Terminated` (one) on SIGTERM,
        with the results file complete up to the last row written.

        After :meth:`resume`, ``stages`` must be the original run's stages: those finished before
        the checkpoint are skipped and the stage in progress continues where it stopped.
        """
        if not (isinstance(stages, (list, tuple)) and stages
                and all(isinstance(s, L.Stage) for s in stages)):
            raise L.LoadingError(f"Simulation.run: stages must be a non-empty list of Stage, got "
                                 f"{stages!r}")
        # fields changed since the options and stages were made (sim.options.max_iter = 2.5)
        self.options.__post_init__()
        for mon in self.monitors:
            if not callable(mon):
                raise OptionsError(f"Simulation.monitors: {mon!r} is not a function "
                                   f"monitor(sim, info, done)")
        for stage in stages:
            L.check_stage(stage)
        if self._closed:
            raise ResultsError(f"Simulation.run: the results file {self.output} was closed "
                               f"(Simulation.close); continue a stored run with a new Simulation "
                               f"and resume")
        if not self._built:
            self.build()
        for stage in stages:  # register every prescribed node set so history columns stay fixed
            self._check_controls(stage)
            for ctl in stage.controls:
                if isinstance(ctl, (L.Displacement, L.Indirect)) and isinstance(ctl.target, L.NodeSet):
                    k = L.dof_index(ctl.dof, rotations=False)
                    self.presc[(ctl.target.name, k)] = (ctl.target.nodes, k)
        k0, i0, starts = self._resume_position(stages) if self._resuming else (0, 0, None)
        self._resuming = False
        from tqdm.auto import tqdm
        total = sum(s.increments for s in stages[k0:]) - i0
        self._bar = tqdm(total=total, disable=not self.options.progress, unit="incr")
        try:
            with terminate_as_interrupt():   # SIGTERM stops the run as Ctrl-C does
                ensure_compiled(self.mesh, self.cont, self.dyn)
                for k, stage in enumerate(stages[k0:], start=k0):
                    self._run_stage(stage, (k, len(stages)),
                                    *((i0, starts) if k == k0 else (0, None)))
        finally:
            if self._bar is not None:
                self._bar.close()
                self._bar = None
            if self.writer is not None:
                self.writer.flush()
        return {k: np.asarray(v) for k, v in self.history.items()}

    def _resume_position(self, stages):
        """(stage index, increments of it done, its controls' start values) of the checkpoint.

        Checkpoints store their position; for older files it is found from the number of
        increments, checked against the prescribed paths (a run whose increments were cut cannot
        be located that way and is refused); a ramp's start follows from its value there.
        """
        pos = self._checkpoint_stage
        if pos is not None:
            if ends_run(pos):   # a finished run: the stages given come after it
                return 0, 0, None
            k, i, starts = pos[:3]
            if k >= len(stages) or i > stages[k].increments:
                raise L.LoadingError(f"resume {self.output}: the checkpoint is at increment {i} of "
                                     f"stage {k}, the stages given have fewer (not the same run)")
            return k, i, {tuple(key): v for key, v in starts}
        done = self.increment
        for k, stage in enumerate(stages):
            if done <= stage.increments:
                break
            done -= stage.increments
        else:
            raise L.LoadingError(f"resume {self.output}: the checkpoint is after {self.increment} "
                                 f"increments, the stages given have fewer (not the same run)")
        starts = {}
        n = stage.increments
        for ctl in stage.controls:
            key = self._key(ctl)
            now = self.values.get(key, 0.0)
            # a ramp's value after `done` of n increments fixes its start value
            starts[key] = (n * now - done * ctl.to) / (n - done) if (
                ctl.path is None and ctl.to is not None and 0 < done < n) else now
            if ctl.path is not None and done and not np.isclose(ctl.path[done - 1], now, rtol=1e-9,
                                                                atol=1e-15):
                raise L.LoadingError(f"resume {self.output}: control {ctl.label} is at {now:.6g}, "
                                     f"not at the value of increment {done} of stage "
                                     f"{stage.name!r} (cut increments: the file has no stage "
                                     f"position)")
        return k, done, starts

    def close(self):
        """Close the result file (a run after this is refused: its rows would not be written)."""
        if self.writer is not None:
            self.writer.close()
            self.writer = None
            self._closed = True

    def _run_stage(self, stage, where, first=0, starts=None):
        """Run the increments ``first`` ... of ``stage``, number ``where[0]`` of the ``where[1]``
        stages of this ``run``; ``starts``: the controls' values at the stage's start when it is
        continued from a checkpoint (default: their current values)."""
        n = stage.increments
        targets = {}
        indirect = None
        resumed = starts is not None
        starts = dict(starts) if resumed else {}
        for ctl in stage.controls:
            key = self._key(ctl)
            start = starts.setdefault(key, self.values.get(key, 0.0))
            targets[key] = (ctl, ctl.values(start, n))
            if isinstance(ctl, L.Indirect):
                indirect = ctl
                if first == 0 and self.factors.get(ctl.pattern.name) is not None:
                    self.lam[0] = self.factors[ctl.pattern.name]
                self.pattern_forces(ctl.pattern)
        start_values = [[list(key), float(starts[key])] for key in targets]
        self.stage_name = stage.name
        for i in range(first, n):
            # a checkpoint inside increment i (after a committed part of a cut increment)
            # continues it from there
            self.stage_position = (where[0], i, start_values, where[1], n)
            goal = {key: vals[i] for key, (ctl, vals) in targets.items()}
            # ... unless that part was its last: the controls at its goal, the increment done
            if not (resumed and i == first and self._checkpoint_inside
                    and all(self.values.get(k) == v for k, v in goal.items())):
                self._increment(stage, targets, goal, indirect, depth=0)
            self.stage_position = (where[0], i + 1, start_values, where[1], n)
            if (i + 1) % stage.frames == 0 or i == n - 1 or i + 1 in stage.frame_at:
                self._write_frame()
            elif self._checkpoint_due():
                self._write_checkpoint()
            if self._bar is not None:
                self._bar.update(1)
        if indirect is not None:
            # the pattern keeps its last factor; the control DOF is released
            self.factors[indirect.pattern.name] = float(self.lam[0])
            t = indirect.target
            k = L.dof_index(indirect.dof, isinstance(t, L.RigidPoint))
            if isinstance(t, L.RigidPoint):
                self.dyn.rpfree[t.index, k] = 1.0
            else:
                self.dyn.free[t.nodes, k] = 1.0

    def _snapshot(self):
        d = self.dyn
        return (d.U.copy(), d.V.copy(), d.rpU.copy(), d.rpV.copy(), d.free.copy(), d.rpfree.copy(),
                self.rp_force.copy(), self.lam.copy(), dict(self.values), dict(self.factors))

    def _restore(self, snap):
        d = self.dyn
        d.U[:], d.V[:], d.rpU[:], d.rpV[:], d.free[:], d.rpfree[:], self.rp_force[:] = snap[:7]
        self.lam[:] = snap[7]
        self.values = dict(snap[8])
        self.factors = dict(snap[9])

    def _increment(self, stage, targets, goal, indirect, depth, parent_diss=None):
        """Relax one increment to ``goal`` and commit it, or cut it in two and recurse;
        ``parent_diss``: the damage dissipation (J) of the attempt this half replaces when that
        one was cut for dissipating too much."""
        o = self.options
        d = self.dyn
        snap = self._snapshot()
        start = {key: self.values.get(key, 0.0) for key in goal}
        for key, val in goal.items():
            self._apply(targets[key][0], val)
            self.values[key] = val
        self._assemble_loads(indirect)
        ctrl = np.zeros(3, dtype=np.int64)
        pc = 1.0
        if indirect is not None:
            ctrl[:], pc = self._control_dof(indirect)
        # predictor: continue the previous increment's motion when the control keeps its direction
        dctl = sum(goal[k] - start[k] for k in goal)
        u_before = snap[0]
        if o.predictor and self.du_prev is not None and self.dctl_prev != 0.0 and dctl * self.dctl_prev > 0:
            ratio = min(dctl / self.dctl_prev, 2.0)
            d.U[:] += ratio * self.du_prev * d.free
        moved = [targets[k][0] for k in goal if goal[k] != start[k]]
        self._drive(moved, indirect)
        info = np.zeros(R.N_INFO)
        info[R.I_BLOCK_TOL] = o.block_tol
        info[R.I_GAP_TOL] = o.gap_tol
        max_iter = stage.max_iter or o.max_iter
        tol = stage.tol or o.tol
        stall = o.stall_iter if depth < o.max_cuts else 0
        t0 = time.perf_counter()
        with _threads_for(self.dyn.U.shape[0]):
            self._relax(ctrl, pc, tol, max_iter, stall, info)
        elapsed = time.perf_counter() - t0
        status = int(info[R.I_STATUS])
        if status in (R.ST_NONFINITE, R.ST_RUNAWAY):
            inverted = self._inverted() if status == R.ST_NONFINITE else ""
            self._restore(snap)
            what = "non-finite force or displacement" if status == R.ST_NONFINITE else \
                f"run-away displacement {info[R.I_QTY]:.3e} m (limit {0.5 * self.size:.3e} m)"
            self._fail(f"increment {self.increment + 1} of stage {stage.name!r}: {what} at "
                       f"{self._place(info)} after {int(info[R.I_ITERS])} iterations{inverted}; "
                       f"the time step is unstable (safety factor {o.safety}) or the "
                       f"structure lost equilibrium (collapse under load control)")
        if status == R.ST_UNSTABLE:
            self._restore(snap)
            node = int(info[R.I_WORST])
            self._fail(f"increment {self.increment + 1} of stage {stage.name!r}: unstable time step "
                       f"after {int(info[R.I_ITERS])} iterations: the motion's stiffness-to-mass "
                       f"ratio (omega dt)^2 = {info[R.I_QTY]:.3g} stayed above the central-"
                       f"difference limit 4 (fastest node {node}, block "
                       f"{self.model.node_block[node]}); the fictitious masses are too small for "
                       f"the stiffness: raise SolverOptions.safety (now {o.safety})")
        short = status in (R.ST_MAXITER, R.ST_STALLED, R.ST_SLOW)
        ratio = info[R.I_RESID]   # with block_tol, the blocks' ratio counts as in the kernel
        if o.block_tol > 0:
            ratio = max(ratio, tol * info[R.I_BLOCK] / o.block_tol)
        floor = short and 0.0 < ratio <= o.floor_tol
        energies = self._energies() if status == R.ST_CONVERGED or floor else None
        balance = self._resultant() if energies is not None else None
        # a row at the floor whose out-of-balance resultant is a large part of the driving force
        unbalanced = floor and o.gap_tol > 0 and balance.ratio > o.gap_tol
        # a half that dissipates as much as the whole step holds a jump (a crack that runs
        # unstably): smaller steps would only repeat it, so it is accepted
        too_much = (energies is not None and not unbalanced and o.max_dissipation > 0
                    and depth < o.max_cuts and energies.ratio > o.max_dissipation
                    and not (parent_diss is not None and energies.diss >= JUMP * parent_diss))
        if (short and not floor) or unbalanced or too_much:
            self._restore(snap)
            self._cut_work[0] += int(info[R.I_ITERS])
            self._cut_work[1] += elapsed
            if depth >= o.max_cuts:
                if unbalanced:
                    k = balance.axis
                    hint = (f"; at the floor, its out-of-balance resultant {balance.gap[k]:.4g} N "
                            f"along {'xyz'[k]} is {balance.ratio:.2%} of the driving force (gap_tol "
                            f"{o.gap_tol}): continue with a larger gap_tol, max_iter or max_cuts")
                elif info[R.I_RESID] >= 1.0:
                    hint = ("; the out-of-balance force exceeds the loads: an unstable step (safety "
                            f"factor {o.safety}) or a structure that lost equilibrium")
                else:
                    hint = ("; to go on, continue from the last checkpoint (scenes: resume=true) "
                            "with a looser tol, a larger max_iter or more max_cuts")
                self._fail(f"increment {self.increment + 1} of stage {stage.name!r} did not converge "
                           f"in {max_iter} iterations after {depth} cuts (residual ratio "
                           f"{info[R.I_RESID]:.2e} > tol {tol:.1e}){hint}")
            mid = {k: 0.5 * (start[k] + goal[k]) for k in goal}
            diss = energies.diss if too_much else None
            self._increment(stage, targets, mid, indirect, depth + 1, diss)
            self._increment(stage, targets, goal, indirect, depth + 1, diss)
            return
        if floor:
            warnings.warn(f"increment {self.increment + 1} of stage {stage.name!r} accepted at "
                          f"residual ratio {info[R.I_RESID]:.2e} (tol {tol:.1e}, floor_tol "
                          f"{o.floor_tol:.1e}) after {int(info[R.I_ITERS])} iterations, "
                          f"out-of-balance resultant {balance.ratio:.2%} of the driving force",
                          RuntimeWarning, stacklevel=2)
        self.du_prev = self._predictor_motion(u_before)
        self.dctl_prev = dctl
        self._commit(info, elapsed, energies, balance)
        if depth > 0 and self._checkpoint_due():
            self._write_checkpoint(inside=True)   # a part of a cut increment (hours, some)

    def _relax(self, ctrl, pc, tol, max_iter, stall, info):
        """Relax the increment (``R.relax``); with ``options.coarse``, in spans of
        ``coarse_every`` iterations (doubled after a rejected correction and after the tenth of
        an increment, up to 64 x; none after two rejections in a row), each preceded by a coarse
        correction on the blocks' affine motions (:mod:`dr_masonry.coarse`); ``stall``: the
        kernel's ``stall_iter``. ``info`` holds the totals. A span runs as compiled calls of at
        most ``CALL_ITERATIONS`` (the same iterates as one call: ``R.I_SEG``), between which the
        progress bar is updated and Ctrl-C is honoured."""
        o, d = self.options, self.dyn
        args = (DAMPING[o.damping], o.alpha, o.ring, tol, self.ref_floor)
        rejected = 0 if self.use_coarse else 2
        if self.use_coarse:
            if self.coarse is None:
                from .coarse import BlockCoarse
                self.coarse = BlockCoarse(self)
            rpres = np.zeros((d.rpX.shape[0], 6))
            self.coarse.refresh()
        call = max(o.check_every, CALL_ITERATIONS - CALL_ITERATIONS % o.check_every)
        done, damped, every, tries, span_end = 0, 0.0, o.coarse_every, 0, 0
        while True:
            if done >= span_end:   # a new span, after a coarse correction while they help
                if rejected < 2:
                    R.place_rigid_nodes(d)
                    R.internal_forces(self.mesh, self.cont, d)
                    R.residual(d, self.lam[0], rpres)
                    ok = self.coarse.correct(self.lam, rpres, ctrl)
                    rejected = 0 if ok else rejected + 1
                    tries += 1
                # a rejected correction, and every one after the first ten of an increment (in
                # softening, accepted steps may keep restarting the relaxation without finishing
                # it), let the relaxation run twice as long before the next try; after two
                # rejections in a row (or without the coarse correction) plain relaxation
                # finishes the increment
                if rejected >= 2:
                    every = max_iter
                elif ok and tries <= 10:
                    every = o.coarse_every
                else:
                    every = min(2 * every, 64 * o.coarse_every)
                span_end = min(done + every, max_iter)
                info[R.I_SEG] = 0
            info[R.I_LEFT] = max_iter - done
            R.relax(self.mesh, self.cont, d, self.lam, ctrl, pc, *args,
                    min(span_end - done, call), o.check_every, stall, 0.5 * self.size, info)
            k = int(info[R.I_ITERS])
            done += k
            info[R.I_SEG] += k
            damped += info[R.I_DAMPED]
            for monitor in self.monitors:
                monitor(self, info, done)
            if int(info[R.I_STATUS]) != R.ST_MAXITER or done >= max_iter:
                break
            if self._bar is not None and time.perf_counter() - self._bar_t > 1.0:
                self._bar_t = time.perf_counter()
                self._bar.set_postfix_str(f"{self.stage_name} row {self.increment + 1} res="
                                          f"{info[R.I_RESID]:.1e} it={done}...")
        info[R.I_ITERS] = done
        info[R.I_DAMPED] = damped

    def _control_dof(self, indirect):
        """([kind, index, dof], pattern force on that DOF) of an indirect control."""
        t = indirect.target
        k = L.dof_index(indirect.dof, isinstance(t, L.RigidPoint))
        P, rpP = self.pattern_forces(indirect.pattern)
        if isinstance(t, L.RigidPoint):
            pc = rpP[t.index, k]
            if k < 3:
                pc += P[t.nodes, k].sum()
            else:
                arm = self.model.nodes[t.nodes] - t.position
                pc += np.cross(arm, P[t.nodes])[:, k - 3].sum()
            ctrl = (2, t.index, k)
        else:
            if t.nodes.size != 1:
                raise L.LoadingError(f"control {indirect.label}: indirect control needs a single "
                                     f"node or a rigid point, got {t.nodes.size} nodes")
            pc = P[t.nodes[0], k]
            ctrl = (1, t.nodes[0], k)
        if abs(pc) < 1e-12 * max(np.max(np.abs(P), initial=0.0), np.max(np.abs(rpP), initial=0.0), 1e-300):
            raise L.LoadingError(f"control {indirect.label}: the pattern {indirect.pattern.name!r} "
                                 f"puts no force on the controlled DOF {indirect.dof}; control a DOF "
                                 f"that the pattern loads (e.g. a rigid point of the loaded blocks)")
        return ctrl, pc

    def _place(self, info):
        """The place a relaxation guard named (``info[R.I_WORST]``, ``info[R.I_KIND]``), in
        words."""
        i, kind = int(info[R.I_WORST]), int(info[R.I_KIND])
        if kind == R.WHERE_RP:
            return f"reference point {self.rigid_points[i].name!r}"
        if kind == R.WHERE_LOAD:
            return "the load factor of the indirectly controlled pattern"
        return f"node {i} (block {self.model.node_block[i]})"

    def _inverted(self):
        """`` (element e of block b inverted: ...)`` if an active hexahedron has turned inside
        out in the current displacements (a corotational element then has NaN forces), else
        ``""``."""
        mesh = self.mesh
        bad = inverted_element(self.dyn.X + self.dyn.U, mesh.conn, mesh.active)
        if bad is None:
            return ""
        e, g, det = bad
        return (f" (element {e} of block {self.model.element_block[e]} inverted: Jacobian "
                f"determinant {det:.3e} m^3 at Gauss point {g})")

    def _fail(self, msg):
        if self.writer is not None:
            self.writer.flush()
        raise SolverError(msg)

    def _energies(self):
        """Forces and state at the current displacements and the energies of the increment so
        far, as :data:`Energies`: stored energy J, external forces incl. reactions (n_nodes, 3)
        N, work increment per DOF (n_nodes, 3) J, the increment's damage dissipation over the
        external work done, that dissipation J, and its whole dissipation by element
        (n_elements,) J and by joint point (nc,) J."""
        d, mesh, cont = self.dyn, self.mesh, self.cont
        eint = R.internal_forces(mesh, cont, d)
        # external forces incl. reactions: applied loads on free DOFs, internal forces elsewhere
        f_tot = np.where(d.free > 0, d.fext + self.lam[0] * d.P, d.fint)
        dw = 0.5 * (f_tot + self.f_prev) * (d.U - self._u_committed)
        element_diss = ((mesh.s_new[:, :, MS_DISS] - mesh.s_old[:, :, MS_DISS])
                        * mesh.wdet).sum(axis=1)
        joint_diss = (cont.s_new[:, JS_DISS] - cont.s_old[:, JS_DISS]) * cont.area
        ddiss = float(element_diss.sum())
        if cont.slave.size:
            dj = (cont.s_new[:, JS_DISS] - cont.s_new[:, JS_DISSF]
                  - cont.s_old[:, JS_DISS] + cont.s_old[:, JS_DISSF])
            ddiss += float(dj @ cont.area)
        w_ext = self.energy["W_ext"] + float(dw.sum())
        return Energies(eint, f_tot, dw, ddiss / w_ext if w_ext > 0 else 0.0, ddiss, element_diss,
                        joint_diss)

    def _drive(self, moved, indirect):
        """Mark what drives the increment for ``R.resultant`` (``dyn.gnode``, ``grp``, ``gspec``
        rows 0-1): the translations of the controls it moves (``moved``: ``Displacement`` and
        ``Indirect`` controls; one that holds its value is a support), the prescribed DOFs whose
        reactions drive it (``indirect``, the stage's indirect control, drives by its pattern),
        and each driven axis's largest |driving force| of the run so far (history ``drive.f*``)."""
        d = self.dyn
        d.gnode[:] = 0.0
        d.grp[:] = 0.0
        d.gspec[:] = 0.0
        for ctl in moved:
            if not isinstance(ctl, (L.Displacement, L.Indirect)):
                continue
            rigid = isinstance(ctl.target, L.RigidPoint)
            k = L.dof_index(ctl.dof, rigid)
            if k >= 3:
                continue
            d.gspec[0, k] = 1.0
            past = np.asarray(self.history.get(f"drive.f{'xyz'[k]}", []))
            d.gspec[1, k] = np.nanmax(np.abs(past), initial=0.0)
            if ctl is indirect:
                continue
            if rigid:
                d.grp[ctl.target.index, k] = 1.0
            else:
                d.gnode[ctl.target.nodes, k] = 1.0

    def _resultant(self):
        """The overall balance of the current state as :data:`Balance` (after
        :meth:`_energies`, which leaves the internal forces of these displacements): the
        out-of-balance resultant, the driving force (NaN on undriven axes) and their ratio of
        ``R.resultant``, with the driving set by :meth:`_drive`. The norm of the residual ratio
        weighs every DOF against loads that gravity may dominate, so a row at the residual floor
        can keep a resultant of several per cent of a lateral load (docs/validation.md, "Rows
        accepted at the residual floor")."""
        d = self.dyn
        rpres = np.zeros((d.rpX.shape[0], 6))
        R.residual(d, self.lam[0], rpres)
        ratio, axis = R.resultant(d, self.lam[0], rpres)
        drive = np.where(d.gspec[0] > 0.0, d.gspec[3], np.nan)
        return Balance(rpres, d.gspec[2].copy(), drive, ratio, axis)

    def _commit(self, info, elapsed, energies, balance):
        """Accept a converged increment (``energies`` from :meth:`_energies` at its end, then
        ``balance`` from :meth:`_resultant`): reactions, history row, state commit."""
        d = self.dyn
        mesh, cont = self.mesh, self.cont
        eint, f_tot, dw, ratio = energies[:4]
        rpres = balance.rpres
        lam = float(self.lam[0])
        self.energy["W_ext"] += float(dw.sum())
        # gross work: the scale of the balance error when works of opposite sign cancel (rocking)
        self.energy["W_gross"] = self.energy.get("W_gross", 0.0) + float(np.abs(dw).sum())
        self.f_prev = f_tot
        self._u_committed = d.U.copy()
        mesh.s_old[:] = mesh.s_new
        cont.s_old[:] = cont.s_new
        self._mark_pristine()
        self.energy["E_damped"] += info[R.I_DAMPED]
        d_blocks = float((mesh.s_old[:, :, MS_DISS] * mesh.wdet).sum())
        off = self.sliding.diss_off if self.sliding is not None else np.zeros(2)
        d_joints = float(cont.s_old[:, JS_DISS] @ cont.area + off[0]) if cont.slave.size else 0.0
        d_friction = float(cont.s_old[:, JS_DISSF] @ cont.area + off[1]) if cont.slave.size else 0.0
        w_ext = self.energy["W_ext"]
        err = w_ext - eint - d_blocks - d_joints
        self.increment += 1
        row = {"increment": self.increment, "iterations": info[R.I_ITERS],
               "residual": info[R.I_RESID], "time_s": elapsed, "lambda": lam,
               "cut_iterations": self._cut_work[0], "cut_s": self._cut_work[1],
               "dissipation_ratio": ratio, "W_ext": w_ext, "E_stored": eint, "D_blocks": d_blocks,
               "D_joints": d_joints,
               "D_joint_damage": d_joints - d_friction, "D_joint_friction": d_friction,
               "E_damped": self.energy["E_damped"], "E_kinetic": info[R.I_KE],
               "balance_error": err / self.energy["W_gross"] if self.energy["W_gross"] > 0 else 0.0,
               "max_joint_damage": float(cont.s_old[:, JS_D].max()) if cont.slave.size else 0.0,
               "max_dt": float(mesh.s_old[:, :, MS_DT].max()),   # (a model has elements)
               "max_dc": float(mesh.s_old[:, :, MS_DC].max()),
               "max_overhang": self._check_overhang(),
               "block_imbalance": self._check_balance(info), "gap_ratio": balance.ratio}
        for k, name in enumerate("xyz"):
            row[f"gap.f{name}"] = balance.gap[k]
            row[f"drive.f{name}"] = balance.drive[k]
        self._check_return_mapping()
        for rp in self.rigid_points:
            for name, k in L.DOFS.items():
                row[f"{rp.name}.u{name}"] = d.rpU[rp.index, k]
                row[f"{rp.name}.f{name}"] = d.rpf[rp.index, k] + lam * d.rpP[rp.index, k] - rpres[rp.index, k]
        for (name, k), (nodes, kk) in self.presc.items():
            row[f"{name}.u{'xyz'[k]}"] = float(d.U[nodes, k].mean())
            row[f"{name}.f{'xyz'[k]}"] = float((d.fint[nodes, k] - d.fext[nodes, k]).sum())
        fb = cont.fbuf.reshape(-1, 5, 3)
        for name, (sl, ms) in self.contact_reactions.items():
            f = fb[sl, 0].sum(axis=0) + fb[ms, 1:].sum(axis=(0, 1))
            for k in range(3):
                row[f"{name}.f{'xyz'[k]}"] = float(f[k])
        # finite sliding: re-pair for the next increment (this row's forces are those above)
        sl = self.sliding
        row["contacts_moved"] = sl.update() if sl is not None else 0
        row["contacts_off"] = int((cont.area == 0.0).sum())
        row["contacts_sunk"] = int((sl.sunk > 0.0).sum()) if sl is not None else 0
        self._cut_work = [0, 0.0]
        for key, v in row.items():
            self.history.setdefault(key, [np.nan] * (self.increment - 1)).append(float(v))
        self._audit(row, err, energies.joint_diss, energies.element_diss)
        self.last_residual = info[R.I_RESID]
        self.last_iters = int(info[R.I_ITERS])
        self.last_row = row
        if self._bar is not None:   # every row, so that the halves of a cut increment show too
            self._bar.set_postfix_str(f"{self.stage_name} row {self.increment} res="
                                      f"{self.last_residual:.1e} it={self.last_iters}")
        if self.writer is not None:
            self.writer.append_history(row)

    def _check_return_mapping(self):
        """Warns once per run when a Gauss point's plastic-damage return mapping has stopped
        short of its tolerance (the sticky ``FLAG_RETURN`` bit of its committed state): its
        stress is approximate there."""
        if "return" in self._warned:
            return
        flags = self.mesh.s_old[:, :, MS_FLAG].astype(np.int64) & FLAG_RETURN
        bad = np.flatnonzero(flags)
        if bad.size:
            self._warned.add("return")
            e, g = divmod(int(bad[0]), flags.shape[1])
            more = f" (and {bad.size - 1} other points)" if bad.size > 1 else ""
            warnings.warn(f"increment {self.increment}: the plastic-damage return mapping stopped "
                          f"short of its tolerance at Gauss point {g} of element {e} (block "
                          f"{self.model.element_block[e]}){more}: the stress there is "
                          f"approximate", RuntimeWarning)

    def _predictor_motion(self, u_before):
        """The accepted increment's displacement (n_nodes, 3) m from ``u_before`` on the free
        DOFs, for the next increment's predictor; zero on the blocks still out of balance by more
        than ``LOOSE_BLOCK``: they moved because they are loose, not because the load
        moved them (continued row after row, S5 cyclic carried bricks out of the wall's plane a
        few mm per row: docs/validation.md). The ratios are those ``R.relax`` left in
        ``dyn.bratio`` for the accepted state."""
        d = self.dyn
        du = (d.U - u_before) * d.free
        du[np.repeat(d.bratio > LOOSE_BLOCK, np.diff(d.bstart))] = 0.0
        return du

    def _check_balance(self, info):
        """The accepted state's largest block imbalance ratio (``info[R.I_BLOCK]``); warns once
        per run beyond ``BLOCK_IMBALANCE_WARN``."""
        ratio, b = float(info[R.I_BLOCK]), int(info[R.I_BLOCK_ID])
        if ratio > BLOCK_IMBALANCE_WARN and "balance" not in self._warned:
            self._warned.add("balance")
            tol = self.options.block_tol
            warnings.warn(f"increment {self.increment}: block {b} is out of balance by "
                          f"{ratio:.0%} of the forces on it at residual ratio "
                          f"{info[R.I_RESID]:.1e} (the global ratio weighs it against the whole "
                          f"model's load): a loose block, whose position and joint forces are "
                          f"approximate"
                          + (f" (accepted at the floor; block_tol {tol})" if tol > 0 else
                             "; SolverOptions.block_tol (scene parameter block_tol) relaxes "
                             "every block to balance"), RuntimeWarning)
        return ratio

    def _check_overhang(self):
        """Largest distance (m) by which a joint node has slid off its master block's face (the
        start's partial overlaps subtracted); warns once per run beyond ``OVERHANG_WARN``."""
        from .contact_search import overhang
        cont = self.cont
        if cont.slave.size == 0:
            return 0.0
        ov = np.maximum(overhang(self.dyn.X + self.dyn.U, cont.slave, self._sides)
                        - self._overhang0, 0.0) * (cont.area > 0.0)   # not the points off a face
        k = int(np.argmax(ov / self._side_size))
        if ov[k] > OVERHANG_WARN * self._side_size[k] and "overhang" not in self._warned:
            self._warned.add("overhang")
            node = int(cont.slave[k])
            why = ("no other face is under it, so it still pushes on that face until it is half an "
                   "element beyond it, then on nothing" if self.sliding is not None else
                   "contact points are paired in the reference configuration "
                   "(SolverOptions.redetect=False), so such a node still pushes on that face")
            warnings.warn(f"increment {self.increment}: joint node {node} (block "
                          f"{self.model.node_block[node]}) has slid {ov[k] * 1e3:.3g} mm off the face "
                          f"of block {self.model.node_block[cont.master[k, 0]]} "
                          f"({ov[k] / self._side_size[k]:.0%} of its shortest edge): {why}; joint "
                          f"forces near the block ends are approximate from here on", RuntimeWarning)
        return float(ov.max())

    def _audit(self, row, err, joint_diss, element_diss):
        """Say once per run when the energy balance leaves its bound, and (at most
        ``BALANCE_JUMPS`` times) which joint points and element dissipated most in an increment
        that alone moved the error by more than the bound: ``err`` J the balance error after
        it, ``joint_diss`` (nc,) and ``element_diss`` (n_elements,) J its dissipation.

        The energy removed by the damping (history column ``E_damped``) is not part of the
        balance: each increment is applied as a step, and relaxing it to rest removes about
        half of (load step x displacement step), whatever the increment; it is reported only.
        """
        tol = self.options.energy_tol
        gross = self.energy["W_gross"]
        if self._balance is None:   # the first increment of this process (a run or a resume)
            self._balance = [err, 0]
        jump = err - self._balance[0]
        self._balance[0] = err
        if gross > 0 and abs(jump) > tol * gross and self._balance[1] < BALANCE_JUMPS:
            self._balance[1] += 1
            c, blocks = self.cont, self.model.element_block
            top = [k for k in np.argsort(joint_diss)[::-1][:3] if joint_diss[k] > 0.0]
            e = int(np.argmax(element_diss))
            e = e if element_diss[e] > 0.0 else -1
            held = joint_diss[top].sum() + (element_diss[e] if e >= 0 else 0.0)
            where = "; ".join([f"joint point {k} (node {c.slave[k]}, blocks {self._pair(k)}) "
                               f"{joint_diss[k]:.3g} J" for k in top]
                              + ([f"element {e} (block {blocks[e]}) {element_diss[e]:.3g} J"]
                                 if e >= 0 else []))
            # a few points that booked most of the move point at them; otherwise the move is
            # the trapezoidal work rule's over a large step
            why = (f"most of it booked at {where}" if held >= 0.5 * abs(jump) else
                   f"no few points hold it (largest: {where or 'none'}), so it is the "
                   f"trapezoidal work rule's error over this step: use smaller increments")
            warnings.warn(f"increment {self.increment}: the energy balance moved by {jump:.3g} J "
                          f"({jump / gross:.1%} of the gross work) in this one increment; {why}",
                          RuntimeWarning)
        err = abs(row["balance_error"])
        if err > tol and "balance" not in self._warned:
            self._warned.add("balance")
            warnings.warn(f"increment {self.increment}: energy balance error {err:.2%} exceeds "
                          f"{tol:.2%}; use smaller increments (the trapezoidal "
                          f"work rule misses O(step^2) where joints open or close within an "
                          f"increment: docs/file_format.md) or tighten SolverOptions.tol",
                          RuntimeWarning)

    def _pair(self, k):
        """'slave-master' blocks of contact point ``k``, as paired now."""
        b = self.sliding.blocks[k] if self.sliding is not None else self.model.contacts.blocks[k]
        return f"{b[0]}-{b[1]}"

    def fields(self):
        """Current field values for a frame: U, dt, dc per element, D/opening/slip per contact."""
        d, mesh, cont = self.dyn, self.mesh, self.cont
        f = state_fields(d.U, mesh.s_old, cont.s_old)
        if cont.slave.size:
            on = cont.area > 0.0   # a point off the surface carries no traction
            f.update(opening=cont.gaps[:, 0].copy(),
                     slip=np.hypot(cont.gaps[:, 1], cont.gaps[:, 2]),
                     sigma=np.where(on, cont.trac[:, 0], 0.0),
                     tau=np.where(on, np.hypot(cont.trac[:, 1], cont.trac[:, 2]), 0.0))
        return f

    def _write_frame(self):
        if self.writer is not None:
            sl = self.sliding
            self.writer.write_frame(self.increment, self.fields(), {"stage": self.stage_name},
                                    contacts=sl.contact_set() if sl is not None and sl.changed
                                    else None)
            self._write_checkpoint()

    # ------------------------------------------------------------------ restart
    _STATE = ("U", "V", "free", "rpU", "rpV", "rpfree")

    def _checkpoint_due(self):
        """True when a result file is written and ``options.checkpoint_s`` have passed since the
        last checkpoint."""
        return (self.writer is not None
                and time.perf_counter() - self._checkpoint_time >= self.options.checkpoint_s)

    def _write_checkpoint(self, inside=False):
        """Store everything a continued run needs (overwritten at every frame and every
        ``options.checkpoint_s`` between frames); ``inside``: after a committed part of a cut
        increment (the stage position is that increment's)."""
        self._checkpoint_time = time.perf_counter()
        d = self.dyn
        arrays = {k: getattr(d, k) for k in self._STATE}
        arrays.update(rp_force=self.rp_force, lam=self.lam, f_prev=self.f_prev,
                      s_blocks=self.mesh.s_old, s_joints=self.cont.s_old,
                      du_prev=self.du_prev if self.du_prev is not None else np.zeros(0))
        if self.sliding is not None:
            arrays.update(self.sliding.state())
        meta = {"values": [[list(k), v] for k, v in self.values.items()],
                "factors": self.factors, "energy": self.energy, "dctl_prev": self.dctl_prev,
                "history": {k: v for k, v in self.history.items()}, "patterns": [],
                "stage": list(self.stage_position), "inside": inside}
        for name, (pat, P, rpP) in self.patterns.items():
            arrays[f"pattern_P/{name}"] = P
            arrays[f"pattern_rpP/{name}"] = rpP
            meta["patterns"].append(name)
        keep = (self.options.keep_checkpoint_s > 0
                and self._checkpoint_time - self._kept_time >= self.options.keep_checkpoint_s)
        if keep:
            self._kept_time = self._checkpoint_time
        self.writer.write_checkpoint(self.increment, arrays, meta, keep=keep)

    def resume(self, path, increment=None):
        """Continue the run stored in ``path`` from its last checkpoint (the last frame), or
        from the checkpoint it kept after ``increment`` (``Result.kept_checkpoints``; the kept
        ones after it are dropped with the rows and frames).

        The simulation must be set up as the original one (same model, supports and reference
        points, e.g. from the scene's ``build``); later rows and frames of the file are dropped and
        the next :meth:`run` appends to it. If the stored run stopped before its end, ``run``
        must get the same stages and continues the one in progress; after a finished run, the
        stages given run after it from the restored state (controls keep their values, patterns
        their factors).
        """
        if self._built:
            raise L.LoadingError("resume() must be called before the first run")
        if increment is not None:   # checked before the file is opened for writing
            require_kept(path, open_result(path).kept_checkpoints, increment)
        self.output = path
        self._resuming = True
        self._resume_increment = increment
        self.build()

    def _check_checkpoint(self, arrays):
        """Raise a clear error unless the checkpoint ``arrays`` fit this model and are finite."""
        d = self.dyn
        need = {k: getattr(d, k).shape for k in self._STATE}
        need.update(rp_force=self.rp_force.shape, lam=self.lam.shape,
                    s_blocks=self.mesh.s_old.shape, s_joints=self.cont.s_old.shape, f_prev=None,
                    du_prev=None)
        for k, shape in need.items():
            if k in arrays and shape is not None and np.shape(arrays[k]) != shape:
                raise L.LoadingError(f"checkpoint of {self.output}: {k} has shape "
                                     f"{np.shape(arrays[k])}, this model needs {shape} (not the "
                                     "same model)")
            check_stored(self.output, k, arrays.get(k))

    def _load_checkpoint(self):
        if self._resume_increment is not None:
            self.writer.rewind(int(self._resume_increment))
        inc, arrays, meta = open_result(self.output).checkpoint()
        d = self.dyn
        sb = arrays.get("s_blocks")
        if sb is not None and sb.ndim == 3 and sb.shape[2] == NMS - 1:
            # written before the states held MS_DL (2026-12-05): no multiplier, no first guess
            arrays["s_blocks"] = np.concatenate([sb, np.zeros(sb.shape[:2] + (1,))], axis=2)
        self._check_checkpoint(arrays)
        for k in self._STATE:
            getattr(d, k)[:] = arrays[k]
        self.rp_force[:] = arrays["rp_force"]
        self.lam[:] = arrays["lam"]
        self.f_prev = arrays["f_prev"]
        self._u_committed = d.U.copy()
        self.mesh.s_old[:] = arrays["s_blocks"]
        self.mesh.s_new[:] = arrays["s_blocks"]
        self._mark_pristine()
        self.cont.s_old[:] = arrays["s_joints"]
        self.cont.s_new[:] = arrays["s_joints"]
        if self.sliding is not None:
            self.sliding.restore(arrays)
        self.du_prev = arrays["du_prev"] if arrays["du_prev"].size else None
        self.values = {tuple(k): v for k, v in meta["values"]}
        self.factors = dict(meta["factors"])
        self.energy = dict(meta["energy"])
        self.dctl_prev = meta["dctl_prev"]
        self._checkpoint_stage = meta.get("stage")
        self._checkpoint_inside = meta.get("inside", True)   # older files: may be
        self.history = {k: list(v) for k, v in meta["history"].items()}
        for name in meta["patterns"]:
            stored = L.StoredPattern(name, arrays[f"pattern_P/{name}"], arrays[f"pattern_rpP/{name}"])
            self.patterns[name] = (stored, stored.P, stored.rpP)
        self.increment = inc
        self.writer.truncate(inc, len(self.history.get("increment", ())))

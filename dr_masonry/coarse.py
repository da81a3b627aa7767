"""Coarse correction of dynamic relaxation on the blocks' affine motions (two-level scheme).

Explicit dynamic relaxation removes the error of a load increment mode by mode, at a rate set by
the mode's frequency: the smooth, global deformation modes of a wall (many blocks moving and
straining almost uniformly, the joints deforming) are the slowest, and they set the iteration
count of large models. The coarse correction removes them directly. Every block gets the 12 DOFs
of an affine motion u = a + B (X - c) (translation, rotation and uniform strain: a rigid-block
space alone cannot compress a brick, and a compressed bed joint 10 x stiffer than the brick then
stalls it), every rigid reference point its 6 DOFs, and the out-of-balance forces projected on
them are solved for at once,

    K_c dq = T^T r,     U <- U + T dq,     K_c = T^T K T (Galerkin),

with ``T`` the interpolation of the coarse DOFs at the nodes and ``K`` the stiffness of the
current state: the blocks' elastic strain energy of affine motions (exact for trilinear
hexahedra; softened by the block's mean damage) and the joints' stiffnesses at each contact
point (slave node against master point): secant where the point softens or slides in the current
trial state (tangentially: along its traction only), elastic unloading elsewhere. Dynamic
relaxation then only has to remove what the affine blocks cannot represent, local and fast: a
two-level method with relaxation as the smoother. The operator is factorised once per increment
(sparse LU, symmetric ordering). A step is accepted only if it moves no node by more than a trust
radius (:data:`TRUST`) and lowers the total potential energy of the trial state (or, with
``coarse_test="residual"``, leaves a residual that still works along it; halved twice before
giving up; the out-of-balance norm is no guide, as a coarse motion leaves element-scale
residuals); it changes trial states only, never the committed history, so it cannot damage
anything the relaxation would not.

Fixed blocks and blocks tied to reference points are not coarse unknowns (the latter move with
their reference point, whose free DOFs are); held node DOFs of the other blocks (supports,
symmetry planes, prescribed values) are kept by a stiff penalty; under indirect control the load
factor is solved for with the step so that the controlled DOF stays where it is.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .kernels import relaxation as R
from .kernels.config import plain
from .kernels.contact_frame import quad_shape, quad_tangents
from .kernels.joint_law import JS_D, JS_DP1, JS_DP2
from .kernels.plastic_damage import MP_LAM, MP_MU, MS_DC, MS_DT
from .model import quad_normal

#: coarse DOFs of a block (affine motion u = a + B (X - c)) and of a reference point (rigid)
NB, NR = 12, 6
#: the largest node motion of an accepted coarse step, in smallest block extents (median block):
#: beyond it the contact pairs of the increment's start no longer describe the joints and the
#: linear coarse model is not trusted; a nearly singular operator (a block or floor held only by
#: sliding or cracked joints) otherwise gives steps of kilometres that still lower the potential
#: (the joints open without cost while the loads work): S7 cyclic row 248, docs/validation.md
TRUST = 0.25


def affine_t(d):
    """Affine interpolation ``T`` (m, 3, 12) at arms ``d`` (m, 3): u = a + B d, DOFs
    [a (3), B row by row (9)]."""
    T = np.zeros((d.shape[0], 3, NB))
    for k in range(3):
        T[:, k, k] = 1.0
        T[:, k, 3 + 3 * k:6 + 3 * k] = d
    return T


def rigid_t(d):
    """Rigid-body interpolation ``T`` (m, 3, 12) at arms ``d`` (m, 3): u = u_p + theta x d,
    DOFs [u_p (3), theta (3)], the last six columns zero."""
    T = np.zeros((d.shape[0], 3, NB))
    T[:, 0, 0] = T[:, 1, 1] = T[:, 2, 2] = 1.0
    T[:, 0, 4], T[:, 0, 5] = d[:, 2], -d[:, 1]
    T[:, 1, 3], T[:, 1, 5] = -d[:, 2], d[:, 0]
    T[:, 2, 3], T[:, 2, 4] = d[:, 1], -d[:, 0]
    return T


def affine_stiffness(lam, mu):
    """Strain-energy matrix (9, 9) of the gradient B of an affine motion per unit volume,
    isotropic Lame constants ``lam``, ``mu`` (Pa): 1/2 V B:K:B = 1/2 V eps:C:eps."""
    K = np.zeros((9, 9))
    for k in range(3):
        for j in range(3):
            for l in range(3):
                for m in range(3):
                    K[3 * k + j, 3 * l + m] = (lam * (k == j) * (l == m)
                                               + mu * ((k == l) * (j == m) + (k == m) * (j == l)))
    return K


class BlockCoarse:
    """Coarse space of a :class:`~dr_masonry.solver.Simulation` after ``build()``.

    Parameters
    ----------
    sim : Simulation
    """

    def __init__(self, sim):
        m = sim.model
        self.sim = sim
        self.start = np.asarray(m.block_node_start, dtype=np.int64)   # (nb + 1,)
        self.node_block = np.asarray(m.node_block, dtype=np.int64)    # (n,)
        X = m.nodes
        cnt = np.diff(self.start)
        self.centre = np.add.reduceat(X, self.start[:-1], axis=0) / cnt[:, None]  # (nb, 3) m
        self.fixed = np.asarray(m.block_fixed, dtype=bool)
        # trust radius (m): a quarter of the median block's smallest extent
        thin = (np.maximum.reduceat(X, self.start[:-1], axis=0)
                - np.minimum.reduceat(X, self.start[:-1], axis=0)).min(axis=1)
        self.trust = TRUST * float(np.median(thin[~self.fixed] if (~self.fixed).any() else thin))
        laws = m.joint_laws
        c = sim.cont
        self.kc_el = np.array([lw.kc_pen for lw in laws])[c.law] if c.slave.size else np.zeros(0)
        self.kt_el = np.array([lw.kss for lw in laws])[c.law] if c.slave.size else np.zeros(0)
        self.normal = quad_normal(X[c.master])  # (nc, 3) reference normals of the master faces
        mesh = sim.mesh
        eb = np.asarray(m.element_block)
        self.volume = np.bincount(eb, mesh.wdet.sum(axis=1), minlength=m.n_blocks)  # (nb,) m^3
        self.lame = mesh.mparams[m.block_material][:, [MP_LAM, MP_MU]]   # (nb, 2) Pa: lambda, mu
        self.n_elem = np.bincount(eb, minlength=m.n_blocks)
        self.n_corrections = 0
        self.n_rejected = 0
        self.op = None

    def groups(self):
        """Coarse group of every block (-1: none) and the number of block groups: every block
        that is neither fixed nor tied to a reference point."""
        d = self.sim.dyn
        tied = np.maximum.reduceat((d.tied >= 0).astype(np.int8), self.start[:-1]) > 0
        ok = ~self.fixed & ~tied
        g = np.full(ok.size, -1, dtype=np.int64)
        g[ok] = np.arange(int(ok.sum()))
        return g, int(ok.sum())

    @staticmethod
    def dof_map(nbg, nr):
        """Global coarse DOF of each (group, slot) (nbg + nr, 12), -1 where unused, and the
        number of coarse DOFs: 12 per block group, then 6 per reference point."""
        dof = np.full((nbg + nr, NB), -1, dtype=np.int64)
        dof[:nbg] = np.arange(NB * nbg).reshape(nbg, NB)
        dof[nbg:, :NR] = NB * nbg + np.arange(NR * nr).reshape(nr, NR)
        return dof, NB * nbg + NR * nr

    def _interp(self, g, arm, nbg):
        """``T`` (m, 3, 12) of points of groups ``g`` at arms ``arm``: affine for blocks, rigid
        for reference points."""
        T = affine_t(arm)
        rp = g >= nbg
        if rp.any():
            T[rp] = rigid_t(arm[rp])
        return T

    def matrix(self, gblock, nbg, dof, ndof):
        """Galerkin coarse stiffness T^T K T (csr, ndof square): the blocks' strain energy of
        affine motions (elastic, scaled by the block's mean integrity) and the joints' current
        stiffnesses (secant where they soften or slide, unloading elsewhere)."""
        sim = self.sim
        d, c, mesh = sim.dyn, sim.cont, sim.mesh
        X = d.X
        rows, cols, vals = [], [], []

        def add(ga, gb, blk):
            ii = np.broadcast_to(dof[ga][:, :, None], blk.shape)
            jj = np.broadcast_to(dof[gb][:, None, :], blk.shape)
            on = (ii >= 0) & (jj >= 0)
            rows.append(ii[on])
            cols.append(jj[on])
            vals.append(blk[on])

        # blocks: affine strain energy, damaged blocks softened by their mean integrity
        blocks = np.nonzero(gblock >= 0)[0]
        if blocks.size:
            eb = self.sim.model.element_block
            dmg = np.maximum(mesh.s_new[:, :, MS_DT], mesh.s_new[:, :, MS_DC]).mean(axis=1)
            integrity = 1.0 - np.bincount(eb, dmg, minlength=gblock.size) / np.maximum(self.n_elem, 1)
            k1 = affine_stiffness(1.0, 0.0)
            k2 = affine_stiffness(0.0, 1.0)
            w = (self.volume * integrity)[blocks]
            blk = np.zeros((blocks.size, NB, NB))
            blk[:, 3:, 3:] = (w * self.lame[blocks, 0])[:, None, None] * k1 \
                + (w * self.lame[blocks, 1])[:, None, None] * k2
            add(gblock[blocks], gblock[blocks], blk)
        if c.slave.size:
            N = np.column_stack(plain(quad_shape)(c.xi[:, 0], c.xi[:, 1]))
            xm = np.matmul(N[:, None, :], X[c.master])[:, 0]
            gs, ds = self._group_of(c.slave, X[c.slave], gblock, nbg)
            gm, dm = self._group_of(c.master[:, 0], xm, gblock, nbg)
            # normal: secant stiffness of each point (N/m), which is also its unloading stiffness
            # ((1 - D) knn open, the penalty closed); untouched points take the compression
            # stiffness (a joint under load is mostly compressed)
            gap, tr = c.gaps, c.trac
            un = np.where(gap[:, 0] == 0.0, 1.0, gap[:, 0])
            kn = np.where(np.abs(gap[:, 0]) > 1e-12, tr[:, 0] / un, self.kc_el)
            # tangential: kss, the stiffness with which a point that slid before sticks or
            # unloads (the law's slider keeps its slip), except along the traction of a point
            # that slides or softens in the current trial state (plastic slip or damage moving),
            # which gets its secant |tau| / |slip| there (its tangent is near zero). Across the
            # traction such a point stays elastic: a slip increment ds across it turns the
            # traction on the yield circle, by kss ds to first order (the law's radial return).
            # With the secant everywhere, most post-peak S5 increments gave the correction up
            # after two rejections; with the secant in every
            # tangential direction, coarse steps carried cracked walls out of plane
            slip = np.hypot(gap[:, 1], gap[:, 2])
            moving = ((c.s_new[:, JS_D] > c.s_old[:, JS_D]) | (c.s_new[:, JS_DP1] != c.s_old[:, JS_DP1])
                      | (c.s_new[:, JS_DP2] != c.s_old[:, JS_DP2])) & (slip > 1e-12)
            kn = np.clip(kn, 0.0, None) * c.area
            kt = np.clip(self.kt_el, 0.0, None) * c.area
            nrm = self.normal
            K = (kn - kt)[:, None, None] * nrm[:, :, None] * nrm[:, None, :] \
                + kt[:, None, None] * np.eye(3)[None]
            if moving.any():
                ksec = np.hypot(tr[moving, 1], tr[moving, 2]) / slip[moving] * c.area[moving]
                e = self._traction_direction(moving, X, tr, gap)
                K[moving] += (ksec - kt[moving])[:, None, None] * e[:, :, None] * e[:, None, :]
            # K_joints = B^T diag(K_c) B, B (3 nc, ndof) the relative motion of each point
            Ts, Tm = self._interp(gs, ds, nbg), self._interp(gm, dm, nbg)
            nc = c.slave.size
            bi, bj, bv = [], [], []
            for gg, TT, sign in ((gs, Ts, 1.0), (gm, Tm, -1.0)):
                cdof = np.where(gg[:, None] >= 0, dof[np.maximum(gg, 0)], -1)   # (nc, 12)
                rr = np.broadcast_to((3 * np.arange(nc))[:, None, None] + np.arange(3)[None, :, None],
                                     TT.shape)
                cc = np.broadcast_to(cdof[:, None, :], TT.shape)
                on = cc >= 0
                bi.append(rr[on])
                bj.append(cc[on])
                bv.append(sign * TT[on])
            B = sp.csr_matrix((np.concatenate(bv), (np.concatenate(bi), np.concatenate(bj))),
                              shape=(3 * nc, ndof))
            D = sp.bsr_matrix((K, np.arange(nc), np.arange(nc + 1)), shape=(3 * nc, 3 * nc))
            joints = (B.T @ (D @ B)).tocsr()
        else:
            joints = None
        Kc = joints
        if rows:
            blocks_k = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                             np.concatenate(cols))),
                                     shape=(ndof, ndof)).tocsr()
            Kc = blocks_k if Kc is None else Kc + blocks_k
        return Kc

    def _traction_direction(self, on, X, tr, gap):
        """Unit global direction (m, 3) of the tangential traction of contact points ``on``
        (mask (nc,)): local [tau1, tau2] ``tr[:, 1:]`` (slip ``gap[:, 1:]`` where it is zero) on
        the master face's frame t1 = a1 / |a1|, t2 = n x t1
        (:mod:`~dr_masonry.kernels.contact_frame`), ``X`` (n, 3) the nodes' coordinates (m)."""
        c = self.sim.cont
        a = plain(quad_tangents)(np.moveaxis(X[c.master[on]], 0, -1), c.xi[on, 0], c.xi[on, 1])
        n = self.normal[on]
        t1 = np.column_stack(a[:3])
        t1 -= (t1 * n).sum(axis=1)[:, None] * n
        t1 /= np.linalg.norm(t1, axis=1)[:, None]
        t2 = np.cross(n, t1)
        v = np.where((np.abs(tr[on, 1:]).max(axis=1) > 0.0)[:, None], tr[on, 1:], gap[on, 1:])
        e = v[:, :1] * t1 + v[:, 1:] * t2
        return e / np.linalg.norm(e, axis=1)[:, None]

    def residual_work(self, lam, nodes, du, drp):
        """Work (J) of the out-of-balance forces of the current trial state at load factor
        ``lam`` along a step: the node motion ``du`` (m, 3) m of ``nodes`` (m,) and the
        reference points' ``drp`` (nr, 6) (leaves the state's forces in ``dyn.fint`` and its
        residual in ``dyn.res``). Positive while the step has not passed the equilibrium along
        its line."""
        d = self.sim.dyn
        R.internal_forces(self.sim.mesh, self.sim.cont, d)
        rp = np.zeros((d.rpX.shape[0], 6))
        R.residual(d, lam, rp)
        return float((d.res[nodes] * du).sum() + (rp * drp).sum())

    def potential(self, lam):
        """Total potential energy (J) of the current trial state: stored energy of blocks and
        joints minus the work of the applied loads at their current values (leaves the internal
        forces of the state in ``dyn.fint``)."""
        sim = self.sim
        d = sim.dyn
        e = R.internal_forces(sim.mesh, sim.cont, d)
        w = float(((d.fext + lam * d.P) * d.U).sum())
        w += float(((d.rpf + lam * d.rpP) * d.rpU * d.rpfree).sum())
        return e - w

    def _group_of(self, nodes, x, gblock, nbg):
        """Coarse group (-1 none) and arm (m, 3) of points ``x`` on the blocks of ``nodes``."""
        d = self.sim.dyn
        b = self.node_block[nodes]
        g = gblock[b].copy()
        arm = x - self.centre[b]
        tied = d.tied[nodes]
        on = tied >= 0
        g[on] = nbg + tied[on]
        arm[on] = x[on] - d.rpX[tied[on]]
        return g, arm

    def refresh(self):
        """Mark the coarse operator out of date (a new increment, or a rejected step)."""
        self.op = None

    def operator(self, ctrl):
        """Factorised coarse operator of the current state: a dict with the groups, the node
        arms and interpolations, the kept DOFs ``idx``, ``solve``, the control direction ``tc``
        and the coarse response ``b`` to the indirect pattern (both None without control)."""
        d = self.sim.dyn
        gblock, nbg = self.groups()
        nr = d.rpX.shape[0]
        dof, ndof = self.dof_map(nbg, nr)
        Kc = self.matrix(gblock, nbg, dof, ndof)
        if Kc is None:
            return None
        nodes = np.nonzero(gblock[self.node_block] >= 0)[0]
        g = gblock[self.node_block[nodes]]
        arm = d.X[nodes] - self.centre[self.node_block[nodes]]
        T = affine_t(arm)                                      # (m, 3, 12)
        free = d.free[nodes].copy()
        tc = None                                              # control direction (ndof,)
        if ctrl[0] == 1:
            j = np.searchsorted(nodes, ctrl[1])
            if j < nodes.size and nodes[j] == ctrl[1]:
                tc = np.zeros(ndof)
                tc[dof[g[j]]] = T[j, ctrl[2]]
                free[j, ctrl[2]] = 1.0                        # held by dlam, not by a penalty
        elif ctrl[0] == 2:
            tc = np.zeros(ndof)
            tc[dof[nbg + ctrl[1], ctrl[2]]] = 1.0
        diag = Kc.diagonal()
        kpen = 1e3 * np.median(diag[dof[:nbg, :3]]) if nbg else 0.0
        hi, hk = np.nonzero(free == 0.0)
        if hi.size:                                            # penalty on held node DOFs
            t = T[hi, hk]                                      # (h, 12)
            blk = kpen * t[:, :, None] * t[:, None, :]
            ii = np.broadcast_to(dof[g[hi]][:, :, None], blk.shape).ravel()
            jj = np.broadcast_to(dof[g[hi]][:, None, :], blk.shape).ravel()
            Kc = Kc + sp.coo_matrix((blk.ravel(), (ii, jj)), shape=Kc.shape).tocsr()
        keep = np.ones(ndof, bool)
        keep[NB * nbg:] = d.rpfree.ravel() > 0
        if ctrl[0] == 2:
            keep[dof[nbg + ctrl[1], ctrl[2]]] = True
        keep &= Kc.diagonal() > 0
        idx = np.nonzero(keep)[0]
        if idx.size == 0:
            return None
        A = Kc[idx][:, idx]
        dg = A.diagonal()
        A = (A + sp.diags(1e-10 * dg + 1e-14 * dg.max())).tocsc()
        try:
            # A is symmetric positive definite: symmetric ordering, no pivoting (half the fill
            # and factorisation time of the default column ordering)
            solve = spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                              options=dict(SymmetricMode=True)).solve
        except RuntimeError:
            return None
        op = dict(nbg=nbg, nr=nr, dof=dof, ndof=ndof, nodes=nodes, g=g, arm=arm, free=free,
                  idx=idx, solve=solve, tc=tc, b=None)
        if tc is not None:  # response to the indirect pattern, fixed over the increment
            prp = d.rpP.copy()                                 # tied nodes' share: see residual
            for p in range(nr):
                tn = d.rpnodes[d.rpptr[p]:d.rpptr[p + 1]]
                prp[p, :3] += d.P[tn].sum(axis=0)
                prp[p, 3:] += np.cross(d.X[tn] - d.rpX[p], d.P[tn]).sum(axis=0)
            op["b"] = solve(self.project(op, d.P, prp)[idx])
        return op

    def project(self, op, f_nodes, f_rp):
        """Coarse vector (ndof,) T^T f: nodal forces (n, 3) of the block groups as their sums
        and first moments about the block centres, plus the reference points' generalised
        forces (nr, 6)."""
        nbg, g, arm = op["nbg"], op["g"], op["arm"]
        f = f_nodes[op["nodes"]] * op["free"]
        out = np.zeros(op["ndof"])
        blk = np.zeros((nbg, NB))
        for k in range(3):
            blk[:, k] = np.bincount(g, f[:, k], minlength=nbg)
            for j in range(3):
                blk[:, 3 + 3 * k + j] = np.bincount(g, f[:, k] * arm[:, j], minlength=nbg)
        out[:NB * nbg] = blk.ravel()
        out[NB * nbg:] = f_rp.ravel()
        return out

    def prolong(self, op, dq_k):
        """Nodal displacements (m, 3) of the operator's nodes ``op["nodes"]`` (m,) and the
        reference points' (nr, 6) of coarse unknowns ``dq_k`` (its kept DOFs ``op["idx"]``), held
        DOFs zero."""
        d = self.sim.dyn
        nbg, g, arm = op["nbg"], op["g"], op["arm"]
        dq = np.zeros(op["ndof"])
        dq[op["idx"]] = dq_k
        qb = dq[:NB * nbg].reshape(nbg, NB)[g]                 # (m, 12)
        du = (qb[:, :3] + np.einsum("mkj,mj->mk", qb[:, 3:].reshape(-1, 3, 3), arm)) \
            * d.free[op["nodes"]]
        return du, dq[NB * nbg:].reshape(op["nr"], NR) * d.rpfree

    def correct(self, lam_arr, rpres, ctrl):
        """Apply one coarse correction to ``sim.dyn`` (after ``internal_forces`` and ``residual``
        of the current state); returns True if a step within the trust radius ``self.trust`` (m)
        passed the test of ``SolverOptions.coarse.test`` (else undone): it lowered the potential
        energy (:meth:`potential`), or the residual at its end still works along it
        (:meth:`residual_work`).

        The operator is factorised at the first correction of an increment and reused for the
        increment. Held node DOFs (supports, prescribed values) of coarse blocks are kept
        by a penalty, held reference-point DOFs are dropped. Under indirect control (``ctrl`` as
        in ``R.relax``) the load factor ``lam_arr[0]`` changes too, so that the controlled DOF
        does not move (bordered solve: dq = a + dlam b, K a = r, K b = p, t_c . dq = 0).
        """
        sim = self.sim
        d = sim.dyn
        lam = lam_arr[0]
        if self.op is None:
            self.op = self.operator(ctrl)
        op = self.op
        if op is None:
            return False
        idx, tc, nodes = op["idx"], op["tc"], op["nodes"]
        dq_k = op["solve"](self.project(op, d.res, rpres)[idx])
        dlam = 0.0
        if tc is not None:
            b = op["b"]
            tb = tc[idx] @ b
            if tb != 0.0:
                dlam = -(tc[idx] @ dq_k) / tb
                dq_k = dq_k + dlam * b
        if not (np.all(np.isfinite(dq_k)) and np.isfinite(dlam)):
            self.op = None
            return False
        du, drp = self.prolong(op, dq_k)
        # the step of a linear coarse model, scaled back while it fails the test (Coarse.test)
        U0, rpU0 = d.U.copy(), d.rpU.copy()
        self.n_corrections += 1
        pi0 = None
        residual_test = sim.options.coarse.test == "residual"
        for step in (1.0, 0.5, 0.25):
            lam_new = lam + step * dlam
            d.U[:], d.rpU[:] = U0, rpU0
            R.place_rigid_nodes(d)
            if not residual_test and (pi0 is None or dlam != 0.0):  # (it depends on the factor)
                pi0 = self.potential(lam_new)
            d.U[nodes] += step * du
            d.rpU[:] += step * drp
            R.place_rigid_nodes(d)
            if np.abs(d.U - U0).max(initial=0.0) > self.trust:
                continue
            if (self.residual_work(lam_new, nodes, du, drp) >= 0.0 if residual_test
                    else self.potential(lam_new) < pi0):
                lam_arr[0] = lam_new
                d.V[:] = 0.0
                d.rpV[:] = 0.0
                return True
        d.U[:], d.rpU[:] = U0, rpU0
        R.place_rigid_nodes(d)
        R.internal_forces(sim.mesh, sim.cont, d)
        self.n_rejected += 1
        return False

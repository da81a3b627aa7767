"""The out-of-balance forces of a state and their measures: rigid-node placement, the
internal-force gather and residual (nodes and reference points), the Rayleigh sums, the residual
and reference norms, the out-of-balance resultant against the driving force, each block's
imbalance ratio, and the place a guard names.

Arrays come in the solver's named tuples: ``mesh`` and ``cont`` (:mod:`.forces`) and ``dyn``
(``dr_masonry.solver.arrays.Dyn``: nodal and reference-point state).
"""
import numpy as np

from .assembly import gather_node, gather_pair
from .config import ijit, jit, pjit, prange
from .forces import element_and_contact_forces

NODE_CHUNK = 256  #: nodes per parallel task of the node passes
#: what ``worst_place`` names: a node, a reference point or the load factor
WHERE_NODE = 0
WHERE_RP = 1
WHERE_LOAD = 2


@jit
def rotation_matrix(th, R):
    """Rodrigues: rotation matrix ``R`` (3, 3) of the rotation vector ``th`` (3,), rad."""
    a = np.sqrt(th[0] ** 2 + th[1] ** 2 + th[2] ** 2)
    if a < 1e-300:
        for i in range(3):
            for j in range(3):
                R[i, j] = 1.0 if i == j else 0.0
        return
    k0, k1, k2 = th[0] / a, th[1] / a, th[2] / a
    c, s = np.cos(a), np.sin(a)
    C = 1.0 - c
    R[0, 0] = c + k0 * k0 * C
    R[0, 1] = k0 * k1 * C - k2 * s
    R[0, 2] = k0 * k2 * C + k1 * s
    R[1, 0] = k1 * k0 * C + k2 * s
    R[1, 1] = c + k1 * k1 * C
    R[1, 2] = k1 * k2 * C - k0 * s
    R[2, 0] = k2 * k0 * C - k1 * s
    R[2, 1] = k2 * k1 * C + k0 * s
    R[2, 2] = c + k2 * k2 * C


@jit
def place_rigid_nodes(dyn):
    """Displacements of nodes tied to reference points from the points' 6 DOFs."""
    R = np.empty((3, 3))
    for p in range(dyn.rpX.shape[0]):
        rotation_matrix(dyn.rpU[p, 3:], R)
        for q in range(dyn.rpptr[p], dyn.rpptr[p + 1]):
            i = dyn.rpnodes[q]
            d0 = dyn.X[i, 0] - dyn.rpX[p, 0]
            d1 = dyn.X[i, 1] - dyn.rpX[p, 1]
            d2 = dyn.X[i, 2] - dyn.rpX[p, 2]
            for k in range(3):
                dyn.U[i, k] = (dyn.rpU[p, k] + R[k, 0] * d0 + R[k, 1] * d1 + R[k, 2] * d2
                               - (d0 if k == 0 else (d1 if k == 1 else d2)))


@jit
def stored_energy(mesh, cont):
    """Stored energy of the last force evaluation (active hexahedra and contact points), J."""
    e = 0.0
    for q in range(mesh.active.shape[0]):
        e += mesh.energy[mesh.active[q]]
    return e + cont.psi.sum()


@jit
def internal_forces(mesh, cont, dyn):
    """Assemble internal forces into ``dyn.fint`` (n_nodes, 3), N; returns the stored energy, J.

    Two parallel regions (forces, then the gather per node): each region costs a wake-up of the
    worker threads (about 0.1 ms with passive OpenMP waiting, docs/internals.md, "Decisions")."""
    element_and_contact_forces(dyn.X, dyn.U, mesh, cont)
    gather_pair(mesh.fbuf.reshape((-1, 3)), mesh.ptr, mesh.rows, cont.fbuf, cont.ptr, cont.rows,
                dyn.fint)
    return stored_energy(mesh, cont)


@ijit
def node_residual(fext, P, fint, res, lam, i):
    """Out-of-balance force ``res[i]`` = fext + lam P - fint of node i, N (arrays (n_nodes, 3))."""
    for k in range(3):
        res[i, k] = fext[i, k] + lam * P[i, k] - fint[i, k]


@ijit
def gather_chunk(lo, hi, hbuf, hptr, hrows, cbuf, cptr, crows, fext, P, fint, res, free, V, minv,
                 fprev, lam, viscous, part):
    """Nodes ``lo:hi`` of :func:`gather_residual` (one parallel task); their Rayleigh sums into
    ``part`` (2,)."""
    num = 0.0
    den = 0.0
    for i in range(lo, hi):
        gather_node(hbuf, hptr, hrows, cbuf, cptr, crows, fint, i)
        node_residual(fext, P, fint, res, lam, i)
        if viscous:
            for k in range(3):
                if free[i, k] > 0.0:   # (fprev is only read at free DOFs)
                    du = V[i, k]
                    num += du * (fint[i, k] - fprev[i, k])
                    den += du * du / minv[i]
                    fprev[i, k] = fint[i, k]
    part[0] = num
    part[1] = den


@pjit
def gather_residual(hbuf, mptr, mrows, cont, dyn, lam, fprev, viscous, parts):
    """One parallel pass over the nodes after the force kernel: ``dyn.fint`` gathered from the
    hexahedra's ``hbuf`` (ne * 8, 3) (node map ``mptr``, ``mrows``) and the contact points'
    buffer, ``dyn.res`` at load factor ``lam``, and with ``viscous`` the Rayleigh quotient's sums
    over the free DOFs, num = V . (fint - fprev) and den = V . M V, with ``fprev`` <- fint there.
    ``parts`` (>= number of tasks, 4) scratch. Returns (num, den), summed task by task in a
    fixed order (the same for any number of threads)."""
    n = dyn.U.shape[0]
    nt = (n + NODE_CHUNK - 1) // NODE_CHUNK
    for t in prange(nt):
        gather_chunk(t * NODE_CHUNK, min(n, (t + 1) * NODE_CHUNK), hbuf, mptr, mrows, cont.fbuf,
                     cont.ptr, cont.rows, dyn.fext, dyn.P, dyn.fint, dyn.res, dyn.free, dyn.V,
                     dyn.minv, fprev, lam, viscous, parts[t])
    num = 0.0
    den = 0.0
    for t in range(nt):
        num += parts[t, 0]
        den += parts[t, 1]
    return num, den


@jit
def residual(dyn, lam, rpres):
    """Out-of-balance forces ``dyn.res`` (n_nodes, 3) and generalised ones ``rpres`` (n_rp, 6)."""
    for i in range(dyn.U.shape[0]):
        node_residual(dyn.fext, dyn.P, dyn.fint, dyn.res, lam, i)
    rp_residual(dyn, lam, rpres)


@jit
def rp_residual(dyn, lam, rpres):
    """Generalised out-of-balance forces ``rpres`` (n_rp, 6) of the reference points (N, N m):
    their loads at factor ``lam`` plus the residuals ``dyn.res`` of their tied nodes."""
    for p in range(dyn.rpX.shape[0]):
        for k in range(6):
            rpres[p, k] = dyn.rpf[p, k] + lam * dyn.rpP[p, k]
        for q in range(dyn.rpptr[p], dyn.rpptr[p + 1]):
            i = dyn.rpnodes[q]
            a0 = dyn.X[i, 0] + dyn.U[i, 0] - dyn.rpX[p, 0] - dyn.rpU[p, 0]
            a1 = dyn.X[i, 1] + dyn.U[i, 1] - dyn.rpX[p, 1] - dyn.rpU[p, 1]
            a2 = dyn.X[i, 2] + dyn.U[i, 2] - dyn.rpX[p, 2] - dyn.rpU[p, 2]
            r0, r1, r2 = dyn.res[i, 0], dyn.res[i, 1], dyn.res[i, 2]
            rpres[p, 0] += r0
            rpres[p, 1] += r1
            rpres[p, 2] += r2
            rpres[p, 3] += a1 * r2 - a2 * r1
            rpres[p, 4] += a2 * r0 - a0 * r2
            rpres[p, 5] += a0 * r1 - a1 * r0


@jit
def rp_rayleigh(dyn, lam, rpres, gprev):
    """Rayleigh sums of the free reference-point DOFs, for a model whose every node is fixed or
    tied (its only motion is theirs): (num, den) = (V . dF, V . M V) with dF the change of the
    points' generalised internal forces since ``gprev`` (n_rp, 6), which takes their current
    value. ``rpres`` (n_rp, 6): :func:`rp_residual` at factor ``lam``; the internal part is
    loads minus residual."""
    num = 0.0
    den = 0.0
    for p in range(dyn.rpX.shape[0]):
        for k in range(6):
            g = dyn.rpf[p, k] + lam * dyn.rpP[p, k] - rpres[p, k]
            if dyn.rpfree[p, k] > 0.0:
                v = dyn.rpV[p, k]
                num += v * (g - gprev[p, k])
                den += v * v / dyn.rpminv[p, k]
            gprev[p, k] = g
    return num, den


@jit
def norms(dyn, lam, rpres):
    """(free residual norm, reference norm) in N; moments are divided by the points' radii."""
    rf = 0.0
    ref = 0.0
    for i in range(dyn.U.shape[0]):
        for k in range(3):
            f = dyn.fext[i, k] + lam * dyn.P[i, k]
            if dyn.free[i, k] > 0.0:
                rf += dyn.res[i, k] ** 2
                ref += f * f
            elif dyn.tied[i] < 0:  # support or prescribed DOF: its reaction counts as load
                ref += f * f + dyn.res[i, k] ** 2
    for p in range(dyn.rpX.shape[0]):
        for k in range(6):
            sc = 1.0 if k < 3 else 1.0 / dyn.rpradius[p]
            f = (dyn.rpf[p, k] + lam * dyn.rpP[p, k]) * sc
            if dyn.rpfree[p, k] > 0.0:
                rf += (rpres[p, k] * sc) ** 2
                ref += f * f
            else:
                ref += f * f + (rpres[p, k] * sc) ** 2
    return np.sqrt(rf), np.sqrt(ref)


@jit
def resultant(dyn, lam, rpres):
    """Out-of-balance resultant against the driving force.

    ``dyn.gspec`` (4, 3): row 0 marks (1.0) the translations x, y, z that the increment's
    controls drive, row 1 holds each one's largest |driving force| so far (N); rows 2 and 3 are
    written: the resultant (N), the free DOFs' out-of-balance forces ``dyn.res`` summed (tied
    nodes through their reference points' ``rpres`` (n_rp, 6)), i.e. the loads minus the
    supports' reactions since internal forces sum to zero; and the driving force (N), the
    indirect pattern's applied resultant (``lam`` times ``dyn.P`` and ``dyn.rpP``) plus the
    reactions of the DOFs whose prescribed motion drives the increment (``dyn.gnode``
    (n_nodes, 3), ``dyn.grp`` (n_rp, 6): 1.0 there). The ratio is |resultant| over the larger of
    |driving force| and its largest so far, on the driven axes (0 where both are 0 or none is
    driven): how far a curve's force may be from the reaction that should balance it.
    Returns (that ratio, its axis 0-2)."""
    g = dyn.gspec
    for k in range(3):
        g[2, k] = 0.0
        g[3, k] = 0.0
    for i in range(dyn.U.shape[0]):
        for k in range(3):
            r = dyn.res[i, k]
            if dyn.free[i, k] > 0.0:
                g[2, k] += r
            elif dyn.gnode[i, k] > 0.0:
                g[3, k] -= r
            g[3, k] += lam * dyn.P[i, k]
    for p in range(dyn.rpX.shape[0]):
        for k in range(3):
            if dyn.rpfree[p, k] > 0.0:
                g[2, k] += rpres[p, k]
            elif dyn.grp[p, k] > 0.0:
                g[3, k] -= rpres[p, k]
            g[3, k] += lam * dyn.rpP[p, k]
    worst = 0.0
    at = 0
    for k in range(3):
        scale = max(abs(g[3, k]), g[1, k])
        if g[0, k] > 0.0 and scale > 0.0 and abs(g[2, k]) / scale > worst:
            worst = abs(g[2, k]) / scale
            at = k
    return worst, at


@jit
def block_imbalance(cont, dyn, lam, ratio):
    """Imbalance ratio ``ratio`` (n_blocks,) of every block: |sum of the block's free residuals|
    (N) over the sum of the magnitudes of the forces acting on it, its joints' (``cont.fbuf``
    rows at its nodes) and its applied loads (N), the "local ratio" of block codes; returns (the
    largest, its block). The global norm of :func:`norms` weighs every DOF against the whole
    model's load, so a loose brick held by little more than its weight may stay out of balance by
    tens of per cent of it (and creep) while the model counts as converged; this ratio sees it.
    (Nodal internal forces would not do as the scale: element and joint forces cancel at an
    unloaded node in balance.) A component counts only where every node of the block is free in
    it (supported or tied components carry reactions); a block with no force has ratio 0."""
    worst = 0.0
    at = -1
    for b in range(dyn.bstart.shape[0] - 1):
        n0, n1, n2 = 0.0, 0.0, 0.0
        a0, a1, a2 = 1.0, 1.0, 1.0
        scale = 0.0
        for i in range(dyn.bstart[b], dyn.bstart[b + 1]):
            n0 += dyn.res[i, 0] * dyn.free[i, 0]
            n1 += dyn.res[i, 1] * dyn.free[i, 1]
            n2 += dyn.res[i, 2] * dyn.free[i, 2]
            a0 = min(a0, dyn.free[i, 0])
            a1 = min(a1, dyn.free[i, 1])
            a2 = min(a2, dyn.free[i, 2])
            f0 = dyn.fext[i, 0] + lam * dyn.P[i, 0]
            f1 = dyn.fext[i, 1] + lam * dyn.P[i, 1]
            f2 = dyn.fext[i, 2] + lam * dyn.P[i, 2]
            scale += np.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
            for q in range(cont.ptr[i], cont.ptr[i + 1]):
                r = cont.rows[q]
                scale += np.sqrt(cont.fbuf[r, 0] ** 2 + cont.fbuf[r, 1] ** 2 + cont.fbuf[r, 2] ** 2)
        ratio[b] = (np.sqrt((a0 * n0) ** 2 + (a1 * n1) ** 2 + (a2 * n2) ** 2) / scale
                    if scale > 0.0 else 0.0)
        if ratio[b] > worst:
            worst = ratio[b]
            at = b
    return worst, at


@jit
def worst_place(dyn, lam):
    """Where a guard fired, for its diagnosis: the first non-finite value among the nodes'
    displacements, the reference points' displacements, the nodes' internal forces (a NaN
    displacement spreads to its elements' forces first) and the load factor ``lam``; if all are
    finite, the largest displacement of a free node DOF or a free reference-point translation.

    Returns (value: the non-finite value or the largest |U| m, kind: WHERE_NODE, WHERE_RP or
    WHERE_LOAD, index: node or reference point, 0 for the load factor)."""
    n = dyn.U.shape[0]
    for i in range(n):
        for k in range(3):
            if not np.isfinite(dyn.U[i, k]):
                return dyn.U[i, k], WHERE_NODE, i
    for p in range(dyn.rpU.shape[0]):
        for k in range(6):
            if not np.isfinite(dyn.rpU[p, k]):
                return dyn.rpU[p, k], WHERE_RP, p
    for i in range(n):
        for k in range(3):
            if not np.isfinite(dyn.fint[i, k]):
                return dyn.fint[i, k], WHERE_NODE, i
    if not np.isfinite(lam):
        return lam, WHERE_LOAD, 0
    umax = -1.0
    kind = WHERE_NODE
    worst = 0
    for i in range(n):
        for k in range(3):
            if dyn.free[i, k] > 0.0 and abs(dyn.U[i, k]) > umax:
                umax = abs(dyn.U[i, k])
                worst = i
    for p in range(dyn.rpU.shape[0]):
        for k in range(3):
            if dyn.rpfree[p, k] > 0.0 and abs(dyn.rpU[p, k]) > umax:
                umax = abs(dyn.rpU[p, k])
                kind = WHERE_RP
                worst = p
    return umax, kind, worst

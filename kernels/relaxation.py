"""Dynamic relaxation: the whole iteration loop of one load increment in compiled code.

Central differences with unit time step and fictitious masses (``minv`` = 1 / mass, chosen by the
solver from Gershgorin bounds so that the step is stable). The loop computes internal forces of
hexahedra and contact points, forms the out-of-balance force, applies the constraints (prescribed
node DOFs, rigid reference points, indirect displacement control) and damps the motion until the
out-of-balance force is small against the applied loads and reactions.

Damping schemes (``DAMP_*``): kinetic damping (velocities zeroed at every peak of the kinetic
energy, displacements moved back to the peak), viscous damping with a Rayleigh-quotient estimate of the lowest active frequency
(Underwood; DOFs that ring get more, see ``relax``), Cundall's local non-viscous damping (force reduced by ``alpha`` against the
velocity sign; the masses are raised by 1 + alpha, which the stable step needs), and FIRE (Bitzek
et al. 2006, PRL 97 170201): undamped dynamics with an adaptive step factor ``dt`` <= 1, the
velocity steered towards the force direction by the mixing factor ``a`` (``alpha`` at the start)
while the power F.v is positive, and the motion stopped (``dt`` halved, ``a`` reset) when it turns
negative. FIRE measures velocities and forces in the metric of the fictitious masses: the mixing
``v <- (1 - a) v + a |v|_M M^-1 F / |M^-1 F|_M`` (``|v|_M^2 = v.M v``, ``|M^-1 F|_M^2 = F.M^-1 F``)
never raises the kinetic energy; the reference points' DOFs take part with their masses.

Arrays are grouped in three named tuples built by ``dr_masonry.solver``: ``mesh`` (hexahedra)
and ``cont`` (contact points), the ``Mesh`` and ``Cont`` of :mod:`.forces`, and ``dyn``, the nodal
and reference-point state (the ``Dyn`` named tuple in ``dr_masonry.solver``).
"""
import numpy as np

from .assembly import gather_node, gather_pair
from .config import ijit, jit, pjit, prange
from .forces import element_and_contact_forces

DAMP_KINETIC = 0
DAMP_VISCOUS = 1
DAMP_LOCAL = 2
DAMP_FIRE = 3

# FIRE constants (Bitzek et al. 2006); the step factor is relative to the unit step of the masses
FIRE_DT_START = 0.5
FIRE_DT_MAX = 1.0
FIRE_N_MIN = 5       # steps with positive power before the step may grow
FIRE_F_INC = 1.1
FIRE_F_DEC = 0.5
FIRE_F_ALPHA = 0.99

# status codes returned in info[I_STATUS]
ST_CONVERGED = 0
ST_MAXITER = 1
ST_NONFINITE = 2
ST_RUNAWAY = 3
ST_UNSTABLE = 4  # viscous damping: the motion's Rayleigh quotient stays above the stable limit
ST_STALLED = 5   # the residual ratio did not fall below STALL_DROP x its best in stall_iter iterations
ST_SLOW = 6      # the decrease of the residual, extrapolated, does not reach tol within the budget

#: nodes per parallel task of the node passes (:func:`gather_residual`, :func:`update_nodes`)
NODE_CHUNK = 256

#: ring damping (viscous scheme): each DOF counts the sign reversals of its velocity, the count
#: multiplied by RING_MEMORY every iteration (a memory of about ten iterations); above RING_COUNT
#: (more than one reversal in five iterations: an oscillation of period < 10 iterations,
#: (omega dt)^2 > 0.4) the DOF is damped with at least the coefficient ``ring`` of ``relax``
RING_MEMORY = 0.9
RING_COUNT = 2.0

#: (omega dt)^2 of the central-difference stability limit, with a 5 % margin for the geometric
#: stiffness that the Gershgorin masses do not bound
UNSTABLE_RQ = 4.2
#: iterations above it (a count halved every UNSTABLE_WINDOW iterations) that stop an increment
UNSTABLE_COUNT = 25
UNSTABLE_WINDOW = 1000
#: progress of an increment: its residual ratio falls below this fraction of its last best
#: (0.5 cut slowly converging increments of S6 that were a few per cent above tol: 10 x the
#: iterations, BENCHMARKS.md section 13)
STALL_DROP = 0.9

# layout of the info vector
I_ITERS = 0
I_STATUS = 1
I_RESID = 2      # ||r_free|| / reference force at exit
I_KE = 3         # kinetic energy at exit (fictitious), J
I_DAMPED = 4     # energy removed by the damping (node DOFs; kinetic: KE at resets), J
I_WORST = 5      # node, reference point or 0 (see I_KIND) where the guard fired (unstable: fastest node)
I_QTY = 6        # the offending value (unstable: the Rayleigh quotient (omega dt)^2)
I_REF = 7        # reference force norm, N
I_EINT = 8       # stored energy (hexahedra + joints), J
I_OVER = 9       # unstable-step count (read and written: it carries over the calls of an increment)
I_GOAL = 10      # residual ratio that counts as progress (read and written; <= 0: none yet)
I_SINCE = 11     # iterations since the last progress (read and written)
I_LEFT = 12      # iterations left in the increment's budget at the call (set by the caller; 0: unknown)
I_BEST = 13      # best residual ratio of the increment so far (read and written)
I_WIN_R = 14     # best residual ratio at the start of the current rate window (read and written)
I_WIN_N = 15     # iterations into the rate window (read and written)
I_WIN_D = 16     # decrease of log(best ratio) over the last complete window (read and written)
I_WIN_K = 17     # complete rate windows so far (read and written)
I_SEG = 18       # iterations of the current span run by earlier calls (set by the caller; see relax)
I_KIND = 19      # what I_WORST counts: WHERE_NODE, WHERE_RP or WHERE_LOAD (the load factor)
I_KE_PREV = 20   # kinetic damping: kinetic energy of the last iteration (read and written)
I_FIRE_DT = 21   # FIRE: step factor, mixing factor and steps since the last stop (read and
I_FIRE_A = 22    # written: with I_KE_PREV the state a call that continues a span carries on)
I_FIRE_N = 23
I_BLOCK_TOL = 24  # largest block imbalance ratio accepted (set by the caller; 0: not a criterion)
I_BLOCK = 25      # largest block imbalance ratio at exit (:func:`block_imbalance`; every
                  # block's in ``dyn.bratio``)
I_BLOCK_ID = 26   # the block that has it
I_GAP_TOL = 27    # largest out-of-balance resultant ratio accepted (set by the caller; 0: not a
                  # criterion; :func:`resultant`)
N_INFO = 28

# kinds of place a guard names (info[I_KIND])
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
    worker threads (about 0.1 ms with passive OpenMP waiting, BENCHMARKS.md section 16)."""
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


@ijit
def update_chunk(lo, hi, fext, P, fint, res, free, V, U, minv, ring_count, lam, stale, scheme,
                 c_visc, alpha, ring, keep, c_mix, dt, part):
    """Nodes ``lo:hi`` of :func:`update_nodes` (one parallel task); into ``part`` (4,): kinetic
    energy, damped energy, largest finite |U| moved, non-finite U moved."""
    ke = 0.0
    damped = 0.0
    umax = 0.0
    n_bad = 0.0
    for i in range(lo, hi):
        if stale:
            node_residual(fext, P, fint, res, lam, i)
        mi = 1.0 / minv[i]
        for k in range(3):
            if free[i, k] > 0.0:
                r = res[i, k]
                v = V[i, k]
                if scheme == DAMP_LOCAL:
                    sg = 1.0 if v > 0.0 else (-1.0 if v < 0.0 else 0.0)
                    V[i, k] = v + minv[i] * (r - alpha * abs(r) * sg) / (1.0 + alpha)
                    damped += alpha * abs(r) * 0.5 * abs(v + V[i, k])
                elif scheme == DAMP_VISCOUS:
                    c = c_visc
                    if ring > 0.0 and ring_count[i, k] > RING_COUNT and ring > c:
                        c = ring
                    vn = ((2.0 - c) * v + 2.0 * minv[i] * r) / (2.0 + c)
                    if ring > 0.0:   # the counts are only read with ring damping on
                        ring_count[i, k] = (RING_MEMORY * ring_count[i, k]
                                            + (1.0 if vn * v < 0.0 else 0.0))
                    V[i, k] = vn
                    damped += c * mi * (0.5 * (v + vn)) ** 2
                elif scheme == DAMP_FIRE:
                    V[i, k] = keep * v + (c_mix + dt) * minv[i] * r
                else:
                    V[i, k] += minv[i] * r
                ke += 0.5 * mi * V[i, k] ** 2
                if scheme != DAMP_KINETIC:
                    U[i, k] += dt * V[i, k]
                    a = abs(U[i, k])
                    if not np.isfinite(a):
                        n_bad += 1.0
                    elif a > umax:
                        umax = a
    part[0] = ke
    part[1] = damped
    part[2] = umax
    part[3] = n_bad


@pjit
def update_nodes(dyn, lam, stale, scheme, c_visc, alpha, ring, keep, c_mix, dt, parts):
    """One parallel pass over the nodes: with ``stale`` (the load factor changed since the
    residual was formed) ``dyn.res`` at load factor ``lam`` first, then the velocity update
    of the free DOFs by damping ``scheme`` (parameters as in :func:`relax`: ``c_visc`` the viscous
    coefficient, ``keep``, ``c_mix`` and ``dt`` FIRE's mixing and step) and, except with kinetic
    damping (which may step back first), their displacement update U += dt V. ``parts`` as in
    :func:`gather_residual`.

    Returns (kinetic energy J, energy removed by the damping in this pass J, largest finite |U|
    moved m, number of non-finite U moved)."""
    n = dyn.U.shape[0]
    nt = (n + NODE_CHUNK - 1) // NODE_CHUNK
    for t in prange(nt):
        update_chunk(t * NODE_CHUNK, min(n, (t + 1) * NODE_CHUNK), dyn.fext, dyn.P, dyn.fint,
                     dyn.res, dyn.free, dyn.V, dyn.U, dyn.minv, dyn.ring, lam, stale, scheme,
                     c_visc, alpha, ring, keep, c_mix, dt, parts[t])
    ke = 0.0
    damped = 0.0
    umax = 0.0
    n_bad = 0
    for t in range(nt):
        ke += parts[t, 0]
        damped += parts[t, 1]
        umax = max(umax, parts[t, 2])
        n_bad += int(parts[t, 3])
    return ke, damped, umax, n_bad


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


@ijit
def reachable_decrease(d, d_prev, windows):
    """Decrease of log(residual ratio) still reachable in ``windows`` (>= 0) rate windows after
    two that decreased it by ``d_prev`` and then ``d`` (>= 0; ``d_prev`` 0: unknown): a geometric
    series of ratio q = d / d_prev when the decrease shrinks (a relaxation approaching a floor
    above tol, BENCHMARKS.md section 15), else ``d`` per window."""
    if d_prev > d > 0.0:
        q = d / d_prev
        return d * q * (1.0 - q ** windows) / (1.0 - q)
    return d * windows


@jit
def relax(mesh, cont, dyn, lam_arr, ctrl, ctrl_pc, scheme, alpha, ring, tol, ref_floor, max_iter,
          check_every, stall_iter, u_limit, info):
    """Iterate one load increment to rest.

    Parameters
    ----------
    lam_arr : (1,) float64
        magnitude of the indirectly controlled load pattern (updated in place).
    ctrl : (3,) int64
        indirect control: [kind (0 none, 1 node DOF, 2 reference-point DOF), index, dof]; the
        controlled DOF is held at its prescribed value and the pattern magnitude follows its
        reaction.
    ctrl_pc : float
        the unit pattern's (generalised) force on the controlled DOF, N (for a reference point:
        its own pattern load plus that of its tied nodes).
    scheme : int
        DAMP_* constant; ``alpha`` its parameter (local damping coefficient, the viscous
        damping scale, or FIRE's initial mixing factor alpha_start). With viscous damping the
        Rayleigh quotient (omega dt)^2 = V.dF / V.M.V of the motion (central differences are
        stable for (omega dt)^2 < 4; over the free node DOFs, or over the reference points' DOFs
        when no node DOF is free: :func:`rp_rayleigh`) is checked every iteration but the first
        of a span (whose
        dF holds the jump of the predictor or coarse correction, or forces of an earlier state
        after a restart; that iteration is undamped): ``UNSTABLE_COUNT`` iterations
        above ``UNSTABLE_RQ`` (the count ``info[I_OVER]`` halved every ``UNSTABLE_WINDOW``
        iterations; an unstable step is held bounded by opening joints, so the quotient only
        exceeds the limit now and then) stop the loop with ST_UNSTABLE.
    ring : float
        viscous scheme: damping coefficient (0 <= ring < 2) of the DOFs that ring, i.e. whose
        velocity reverses more often than every 5 iterations (``RING_COUNT``; the counts
        ``dyn.ring`` restart with each span); 0: none. The Rayleigh quotient is that of the
        whole motion, and a local oscillation at high frequency (joints sliding and sticking
        under a slab, or chattering at a crack) dominates it: the coefficient then suits neither
        that oscillation, which frictional joints keep going, nor the slow motion that is left
        (BENCHMARKS.md section 27).
    tol : float
        converged when ||r_free|| <= tol * max(reference, ref_floor) (``ref_floor``: N, the
        smallest reference force that counts, for an unloaded model) and, with
        ``info[I_BLOCK_TOL]`` > 0, every block's imbalance ratio (:func:`block_imbalance`) is at
        most ``info[I_BLOCK_TOL]``; the stall and rate tests below then follow the larger of the
        residual ratio and the block ratio scaled by tol / ``info[I_BLOCK_TOL]``; likewise, with
        ``info[I_GAP_TOL]`` > 0, the out-of-balance resultant's ratio (:func:`resultant`) must
        be at most ``info[I_GAP_TOL]``.
    max_iter : int
        iterations of this call at most (ST_MAXITER when they run out).
    check_every : int
        the residual norm, convergence, stall and budget are checked on the span's iterations
        that are multiples of it (and its first).
    stall_iter : int
        stop with ST_STALLED when the residual ratio has not fallen below ``STALL_DROP`` times
        its best value for this many iterations (a relaxation that hovers above ``tol``, e.g.
        joints chattering at a mechanism's onset; the solver cuts the increment); 0: never.
        The progress marks ``info[I_GOAL]``, ``info[I_SINCE]`` carry over the calls of an
        increment. Every ``stall_iter`` iterations the decrease of the best residual ratio over
        that window is also extrapolated over the windows left of the increment's budget
        (``info[I_LEFT]`` minus the iterations of this call; :func:`reachable_decrease`): an
        attempt that cannot reach ``tol`` in them (converging steadily but too slowly, or
        towards a floor above tol) stops with ST_SLOW. ``info[I_LEFT]`` = 0: no budget known,
        no such test.
    u_limit : float
        run-away guard: a free node DOF's or a free reference-point translation's displacement
        above it (m) stops the loop (ST_RUNAWAY; non-finite: ST_NONFINITE); ``info[I_WORST]``,
        ``info[I_KIND]`` name the place (:func:`worst_place`).
    info : (N_INFO,) float64 written.

    A call may continue the previous one: ``info[I_SEG]`` > 0 is the number of iterations that
    earlier calls ran since the state was last moved from outside (the increment's predictor, a
    coarse correction). The checks, the unstable-step window and the first-iteration exemption
    then count on from there, and kinetic damping's last kinetic energy and FIRE's step, mixing
    factor and count (``info[I_KE_PREV]``, ``info[I_FIRE_*]``) carry over, so that a relaxation
    split into calls of a multiple of ``check_every`` iterations is bit for bit the uninterrupted
    one (the solver splits long spans to return to Python regularly: progress, Ctrl-C).
    """
    n = dyn.U.shape[0]
    nr = dyn.rpX.shape[0]
    rpres = np.zeros((nr, 6))
    lam = lam_arr[0]
    damped = 0.0
    status = ST_MAXITER
    it = 0
    rn = 0.0
    ref = 0.0
    ke = 0.0
    eint = 0.0
    worst = 0
    kind = WHERE_NODE
    qty = 0.0
    # viscous damping: Rayleigh quotient with the previous internal force (of the reference
    # points when they are all that moves: a rigid block on a fixed one)
    fprev = dyn.fint.copy()
    rp_only = scheme == DAMP_VISCOUS and nr > 0 and not np.any(dyn.free > 0.0)
    gprev = np.zeros((nr, 6))
    if rp_only:
        rp_residual(dyn, lam, rpres)
        rp_rayleigh(dyn, lam, rpres, gprev)
    seg = int(info[I_SEG])
    # kinetic damping: the last kinetic energy; FIRE: step factor, mixing factor, steps since
    # the last stop (a call that continues a span carries them on)
    ke_prev = info[I_KE_PREV] if seg > 0 else 0.0
    dt = (info[I_FIRE_DT] if seg > 0 else FIRE_DT_START) if scheme == DAMP_FIRE else 1.0
    a_mix = info[I_FIRE_A] if seg > 0 and scheme == DAMP_FIRE else alpha
    n_pos = int(info[I_FIRE_N]) if seg > 0 else 0
    n_over = info[I_OVER]
    goal = info[I_GOAL]
    since = info[I_SINCE]
    left = info[I_LEFT]
    best = info[I_BEST]
    win_r = info[I_WIN_R]
    win_n = info[I_WIN_N]
    win_d = info[I_WIN_D]
    win_k = info[I_WIN_K]
    last_check = seg
    block_tol = info[I_BLOCK_TOL]
    gap_tol = info[I_GAP_TOL]
    if seg == 0:
        dyn.ring[:] = 0.0
    hbuf = mesh.fbuf.reshape((-1, 3))
    parts = np.zeros(((n + NODE_CHUNK - 1) // NODE_CHUNK, 4))   # per-task sums of the node passes
    place_rigid_nodes(dyn)
    for it in range(1, max_iter + 1):
        its = seg + it   # iteration of the span
        # forces, then one pass over the nodes: gathered forces, residual, the Rayleigh sums
        element_and_contact_forces(dyn.X, dyn.U, mesh, cont)
        num, den = gather_residual(hbuf, mesh.ptr, mesh.rows, cont, dyn, lam, fprev,
                                   scheme == DAMP_VISCOUS, parts)
        # indirect displacement control: pattern magnitude follows the reaction of the held DOF
        # (the node residuals at the new factor are formed where they are read next: below when
        # the whole residual is needed before the update, else in ``update_nodes``)
        if ctrl[0] == 1:
            lam -= dyn.res[ctrl[1], ctrl[2]] / ctrl_pc
        elif ctrl[0] == 2:
            rp_residual(dyn, lam, rpres)
            lam -= rpres[ctrl[1], ctrl[2]] / ctrl_pc
        check = its % check_every == 0 or its == 1
        whole = check or scheme == DAMP_FIRE or scheme == DAMP_KINETIC
        if whole:   # the whole residual at the new factor is read before the node update
            if ctrl[0] != 0:
                residual(dyn, lam, rpres)
            else:
                rp_residual(dyn, lam, rpres)
        if check:
            rn, ref = norms(dyn, lam, rpres)
            if not (np.isfinite(rn) and np.isfinite(lam)):
                status = ST_NONFINITE
                qty, kind, worst = worst_place(dyn, lam)
                break
            done = rn <= tol * max(ref, ref_floor)
            ratio = rn / max(ref, ref_floor)
            if block_tol > 0.0:   # the blocks' balance too, scaled onto the ratio's tol
                rb = tol * block_imbalance(cont, dyn, lam, dyn.bratio)[0] / block_tol
                done = done and rb <= tol
                ratio = max(ratio, rb)
            if gap_tol > 0.0:   # the resultant too, scaled the same way
                rg = tol * resultant(dyn, lam, rpres)[0] / gap_tol
                done = done and rg <= tol
                ratio = max(ratio, rg)
            if done and its > 1:
                status = ST_CONVERGED
                break
            if ratio <= goal or goal <= 0.0:
                goal = STALL_DROP * ratio
                since = 0.0
            else:
                since += its - last_check
            if ratio < best or best <= 0.0:
                best = ratio
            if win_r <= 0.0:
                win_r = best
            win_n += its - last_check
            last_check = its
            if stall_iter > 0 and since >= stall_iter:
                status = ST_STALLED
                qty = ratio
                break
            if stall_iter > 0 and win_n >= stall_iter:
                # can the windows left of the budget bring the best ratio down to tol?
                d = np.log(win_r / best) if best < win_r else 0.0
                d_prev = win_d if win_k >= 2.0 else 0.0   # the first window holds the transient
                if left > 0.0 and (reachable_decrease(d, d_prev, (left - it) / win_n)
                                   < np.log(best / tol)):
                    status = ST_SLOW
                    qty = ratio
                    break
                win_r = best
                win_n = 0.0
                win_d = d
                win_k += 1.0
        # ---- velocity update ----------------------------------------------------------
        c_visc = 0.0
        if rp_only:
            if not whole:
                rp_residual(dyn, lam, rpres)
            num, den = rp_rayleigh(dyn, lam, rpres, gprev)
        if scheme == DAMP_VISCOUS:
            if den > 0.0 and num > 0.0 and its > 1:
                c_visc = alpha * 2.0 * np.sqrt(num / den)
            if c_visc > 1.9:
                c_visc = 1.9
            if its > 1 and num > UNSTABLE_RQ * den > 0.0:
                n_over += 1.0
            if its % UNSTABLE_WINDOW == 0:
                n_over *= 0.5
            if n_over >= UNSTABLE_COUNT:
                status = ST_UNSTABLE
                qty = num / den
                vmax = -1.0
                for i in range(n):
                    for k in range(3):
                        if dyn.free[i, k] > 0.0 and abs(dyn.V[i, k]) > vmax:
                            vmax = abs(dyn.V[i, k])
                            worst = i
                break
        # FIRE: v <- keep v + (c_mix + dt) M^-1 r (mixing, then the semi-implicit Euler step)
        keep = 1.0
        c_mix = 0.0
        if scheme == DAMP_FIRE:
            pw = 0.0   # power F.v, W
            vmv = 0.0  # v.M v = 2 KE
            fmf = 0.0  # F.M^-1 F
            for i in range(n):
                for k in range(3):
                    if dyn.free[i, k] > 0.0:
                        r = dyn.res[i, k]
                        v = dyn.V[i, k]
                        pw += r * v
                        vmv += v * v / dyn.minv[i]
                        fmf += r * r * dyn.minv[i]
            for p in range(nr):
                for k in range(6):
                    if dyn.rpfree[p, k] > 0.0:
                        r = rpres[p, k]
                        v = dyn.rpV[p, k]
                        pw += r * v
                        vmv += v * v / dyn.rpminv[p, k]
                        fmf += r * r * dyn.rpminv[p, k]
            if pw < 0.0:
                # moving uphill: stop, shorten the step, restart the mixing
                # (P = 0 only at rest, where there is nothing to stop)
                damped += 0.5 * vmv
                keep = 0.0
                # back half a step, to about where the power changed sign (FIRE 2.0)
                for i in range(n):
                    for k in range(3):
                        if dyn.free[i, k] > 0.0:
                            dyn.U[i, k] -= 0.5 * dt * dyn.V[i, k]
                for p in range(nr):
                    for k in range(6):
                        if dyn.rpfree[p, k] > 0.0:
                            dyn.rpU[p, k] -= 0.5 * dt * dyn.rpV[p, k]
                dt *= FIRE_F_DEC
                a_mix = alpha
                n_pos = 0
            else:
                n_pos += 1
                if n_pos > FIRE_N_MIN:
                    dt = min(dt * FIRE_F_INC, FIRE_DT_MAX)
                    a_mix *= FIRE_F_ALPHA
                if fmf > 0.0:
                    keep = 1.0 - a_mix
                    c_mix = a_mix * np.sqrt(vmv / fmf)
                    # |v_mixed|_M^2 = keep^2 vmv + 2 keep c_mix pw + c_mix^2 fmf <= vmv
                    damped += 0.5 * (vmv - keep * keep * vmv - 2.0 * keep * c_mix * pw
                                     - c_mix * c_mix * fmf)
        ke, dmp, umax, n_bad = update_nodes(dyn, lam, ctrl[0] != 0 and not whole, scheme, c_visc,
                                            alpha, ring, keep, c_mix, dt, parts)
        damped += dmp
        if not whole:   # (the reference points have not moved since the gather)
            rp_residual(dyn, lam, rpres)
        for p in range(nr):
            for k in range(6):
                if dyn.rpfree[p, k] > 0.0:
                    r = rpres[p, k]
                    if scheme == DAMP_VISCOUS:
                        dyn.rpV[p, k] = ((2.0 - c_visc) * dyn.rpV[p, k] + 2.0 * dyn.rpminv[p, k] * r) / (2.0 + c_visc)
                    elif scheme == DAMP_FIRE:
                        dyn.rpV[p, k] = keep * dyn.rpV[p, k] + (c_mix + dt) * dyn.rpminv[p, k] * r
                    else:
                        if scheme == DAMP_LOCAL:
                            v = dyn.rpV[p, k]
                            sg = 1.0 if v > 0.0 else (-1.0 if v < 0.0 else 0.0)
                            r = (r - alpha * abs(r) * sg) / (1.0 + alpha)
                        dyn.rpV[p, k] += dyn.rpminv[p, k] * r
                    ke += 0.5 * dyn.rpV[p, k] ** 2 / dyn.rpminv[p, k]
        if scheme == DAMP_KINETIC:
            if ke < ke_prev:
                # kinetic-energy peak passed: stop every velocity and go back to the peak, half
                # a step before U: U* = U - v_old / 2 with v_old = V - minv r (Barnes, Cundall)
                damped += ke
                for i in range(n):
                    for k in range(3):
                        if dyn.free[i, k] > 0.0:
                            dyn.U[i, k] -= 0.5 * (dyn.V[i, k] - dyn.minv[i] * dyn.res[i, k])
                for p in range(nr):
                    for k in range(6):
                        if dyn.rpfree[p, k] > 0.0:
                            dyn.rpU[p, k] -= 0.5 * (dyn.rpV[p, k] - dyn.rpminv[p, k] * rpres[p, k])
                dyn.V[:] = 0.0
                dyn.rpV[:] = 0.0
                ke = 0.0
            ke_prev = ke
        # ---- displacement update (node DOFs: above, except with kinetic damping) -----------
        if scheme == DAMP_KINETIC:
            for i in range(n):
                for k in range(3):
                    if dyn.free[i, k] > 0.0:
                        dyn.U[i, k] += dt * dyn.V[i, k]
                        a = abs(dyn.U[i, k])
                        if not np.isfinite(a):
                            n_bad += 1
                        elif a > umax:
                            umax = a
        for p in range(nr):
            for k in range(6):
                if dyn.rpfree[p, k] > 0.0:
                    dyn.rpU[p, k] += dt * dyn.rpV[p, k]
                    a = abs(dyn.rpU[p, k])
                    if not np.isfinite(a):
                        n_bad += 1
                    elif k < 3 and a > umax:
                        umax = a
        place_rigid_nodes(dyn)
        if n_bad > 0 or umax > u_limit:
            qty, kind, worst = worst_place(dyn, lam)
            status = ST_NONFINITE if n_bad > 0 else ST_RUNAWAY
            break
    if it > 0:
        eint = stored_energy(mesh, cont)
    lam_arr[0] = lam
    info[I_ITERS] = it
    info[I_STATUS] = status
    info[I_RESID] = rn / max(ref, ref_floor)
    if it > 0:
        info[I_BLOCK], info[I_BLOCK_ID] = block_imbalance(cont, dyn, lam, dyn.bratio)
    info[I_KE] = ke
    info[I_DAMPED] = damped
    info[I_GOAL] = goal
    info[I_SINCE] = since
    info[I_BEST] = best
    info[I_WIN_R] = win_r
    info[I_WIN_N] = win_n
    info[I_WIN_D] = win_d
    info[I_WIN_K] = win_k
    info[I_WORST] = worst
    info[I_KIND] = kind
    info[I_KE_PREV] = ke_prev
    info[I_FIRE_DT] = dt
    info[I_FIRE_A] = a_mix
    info[I_FIRE_N] = n_pos
    info[I_QTY] = qty
    info[I_REF] = ref
    info[I_EINT] = eint
    info[I_OVER] = n_over

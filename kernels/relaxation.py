"""Dynamic relaxation: the iteration loop of one load increment in compiled code, viscous damping.

Central differences with unit time step and fictitious masses (``minv`` = 1 / mass, chosen by the
solver from Gershgorin bounds so that the step is stable). Each iteration computes the internal
forces of hexahedra and contact points, forms the out-of-balance force, applies the constraints
(prescribed node DOFs, rigid reference points, indirect displacement control) and damps the
motion with a viscous coefficient from the Rayleigh-quotient estimate of the lowest active
frequency (Underwood), raised on DOFs that ring, until the out-of-balance force is small against
the applied loads and reactions. The other damping schemes (kinetic, local, FIRE), which no
default run uses, are in :mod:`.damping_schemes`.

The loop exchanges three named records with its caller:

* :data:`Criteria` (read): when to stop;
* :data:`Progress` (read and returned): what carries over the calls of one increment (a long
  increment is relaxed in calls of a few thousand iterations, so that Python regains control);
* :data:`Exit` (returned): how the call ended.

Arrays come in the solver's named tuples ``mesh``, ``cont`` (:mod:`.forces`) and ``dyn``.
"""
from collections import namedtuple

import numpy as np

from .balance import (NODE_CHUNK, WHERE_NODE, block_imbalance, gather_residual, node_residual,
                      norms, place_rigid_nodes, residual, resultant, rp_rayleigh, rp_residual,
                      stored_energy, worst_place)
# the names of the force assembly, its gather and the places a guard names, as the solver and
# precompile use them
from .balance import WHERE_LOAD, WHERE_RP, gather_pair, internal_forces  # noqa: F401
from .config import ijit, jit, pjit, prange
from .forces import element_and_contact_forces

# how a call ended (``Exit.status``)
ST_CONVERGED = 0
ST_MAXITER = 1
ST_NONFINITE = 2
ST_RUNAWAY = 3
ST_UNSTABLE = 4  # the motion's Rayleigh quotient stays above the stable limit
ST_STALLED = 5   # the ratio did not fall below STALL_DROP x its best in stall_iter iterations
ST_SLOW = 6      # the decrease of the residual, extrapolated, does not reach tol within the budget

#: ring damping: each DOF counts the sign reversals of its velocity, the count multiplied by
#: RING_MEMORY every iteration (a memory of about ten iterations); above RING_COUNT (more than
#: one reversal in five iterations: an oscillation of period < 10 iterations, (omega dt)^2 > 0.4)
#: the DOF is damped with at least the coefficient ``ring`` of ``relax``
RING_MEMORY = 0.9
RING_COUNT = 2.0
#: (omega dt)^2 of the central-difference stability limit, with a 5 % margin for the geometric
#: stiffness that the Gershgorin masses do not bound
UNSTABLE_RQ = 4.2
#: iterations above UNSTABLE_RQ (the count halved every UNSTABLE_WINDOW) that stop the loop
UNSTABLE_COUNT = 25
UNSTABLE_WINDOW = 1000
#: a residual ratio below this fraction of the best so far counts as progress (stall rule)
STALL_DROP = 0.9

#: when a call stops. tol: converged when ||r_free|| <= tol * max(reference, ref_floor) (N, the
#: smallest reference force that counts, for an unloaded model) and, with block_tol > 0, every
#: block's imbalance ratio (``balance.block_imbalance``) is at most block_tol, and with gap_tol
#: > 0 the out-of-balance resultant's ratio (``balance.resultant``) at most gap_tol; the stall
#: and rate rules follow the largest of these ratios, each scaled onto tol. check_every: the
#: iterations of a span that are multiples of it (and its first) check convergence, stall and
#: budget. stall_iter: ST_STALLED after this many iterations without the ratio falling below
#: STALL_DROP x its best; every stall_iter iterations the decrease of the best ratio is also
#: extrapolated over the windows left of the budget ``left`` (iterations left in the increment
#: at the call; 0: unknown, no such test) and an attempt that cannot reach tol stops with
#: ST_SLOW; 0: neither rule. u_limit: m, a free DOF's displacement above it stops the loop
#: (ST_RUNAWAY; non-finite: ST_NONFINITE). max_iter: iterations of this call at most.
Criteria = namedtuple("Criteria", "tol ref_floor block_tol gap_tol check_every stall_iter "
                                  "u_limit left max_iter")
#: carried over the calls of one increment: seg, the iterations of the current span run by
#: earlier calls (0: the state was just moved from outside, by the predictor or a coarse
#: correction: the span's first iteration is undamped and checked, the ring counts restart);
#: n_over, the unstable-iteration count; goal, since: the ratio that counts as progress and the
#: iterations since it was last reached; best: the best ratio; win_r, win_n, win_d, win_k: the
#: rate window's best ratio at its start, its iterations, the last window's decrease of
#: log(best), the windows completed; mu: the held :data:`Constraint`'s reaction N at the last
#: iteration (what a constraint with a ``gain`` moves the load factor by); gmul, msign, msince:
#: the multiple (0, 1] of the constraint's gain in use, the sign of its reaction at the last check
#: that found it above tolerance (0: none yet) and the iterations since that sign last reversed
#: (:func:`adapt_gain`). A call that continues a span is bit for bit the same relaxation as one
#: uninterrupted call.
Progress = namedtuple("Progress", "seg n_over goal since best win_r win_n win_d win_k mu gmul "
                                  "msign msince")
#: how a call ended: status ``ST_*``; iterations of the call; residual ratio ||r|| / reference
#: and the ratio that counts against tol (the largest of it, the blocks' ratio scaled by tol /
#: block_tol and, with gap_tol, the resultant's scaled by tol / gap_tol), both of the last check;
#: kinetic energy J and damped energy J of the call; stored energy J; the reference force N; the
#: largest block imbalance ratio and its block; where, where_kind: the node, reference point or
#: load factor a guard named (``WHERE_*``; unstable: the fastest node); quantity: the offending
#: value (run-away displacement m, Rayleigh quotient, stalled ratio); reaction: the force N of
#: the held :data:`Constraint` at the last check (0 without one).
Exit = namedtuple("Exit", "status iterations residual ratio kinetic damped stored ref "
                          "block_ratio block where where_kind quantity reaction")
#: a held linear combination of node displacements, sum_i coef[i] U[node[i], dof[i]] = target (m):
#: at the start of a call the displacements and velocities are projected onto it in the metric
#: of the masses, and every iteration the residual gets the constraint's force coef * reaction
#: that leaves it no acceleration along the constraint (so the motion keeps it); ``Exit.reaction``
#: (N) is that force's magnitude at the last check. An opening control (``loading.Opening``) holds
#: a joint's opening this way. ``gain`` (per N and iteration, 0: none): the load factor relaxes
#: with the motion, lam -= gmul x gain x reaction every iteration (``Progress.gmul``, cut when
#: the factor overshoots: :func:`adapt_gain`; ``settle``: the iterations the factor needs to move
#: by its whole correction at the full gain, 1 / ``Opening.rate``), and a check converges only
#: with the reaction within tol x the reference force. No entries: no constraint.
Constraint = namedtuple("Constraint", "node dof coef target gain settle")


def no_constraint():
    """The :data:`Constraint` of an increment that holds nothing."""
    return Constraint(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), 0.0, 0.0, 0.0)


#: what an overshoot of a held constraint's reaction multiplies the factor's gain by
GAIN_CUT = 0.5


def start_progress(gmul=1.0):
    """The :data:`Progress` of an increment's first call; ``gmul``: the multiple of a held
    constraint's gain to start with."""
    return Progress(0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, float(gmul), 0.0, 0.0)


@ijit
def adapt_gain(mu, tol_n, gmul, msign, msince, settle, step):
    """The gain multiple of a held constraint after a check ``step`` iterations after the last
    one that found its reaction ``mu`` N; returns (gmul, msign, msince) (:data:`Progress`).

    A reaction within ``tol_n`` N changes nothing. Above it, a sign opposite to ``msign`` is a
    reversal: when the sign held for at least ``settle / gmul`` iterations, the time the factor
    takes to move by its whole correction, the factor has overshot its equilibrium (a structure
    that relaxes more slowly than the factor moves makes the pair cycle round it, BENCHMARKS.md
    "Path-following controls") and ``gmul`` is multiplied by ``GAIN_CUT``; faster reversals are
    the structure's vibration, which the factor does not follow."""
    msince += step
    if abs(mu) <= tol_n:
        return gmul, msign, msince
    if msign * mu < 0.0:
        if msince >= settle / gmul:
            gmul *= GAIN_CUT
        msince = 0.0
    return gmul, 1.0 if mu > 0.0 else -1.0, msince


@ijit
def reachable_decrease(d, d_prev, windows):
    """Decrease of log(residual ratio) still reachable in ``windows`` (>= 0) rate windows after
    two that decreased it by ``d_prev`` and then ``d`` (>= 0; ``d_prev`` 0: unknown): a geometric
    series of ratio q = d / d_prev when the decrease shrinks (a relaxation approaching a floor
    above tol), else ``d`` per window."""
    if d_prev > d > 0.0:
        q = d / d_prev
        return d * q * (1.0 - q ** windows) / (1.0 - q)
    return d * windows


@jit
def check(cont, dyn, lam, rpres, crit, pr, its, it, last, fc):
    """The convergence check of span iteration ``its`` (call iteration ``it``; ``last``: the span
    iteration of the previous check), after the residual at factor ``lam`` was formed; ``fc`` N:
    the norm of a held constraint's force, which counts in the reference as a support's reaction
    does (0: none).

    Returns (status: ST_MAXITER to go on, the ratio counted against tol, rn and ref N: the norms
    of :func:`balance.norms`, the resultant's ratio scaled onto tol, the updated
    :data:`Progress`)."""
    rn, ref = norms(dyn, lam, rpres)
    if fc > 0.0:
        ref = np.sqrt(ref * ref + fc * fc)
    if not (np.isfinite(rn) and np.isfinite(lam)):
        return ST_NONFINITE, np.nan, rn, ref, 0.0, pr
    tol = crit.tol
    done = rn <= tol * max(ref, crit.ref_floor)
    ratio = rn / max(ref, crit.ref_floor)
    rg = 0.0
    if crit.block_tol > 0.0:   # the blocks' balance too, scaled onto the ratio's tol
        rb = tol * block_imbalance(cont, dyn, lam, dyn.bratio)[0] / crit.block_tol
        done = done and rb <= tol
        ratio = max(ratio, rb)
    if crit.gap_tol > 0.0:   # the resultant too, scaled the same way
        rg = tol * resultant(dyn, lam, rpres)[0] / crit.gap_tol
        done = done and rg <= tol
        ratio = max(ratio, rg)
    goal, since, best = pr.goal, pr.since, pr.best
    win_r, win_n, win_d, win_k = pr.win_r, pr.win_n, pr.win_d, pr.win_k
    status = ST_MAXITER
    if done and its > 1:
        status = ST_CONVERGED
    else:
        if ratio <= goal or goal <= 0.0:
            goal = STALL_DROP * ratio
            since = 0.0
        else:
            since += its - last
        if ratio < best or best <= 0.0:
            best = ratio
        if win_r <= 0.0:
            win_r = best
        win_n += its - last
        stall = crit.stall_iter
        if stall > 0 and since >= stall:
            status = ST_STALLED
        elif stall > 0 and win_n >= stall:
            # can the windows left of the budget bring the best ratio down to tol?
            d = np.log(win_r / best) if best < win_r else 0.0
            d_prev = win_d if win_k >= 2.0 else 0.0   # the first window holds the transient
            if crit.left > 0.0 and (reachable_decrease(d, d_prev, (crit.left - it) / win_n)
                                    < np.log(best / tol)):
                status = ST_SLOW
            else:
                win_r = best
                win_n = 0.0
                win_d = d
                win_k += 1.0
    return status, ratio, rn, ref, rg, Progress(pr.seg, pr.n_over, goal, since, best, win_r,
                                                win_n, win_d, win_k, pr.mu, pr.gmul, pr.msign,
                                                pr.msince)


@ijit
def update_chunk(lo, hi, fext, P, fint, res, free, V, U, minv, ring_count, lam, stale, c_visc,
                 ring, part):
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
                c = c_visc
                if ring > 0.0 and ring_count[i, k] > RING_COUNT and ring > c:
                    c = ring
                vn = ((2.0 - c) * v + 2.0 * minv[i] * r) / (2.0 + c)
                if ring > 0.0:   # the counts are only read with ring damping on
                    ring_count[i, k] = (RING_MEMORY * ring_count[i, k]
                                        + (1.0 if vn * v < 0.0 else 0.0))
                V[i, k] = vn
                damped += c * mi * (0.5 * (v + vn)) ** 2
                ke += 0.5 * mi * vn ** 2
                U[i, k] += vn
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
def update_nodes(dyn, lam, stale, c_visc, ring, parts):
    """One parallel pass over the nodes: with ``stale`` (the load factor changed since the
    residual was formed) ``dyn.res`` at load factor ``lam`` first, then the damped velocity
    update of the free DOFs (viscous coefficient ``c_visc``, ``ring`` as in :func:`relax`) and
    their displacement update U += V. ``parts`` (>= tasks, 4) scratch.

    Returns (kinetic energy J, energy removed by the damping in this pass J, largest finite |U|
    moved m, number of non-finite U moved)."""
    n = dyn.U.shape[0]
    nt = (n + NODE_CHUNK - 1) // NODE_CHUNK
    for t in prange(nt):
        update_chunk(t * NODE_CHUNK, min(n, (t + 1) * NODE_CHUNK), dyn.fext, dyn.P, dyn.fint,
                     dyn.res, dyn.free, dyn.V, dyn.U, dyn.minv, dyn.ring, lam, stale, c_visc,
                     ring, parts[t])
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
def control_factor(dyn, lam, ctrl, ctrl_pc, rpres):
    """Indirect displacement control: the load factor after ``lam`` that cancels the reaction of
    the held DOF ``ctrl`` = [kind (0 none, 1 node DOF, 2 reference-point DOF), index, dof]
    (``ctrl_pc``: the unit pattern's force on it, N); ``rpres`` is formed for kind 2."""
    if ctrl[0] == 1:
        return lam - dyn.res[ctrl[1], ctrl[2]] / ctrl_pc
    if ctrl[0] == 2:
        rp_residual(dyn, lam, rpres)
        return lam - rpres[ctrl[1], ctrl[2]] / ctrl_pc
    return lam


@jit
def rp_step(dyn, rpres, c_visc, ke):
    """Damped velocity and displacement update of the free reference-point DOFs (generalised
    residual ``rpres`` (n_rp, 6)). Returns (``ke`` J plus their kinetic energy, largest finite
    |translation| m, number of non-finite values)."""
    umax = 0.0
    n_bad = 0
    for p in range(dyn.rpX.shape[0]):
        for k in range(6):
            if dyn.rpfree[p, k] > 0.0:
                dyn.rpV[p, k] = (((2.0 - c_visc) * dyn.rpV[p, k] + 2.0 * dyn.rpminv[p, k]
                                  * rpres[p, k]) / (2.0 + c_visc))
                ke += 0.5 * dyn.rpV[p, k] ** 2 / dyn.rpminv[p, k]
    for p in range(dyn.rpX.shape[0]):
        for k in range(6):
            if dyn.rpfree[p, k] > 0.0:
                dyn.rpU[p, k] += dyn.rpV[p, k]
                a = abs(dyn.rpU[p, k])
                if not np.isfinite(a):
                    n_bad += 1
                elif k < 3 and a > umax:
                    umax = a
    return ke, umax, n_bad


@jit
def fastest_node(dyn):
    """The free node with the largest velocity component (the unstable step's diagnosis)."""
    vmax = -1.0
    worst = 0
    for i in range(dyn.U.shape[0]):
        for k in range(3):
            if dyn.free[i, k] > 0.0 and abs(dyn.V[i, k]) > vmax:
                vmax = abs(dyn.V[i, k])
                worst = i
    return worst


@jit
def hold(dyn, con):
    """Project ``dyn.U`` and ``dyn.V`` onto the :data:`Constraint` ``con`` (mass metric)."""
    m = con.node.shape[0]
    if m == 0:
        return
    q, qv, s = 0.0, 0.0, 0.0
    for k in range(m):
        i, d, c = con.node[k], con.dof[k], con.coef[k]
        q += c * dyn.U[i, d]
        qv += c * dyn.V[i, d]
        s += c * c * dyn.minv[i]
    for k in range(m):
        i, d, c = con.node[k], con.dof[k], con.coef[k]
        dyn.U[i, d] += c * dyn.minv[i] * (con.target - q) / s
        dyn.V[i, d] -= c * dyn.minv[i] * qv / s


@jit
def constraint_force(dyn, con):
    """Add the :data:`Constraint`'s force to ``dyn.res``: the multiple ``reaction`` of ``coef``
    that leaves the residual without acceleration along it; returns (``reaction`` N, the norm
    of the force, N)."""
    m = con.node.shape[0]
    if m == 0:
        return 0.0, 0.0
    num, s, cc = 0.0, 0.0, 0.0
    for k in range(m):
        i, d, c = con.node[k], con.dof[k], con.coef[k]
        num += c * dyn.minv[i] * dyn.res[i, d]
        s += c * c * dyn.minv[i]
        cc += c * c
    mu = -num / s
    for k in range(m):
        dyn.res[con.node[k], con.dof[k]] += con.coef[k] * mu
    return mu, abs(mu) * np.sqrt(cc)


@jit
def finish(mesh, cont, dyn, lam, crit, status, it, rn, ref, rg, ke, damped, worst, kind, qty,
           mu):
    """The :data:`Exit` of a call that ran ``it`` iterations (shared with
    :mod:`.damping_schemes`)."""
    eint = stored_energy(mesh, cont) if it > 0 else 0.0
    block, at = block_imbalance(cont, dyn, lam, dyn.bratio) if it > 0 else (0.0, -1)
    resid = rn / max(ref, crit.ref_floor)
    ratio = resid
    if crit.block_tol > 0.0:
        ratio = max(ratio, crit.tol * block / crit.block_tol)
    if crit.gap_tol > 0.0:
        ratio = max(ratio, rg)
    return Exit(status, it, resid, ratio, ke, damped, eint, ref, block, at, worst, kind, qty, mu)


@jit
def relax(mesh, cont, dyn, lam_arr, ctrl, ctrl_pc, alpha, ring, crit, pr, con):
    """Iterate one load increment to rest; returns (:data:`Exit`, the :data:`Progress` to pass
    to the next call of the increment, its ``seg`` counted on).

    Parameters
    ----------
    lam_arr : (1,) float64
        magnitude of the indirectly controlled load pattern (updated in place).
    ctrl : (3,) int64
        indirect control: [kind (0 none, 1 node DOF, 2 reference-point DOF), index, dof]; the
        controlled DOF is held at its prescribed value and the pattern magnitude follows its
        reaction (:func:`control_factor`).
    ctrl_pc : float
        the unit pattern's (generalised) force on the controlled DOF, N.
    alpha : float
        fraction of the critical damping of the Rayleigh-quotient frequency: (omega dt)^2 =
        V.dF / V.M.V of the motion (over the free node DOFs, or over the reference points' DOFs
        when no node DOF is free), checked every iteration but the first of a span (whose dF
        holds the jump of the predictor or coarse correction; that iteration is undamped).
        ``UNSTABLE_COUNT`` iterations above ``UNSTABLE_RQ`` stop the loop with ST_UNSTABLE
        (central differences are stable below 4).
    ring : float
        damping coefficient (0 <= ring < 2) of the DOFs that ring, i.e. whose velocity reverses
        more often than every 5 iterations (``RING_COUNT``); 0: none. The Rayleigh quotient is
        that of the whole motion, and a local oscillation at high frequency (joints sliding and
        sticking under a slab, or chattering at a crack) dominates it.
    crit : :data:`Criteria`
    pr : :data:`Progress`
    con : :data:`Constraint` (``no_constraint()``: none)
    """
    n = dyn.U.shape[0]
    nr = dyn.rpX.shape[0]
    rpres = np.zeros((nr, 6))
    lam = lam_arr[0]
    damped = 0.0
    status = ST_MAXITER
    it = 0
    rn, ref, rg, ke, qty = 0.0, 0.0, 0.0, 0.0, 0.0
    worst = 0
    kind = WHERE_NODE
    n_over = pr.n_over
    fprev = dyn.fint.copy()   # the Rayleigh quotient's previous internal force
    rp_only = nr > 0 and not np.any(dyn.free > 0.0)   # a rigid block on a fixed one
    gprev = np.zeros((nr, 6))
    if rp_only:
        rp_residual(dyn, lam, rpres)
        rp_rayleigh(dyn, lam, rpres, gprev)
    seg = pr.seg
    last = seg
    if seg == 0:
        dyn.ring[:] = 0.0
    hbuf = mesh.fbuf.reshape((-1, 3))
    parts = np.zeros(((n + NODE_CHUNK - 1) // NODE_CHUNK, 4))   # per-task sums of the node passes
    mu = pr.mu
    gmul, msign, msince = pr.gmul, pr.msign, pr.msince
    place_rigid_nodes(dyn)
    hold(dyn, con)
    for it in range(1, crit.max_iter + 1):
        its = seg + it   # iteration of the span
        if con.gain != 0.0 and its > 1:   # the factor relaxes with the held constraint
            lam -= gmul * con.gain * mu
        # forces, then one pass over the nodes: gathered forces, residual, the Rayleigh sums
        element_and_contact_forces(dyn.X, dyn.U, mesh, cont)
        num, den = gather_residual(hbuf, mesh.ptr, mesh.rows, cont, dyn, lam, fprev, True, parts)
        # (the node residuals at the new factor are formed where they are read next: below when
        # the whole residual is needed before the update, else in ``update_nodes``)
        lam = control_factor(dyn, lam, ctrl, ctrl_pc, rpres)
        mu, fc = constraint_force(dyn, con)   # (no constraint: nothing)
        whole = its % crit.check_every == 0 or its == 1
        if whole:   # a check: the whole residual at the new factor before the node update
            if ctrl[0] != 0:
                residual(dyn, lam, rpres)
            else:
                rp_residual(dyn, lam, rpres)
            status, ratio, rn, ref, rg, pr = check(cont, dyn, lam, rpres, crit, pr, its, it, last,
                                                   fc)
            if con.gain != 0.0:
                tol_n = crit.tol * max(ref, crit.ref_floor)
                if status == ST_CONVERGED and abs(mu) > tol_n:
                    status = ST_MAXITER   # balanced only with the constraint's help: not yet
                gmul, msign, msince = adapt_gain(mu, tol_n, gmul, msign, msince, con.settle,
                                                 its - last)
            last = its
            if status == ST_NONFINITE:
                qty, kind, worst = worst_place(dyn, lam)
            elif status == ST_STALLED or status == ST_SLOW:
                qty = ratio
            if status != ST_MAXITER:
                break
        # ---- velocity and displacement update ------------------------------------------
        c_visc = 0.0
        if rp_only:
            if not whole:
                rp_residual(dyn, lam, rpres)
            num, den = rp_rayleigh(dyn, lam, rpres, gprev)
        if den > 0.0 and num > 0.0 and its > 1:
            c_visc = min(alpha * 2.0 * np.sqrt(num / den), 1.9)
        if its > 1 and num > UNSTABLE_RQ * den > 0.0:
            n_over += 1.0
        if its % UNSTABLE_WINDOW == 0:
            n_over *= 0.5
        if n_over >= UNSTABLE_COUNT:
            status = ST_UNSTABLE
            qty = num / den
            worst = fastest_node(dyn)
            break
        ke, dmp, umax, n_bad = update_nodes(dyn, lam, ctrl[0] != 0 and not whole, c_visc, ring,
                                            parts)
        damped += dmp
        if not whole:   # (the reference points have not moved since the gather)
            rp_residual(dyn, lam, rpres)
        ke, rmax, rbad = rp_step(dyn, rpres, c_visc, ke)
        place_rigid_nodes(dyn)
        if n_bad + rbad > 0 or max(umax, rmax) > crit.u_limit:
            qty, kind, worst = worst_place(dyn, lam)
            status = ST_NONFINITE if n_bad + rbad > 0 else ST_RUNAWAY
            break
    lam_arr[0] = lam
    out = finish(mesh, cont, dyn, lam, crit, status, it, rn, ref, rg, ke, damped, worst, kind,
                 qty, mu)
    return out, Progress(seg + it, n_over, pr.goal, pr.since, pr.best, pr.win_r, pr.win_n,
                         pr.win_d, pr.win_k, mu, gmul, msign, msince)

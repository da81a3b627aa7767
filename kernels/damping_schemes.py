"""The damping schemes that no default run uses, in their own loop so that a run with the default
(viscous, :func:`.relaxation.relax`) never compiles them:

* ``DAMP_KINETIC``: kinetic damping, velocities zeroed at every peak of the kinetic energy and
  the displacements moved back to the peak (Barnes, Cundall);
* ``DAMP_LOCAL``: Cundall's local non-viscous damping, the force reduced by ``alpha`` against the
  velocity's sign (the masses are raised by 1 + alpha, which the stable step needs);
* ``DAMP_FIRE``: FIRE (Bitzek et al. 2006, PRL 97 170201), undamped dynamics with an adaptive step
  factor ``dt`` <= 1, the velocity steered towards the force by the mixing factor ``a``
  (``alpha`` at the start) while the power F.v is positive, and the motion stopped (``dt``
  halved, ``a`` reset) when it turns negative. Velocities and forces are measured in the metric
  of the fictitious masses: the mixing ``v <- (1 - a) v + a |v|_M M^-1 F / |M^-1 F|_M`` never
  raises the kinetic energy; the reference points' DOFs take part with their masses.

The loop shares the convergence check, the records and the guards of :mod:`.relaxation`; it
carries its scheme's state over the calls of an increment in a :data:`SchemeState`.
"""
from collections import namedtuple

import numpy as np

from .balance import (NODE_CHUNK, WHERE_NODE, gather_residual, node_residual, place_rigid_nodes,
                      residual, rp_residual, worst_place)
from .config import ijit, jit, pjit, prange
from .forces import element_and_contact_forces
from .relaxation import (ST_MAXITER, ST_NONFINITE, ST_RUNAWAY, ST_SLOW, ST_STALLED, Progress,
                         check, control_factor, finish)

DAMP_KINETIC = 0
DAMP_LOCAL = 2
DAMP_FIRE = 3

# FIRE constants (Bitzek et al. 2006); the step factor is relative to the unit step of the masses
FIRE_DT_START = 0.5
FIRE_DT_MAX = 1.0
FIRE_N_MIN = 5       # steps with positive power before the step may grow
FIRE_F_INC = 1.1
FIRE_F_DEC = 0.5
FIRE_F_ALPHA = 0.99

#: carried over the calls of an increment: kinetic damping's last kinetic energy J; FIRE's step
#: factor, mixing factor and steps since the last stop
SchemeState = namedtuple("SchemeState", "ke_prev dt a_mix n_pos")


@jit
def start_state(scheme, alpha):
    """The :data:`SchemeState` of a span's first call."""
    return SchemeState(0.0, FIRE_DT_START if scheme == DAMP_FIRE else 1.0, float(alpha), 0)


@ijit
def update_chunk(lo, hi, fext, P, fint, res, free, V, U, minv, lam, stale, scheme, alpha, keep,
                 c_mix, dt, part):
    """Nodes ``lo:hi`` of :func:`update_nodes`; into ``part`` (4,): kinetic energy, damped
    energy, largest finite |U| moved, non-finite U moved."""
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
def update_nodes(dyn, lam, stale, scheme, alpha, keep, c_mix, dt, parts):
    """One parallel pass over the nodes: the velocity update of the free DOFs by ``scheme`` and,
    except with kinetic damping (which may step back first), U += dt V. Returns (kinetic
    energy J, damped energy J, largest finite |U| m, non-finite U moved)."""
    n = dyn.U.shape[0]
    nt = (n + NODE_CHUNK - 1) // NODE_CHUNK
    for t in prange(nt):
        update_chunk(t * NODE_CHUNK, min(n, (t + 1) * NODE_CHUNK), dyn.fext, dyn.P, dyn.fint,
                     dyn.res, dyn.free, dyn.V, dyn.U, dyn.minv, lam, stale, scheme, alpha, keep,
                     c_mix, dt, parts[t])
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
def fire_mixing(dyn, rpres, alpha, st):
    """FIRE's step: (keep, c_mix, dt, a_mix, n_pos, damped J) from the power of the current
    velocities against the residual (nodes and reference points); moving uphill stops the
    motion and steps half a step back (FIRE 2.0)."""
    n, nr = dyn.U.shape[0], dyn.rpX.shape[0]
    dt, a_mix, n_pos = st.dt, st.a_mix, st.n_pos
    pw, vmv, fmf = 0.0, 0.0, 0.0   # power F.v W, v.M v = 2 KE, F.M^-1 F
    for i in range(n):
        for k in range(3):
            if dyn.free[i, k] > 0.0:
                r, v = dyn.res[i, k], dyn.V[i, k]
                pw += r * v
                vmv += v * v / dyn.minv[i]
                fmf += r * r * dyn.minv[i]
    for p in range(nr):
        for k in range(6):
            if dyn.rpfree[p, k] > 0.0:
                r, v = rpres[p, k], dyn.rpV[p, k]
                pw += r * v
                vmv += v * v / dyn.rpminv[p, k]
                fmf += r * r * dyn.rpminv[p, k]
    keep, c_mix, damped = 1.0, 0.0, 0.0
    if pw < 0.0:   # (P = 0 only at rest, where there is nothing to stop)
        damped = 0.5 * vmv
        keep = 0.0
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
            damped = 0.5 * (vmv - keep * keep * vmv - 2.0 * keep * c_mix * pw
                            - c_mix * c_mix * fmf)
    return keep, c_mix, dt, a_mix, n_pos, damped


@jit
def relax_scheme(mesh, cont, dyn, lam_arr, ctrl, ctrl_pc, scheme, alpha, crit, pr, st):
    """:func:`.relaxation.relax` with damping ``scheme`` (``DAMP_*`` of this module; ``alpha``
    its parameter: Cundall's coefficient or FIRE's alpha_start). Returns (Exit, Progress,
    :data:`SchemeState`) for the next call of the increment."""
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
    seg = pr.seg
    last = seg
    if seg == 0:
        st = start_state(scheme, alpha)
    ke_prev, dt, a_mix, n_pos = st.ke_prev, st.dt, st.a_mix, st.n_pos
    hbuf = mesh.fbuf.reshape((-1, 3))
    parts = np.zeros(((n + NODE_CHUNK - 1) // NODE_CHUNK, 4))
    place_rigid_nodes(dyn)
    for it in range(1, crit.max_iter + 1):
        its = seg + it
        element_and_contact_forces(dyn.X, dyn.U, mesh, cont)
        gather_residual(hbuf, mesh.ptr, mesh.rows, cont, dyn, lam, dyn.fint, False, parts)
        lam = control_factor(dyn, lam, ctrl, ctrl_pc, rpres)
        if ctrl[0] != 0:   # these schemes read the whole residual every iteration
            residual(dyn, lam, rpres)
        else:
            rp_residual(dyn, lam, rpres)
        if its % crit.check_every == 0 or its == 1:
            status, ratio, rn, ref, rg, pr = check(cont, dyn, lam, rpres, crit, pr, its, it, last,
                                                   0.0)
            last = its
            if status == ST_NONFINITE:
                qty, kind, worst = worst_place(dyn, lam)
            elif status == ST_STALLED or status == ST_SLOW:
                qty = ratio
            if status != ST_MAXITER:
                break
        keep, c_mix = 1.0, 0.0
        if scheme == DAMP_FIRE:
            keep, c_mix, dt, a_mix, n_pos, dmp = fire_mixing(
                dyn, rpres, alpha, SchemeState(ke_prev, dt, a_mix, n_pos))
            damped += dmp
        ke, dmp, umax, n_bad = update_nodes(dyn, lam, False, scheme, alpha, keep, c_mix, dt,
                                            parts)
        damped += dmp
        for p in range(nr):
            for k in range(6):
                if dyn.rpfree[p, k] > 0.0:
                    r = rpres[p, k]
                    if scheme == DAMP_FIRE:
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
                # a step before U: U* = U - v_old / 2 with v_old = V - minv r
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
        if n_bad > 0 or umax > crit.u_limit:
            qty, kind, worst = worst_place(dyn, lam)
            status = ST_NONFINITE if n_bad > 0 else ST_RUNAWAY
            break
    lam_arr[0] = lam
    out = finish(mesh, cont, dyn, lam, crit, status, it, rn, ref, rg, ke, damped, worst, kind,
                 qty, 0.0)
    return (out, Progress(seg + it, pr.n_over, pr.goal, pr.since, pr.best, pr.win_r, pr.win_n,
                          pr.win_d, pr.win_k, pr.mu, pr.gmul, pr.msign, pr.msince),
            SchemeState(ke_prev, dt, a_mix, n_pos))

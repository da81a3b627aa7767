"""Node-to-face cohesive-frictional springs: gather 5 nodes, evaluate the joint law, write forces.

Force convention: internal (resisting) forces. With local tractions t = [sigma, tau1, tau2] (Pa)
and frame rows [n, t1, t2], the joint force ``F = area * (sigma n + tau1 t1 + tau2 t2)`` (N) acts
as internal force +F on the slave node and -N_a F on master node a. Residual = external - internal.
"""
import numpy as np

from .config import ijit, jit, plain
from .contact_frame import contact_frame, frame_gap, quad_dshape, quad_shape, quad_tangents
from .joint_law import JS_D, JS_DP1, JS_DP2, P_KC, P_KNN, P_KSS, joint_point

CHUNK = 64  #: contact points per parallel task (scratch arrays allocated once per task)
#: a point whose stored offset gap0 exceeds this (m) gets the forces of its frame's turning
#: (:func:`offset_forces`); below it the separation is the gap itself and the term is negligible
OFFSET_TOL = 1e-9


@ijit
def joint_energy(p, gap, s):
    """Free energy per unit area (J/m^2) of the joint at local gap ``gap`` (3,) in state ``s``."""
    d = s[JS_D]
    u = gap[0]
    e = 0.0
    if u >= 0.0:
        e += 0.5 * (1.0 - d) * p[P_KNN] * u * u
    else:
        e += 0.5 * p[P_KC] * u * u
    e1 = gap[1] - s[JS_DP1]
    e2 = gap[2] - s[JS_DP2]
    e += 0.5 * (1.0 - d) * p[P_KSS] * (gap[1] ** 2 + gap[2] ** 2)
    e += 0.5 * d * p[P_KSS] * (e1 * e1 + e2 * e2)
    return e


@ijit
def _cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@ijit
def _dnormal(jac, n0, n1, n2, v0, v1, v2):
    """w = d(n . v) / d(a1 x a2) = (v - n (n . v)) / |a1 x a2| for the fixed vector v."""
    nv = n0 * v0 + n1 * v1 + n2 * v2
    return (v0 - n0 * nv) / jac, (v1 - n1 * nv) / jac, (v2 - n2 * nv) / jac


# a call, not inlined: only the few points off their master face take it
@jit
def offset_forces(xq, r, s, d, frame, jac, t, ar, fbuf, row):
    """Add to the master rows ``fbuf[row:row + 4]`` the forces of the frame's turning,
    ``ar * sum_k t_k d(frame_k . d) / d x_a`` (N), for the separation ``d`` (3,) = x_slave -
    x_master (m): with them the point's forces are the gradient of its stored energy and carry no
    couple. First order in |d|: needed where the slave node lies off its master face (gap0 holds
    the offset, up to a brick's width), negligible where d is the gap itself.

    ``xq`` (4, 3) master quad, (r, s) the point's natural coordinates, ``frame`` rows [n, t1, t2]
    and ``jac`` = |a1 x a2| from :func:`contact_frame`, ``t`` (3,) tractions [sigma, tau1, tau2]
    Pa, ``ar`` area m^2.
    """
    a10, a11, a12, a20, a21, a22 = quad_tangents(xq, r, s)
    la1 = np.sqrt(a10 * a10 + a11 * a11 + a12 * a12)
    n0, n1, n2 = frame[0, 0], frame[0, 1], frame[0, 2]
    e0, e1, e2 = frame[1, 0], frame[1, 1], frame[1, 2]
    d0, d1, d2 = d[0], d[1], d[2]
    # normal row: d(n . d)/da1 = a2 x w, d/da2 = w x a1, w = d(n . d)/dm
    w0, w1, w2 = _dnormal(jac, n0, n1, n2, d0, d1, d2)
    g10, g11, g12 = _cross(a20, a21, a22, w0, w1, w2)
    g20, g21, g22 = _cross(w0, w1, w2, a10, a11, a12)
    g10, g11, g12, g20, g21, g22 = (t[0] * g10, t[0] * g11, t[0] * g12, t[0] * g20, t[0] * g21,
                                    t[0] * g22)
    # first tangent t1 = a1 / |a1|: d(t1 . v)/da1 = (v - t1 (t1 . v)) / |a1|
    ed = e0 * d0 + e1 * d1 + e2 * d2
    g10 += t[1] * (d0 - e0 * ed) / la1
    g11 += t[1] * (d1 - e1 * ed) / la1
    g12 += t[1] * (d2 - e2 * ed) / la1
    # second tangent t2 = n x t1: t2 . d = n . (t1 x d) = t1 . (d x n)
    u0, u1, u2 = _cross(e0, e1, e2, d0, d1, d2)
    w0, w1, w2 = _dnormal(jac, n0, n1, n2, u0, u1, u2)
    h10, h11, h12 = _cross(a20, a21, a22, w0, w1, w2)
    h20, h21, h22 = _cross(w0, w1, w2, a10, a11, a12)
    q0, q1, q2 = _cross(d0, d1, d2, n0, n1, n2)
    eq = e0 * q0 + e1 * q1 + e2 * q2
    g10 += t[2] * (h10 + (q0 - e0 * eq) / la1)
    g11 += t[2] * (h11 + (q1 - e1 * eq) / la1)
    g12 += t[2] * (h12 + (q2 - e2 * eq) / la1)
    g20 += t[2] * h20
    g21 += t[2] * h21
    g22 += t[2] * h22
    # a1 = sum_a dN_a/dr x_a, a2 = sum_a dN_a/ds x_a
    dnr, dns = quad_dshape(r, s)
    for a in range(4):
        fbuf[row + a, 0] += ar * (g10 * dnr[a] + g20 * dns[a])
        fbuf[row + a, 1] += ar * (g11 * dnr[a] + g21 * dns[a])
        fbuf[row + a, 2] += ar * (g12 * dnr[a] + g22 * dns[a])



@ijit
def contact_chunk(lo, hi, X, U, slave, master, xi, area, law, lparams, gap0, s_old, s_new, gaps,
                  trac, fbuf, psi):
    """Points ``lo:hi`` of :func:`.forces.contact_forces` (one parallel task, its own scratch)."""
    xq = np.empty((4, 3))
    xm = np.empty(3)
    frame = np.empty((3, 3))
    xs = np.empty(3)
    t = np.empty(3)
    for c in range(lo, hi):
        for a in range(4):
            for k in range(3):
                xq[a, k] = X[master[c, a], k] + U[master[c, a], k]
        for k in range(3):
            xs[k] = X[slave[c], k] + U[slave[c], k]
        r = xi[c, 0]
        s = xi[c, 1]
        jac = contact_frame(xq, r, s, xm, frame)
        for a in range(3):
            gaps[c, a] = frame_gap(xs, xm, frame, a) - gap0[c, a]
        p = lparams[law[c]]
        joint_point(p, gaps[c, 0], gaps[c, 1], gaps[c, 2], s_old[c], s_new[c], t)
        for a in range(3):
            trac[c, a] = t[a]
        psi[c] = area[c] * joint_energy(p, gaps[c], s_new[c])
        n0, n1, n2, n3 = quad_shape(r, s)
        for k in range(3):
            f = area[c] * (t[0] * frame[0, k] + t[1] * frame[1, k] + t[2] * frame[2, k])
            fbuf[5 * c, k] = f
            fbuf[5 * c + 1, k] = -n0 * f
            fbuf[5 * c + 2, k] = -n1 * f
            fbuf[5 * c + 3, k] = -n2 * f
            fbuf[5 * c + 4, k] = -n3 * f
        if abs(gap0[c, 0]) + abs(gap0[c, 1]) + abs(gap0[c, 2]) > OFFSET_TOL:
            for k in range(3):
                xs[k] -= xm[k]   # the separation d = x_slave - x_master
            offset_forces(xq, r, s, xs, frame, jac, t, area[c], fbuf, 5 * c + 1)


def contact_rowsum(slave, master, xi, area, kbound, n_nodes, X=None, gap0=None):
    """Gershgorin row sums (N/m) per node of the contact springs, stiffness bound ``kbound`` (nc,) Pa/m.

    The spring couples the slave with weight 1 and master a with -N_a (sum N_a = 1), so the absolute
    row sum is 2 k A at the slave and 2 k A N_a at master node a. A point off its master face
    (|gap0| > ``OFFSET_TOL``; ``X`` (n_nodes, 3) m and ``gap0`` (nc, 3) m given) also moves with
    the turning of the face over its offset (:func:`offset_forces`): master a then weighs
    w_a = N_a + 2 |gap0| (|dN_a/dr| / |a1| + |dN_a/ds| / |a2|), and the row sums are
    k A (1 + W) at the slave and k A w_a (1 + W) at master a, W = sum w_a.
    """
    r, s = xi[:, 0], xi[:, 1]
    shp = np.column_stack(plain(quad_shape)(r, s))
    ka = 2.0 * kbound * area
    w_slave = ka.copy()
    w_master = ka[:, None] * np.abs(shp)
    if X is not None and gap0 is not None:
        off = np.nonzero(np.abs(gap0).sum(axis=1) > OFFSET_TOL)[0]
        if off.size:
            ro, so = r[off], s[off]
            dnr, dns = (np.column_stack(d) for d in plain(quad_dshape)(ro, so))
            xq = X[master[off]]
            la1 = np.linalg.norm(np.einsum("na,naj->nj", dnr, xq), axis=1)
            la2 = np.linalg.norm(np.einsum("na,naj->nj", dns, xq), axis=1)
            arm = 2.0 * np.linalg.norm(gap0[off], axis=1)
            w = (np.abs(shp[off]) + arm[:, None] * (np.abs(dnr) / la1[:, None]
                                                   + np.abs(dns) / la2[:, None]))
            big = 1.0 + w.sum(axis=1)
            w_slave[off] = 0.5 * ka[off] * big
            w_master[off] = 0.5 * (ka[off] * big)[:, None] * w
    out = np.bincount(slave, weights=w_slave, minlength=n_nodes)
    out += np.bincount(master.ravel(), weights=w_master.ravel(), minlength=n_nodes)
    return out

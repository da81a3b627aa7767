"""Node-to-face cohesive-frictional springs: gather 5 nodes, evaluate the joint law, write forces.

Force convention: internal (resisting) forces. With local tractions t = [sigma, tau1, tau2] (Pa)
and frame rows [n, t1, t2], the joint force ``F = area * (sigma n + tau1 t1 + tau2 t2)`` (N) acts
as internal force +F on the slave node and -N_a F on master node a. Residual = external - internal.
"""
import numpy as np

from .config import ijit, pjit, prange
from .contact_frame import contact_frame
from .joint_law import JS_D, JS_DP1, JS_DP2, P_KC, P_KNN, P_KSS, joint_point

CHUNK = 64  #: contact points per parallel task (scratch arrays allocated once per task)


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


@pjit
def contact_forces(X, U, slave, master, xi, area, law, lparams, gap0, s_old, s_new, gaps, trac,
                   fbuf, psi):
    """Evaluate every contact point at current coordinates ``X + U`` (n_nodes, 3), m.

    Parameters
    ----------
    X, U : (n_nodes, 3) reference coordinates and displacements, m.
    slave (nc,), master (nc, 4), xi (nc, 2), area (nc,) m^2, law (nc,), lparams (n_laws, NJP),
    gap0 (nc, 3) m : the contact set (docs/internals.md).
    s_old, s_new : (nc, NJS) committed and updated joint histories.
    gaps, trac : (nc, 3) written: local gap [u, d1, d2] (m) and tractions [sigma, tau1, tau2] (Pa).
    fbuf : (nc * 5, 3) written: internal force on the slave (row 5c) and masters (5c + 1..4), N.
    psi : (nc,) written: stored energy of each point, J.
    """
    nc = slave.shape[0]
    for ch in prange((nc + CHUNK - 1) // CHUNK):
        contact_chunk(ch * CHUNK, min(nc, (ch + 1) * CHUNK), X, U, slave, master, xi, area, law,
                      lparams, gap0, s_old, s_new, gaps, trac, fbuf, psi)


@ijit
def contact_chunk(lo, hi, X, U, slave, master, xi, area, law, lparams, gap0, s_old, s_new, gaps,
                  trac, fbuf, psi):
    """Points ``lo:hi`` of :func:`contact_forces` (one parallel task, its own scratch)."""
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
        contact_frame(xq, r, s, xm, frame)
        for a in range(3):
            ga = ((xs[0] - xm[0]) * frame[a, 0] + (xs[1] - xm[1]) * frame[a, 1]
                  + (xs[2] - xm[2]) * frame[a, 2]) - gap0[c, a]
            gaps[c, a] = ga
        p = lparams[law[c]]
        joint_point(p, gaps[c, 0], gaps[c, 1], gaps[c, 2], s_old[c], s_new[c], t)
        for a in range(3):
            trac[c, a] = t[a]
        psi[c] = area[c] * joint_energy(p, gaps[c], s_new[c])
        n0 = 0.25 * (1.0 - r) * (1.0 - s)
        n1 = 0.25 * (1.0 + r) * (1.0 - s)
        n2 = 0.25 * (1.0 + r) * (1.0 + s)
        n3 = 0.25 * (1.0 - r) * (1.0 + s)
        for k in range(3):
            f = area[c] * (t[0] * frame[0, k] + t[1] * frame[1, k] + t[2] * frame[2, k])
            fbuf[5 * c, k] = f
            fbuf[5 * c + 1, k] = -n0 * f
            fbuf[5 * c + 2, k] = -n1 * f
            fbuf[5 * c + 3, k] = -n2 * f
            fbuf[5 * c + 4, k] = -n3 * f


def contact_rowsum(slave, master, xi, area, kbound, n_nodes):
    """Gershgorin row sums (N/m) per node of the contact springs, stiffness bound ``kbound`` (nc,) Pa/m.

    The spring couples the slave with weight 1 and master a with -N_a (sum N_a = 1), so the absolute
    row sum is 2 k A at the slave and 2 k A N_a at master node a.
    """
    r, s = xi[:, 0], xi[:, 1]
    shp = 0.25 * np.column_stack([(1 - r) * (1 - s), (1 + r) * (1 - s), (1 + r) * (1 + s),
                                  (1 - r) * (1 + s)])
    ka = 2.0 * kbound * area
    out = np.bincount(slave, weights=ka, minlength=n_nodes)
    out += np.bincount(master.ravel(), weights=(ka[:, None] * np.abs(shp)).ravel(),
                       minlength=n_nodes)
    return out

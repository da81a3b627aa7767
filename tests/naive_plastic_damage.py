"""Slow plain-Python reference of the Lee-Fenves Gauss-point update (tests only).

Independent of the kernel's shortcuts: full 3x3 tensors, numpy eigh with eigenvectors, hardening
curves evaluated from the input rows (inelastic strain found by root solving, no densified
table), scipy brentq for every scalar equation.
"""
import numpy as np
from scipy.optimize import brentq


def _curve(rows, E, cap, href, h, kappa):
    """(stress, damage) of a table of rows at equivalent plastic strain kappa, element length h."""
    rows = np.asarray(rows, float)
    ipk = int(np.argmax(rows[:, 0]))
    epk = rows[ipk, 1]
    s = href / h

    def at(ein):  # ein = input (unscaled) inelastic strain
        sg = np.interp(ein, rows[:, 1], rows[:, 0])
        d = min(np.interp(ein, rows[:, 1], rows[:, 2]), cap)
        eis = ein if ein <= epk else epk + s * (ein - epk)
        return eis - d / (1 - d) * sg / E, sg, d

    if kappa <= 0:
        return rows[0, 0], 0.0
    if kappa >= at(rows[-1, 1])[0]:
        return at(rows[-1, 1])[1:]
    ein = brentq(lambda x: at(x)[0] - kappa, 0.0, rows[-1, 1], xtol=1e-16, rtol=1e-14)
    return at(ein)[1:]


def naive_update(mat, h, eps_v, state):
    """One update. ``state`` dict with eps_p (6,), kt, kc; returns (sig (6,), new state dict, dt, dc)."""
    E, nu = mat.E, mat.nu
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E / (2 * (1 + nu))
    K = E / (3 * (1 - 2 * nu))
    al = (mat.fb0_fc0 - 1) / (2 * mat.fb0_fc0 - 1)
    ga = 3 * (1 - mat.Kc) / (2 * mat.Kc - 1)
    tp = np.tan(np.radians(mat.dilation))
    e = mat.eccentricity * mat.tension[0][0] * tp

    def tens(v, shear_factor):
        return np.array([[v[0], v[5] * shear_factor, v[4] * shear_factor],
                         [v[5] * shear_factor, v[1], v[3] * shear_factor],
                         [v[4] * shear_factor, v[3] * shear_factor, v[2]]])

    ee = tens(np.asarray(eps_v) - state["eps_p"], 0.5)
    sb_tr = lam * np.trace(ee) * np.eye(3) + 2 * mu * ee
    w_, V = np.linalg.eigh(sb_tr)
    w_, V = w_[::-1], V[:, ::-1]
    i1tr = w_.sum()
    dev = w_ - i1tr / 3
    qtr = np.sqrt(1.5 * np.sum(dev ** 2))

    def strengths(kt, kc):
        st, dt = _curve(mat.tension, E, mat.damage_cap, mat.h_ref, h, kt)
        sc, dc = _curve(mat.compression, E, mat.damage_cap, mat.h_ref, h, kc)
        return st / (1 - dt), sc / (1 - dc), dt, dc

    def F(pr, sbt, sbc):
        i1 = pr.sum()
        q = np.sqrt(1.5 * np.sum((pr - i1 / 3) ** 2))
        beta = sbc / sbt * (1 - al) - (1 + al)
        return (al * i1 + q + beta * max(pr[0], 0) - ga * max(-pr[0], 0)) / (1 - al) - sbc

    def rweight(pr):
        den = np.abs(pr).sum()
        return 0.0 if den == 0 else np.maximum(pr, 0).sum() / den

    def ret(dl):
        i1 = i1tr - 3 * K * tp * dl
        if qtr > 0 and dl > 0:
            q = brentq(lambda q: q * (1 + 3 * mu * dl / np.sqrt(e * e + q * q)) - qtr, 0.0, qtr,
                       xtol=1e-14 * qtr, rtol=1e-15)
        else:
            q = qtr
        rho = q / qtr if qtr > 0 else 0.0
        pr = i1 / 3 + rho * dev
        dep = dl * (1.5 * rho * dev / np.sqrt(e * e + q * q) + tp / 3)
        r = rweight(pr)
        kt = state["kt"] + r * max(dep[0], 0)
        kc = state["kc"] + (1 - r) * max(-dep[2], 0)
        sbt, sbc, dt, dc = strengths(kt, kc)
        return F(pr, sbt, sbc), pr, dep, kt, kc, dt, dc, r

    sbt0, sbc0, _, _ = strengths(state["kt"], state["kc"])
    dl = 0.0
    if F(w_, sbt0, sbc0) > 1e-10 * mat.compression[0][0]:
        hi = 1e-12
        while ret(hi)[0] > 0:
            hi *= 2
        dl = brentq(lambda x: ret(x)[0], 0.0, hi, xtol=1e-18, rtol=1e-14)
    _, pr, dep, kt, kc, dt, dc, r = ret(dl)
    sb = V @ np.diag(pr) @ V.T
    depT = V @ np.diag(dep) @ V.T
    sig = (1 - dc) * (1 - r * dt) * sb
    voigt = [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]
    sig_v = np.array([sig[a, b] for a, b in voigt])
    dep_v = np.array([depT[a, b] * (1 if a == b else 2) for a, b in voigt])
    new = {"eps_p": state["eps_p"] + dep_v, "kt": kt, "kc": kc}
    return sig_v, new, dt, dc

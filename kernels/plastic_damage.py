"""Lee-Fenves plastic-damage stress update at one Gauss point (MODEL.md section 3).

Effective stress ``sb = E0 : (eps - eps_p)``, nominal stress ``sig = (1 - d) sb`` with
``d = 1 - (1 - dc)(1 - r dt)`` (w_t = 0, w_c = 1; ``r`` the tensile weight of the principal
effective stresses). Yield surface (Lubliner / Lee-Fenves) in effective stress, hyperbolic
Drucker-Prager flow potential, two hardening variables = equivalent plastic strains
``kt += r <de_max>``, ``kc += (1 - r) <-de_min>`` (Abaqus CDP form of Lee-Fenves eq. 20-21).

Return mapping: backward Euler. The potential is isotropic and so is elasticity, so the
return is coaxial with the trial stress: ``sb = I1/3 1 + rho s_tr`` with
``I1 = I1_tr - 3 K tan(psi) dl`` and ``q (1 + 3 mu dl / sqrt(e^2 + q^2)) = q_tr``. Only the
eigenvalues of the trial deviator are needed (no eigenvectors); the consistency condition is
one scalar equation F(dl) = 0, bracketed (F(0) > 0, F -> -inf) and solved by the Illinois
regula falsi. The bracket starts around the multiplier of the point's previous return (kept in
the state: between two relaxation iterations the strain hardly moves, so the root is within a
fraction of a per cent of it), else from the perfectly plastic estimate. A return that does not
reach the tolerance keeps the bracketed value and sets bit 1 of the state flag; an element length
outside (0, h_max] is clamped and sets bit 2.

Parameters ``p`` (NMP,) come from ``PlasticDamage.params_array()``: a header (``MP_*``) and two
hardening tables of NTAB points (tension at ``MP_TAB``, compression at ``MP_TAB + 4 NTAB``),
each stored as four arrays a, b, stress, damage with the equivalent plastic strain of point j
at crack-band scale s = h_ref / h equal to ``a_j + s b_j``.
"""
import numpy as np

from .config import ijit, jit

NTAB = 257  #: points of each densified hardening table

MP_ELASTIC = 0   #: 1.0 = linear elastic material (fast path, state not written)
MP_E = 1         #: Young's modulus E0, Pa
MP_NU = 2        #: Poisson ratio
MP_LAM = 3       #: Lame lambda, Pa
MP_MU = 4        #: shear modulus, Pa
MP_K = 5         #: bulk modulus, Pa
MP_ALPHA = 6     #: alpha = (fb0/fc0 - 1) / (2 fb0/fc0 - 1)
MP_GAMMA = 7     #: gamma = 3 (1 - Kc) / (2 Kc - 1)
MP_ECC = 8       #: eccentricity * ft0 * tan(psi), Pa (hyperbola parameter)
MP_TANPSI = 9    #: tan of the dilation angle
MP_HREF = 10     #: characteristic length of the tables, m
MP_HMAX = 11     #: largest element length without snap-back, m
MP_FTOL = 12     #: yield tolerance, Pa
MP_NT = 13       #: used points of the tension table
MP_NC = 14       #: used points of the compression table
MP_RHO = 15      #: density, kg/m^3
MP_TAB = 16      #: start of the tables
NMP = MP_TAB + 8 * NTAB
MP_SBT0 = MP_TAB + 2 * NTAB  #: first stress of the tension table: the virgin effective strength, Pa
MP_SBC0 = MP_TAB + 6 * NTAB  #: first stress of the compression table, Pa

MS_DT = 0        #: tensile damage dt
MS_DC = 1        #: compressive damage dc
MS_EPSP = 2      #: start of the 6 plastic strains (Voigt, engineering shears)
MS_DISS = 8      #: cumulative dissipated energy density, J/m^3
MS_KT = 9        #: tensile equivalent plastic strain
MS_KC = 10       #: compressive equivalent plastic strain
MS_SBT = 11      #: effective tensile strength at MS_KT, Pa
MS_SBC = 12      #: effective compressive strength at MS_KC, Pa
MS_FLAG = 13     #: bit flags: 1 = return not converged to tolerance, 2 = element length clamped
MS_DL = 14       #: plastic multiplier of the point's last return (the next return's first guess)
NMS = 15

FLAG_RETURN = 1
FLAG_LENGTH = 2


@jit
def curve_lookup(p, off, n, kappa, s):
    """Stress (Pa) and damage of a hardening table at equivalent plastic strain ``kappa``.

    ``off`` start of the table in ``p``, ``n`` its used points, ``s`` = h_ref / h.
    Linear interpolation in plastic strain, constant beyond the last point.
    """
    a = off
    b = off + NTAB
    sg = off + 2 * NTAB
    dd = off + 3 * NTAB
    if kappa <= 0.0 or n == 1:
        return p[sg], p[dd]
    last = n - 1
    if kappa >= p[a + last] + s * p[b + last]:
        return p[sg + last], p[dd + last]
    lo = 0
    hi = last
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if p[a + mid] + s * p[b + mid] <= kappa:
            lo = mid
        else:
            hi = mid
    k0 = p[a + lo] + s * p[b + lo]
    k1 = p[a + hi] + s * p[b + hi]
    t = (kappa - k0) / (k1 - k0)
    return (p[sg + lo] + t * (p[sg + hi] - p[sg + lo]),
            p[dd + lo] + t * (p[dd + hi] - p[dd + lo]))


@ijit
def yield_value(p, i1, q, smax, sbt, sbc):
    """Yield function F (Pa) from I1, q = sqrt(3 J2), the largest principal effective stress
    ``smax`` and the effective strengths ``sbt``, ``sbc`` (Pa)."""
    al = p[MP_ALPHA]
    beta = sbc / sbt * (1.0 - al) - (1.0 + al)
    return (al * i1 + q + beta * max(smax, 0.0) - p[MP_GAMMA] * max(-smax, 0.0)) / (1.0 - al) - sbc


@jit
def dev_eigenvalues(s0, s1, s2, s3, s4, s5):
    """Eigenvalues (descending) of a deviator in Voigt order [xx, yy, zz, yz, xz, xy] (tensor shears)."""
    j2 = 0.5 * (s0 * s0 + s1 * s1 + s2 * s2) + s3 * s3 + s4 * s4 + s5 * s5
    if j2 <= 0.0:
        return 0.0, 0.0, 0.0
    j3 = s0 * (s1 * s2 - s3 * s3) - s5 * (s5 * s2 - s3 * s4) + s4 * (s5 * s3 - s1 * s4)
    c = 1.5 * np.sqrt(3.0) * j3 / (j2 * np.sqrt(j2))
    c = min(1.0, max(-1.0, c))
    th = np.arccos(c) / 3.0
    rr = 2.0 * np.sqrt(j2 / 3.0)
    return rr * np.cos(th), rr * np.cos(th - 2.0 * np.pi / 3.0), rr * np.cos(th + 2.0 * np.pi / 3.0)


@jit
def tension_weight(a, b, c):
    """Lee-Fenves weight r = sum <s_i> / sum |s_i| (0 at zero stress)."""
    den = abs(a) + abs(b) + abs(c)
    if den <= 0.0:
        return 0.0
    return (max(a, 0.0) + max(b, 0.0) + max(c, 0.0)) / den


@jit
def _solve_q(qtr, c, e):
    """Root q in [0, qtr] of q (1 + c / sqrt(e^2 + q^2)) = qtr (increasing, concave in q)."""
    if qtr <= 0.0 or c <= 0.0:
        return qtr
    q = qtr * np.sqrt(e * e + qtr * qtr) / (np.sqrt(e * e + qtr * qtr) + c)
    for _ in range(60):
        rt = np.sqrt(e * e + q * q)
        f = q + c * q / rt - qtr
        dq = f / (1.0 + c * e * e / (rt * rt * rt))
        qn = max(q - dq, 0.0)
        if abs(qn - q) <= 1e-15 * qtr:
            return qn
        q = qn
    return q


@jit
def _returned(p, s, dl, i1tr, qtr, e1, e2, e3, kt0, kc0):
    """State after a return of plastic multiplier ``dl`` from the trial (I1_tr, q_tr, deviatoric
    eigenvalues e1 >= e2 >= e3). Returns (F, I1, rho, w, kt, kc, sbt, sbc, dt, dc, r)."""
    tp = p[MP_TANPSI]
    e = p[MP_ECC]
    i1 = i1tr - 3.0 * p[MP_K] * tp * dl
    q = _solve_q(qtr, 3.0 * p[MP_MU] * dl, e)
    rho = q / qtr if qtr > 0.0 else 0.0
    w = 1.0 / np.sqrt(e * e + q * q)
    m = i1 / 3.0
    p1 = m + rho * e1
    p2 = m + rho * e2
    p3 = m + rho * e3
    r = tension_weight(p1, p2, p3)
    de1 = dl * (1.5 * rho * e1 * w + tp / 3.0)
    de3 = dl * (1.5 * rho * e3 * w + tp / 3.0)
    kt = kt0 + r * max(de1, 0.0)
    kc = kc0 + (1.0 - r) * max(-de3, 0.0)
    st, dt = curve_lookup(p, MP_TAB, int(p[MP_NT]), kt, s)
    sc, dc = curve_lookup(p, MP_TAB + 4 * NTAB, int(p[MP_NC]), kc, s)
    sbt = st / (1.0 - dt)
    sbc = sc / (1.0 - dc)
    f = yield_value(p, i1, q, p1, sbt, sbc)
    return f, i1, rho, w, kt, kc, sbt, sbc, dt, dc, r


@jit
def _return(p, s, f0, guess, i1tr, qtr, e1, e2, e3, kt0, kc0):
    """Plastic multiplier of the return from a trial state with F(0) = ``f0`` > tolerance (the
    arguments after ``guess`` as for :func:`_returned`): a bracket [lo, hi], F(lo) > 0 >= F(hi),
    found around ``guess`` (the point's previous multiplier; none if not > 0) by steps of 0.1 %
    of it growing 4 x, or else grown 4 x at a time from the perfectly plastic estimate
    f0 (1 - alpha) / (3 mu), narrowed by the Illinois regula falsi to |F| <= tolerance or a width
    of 1e-15 dl. Returns (dl, converged, the state at dl as :func:`_returned` gives it)."""
    ftol = p[MP_FTOL]
    lo = 0.0
    flo = f0
    warm = 0.0 < guess < np.inf
    hi = guess if warm else f0 * (1.0 - p[MP_ALPHA]) / (3.0 * p[MP_MU])
    step = 1e-3 * hi
    res = _returned(p, s, hi, i1tr, qtr, e1, e2, e3, kt0, kc0)
    fhi = res[0]
    if warm and abs(fhi) <= ftol:
        return hi, True, res
    it = 0
    if warm and fhi <= 0.0:   # the root is below the guess (and above 0, where F = f0 > 0)
        while it < 200:
            x = hi - step
            if x <= 0.0:
                break
            rx = _returned(p, s, x, i1tr, qtr, e1, e2, e3, kt0, kc0)
            if not rx[0] <= 0.0:
                lo = x
                flo = rx[0]
                break
            hi = x
            fhi = rx[0]
            res = rx
            step *= 4.0
            it += 1
    else:   # the root is above hi: grow it (from the guess by steps, else 4 x)
        while not fhi <= 0.0 and it < 200:
            lo = hi
            flo = fhi
            if warm:
                hi += step
                step *= 4.0
            else:
                hi *= 4.0
            res = _returned(p, s, hi, i1tr, qtr, e1, e2, e3, kt0, kc0)
            fhi = res[0]
            it += 1
    if not fhi <= 0.0:
        return hi, False, res
    side = 0
    for _ in range(200):
        x = hi - fhi * (hi - lo) / (fhi - flo)
        if not (lo < x < hi):
            x = 0.5 * (lo + hi)
        rx = _returned(p, s, x, i1tr, qtr, e1, e2, e3, kt0, kc0)
        fx = rx[0]
        if abs(fx) <= ftol:
            return x, True, rx
        if fx > 0.0:
            lo = x
            flo = fx
            if side == 1:
                fhi *= 0.5
            side = 1
        else:
            hi = x
            fhi = fx
            res = rx
            if side == -1:
                flo *= 0.5
            side = -1
        if hi - lo <= 1e-15 * hi:
            return hi, True, res
    return hi, False, res


@ijit
def elastic_stress(p, eps, sig):
    """Linear elastic stress ``sig`` (6,) Pa = lam tr(eps) 1 + 2 mu eps of strain ``eps`` (6,)
    (Voigt [xx, yy, zz, yz, xz, xy], engineering shears) with the Lame constants of ``p``."""
    lam = p[MP_LAM]
    mu = p[MP_MU]
    tr = eps[0] + eps[1] + eps[2]
    for i in range(3):
        sig[i] = lam * tr + 2.0 * mu * eps[i]
        sig[i + 3] = mu * eps[i + 3]


@ijit
def trial_stress(p, e0, e1, e2, e3, e4, e5):
    """Trial effective stress of the elastic strain ``e0..e5`` (Voigt, engineering shears):
    returns (I1 Pa, q = sqrt(3 J2) Pa, the deviator d0..d5 Pa, tensor shears)."""
    mu = p[MP_MU]
    tr = e0 + e1 + e2
    i1tr = 3.0 * p[MP_K] * tr
    d0 = 2.0 * mu * (e0 - tr / 3.0)
    d1 = 2.0 * mu * (e1 - tr / 3.0)
    d2 = 2.0 * mu * (e2 - tr / 3.0)
    d3 = mu * e3
    d4 = mu * e4
    d5 = mu * e5
    j2 = 0.5 * (d0 * d0 + d1 * d1 + d2 * d2) + d3 * d3 + d4 * d4 + d5 * d5
    return i1tr, np.sqrt(3.0 * j2), d0, d1, d2, d3, d4, d5


@ijit
def surely_elastic(p, i1tr, qtr, sbt, sbc):
    """The cheap elastic check: F(I1, q, I1/3 + 2q/3) <= tol at strengths ``sbt``, ``sbc`` (Pa)
    proves the trial state elastic (the largest principal stress is at most I1/3 + 2q/3 and F
    grows with it), without the eigenvalues."""
    return yield_value(p, i1tr, qtr, i1tr / 3.0 + 2.0 * qtr / 3.0, sbt, sbc) <= p[MP_FTOL]


# a call, not inlined: the return mapping doubled the fused force kernel's compile time, and
# its cost per plastic point dwarfs a call (BENCHMARKS.md, "Cold and warm start")
@jit
def gp_update(p, h, eps, s_old, s_new, sig):
    """Stress update at one Gauss point.

    Parameters
    ----------
    p : (NMP,) float64
        material parameters from ``PlasticDamage.params_array()``.
    h : float
        characteristic length of the element, m (crack band); clamped to (0, p[MP_HMAX]].
    eps : (6,) float64
        total strain, Voigt [xx, yy, zz, yz, xz, xy], engineering shears.
    s_old : (NMS,) float64
        committed state at the start of the increment (read only).
    s_new : (NMS,) float64
        updated state (written; not written for an elastic material). Its ``MS_DL`` on entry,
        the multiplier of the point's previous return (a trial's or the committed one), is the
        first guess of this return: any value is safe, a good one saves most of the search.
    sig : (6,) float64
        stress written, Pa, same Voigt order.
    """
    if p[MP_ELASTIC] == 1.0:
        elastic_stress(p, eps, sig)
        return
    guess = s_new[MS_DL]   # the multiplier of this point's previous trial (or committed) return
    for i in range(NMS):
        s_new[i] = s_old[i]
    flag = int(s_old[MS_FLAG])
    href = p[MP_HREF]
    if not h > 0.0:
        flag |= FLAG_LENGTH
        h = href
    elif h > p[MP_HMAX]:
        flag |= FLAG_LENGTH
        h = p[MP_HMAX]
    s = href / h
    i1tr, qtr, d0, d1, d2, d3, d4, d5 = trial_stress(
        p, eps[0] - s_old[MS_EPSP], eps[1] - s_old[MS_EPSP + 1], eps[2] - s_old[MS_EPSP + 2],
        eps[3] - s_old[MS_EPSP + 3], eps[4] - s_old[MS_EPSP + 4], eps[5] - s_old[MS_EPSP + 5])
    m = i1tr / 3.0
    sbt0 = s_old[MS_SBT]
    sbc0 = s_old[MS_SBC]
    dt0 = s_old[MS_DT]
    dc0 = s_old[MS_DC]
    ftol = p[MP_FTOL]
    if surely_elastic(p, i1tr, qtr, sbt0, sbc0):
        if dt0 > 0.0:
            e1, e2, e3 = dev_eigenvalues(d0, d1, d2, d3, d4, d5)
            r = tension_weight(m + e1, m + e2, m + e3)
        else:
            r = 0.0
        fac = (1.0 - dc0) * (1.0 - r * dt0)
        sig[0] = fac * (m + d0)
        sig[1] = fac * (m + d1)
        sig[2] = fac * (m + d2)
        sig[3] = fac * d3
        sig[4] = fac * d4
        sig[5] = fac * d5
        s_new[MS_FLAG] = flag
        return
    e1, e2, e3 = dev_eigenvalues(d0, d1, d2, d3, d4, d5)
    kt0 = s_old[MS_KT]
    kc0 = s_old[MS_KC]
    f0 = yield_value(p, i1tr, qtr, m + e1, sbt0, sbc0)
    if f0 > ftol:
        dl, converged, res = _return(p, s, f0, guess, i1tr, qtr, e1, e2, e3, kt0, kc0)
        if not converged:
            flag |= FLAG_RETURN
        s_new[MS_DL] = dl
    else:
        dl = 0.0
        res = _returned(p, s, dl, i1tr, qtr, e1, e2, e3, kt0, kc0)
    f, i1, rho, w, kt, kc, sbt, sbc, dt, dc, r = res
    m = i1 / 3.0
    a = dl * rho * w
    b = dl * p[MP_TANPSI] / 3.0
    sbar0 = m + rho * d0
    sbar1 = m + rho * d1
    sbar2 = m + rho * d2
    sbar3 = rho * d3
    sbar4 = rho * d4
    sbar5 = rho * d5
    dp0 = 1.5 * a * d0 + b
    dp1 = 1.5 * a * d1 + b
    dp2 = 1.5 * a * d2 + b
    dp3 = 3.0 * a * d3
    dp4 = 3.0 * a * d4
    dp5 = 3.0 * a * d5
    s_new[MS_EPSP] = s_old[MS_EPSP] + dp0
    s_new[MS_EPSP + 1] = s_old[MS_EPSP + 1] + dp1
    s_new[MS_EPSP + 2] = s_old[MS_EPSP + 2] + dp2
    s_new[MS_EPSP + 3] = s_old[MS_EPSP + 3] + dp3
    s_new[MS_EPSP + 4] = s_old[MS_EPSP + 4] + dp4
    s_new[MS_EPSP + 5] = s_old[MS_EPSP + 5] + dp5
    fac = (1.0 - dc) * (1.0 - r * dt)
    sig[0] = fac * sbar0
    sig[1] = fac * sbar1
    sig[2] = fac * sbar2
    sig[3] = fac * sbar3
    sig[4] = fac * sbar4
    sig[5] = fac * sbar5
    # dissipation: (1 - d) sb : d eps_p + psi0 * (dissipative part of the change of d)
    wp = sbar0 * dp0 + sbar1 * dp1 + sbar2 * dp2 + sbar3 * dp3 + sbar4 * dp4 + sbar5 * dp5
    psi0 = 0.5 * (sbar0 * (eps[0] - s_new[MS_EPSP]) + sbar1 * (eps[1] - s_new[MS_EPSP + 1])
                  + sbar2 * (eps[2] - s_new[MS_EPSP + 2]) + sbar3 * (eps[3] - s_new[MS_EPSP + 3])
                  + sbar4 * (eps[4] - s_new[MS_EPSP + 4]) + sbar5 * (eps[5] - s_new[MS_EPSP + 5]))
    ddiss = r * (1.0 - dc) * (dt - dt0) + (1.0 - r * dt) * (dc - dc0)
    s_new[MS_DISS] = s_old[MS_DISS] + fac * wp + psi0 * ddiss
    s_new[MS_DT] = dt
    s_new[MS_DC] = dc
    s_new[MS_KT] = kt
    s_new[MS_KC] = kc
    s_new[MS_SBT] = sbt
    s_new[MS_SBC] = sbc
    s_new[MS_FLAG] = flag

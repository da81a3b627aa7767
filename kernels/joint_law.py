"""Cohesive-frictional joint law at one contact point (MODEL.md section 2).

Local kinematics: total gap [u, d1, d2] (m), u > 0 opening. Tractions [sigma, tau1, tau2] (Pa),
sigma > 0 tension.

* Normal: u < 0 penalty ``sigma = kc_pen * u`` whatever D; u >= 0 ``sigma = (1 - D) knn u``.
* Shear: ``tau = (1 - D) kss d + D tau_f``, tau_f a 2-D elastic-perfectly-plastic slider
  (stiffness kss, capacity ``mu <-sigma>``, radial return), plastic slip dp.
* Damage ``D = max(D_old, D_t(u_max), D_s(delta_max, sigma))`` in [0, 1]; D_t is eq (7) of the
  paper; D_s is eq (7) for ``shear_damage = "paper"`` and, by default ("calibrated"), the value
  that makes the monotonic envelope ``fs (1 - g_s) + g_s mu <-sigma>`` exactly.
* Elastic limit in shear ``delta0 = max(fs, 0) / kss`` clamped to ``DELTA0_CAP * delta_k``. When
  tension makes ``fs = c - tan_phi sigma <= 0`` the joint has no shear strength: any slip
  (``delta_max > 0``) gives D_s = 1. In tension, fs is evaluated with the normal traction after
  tensile damage (staggered: D_t first, then D_s, then sigma with the final D).
* Free energy ``psi = 0.5 (1-D) knn <u>^2 + 0.5 kc_pen <-u>^2 + 0.5 (1-D) kss |d|^2
  + 0.5 D kss |d - dp|^2``; dissipation rate ``Y dD + D tau_f . d(dp)`` with
  ``Y = -dpsi/dD``, integrated by a midpoint-type rule between the committed and the new state
  (Y from products of the old and new gaps, the slider's part corrected as in the code;
  ``D_mid tau_f_mid . (dp_new - dp_old)``). This matches the trapezoidal work of the tractions
  exactly in every step that does not cross u = 0 (there the trapezoid misses the kink between
  kc_pen and knn, O(step^2)). A single step much larger than the stick range
  ``2 mu<-sigma>/kss`` that reverses the slip or enters contact while sliding can give a
  negative increment; resolved paths dissipate >= 0.

Modes (``p[P_MODE]``): ``MODE_COHESIVE``; ``MODE_DRY`` (ft = c = 0: D = 1 always, penalty plus
Coulomb friction, no damage dissipation); ``MODE_TIED`` (elastic and unbreakable: sigma = knn u
for u >= 0, kc_pen u for u < 0, tau = kss d, state never changes except the stored gap).
"""
import numpy as np

from .config import ijit, jit

# ---------------------------------------------------------------- parameter vector
P_MODE = 0     # MODE_* below
P_FT = 1       # tensile strength ft, Pa
P_UK = 2       # opening at zero tension u_k, m
P_ZETA = 3     # tensile softening exponent zeta, -
P_KNN = 4      # normal stiffness knn, Pa/m
P_C = 5        # cohesion c, Pa
P_TANPHI = 6   # friction coefficient of the strength, -
P_DK = 7       # slip at zero cohesion delta_k, m
P_XI = 8       # shear softening exponent xi, -
P_MU = 9       # residual friction coefficient mu, -
P_KSS = 10     # shear stiffness kss, Pa/m
P_KC = 11      # compression penalty kc_pen, Pa/m
P_SHEAR = 12   # SHEAR_CALIBRATED or SHEAR_PAPER
P_U0 = 13      # ft / knn, m
P_EZ = 14      # 1 - exp(-zeta)
P_EX = 15      # 1 - exp(-xi)
NJP = 16

MODE_COHESIVE = 0.0
MODE_DRY = 1.0
MODE_TIED = 2.0
SHEAR_CALIBRATED = 0.0
SHEAR_PAPER = 1.0

# ---------------------------------------------------------------- state vector
JS_D = 0       # damage D, -
JS_UMAX = 1    # largest opening ever u_max, m
JS_DMAX = 2    # largest slip magnitude ever delta_max, m
JS_DP1 = 3     # plastic slip of the friction slider, m
JS_DP2 = 4
JS_DISS = 5    # cumulative dissipated energy, J/m^2
JS_GU = 6      # gap [u, d1, d2] of this state (needed by the midpoint rule), m
JS_G1 = 7
JS_G2 = 8
JS_DISSF = 9   # the part of JS_DISS dissipated by friction (slider), J/m^2
NJS = 10

#: delta0 is clamped to this fraction of delta_k (huge compression would otherwise put the peak
#: beyond the point of zero cohesion)
DELTA0_CAP = 0.99


@jit
def _softening(x, x0, xk, zeta, ez):
    """Fraction g in [0, 1] of eq (7): 0 at x0, 1 at xk and beyond."""
    if x >= xk:
        return 1.0
    return (1.0 - np.exp(-zeta * (x - x0) / (xk - x0))) / ez


@jit
def _shear_damage(p, dmax, sigma):
    """D_s for the largest slip ``dmax`` (m) at normal traction ``sigma`` (Pa)."""
    kss = p[P_KSS]
    dk = p[P_DK]
    fs = p[P_C] - p[P_TANPHI] * sigma
    delta0 = min(max(fs, 0.0) / kss, DELTA0_CAP * dk)
    if dmax <= delta0:
        return 0.0
    g = _softening(dmax, delta0, dk, p[P_XI], p[P_EX])
    if g >= 1.0:
        return 1.0
    if p[P_SHEAR] == SHEAR_PAPER:
        return 1.0 - delta0 / dmax * (1.0 - g)
    mup = p[P_MU] * max(-sigma, 0.0)
    ktd = kss * dmax
    den = ktd - mup
    if den <= 0.0:  # slider still elastic: tau = kss d whatever D
        return 0.0
    ds = (ktd - kss * delta0 * (1.0 - g) - g * mup) / den
    return min(max(ds, 0.0), 1.0)


@ijit
def joint_point(p, u, d1, d2, s_old, s_new, t):
    """Tractions and updated history of one contact point (backward Euler over the increment).

    Parameters
    ----------
    p : (NJP,) float64
        parameters from ``JointLaw.params_array()``.
    u, d1, d2 : float
        total local gap (m): opening and the two slips.
    s_old : (NJS,) float64
        committed history at the start of the increment (read only).
    s_new : (NJS,) float64
        updated history (written).
    t : (3,) float64
        tractions [sigma, tau1, tau2] (Pa, written).
    """
    for k in range(NJS):
        s_new[k] = s_old[k]
    s_new[JS_GU] = u
    s_new[JS_G1] = d1
    s_new[JS_G2] = d2
    knn = p[P_KNN]
    kss = p[P_KSS]
    mode = p[P_MODE]
    if mode == MODE_TIED:
        t[0] = knn * u if u >= 0.0 else p[P_KC] * u
        t[1] = kss * d1
        t[2] = kss * d2
        return
    umax = max(s_old[JS_UMAX], u)
    # sqrt of the squares, not np.hypot: hypot's guard against overflow cost 15-20 % of a
    # contact point's time; slips (m) and tractions (Pa) are far
    # from where their squares over- or underflow
    dmag = np.sqrt(d1 * d1 + d2 * d2)
    dmax = max(s_old[JS_DMAX], dmag)
    d_old = s_old[JS_D]
    if mode == MODE_DRY:
        d_old = 1.0
        dam = 1.0
    else:
        dam = d_old
        u0 = p[P_U0]
        if umax > u0:
            dam = max(dam, 1.0 - u0 / umax * (1.0 - _softening(umax, u0, p[P_UK], p[P_ZETA],
                                                                p[P_EZ])))
    sigma = p[P_KC] * u if u < 0.0 else (1.0 - dam) * knn * u
    if mode != MODE_DRY:
        dam = max(dam, _shear_damage(p, dmax, sigma))
        if u >= 0.0:
            sigma = (1.0 - dam) * knn * u
    # friction slider, radial return from the committed plastic slip
    dp1o = s_old[JS_DP1]
    dp2o = s_old[JS_DP2]
    tf1 = kss * (d1 - dp1o)
    tf2 = kss * (d2 - dp2o)
    cap = p[P_MU] * max(-sigma, 0.0)
    tfn = np.sqrt(tf1 * tf1 + tf2 * tf2)
    if tfn > cap:
        sc = cap / tfn
        tf1 *= sc
        tf2 *= sc
    dp1 = d1 - tf1 / kss
    dp2 = d2 - tf2 / kss
    t[0] = sigma
    t[1] = (1.0 - dam) * kss * d1 + dam * tf1
    t[2] = (1.0 - dam) * kss * d2 + dam * tf2
    s_new[JS_UMAX] = umax
    s_new[JS_DMAX] = dmax
    s_new[JS_DP1] = dp1
    s_new[JS_DP2] = dp2
    if dam == 0.0 and d_old == 0.0:   # undamaged: both dissipation terms below are exactly 0
        return
    # dissipation, midpoint rule between the committed and the new state
    g1o = s_old[JS_G1]
    g2o = s_old[JS_G2]
    # Y from products of the old and new gaps rather than squares of their mean: equally
    # second-order, and exact for the secant branch D = 1 - u0 / u_max that dominates right
    # after the peak (where the mean-square form overestimates the dissipation)
    uo = max(s_old[JS_GU], 0.0)
    un = max(u, 0.0)
    # the slider's part: e_old . e_new less half (change of e) . (change of dp), e = d - dp its
    # elastic slip, makes its dissipation its trapezoidal work less its change of free energy in
    # any step; the product alone over-dissipates 0.25 kss dD |d(dp)|^2 where the slider lets go
    # in the step that damages (a joint opening from compression while slipped)
    e1o = g1o - dp1o
    e2o = g2o - dp2o
    e1n = d1 - dp1
    e2n = d2 - dp2
    xs = e1o * e1n + e2o * e2n - 0.5 * ((e1n - e1o) * (dp1 - dp1o) + (e2n - e2o) * (dp2 - dp2o))
    y = 0.5 * knn * uo * un + 0.5 * kss * (g1o * d1 + g2o * d2 - xs)
    tfm1 = 0.5 * (kss * (g1o - dp1o) + tf1)
    tfm2 = 0.5 * (kss * (g2o - dp2o) + tf2)
    friction = 0.5 * (d_old + dam) * (tfm1 * (dp1 - dp1o) + tfm2 * (dp2 - dp2o))
    s_new[JS_DISS] = s_old[JS_DISS] + y * (dam - d_old) + friction
    s_new[JS_DISSF] = s_old[JS_DISSF] + friction
    s_new[JS_D] = dam


@jit
def joint_path(p, path, s_init, t, states):
    """Drive one point along ``path`` (n, 3) m, committing after every point.

    ``s_init`` (NJS,) is the starting history; ``t`` (n, 3) Pa and ``states`` (n, NJS) are
    written with the tractions and the committed history after each point.
    """
    s_old = s_init.copy()
    for i in range(path.shape[0]):
        joint_point(p, path[i, 0], path[i, 1], path[i, 2], s_old, states[i], t[i])
        s_old[:] = states[i]

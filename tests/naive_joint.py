"""Plain-Python reference of the joint law (MODEL.md section 2), written from the formulas.

State is a dict; no Numba, no shared code with the kernel except the layout of its state vector
(used only to compare).
"""
import math


def softening_fraction(x, x0, xk, k):
    """g of eq (7): (1 - exp(-k (x - x0)/(xk - x0))) / (1 - exp(-k)), capped at 1."""
    if x >= xk:
        return 1.0
    return (1.0 - math.exp(-k * (x - x0) / (xk - x0))) / (1.0 - math.exp(-k))


def virgin(law):
    return {"D": 1.0 if law.is_dry else 0.0, "umax": 0.0, "dmax": 0.0, "dp": (0.0, 0.0),
            "diss": 0.0, "dissf": 0.0, "gap": (0.0, 0.0, 0.0)}


def tension_damage(law, umax):
    u0 = law.ft / law.knn
    if umax <= u0:
        return 0.0
    return 1.0 - (u0 / umax) * (1.0 - softening_fraction(umax, u0, law.u_k, law.zeta))


def shear_damage(law, dmax, sigma):
    fs = law.c - law.tan_phi * sigma
    delta0 = min(max(fs, 0.0) / law.kss, 0.99 * law.delta_k)
    if dmax <= delta0:
        return 0.0
    g = softening_fraction(dmax, delta0, law.delta_k, law.xi)
    if g >= 1.0:
        return 1.0
    if law.shear_damage == "paper":
        return 1.0 - (delta0 / dmax) * (1.0 - g)
    friction = law.mu * max(-sigma, 0.0)
    elastic = law.kss * dmax
    if elastic <= friction:
        return 0.0
    envelope = law.kss * delta0 * (1.0 - g) + g * friction
    return min(1.0, max(0.0, (elastic - envelope) / (elastic - friction)))


def free_energy(law, state):
    """psi (J/m^2) of a state dict."""
    u, d1, d2 = state["gap"]
    if law.is_tied:
        return 0.5 * (law.knn if u >= 0 else law.kc_pen) * u * u + 0.5 * law.kss * (d1 * d1 + d2 * d2)
    D = state["D"]
    e1, e2 = d1 - state["dp"][0], d2 - state["dp"][1]
    return (0.5 * (1 - D) * law.knn * max(u, 0.0) ** 2 + 0.5 * law.kc_pen * min(u, 0.0) ** 2
            + 0.5 * (1 - D) * law.kss * (d1 * d1 + d2 * d2) + 0.5 * D * law.kss * (e1 * e1 + e2 * e2))


def step(law, old, gap):
    """New state dict and tractions (sigma, tau1, tau2) for total gap (u, d1, d2), from ``old``."""
    u, d1, d2 = gap
    new = dict(old)
    new["gap"] = (u, d1, d2)
    if law.is_tied:
        sigma = (law.knn if u >= 0 else law.kc_pen) * u
        return new, (sigma, law.kss * d1, law.kss * d2)
    umax = max(old["umax"], u)
    dmax = max(old["dmax"], math.hypot(d1, d2))
    D_old = 1.0 if law.is_dry else old["D"]
    if law.is_dry:
        D = 1.0
    else:
        D = max(D_old, tension_damage(law, umax))

    def normal(D):
        return law.kc_pen * u if u < 0 else (1 - D) * law.knn * u

    if not law.is_dry:
        D = max(D, shear_damage(law, dmax, normal(D)))
    sigma = normal(D)
    cap = law.mu * max(-sigma, 0.0)
    trial = (law.kss * (d1 - old["dp"][0]), law.kss * (d2 - old["dp"][1]))
    size = math.hypot(*trial)
    tf = trial if size <= cap else (trial[0] * cap / size, trial[1] * cap / size)
    dp = (d1 - tf[0] / law.kss, d2 - tf[1] / law.kss)
    tau = tuple((1 - D) * law.kss * d + D * f for d, f in zip((d1, d2), tf))
    # dissipation: Y from products of the old and new gaps; the slider's elastic slip e = d - dp
    # enters as e_old . e_new - 0.5 (e_new - e_old) . (dp_new - dp_old) (MODEL.md's free energy,
    # trapezoidal work: the step's balance is then exact off u = 0)
    go = old["gap"]
    eo = [g - q for g, q in zip(go[1:], old["dp"])]
    en = [d1 - dp[0], d2 - dp[1]]
    xs = sum(a * b - 0.5 * (b - a) * (q1 - q0) for a, b, q1, q0 in zip(eo, en, dp, old["dp"]))
    Y = (0.5 * law.knn * max(go[0], 0.0) * max(u, 0.0)
         + 0.5 * law.kss * (go[1] * d1 + go[2] * d2 - xs))
    tf_old = [law.kss * (g - q) for g, q in zip(old["gap"][1:], old["dp"])]
    slide = sum((a + b) / 2 * (q1 - q0) for a, b, q1, q0 in zip(tf_old, tf, dp, old["dp"]))
    new.update(D=D, umax=umax, dmax=dmax, dp=dp,
               diss=old["diss"] + Y * (D - D_old) + (D_old + D) / 2 * slide,
               dissf=old["dissf"] + (D_old + D) / 2 * slide)
    return new, (sigma,) + tau


def drive(law, path):
    """Lists of tractions and state dicts along ``path`` (iterable of (u, d1, d2))."""
    s = virgin(law)
    ts, ss = [], []
    for g in path:
        s, t = step(law, s, tuple(float(x) for x in g))
        ts.append(t)
        ss.append(s)
    return ts, ss

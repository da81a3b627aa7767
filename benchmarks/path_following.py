"""Which path-following control a dynamic relaxation can solve: the closed-form snap-back bar.

Two elastic bars (length ``L`` each, Young's modulus ``E``, unit area) joined by a cohesive joint
(penalty stiffness ``kj``, strength ``ft``, linear softening to zero at the opening ``wc``, secant
unloading), the left end fixed and the right end loaded by a force ``lam`` (the load factor of a
unit pattern). The analytical curve is u_end = 2 L sigma / E + w(sigma), w = sigma / kj up to the
peak and w = w0 + (1 - sigma / ft) (wc - w0) after it (w0 = ft / kj): with 2 L / E > (wc - w0) /
ft the end displacement decreases on the softening branch (a snap-back).

The bar is a chain of ``n`` two-node elements per side relaxed as the solver relaxes a model:
fictitious masses from the Gershgorin row sums (safety 1.1), unit step, viscous damping on the
Rayleigh-quotient frequency. Each control is run through the whole curve in ``steps`` increments
and compared with the analytical curve:

* ``end displacement``: the loaded end held at a prescribed displacement, ``lam`` its reaction
  (the solver's ``Displacement`` / ``Indirect`` on the loaded DOF): past the peak it cannot follow
  the snap-back and jumps;
* ``dissipation (slaved)``: the load factor set at every iteration from the dissipation
  constraint of Gutierrez (2004), dG = 1/2 (lam0 P.du - dlam P.u0) = dtau, solved for lam with
  the current displacements (the way ``Indirect`` sets it from the held DOF's reaction). Along
  the constraint the out-of-balance force grows with the motion: its stiffness is k_t - lam0 P
  P^T / P.u0, on the 1-DOF spring k_t - k_secant < 0, so the equilibrium it should find repels
  the relaxation; the run records the residual ratio where it gave up;
* ``opening``: the joint's opening held at a prescribed value (the relaxation projected onto the
  constraint, in the metric of the masses), the load factor found by a secant iteration on the
  constraint's reaction, one relaxation per secant step (crack-opening control, de Borst 1987):
  traces the curve, snap-back included.

Run: ``python benchmarks/path_following.py [n=20 steps=60 L=1.0]``; prints one table (the largest
difference from the analytical curve in % of ft, relaxations and iterations per increment) and
writes ``benchmarks/out/path_following.csv``.
"""
import numpy as np

from common import report, start  # noqa: I100  (script folder on sys.path)

PARAMS = dict(
    n=20,              # elements per bar
    steps=60,          # increments over the curve (each control)
    L=1.0,             # m, length of each bar
    E=1.0e9,           # Pa
    ft=1.0e5,          # Pa, joint strength
    wc=1.0e-4,         # m, opening where the joint's traction reaches zero
    kj=1.0e12,         # Pa/m, joint penalty stiffness
    tol=1e-6,          # residual ratio of a converged relaxation
    max_iter=200_000,  # iterations of one relaxation at most
)


class Bar:
    """The chain: nodes 0..2n+1 (node 0 fixed, the joint between nodes n and n+1, the load on
    node 2n+1); ``kappa`` the joint's largest opening (its damage history)."""

    def __init__(self, p):
        self.p = p
        n = p["n"]
        self.k = p["E"] / (p["L"] / n)   # N/m per element (unit area)
        self.nn = 2 * n + 2
        self.j = n                         # the joint's left node
        self.kappa = 0.0
        diag = np.full(self.nn, 2.0 * self.k)
        diag[-1] = self.k
        diag[self.j] = diag[self.j + 1] = self.k + p["kj"]
        self.m = 1.1 * 2.0 * diag / 4.0    # fictitious masses from the row sums 2 x diag, kg
        self.free = np.ones(self.nn, bool)
        self.free[0] = False

    def traction(self, w, kappa):
        """Joint traction Pa at opening ``w`` with history ``kappa`` (secant unloading)."""
        p = self.p
        w0 = p["ft"] / p["kj"]
        k = max(kappa, w)
        if k <= w0:
            return p["kj"] * w
        env = p["ft"] * max(0.0, 1.0 - (k - w0) / (p["wc"] - w0))
        return env / k * w

    def internal(self, u):
        """Internal forces (nn,) N."""
        f = np.zeros(self.nn)
        j = self.j
        for lo, hi in ((0, j), (j + 1, self.nn - 1)):
            s = self.k * np.diff(u[lo:hi + 1])
            f[lo:hi] -= s
            f[lo + 1:hi + 1] += s
        t = self.traction(u[j + 1] - u[j], self.kappa)
        f[j] -= t
        f[j + 1] += t
        return f

    def relax(self, u, lam_of, hold, tol, max_iter):
        """Relax ``u`` in place; ``lam_of(u, fint)``: the load factor at each iteration;
        ``hold(u, v)``: projects the state onto the control's constraint. Returns (converged,
        iterations, the load factor, residual ratio)."""
        v = np.zeros(self.nn)
        P = np.zeros(self.nn)
        P[-1] = 1.0
        fprev = self.internal(u)
        ratio = np.inf
        for it in range(1, max_iter + 1):
            fint = self.internal(u)
            lam = lam_of(u, fint)
            r = (lam * P - fint) * self.free
            if it % 10 == 0 or it == 1:
                held = hold(u, None, r)
                ref = max(abs(lam), np.abs(fint).max(), 1e-300)
                ratio = np.linalg.norm(held) / ref
                if ratio <= tol and it > 1:
                    return True, it, lam, ratio
                if not np.isfinite(ratio) or np.abs(u).max() > 1.0:
                    return False, it, lam, ratio
            num = v @ (fint - fprev)
            den = v @ (self.m * v)
            c = min(2.0 * np.sqrt(num / den), 1.9) if num > 0 and den > 0 and it > 1 else 0.0
            fprev = fint
            v = ((2.0 - c) * v + 2.0 * r / self.m) / (2.0 + c)
            u += v
            hold(u, v, None)
        return False, max_iter, lam, ratio


def analytic(p, sigma, softening):
    """End displacement m at stress ``sigma`` Pa, before (False) or after (True) the peak."""
    w0 = p["ft"] / p["kj"]
    w = w0 + (1.0 - sigma / p["ft"]) * (p["wc"] - w0) if softening else sigma / p["kj"]
    return 2.0 * p["L"] * sigma / p["E"] + w


def error(p, u_end, sigma, peaked):
    """Distance (Pa) of the point (u_end, sigma) from the analytical curve, along sigma."""
    sig = np.linspace(0.0, p["ft"], 2001)
    branch = analytic(p, sig, peaked)
    k = np.argmin(np.abs(branch - u_end))
    return abs(sig[k] - sigma) if np.abs(branch - u_end).min() < 1e-3 * p["wc"] else np.inf


def run_end_displacement(p):
    bar = Bar(p)
    u = np.zeros(bar.nn)
    top = analytic(p, p["ft"], False)
    rows, worst, iters, jumped = 0, 0.0, [], False
    for target in np.linspace(0.0, 1.5 * top, p["steps"] + 1)[1:]:
        bar.free[-1] = False
        u[-1] = target

        def lam_of(u, fint):
            return fint[-1]

        ok, it, lam, _ = bar.relax(u, lam_of, lambda u, v, r: r if r is not None else None,
                                   p["tol"], p["max_iter"])
        bar.kappa = max(bar.kappa, u[bar.j + 1] - u[bar.j])
        iters.append(it)
        rows += 1
        peaked = bar.kappa > p["ft"] / p["kj"] * 1.0001
        e = error(p, target, lam, peaked)
        if not np.isfinite(e):
            jumped = True    # no point of the analytical curve at this state: a jump
        else:
            worst = max(worst, e)
    return dict(control="end displacement", traced="no (jumps)" if jumped else "yes",
                max_error_pct_ft=100 * worst / p["ft"], relaxations_per_incr=1.0,
                iterations_per_incr=float(np.median(iters)))


def run_dissipation(p):
    """Up to 90 % of the peak under load control, then dissipation control (slaved)."""
    bar = Bar(p)
    u = np.zeros(bar.nn)
    P = np.zeros(bar.nn)
    P[-1] = 1.0
    for lam in np.linspace(0.0, 0.9 * p["ft"], 10)[1:]:
        bar.relax(u, lambda u, f, lam=lam: lam, lambda u, v, r: r, p["tol"], p["max_iter"])
    lam0, u0 = 0.9 * p["ft"], u.copy()
    dtau = 0.5 * p["ft"] * p["wc"] / p["steps"]   # the fracture energy in `steps` increments

    def lam_of(u, fint):
        return lam0 + (lam0 * P @ (u - u0) - 2.0 * dtau) / (P @ u0)

    ok, it, lam, ratio = bar.relax(u, lam_of, lambda u, v, r: r, p["tol"], p["max_iter"])
    return dict(control="dissipation (slaved)",
                traced="yes" if ok else (f"no: residual ratio {ratio:.2g} after {it:,} "
                                         f"iterations"),
                max_error_pct_ft=float("nan"), relaxations_per_incr=1.0,
                iterations_per_incr=float(it))


def run_opening(p):
    bar = Bar(p)
    u = np.zeros(bar.nn)
    j = bar.j
    mi = 1.0 / bar.m[j:j + 2]
    share = mi / mi.sum()
    worst, iters, relaxations = 0.0, [], []
    for w in np.linspace(0.0, p["wc"], p["steps"] + 1)[1:]:
        def hold(u, v, r, w=w):
            if r is not None:   # the residual plus the constraint's force c mu
                mu = -(r[j + 1] * mi[1] - r[j] * mi[0]) / mi.sum()
                r = r.copy()
                r[j + 1] += mu
                r[j] -= mu
                return r
            gap = w - (u[j + 1] - u[j])
            u[j + 1] += share[1] * gap
            u[j] -= share[0] * gap
            if v is not None:
                dv = v[j + 1] - v[j]
                v[j + 1] -= share[1] * dv
                v[j] += share[0] * dv
            return None

        def reaction(lam):
            ok, it, _, _ = bar.relax(u, lambda u, f: lam, hold, p["tol"], p["max_iter"])
            iters.append(it)
            r = lam * (np.arange(bar.nn) == bar.nn - 1) - bar.internal(u)
            return r[j + 1]    # the constraint's reaction on the right face, N

        hold(u, None, None)
        lam_a = bar.traction(w, bar.kappa)
        lam_b = 1.01 * lam_a + 1e-3 * p["ft"]
        mu_a, mu_b = reaction(lam_a), reaction(lam_b)
        n = 2
        while abs(mu_b) > 1e-6 * p["ft"] and n < 20:
            lam_a, lam_b, mu_a = lam_b, lam_b - mu_b * (lam_b - lam_a) / (mu_b - mu_a), mu_b
            mu_b = reaction(lam_b)
            n += 1
        relaxations.append(n)
        bar.kappa = max(bar.kappa, w)
        worst = max(worst, error(p, u[-1], lam_b, w > p["ft"] / p["kj"] * 1.0001))
    return dict(control="opening (secant on the load factor)",
                traced="yes" if np.isfinite(worst) else "no",
                max_error_pct_ft=100 * worst / p["ft"],
                relaxations_per_incr=float(np.mean(relaxations)),
                iterations_per_incr=float(np.sum(iters) / p["steps"]))


def main(argv=None):
    p = start(PARAMS, __doc__, argv)
    snap = 2 * p["L"] / p["E"] > (p["wc"] - p["ft"] / p["kj"]) / p["ft"]
    print(f"snap-back: {'yes' if snap else 'no'} (2 L / E = {2 * p['L'] / p['E']:.3g} m/Pa, "
          f"softening compliance {(p['wc'] - p['ft'] / p['kj']) / p['ft']:.3g} m/Pa)")
    rows = [run_end_displacement(p), run_dissipation(p), run_opening(p)]
    report(rows, "path_following", "Path-following controls on the snap-back bar")


if __name__ == "__main__":
    main()

"""Is the out-of-balance force of a creeping increment differentiable, and what does a
matrix-free Newton-Krylov step do there? (docs/internals.md, "Decisions")

Runs scene ``scene`` (default: the main job, S5 coarse mesh) to row ``row`` and, once its
relaxation has run ``at`` iterations (at the end of the compiled call that passes them), freezes
the state and probes the out-of-balance force F(x) of the free DOFs x (nodes and reference points;
the trial state of an increment is a function of the displacements alone; scenes under indirect
control, whose load factor is an unknown too, are refused):

* the contact points that damage or slide in the trial state;
* finite-difference directional derivatives A(v) = -(F(x + h v) - F(x)) / h, h scaled so that
  the largest component moves by ``h`` times the largest displacement, along random directions
  and along the relaxation's velocity (the creep): their additivity |A(u + v) - A(u) - A(v)| and
  odd symmetry |A(-u) + A(u)|, both 0 where F has a Jacobian;
* one Newton step on those products, K dx = F (K = -dF/dx), by right-preconditioned GMRES of at
  most ``krylov`` iterations with the fictitious masses (Jacobi) and with the coarse affine-block
  space added (:mod:`dr_masonry.coarse`): GMRES's own residual, the true one recomputed at its
  answer, and the residual ratio after a backtracking line search (each product is one force
  evaluation, the cost of about one relaxation iteration);
* preconditioned nonlinear conjugate gradients (Polak-Ribiere+, restarted along the preconditioned
  force where the curvature turns negative) from the frozen state, with each preconditioner, for
  at most ``cg`` force evaluations: per iteration one secant product along the search direction
  (at the previous step length) and one true out-of-balance force; the evaluations it takes to
  reach the solver's tolerance, or the ratio it has when the budget ends (BENCHMARKS.md,
  "Nonlinear conjugate gradients from a frozen row");

then lets the relaxation finish the row from the frozen state and reports its iterations (with
those of the attempts it cut, if the stall rule cut the probed one). Run:
``NUMBA_NUM_THREADS=1 python benchmarks/newton_krylov.py [scene=squat_wall args= row=17 at=2000
krylov=200 h=1e-8 cg=3000]`` (about 1 min; ``cg=0`` skips the conjugate gradients; ``args``: the
scene's own parameters, space-separated, e.g. ``args=protocol=cyclic``); writes
``benchmarks/out/newton_krylov*.csv``.
"""
import numpy as np

import common

DEFAULTS = dict(scene="squat_wall", args="", row=17, at=2000, krylov=200, h=1e-8, seed=1, cg=3000)


class _Done(Exception):
    """The probed row is committed."""


class Probe:
    """F(x), its finite-difference products and a Newton-Krylov step at the frozen state of
    ``sim``."""

    def __init__(self, sim, h):
        from dr_masonry.coarse import BlockCoarse
        d = sim.dyn
        self.sim, self.h = sim, h
        self.nm = (d.free > 0) & (d.tied[:, None] < 0)   # (n, 3) free DOFs of untied nodes
        self.rm = d.rpfree > 0                            # (nr, 6)
        self.rpres = np.zeros((d.rpX.shape[0], 6))
        self.lam = float(sim.lam[0])
        self.evals = 0
        self.x0 = np.concatenate([d.U[self.nm], d.rpU[self.rm]])
        self.F0 = self.F(self.x0)
        self.ratio0 = self.ratio()
        self.scale = max(np.abs(self.x0).max(), 1e-3)
        c = sim.coarse if sim.coarse is not None else BlockCoarse(sim)
        self.coarse, self.op = c, c.operator(np.zeros(3, dtype=np.int64))
        self.dinv = self.pack(np.repeat(d.minv[:, None], 3, axis=1), d.rpminv)

    def pack(self, nodal, rp):
        """Vector (m,) of the free DOFs of nodal (n, 3) and reference-point (nr, 6) arrays."""
        return np.concatenate([nodal[self.nm], rp[self.rm]])

    def unpack(self, v):
        """Nodal (n, 3) and reference-point (nr, 6) arrays of a free-DOF vector ``v`` (m,)."""
        nodal = np.zeros(self.nm.shape)
        rp = np.zeros(self.rm.shape)
        k = int(self.nm.sum())
        nodal[self.nm], rp[self.rm] = v[:k], v[k:]
        return nodal, rp

    def F(self, x):
        """Out-of-balance forces (m,) N of the free DOFs at x (m,) m / rad."""
        from dr_masonry.kernels import relaxation as R
        s, d = self.sim, self.sim.dyn
        k = int(self.nm.sum())
        d.U[self.nm], d.rpU[self.rm] = x[:k], x[k:]
        R.place_rigid_nodes(d)
        R.internal_forces(s.mesh, s.cont, d)
        R.residual(d, self.lam, self.rpres)
        self.evals += 1
        return np.concatenate([d.res[self.nm], self.rpres[self.rm]])

    def ratio(self):
        """The solver's convergence ratio of the last ``F``: max(global ratio, scaled block
        ratio), as in ``R.relax``."""
        from dr_masonry.kernels import relaxation as R
        s, d = self.sim, self.sim.dyn
        rn, ref = R.norms(d, self.lam, self.rpres)
        c = s.options.convergence
        rb = (c.tol * R.block_imbalance(s.cont, d, self.lam, d.bratio)[0] / c.block_tol
              if c.block_tol > 0 else 0.0)
        return max(rn / max(ref, s.ref_floor), rb)

    def A(self, v):
        """Finite-difference product -(F(x0 + e v) - F(x0)) / e, N/m."""
        e = self.h * self.scale / max(np.abs(v).max(), 1e-300)
        return -(self.F(self.x0 + e * v) - self.F0) / e

    def precondition(self, r, coarse):
        """Fictitious-mass (Jacobi) preconditioner, plus the coarse affine-block solve."""
        z = self.dinv * r
        if coarse and self.op is not None:
            nodal, rp = self.unpack(r)
            dq = self.op["solve"](self.coarse.project(self.op, nodal, rp)[self.op["idx"]])
            du, drp = self.coarse.prolong(self.op, dq)
            full = np.zeros(self.nm.shape)
            full[self.op["nodes"]] = du
            z += self.pack(full, drp)
        return z

    def newton_step(self, krylov, coarse):
        """One Newton step from x0: a table row."""
        import scipy.sparse.linalg as spla
        n = self.x0.size
        e0 = self.evals
        AM = spla.LinearOperator((n, n), matvec=lambda y: self.A(self.precondition(y, coarse)))
        res = []
        y, _ = spla.gmres(AM, self.F0, rtol=1e-2, restart=krylov, maxiter=1,
                          callback=res.append, callback_type="pr_norm")
        dx = self.precondition(y, coarse)
        true = np.linalg.norm(self.F0 - self.A(dx)) / np.linalg.norm(self.F0)
        step, after = 1.0, self.ratio0
        while step >= 1.0 / 32:
            self.F(self.x0 + step * dx)
            after = self.ratio()
            if after < self.ratio0:
                break
            step *= 0.5
        else:
            step = 0.0
        self.F(self.x0)   # back to the frozen state
        return dict(preconditioner="masses + coarse" if coarse else "masses",
                    gmres_iterations=len(res), gmres_residual=float(res[-1]) if res else 1.0,
                    true_residual=float(true), largest_dx_mm=float(np.abs(dx[:self.nm.sum()]).max() * 1e3),
                    line_search_step=step, ratio_before=self.ratio0,
                    ratio_after=float(after), force_evaluations=self.evals - e0)

    def conjugate_gradients(self, evals, coarse):
        """Nonlinear preconditioned CG from x0 for at most ``evals`` force evaluations: a table
        row. The step along the search direction p is p.r / p.q with q the secant product
        (r - F(x + a p)) / a at the last step length a (1 at the start, the fictitious masses'
        step)."""
        e0, tol = self.evals, self.sim.options.convergence.tol
        x, r, ratio = self.x0.copy(), self.F0.copy(), self.ratio0
        z = self.precondition(r, coarse)
        p, rz, a_try = z.copy(), r @ z, 1.0
        its, restarts, best, status = 0, 0, ratio, "budget spent"
        while self.evals - e0 < evals:
            q = (r - self.F(x + a_try * p)) / a_try
            pq = p @ q
            if not np.isfinite(pq):
                status = "non-finite forces"
                break
            if pq <= 0.0:   # negative curvature along p: restart along z with a shorter trial
                restarts += 1
                p, a_try = z.copy(), 0.5 * a_try
                continue
            a = (p @ r) / pq
            x = x + a * p
            its += 1
            rn = self.F(x)
            ratio = self.ratio()
            if not np.isfinite(ratio):
                status = "non-finite forces"
                break
            best = min(best, ratio)
            if ratio < tol:
                status = "converged"
                break
            zn = self.precondition(rn, coarse)
            beta = max(0.0, zn @ (rn - r) / rz)
            r, z, rz = rn, zn, rn @ zn
            p = z + beta * p
            a_try = min(max(a, 0.1 * a_try), 10.0 * a_try)
        self.F(self.x0)   # back to the frozen state
        return dict(preconditioner="masses + coarse" if coarse else "masses", status=status,
                    iterations=its, force_evaluations=self.evals - e0,
                    negative_curvature_restarts=restarts, ratio_before=self.ratio0,
                    ratio_at_end=float(ratio), lowest_ratio=float(best))


class Monitor:
    """Probe row ``row`` once ``at`` iterations into it; stop when the row is committed."""

    def __init__(self, params):
        self.p = params
        self.rows, self.newton, self.cg, self.frozen_at = None, None, [], 0

    def __call__(self, sim, info, done):
        row = self.p["row"]
        if sim.increment >= row:
            raise _Done
        if sim.increment + 1 != row or self.rows is not None or done < self.p["at"]:
            return
        from dr_masonry.kernels import joint_law as J
        from dr_masonry.kernels import relaxation as R
        from dr_masonry.solver import controls
        snap = controls.snapshot(sim)
        pr = Probe(sim, self.p["h"])
        c = sim.cont
        damaging = int((c.s_new[:, J.JS_D] > c.s_old[:, J.JS_D]).sum())
        sliding = int(((c.s_new[:, J.JS_DP1] != c.s_old[:, J.JS_DP1])
                       | (c.s_new[:, J.JS_DP2] != c.s_old[:, J.JS_DP2])).sum())
        self.frozen_at = done
        print(f"row {row}, {done} iterations in: ratio {pr.ratio0:.3e}; contact points "
              f"{c.slave.size}, damaging {damaging}, sliding {sliding}", flush=True)
        rng = np.random.default_rng(self.p["seed"])
        creep = pr.pack(sim.dyn.V, sim.dyn.rpV)
        creep /= np.abs(creep).max()
        pairs = {"random, random": (rng.standard_normal(creep.size), rng.standard_normal(creep.size)),
                 "creep, random / 100": (creep, 1e-2 * rng.standard_normal(creep.size))}
        self.rows = []
        for name, (u, v) in pairs.items():
            au, auv = pr.A(u), pr.A(u + v)
            self.rows.append(dict(directions=name, additivity=float(
                np.linalg.norm(auv - au - pr.A(v)) / np.linalg.norm(auv)),
                odd_symmetry=float(np.linalg.norm(pr.A(-u) + au) / np.linalg.norm(au))))
        self.newton = [pr.newton_step(self.p["krylov"], coarse) for coarse in (False, True)]
        if self.p["cg"] > 0:
            self.cg = [pr.conjugate_gradients(self.p["cg"], coarse) for coarse in (False, True)]
        controls.restore(sim, snap)
        R.place_rigid_nodes(sim.dyn)


def main(argv=None):
    params = common.start(DEFAULTS, __doc__, argv)
    from dr_masonry.loading import Indirect
    from dr_masonry.params import ParameterError
    sim, stages = common.built_scene(params["scene"], params["args"], "newton_krylov_run")
    if any(isinstance(c, Indirect) for st in stages for c in st.controls):
        raise ParameterError(f"parameter scene={params['scene']!r}: the scene loads by indirect "
                             f"control, whose load factor is an unknown of the increment; the "
                             f"probe holds it fixed, which is another problem: probe a "
                             f"displacement-controlled scene (squat_wall, slender_wall)")
    mon = Monitor(params)
    sim.monitors.append(mon)
    try:
        sim.run(stages)
    except _Done:
        pass
    if mon.rows is None:
        raise SystemExit(f"row {params['row']} converged before {params['at']} iterations: "
                         f"nothing probed (a smaller at= probes it)")
    cut = int(sim.history["cut_iterations"][-1])   # the probed attempt, when it was cut
    total = int(sim.history["iterations"][-1]) + cut
    what = (f"committed the first part of the row ({cut:,} iterations in the attempts it cut)"
            if cut else "finished the row")
    common.report(mon.rows, "newton_krylov_derivatives",
                  f"finite-difference derivatives at row {params['row']} (h = {params['h']:g})")
    common.report(mon.newton, "newton_krylov_step",
                  f"one Newton step; the relaxation {what} {total - mon.frozen_at:,} iterations "
                  f"later ({total:,} in all)")
    if mon.cg:
        common.report(mon.cg, "newton_krylov_cg",
                      f"nonlinear conjugate gradients from the frozen state (tol "
                      f"{sim.options.convergence.tol:g}); the relaxation {what} {total - mon.frozen_at:,} "
                      f"iterations later")


if __name__ == "__main__":
    main()

"""Why an increment is slow: relax the next row of a stored run under a monitor.

Copies the result file ``file`` of scene ``scene`` and continues it from its checkpoint with the
parameters stored in it, for ``rows`` committed rows (a cut increment commits one per part), while a
monitor (``Simulation.monitors``) records the residual ratio after every call of the relaxation
and the coarse corrections accepted and rejected. From ``probe`` iterations into an attempt it
also records, every iteration for ``trace`` iterations, the residual of the nodes where it is
largest, and reports:

* how concentrated the residual is (share of its square in the top 1 % of the nodes; the blocks
  holding most of it),
* whether the motion is a steady creep (cosine between the displacement changes of the two
  halves of the trace: near 1 for a slow mode relaxing),
* whether the worst nodes ring (sign changes of their residual over the trace, and the period
  in iterations),
* whether the slow motion is one the coarse correction can represent: the share of the
  displacement change over the ``window`` iterations before the probe that each block's affine
  motion (mass-weighted least squares, :func:`affine_share`) carries, and the share of the rest
  in blocks with brick damage above 0.1 (a crack inside a brick is not affine).

The relaxation runs in calls of ``check_every`` = 1 iteration from the start (the iterates are
those of the stored run; an attempt may stop up to 9 iterations earlier than it would have with
checks every 10). Run: ``python benchmarks/slow_increment.py file=results/terraced_house.h5
scene=terraced_house [rows=1 probe=20000 trace=60 window=2000]``; writes ``benchmarks/out/
slow_increment.csv`` (residual ratio per call).
"""
import numpy as np

import common

DEFAULTS = dict(file="", scene="", rows=1, probe=20000, trace=60, top=5, window=2000)


def affine_share(du, mass, X, start):
    """Mass-weighted share of the node motion ``du`` (n, 3) (m) that the blocks' affine motions
    carry, and the squared mass norm of the rest per block (nb,): per block (nodes
    ``start[b]:start[b + 1]``, coordinates ``X`` (n, 3), masses ``mass`` (n,)) the affine field
    a + B (X - c) closest to ``du`` in the mass norm (massless nodes do not count)."""
    nb = start.size - 1
    blk = np.repeat(np.arange(nb), np.diff(start))
    msum = np.maximum(np.add.reduceat(mass, start[:-1]), 1e-300)[:, None]
    c = np.add.reduceat(X * mass[:, None], start[:-1]) / msum
    phi = np.column_stack([np.ones(X.shape[0]), X - c[blk]])                   # (n, 4)
    wphi = mass[:, None] * phi
    A = np.add.reduceat(wphi[:, :, None] * phi[:, None, :], start[:-1])        # (nb, 4, 4)
    b = np.add.reduceat(wphi[:, :, None] * du[:, None, :], start[:-1])         # (nb, 4, 3)
    coef = np.linalg.solve(A + 1e-30 * np.eye(4), b)
    rest = du - np.einsum("ni,nik->nk", phi, coef[blk])
    total = float((mass[:, None] * du * du).sum())
    rest_b = np.bincount(blk, (mass[:, None] * rest * rest).sum(axis=1), minlength=nb)
    return (1.0 - rest_b.sum() / total if total > 0.0 else 1.0), rest_b


class _Done(Exception):
    """The rows asked for are relaxed."""


class Monitor:
    """Residual ratio per call, coarse corrections, and the probe of one attempt."""

    def __init__(self, sim, rows, probe, trace, top, window):
        self.last_row = sim.increment + rows
        self.probe, self.trace, self.top, self.window = probe, trace, top, window
        self.u_window = None   # displacements ``window`` iterations before the probe
        self.calls = []        # (row, iterations of the attempt, residual ratio, status)
        self.nodes = None      # probed nodes; their residual per traced iteration
        self.res, self.u = [], []
        self.report = None

    def __call__(self, sim, out, done):
        if sim.increment >= self.last_row:
            raise _Done
        if self.calls and done < self.calls[-1][1] and self.report is None:
            self.nodes, self.res, self.u = None, [], []   # a new attempt: probe that one
            self.u_window = None
        self.calls.append((sim.increment + 1, done, out.residual, out.status))
        d = sim.dyn
        if self.report is None and self.u_window is None and done >= self.probe - self.window:
            self.u_window = d.U.copy()
        if self.report is None and done >= self.probe:
            r = d.res * d.free
            if self.nodes is None:
                self.nodes = np.argsort(-np.linalg.norm(r, axis=1))[:self.top]
                self.u = [d.U.copy()]
            self.res.append(r[self.nodes].copy())
            if len(self.res) == self.trace // 2:
                self.u.append(d.U.copy())
            if len(self.res) >= self.trace:
                self.u.append(d.U.copy())
                self.report = self._analyse(sim, r)

    def _analyse(self, sim, r):
        """The probe's findings as a dict (table row)."""
        rn2 = (r ** 2).sum(axis=1)
        share = np.sort(rn2)[::-1][:max(1, rn2.size // 100)].sum() / rn2.sum()
        blocks = np.bincount(sim.model.node_block, weights=rn2, minlength=sim.model.n_blocks)
        worst = np.argsort(-blocks)[:3]
        a, b = self.u[1] - self.u[0], self.u[2] - self.u[1]
        creep = float((a * b).sum() / max(np.linalg.norm(a) * np.linalg.norm(b), 1e-300))
        tr = np.asarray(self.res)                      # (trace, top, 3)
        k = np.argmax(np.abs(tr).max(axis=0), axis=1)  # each node's largest component
        comp = tr[:, np.arange(self.top), k]           # (trace, top)
        flips = (np.diff(np.sign(comp), axis=0) != 0).sum(axis=0)
        period = 2.0 * (tr.shape[0] - 1) / max(int(flips.max()), 1)
        from dr_masonry.kernels.plastic_damage import MS_DC, MS_DT
        m, d = sim.model, sim.dyn
        mass = np.divide(1.0, d.minv, out=np.zeros_like(d.minv), where=d.minv > 0.0)
        aff, rest = affine_share((self.u[0] - self.u_window) * d.free, mass, m.nodes,
                                 np.asarray(m.block_node_start))
        s = sim.mesh.s_new
        dmg = np.zeros(m.n_blocks)   # each block's largest brick damage
        np.maximum.at(dmg, np.asarray(m.element_block),
                      np.maximum(s[:, :, MS_DT], s[:, :, MS_DC]).max(axis=1))
        return dict(row=sim.increment + 1, at_iteration=self.probe,
                    top1pct_share=float(share),
                    worst_blocks=" ".join(f"{b}:{blocks[b] / rn2.sum():.2f}" for b in worst),
                    creep_cosine=creep, worst_nodes=" ".join(map(str, self.nodes)),
                    sign_changes=" ".join(map(str, flips)), ringing_period=period,
                    amplitude_N=float(np.abs(comp).max()), window=self.window,
                    affine_share=aff,
                    rest_in_damaged=float(rest[dmg > 0.1].sum() / max(rest.sum(), 1e-300)),
                    damaged_blocks=int((dmg > 0.1).sum()))


def main(argv=None):
    params = common.start(DEFAULTS, __doc__, argv)
    from dr_masonry.params import ParameterError
    import dr_masonry.solver as S
    for key, low in (("rows", 1), ("probe", 0), ("trace", 2), ("top", 1), ("window", 1)):
        if params[key] < low:
            raise ParameterError(f"parameter {key}={params[key]!r}: must be >= {low}")
    sim, stages, copy = common.stored_run(params["scene"], params["file"], "slow_increment")
    sim.options.convergence.check_every = 1
    S.CALL_ITERATIONS = 1
    sim.resume(copy)
    mon = Monitor(sim, params["rows"], params["probe"], params["trace"], params["top"],
                  params["window"])
    sim.monitors.append(mon)
    counts = (0, 0)
    try:
        sim.run(stages)
    except _Done:
        pass
    if sim.coarse is not None:
        counts = (sim.coarse.n_corrections - sim.coarse.n_rejected, sim.coarse.n_rejected)
    calls = [dict(row=c[0], iterations=c[1], residual_ratio=c[2], status=c[3])
             for c in mon.calls if c[1] % 2000 == 0 or c[3] != 1]
    common.report(calls, "slow_increment", f"residual ratio every 2,000 iterations and at each "
                  f"attempt's end ({params['scene']}, from {params['file']})")
    print(f"\ncoarse corrections accepted {counts[0]}, rejected {counts[1]}")
    if mon.report is not None:
        common.report([mon.report], "slow_increment_probe", "where the residual sits")
    else:
        print(f"(no attempt reached {params['probe']} iterations: nothing probed)")


if __name__ == "__main__":
    main()

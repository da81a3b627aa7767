"""Where the energy-balance error of a run comes from: the joints' work rule, point by point.

Runs scene ``scene`` (a module of ``cases/``) with the parameters ``args`` (``key=value`` words,
as on its command line) and, at every committed row, compares each contact point's trapezoidal
work, ``area * (t_prev + t) / 2 . (g - g_prev)`` with the local gap g (m) and tractions t (Pa) of
the last and this committed state, with its change of stored energy plus dissipation (J). Their
difference is the point's share of the run's balance error (``W_ext - E_stored - D``, the
history column ``balance_error`` times the gross work). It is split into points whose normal gap
changed sign within the row (opened from compression, or closed) and the others: at the kink of
the normal law (penalty kc closed, (1 - D) knn open) the trapezoidal rule's work minus the
energy the point stores is ``0.5 (k_before - k_after) u0 u1``, negative for an opening point,
positive for a closing one, O(step^2) each. The same with the
points' nodal forces and displacements (which also counts the turning of their frames), the
hexahedra's share, and the work of the out-of-balance forces left at convergence add up to the
row's balance error.

Rows whose contact set was re-detected (sliding) compare the points by index, as stored.

Run: ``python benchmarks/balance_split.py [scene=terraced_house args="fast=true direction=-1"
rows=0]`` (``rows`` > 0 stops after that many committed rows); writes ``benchmarks/out/
balance_split.csv``.
"""
import importlib

import numpy as np

import common

DEFAULTS = dict(scene="terraced_house", args="fast=true direction=-1", rows=0)


class _Done(Exception):
    """The rows asked for are committed."""


def split_rows(sim, stages, rows=0):
    """Run ``stages`` on ``sim``; returns one dict per committed row after the first: the row's
    balance error (fraction of the gross work), its external work, and the joints' bookkeeping
    error (J) in all, at points that changed between closed and open (and how many), and at the
    others; the joints' error with their nodal forces and displacements instead of their local
    tractions and gaps (``joints_nodal``: also counts the turning of their frames), and the blocks'
    (the hexahedra's nodal trapezoidal work against their change of stored energy + dissipation).
    ``residual``: the trapezoidal work of the out-of-balance forces left at the free DOFs (the
    rows are converged to a tolerance, not to zero), the part of the external work that no
    internal force absorbed. ``joints_nodal + blocks + residual`` is the row's change of the
    balance error times the gross work, up to the rigid reference points' rotations."""
    from dr_masonry.kernels.joint_law import JS_DISS
    from dr_masonry.kernels.plastic_damage import MS_DISS
    out, prev = [], {}

    class Recorder:
        """An observer of the committed rows (``Simulation.observers``)."""

        def row(self, sim, row):
            c, m, d = sim.cont, sim.mesh, sim.dyn
            act = m.active
            state = dict(g=c.gaps.copy(), t=c.trac.copy(), psi=c.psi.copy(),
                         dis=c.s_old[:, JS_DISS] * c.area, fc=c.fbuf.reshape(-1, 5, 3).copy(),
                         nodes=np.column_stack([c.slave, c.master]), U=d.U.copy(),
                         fh=m.fbuf[act].copy(), eh=m.energy[act].copy(),
                         dh=(m.s_old[act, :, MS_DISS] * m.wdet[act]).sum(axis=1),
                         res=np.where(d.free > 0, d.res, 0.0))
            w_ext = sim.energy.totals["W_ext"]
            if prev and prev["g"].shape == state["g"].shape:
                stored = (state["psi"] - prev["psi"]) + (state["dis"] - prev["dis"])
                work = c.area * (0.5 * (prev["t"] + state["t"])
                                 * (state["g"] - prev["g"])).sum(axis=1)
                err = work - stored
                du = state["U"] - prev["U"]
                # the same in nodal forces and displacements: includes the turning of the frames
                nodal = ((0.5 * (prev["fc"] + state["fc"]) * du[state["nodes"]]).sum(axis=(1, 2))
                         - stored)
                hex_work = (0.5 * (prev["fh"] + state["fh"]) * du[m.conn[act]]).sum()
                blocks = (hex_work - (state["eh"] - prev["eh"]).sum()
                          - (state["dh"] - prev["dh"]).sum())
                res_work = (0.5 * (prev["res"] + state["res"]) * du).sum()
                # points re-paired by the sliding check (another master quad) since the last row
                moved = np.any(prev["nodes"] != state["nodes"], axis=1)
                # slave nodes off their master face: paired with a tangential offset gap0
                off_face = np.abs(c.gap0).max(axis=1) > 1e-9
                cross = np.sign(prev["g"][:, 0]) != np.sign(state["g"][:, 0])
                out.append(dict(row=sim.increment, balance_error=sim.history["balance_error"][-1],
                                W_gross=sim.energy.totals["W_gross"],
                                dW_ext=w_ext - prev["w_ext"], joints=float(err.sum()),
                                crossing=float(err[cross].sum()), n_crossing=int(cross.sum()),
                                others=float(err[~cross].sum()), joints_nodal=float(nodal.sum()),
                                n_repaired=int(moved.sum()),
                                nodal_minus_local_repaired=float((nodal - err)[moved].sum()),
                                n_off_face=int(off_face.sum()),
                                nodal_minus_local_off_face=float((nodal - err)[off_face].sum()),
                                blocks=float(blocks), residual=float(res_work)))
                print(" ".join(f"{k}={v:.5g}" for k, v in out[-1].items()), flush=True)
            state["w_ext"] = w_ext
            prev.update(state)
            if rows and len(out) >= rows:
                raise _Done

    sim.observers.append(Recorder())
    try:
        sim.run(stages)
    except _Done:
        pass
    return out


def main(argv=None):
    params = common.start(DEFAULTS, __doc__, argv)
    from dr_masonry.scene import scene_params
    case = importlib.import_module(f"dr_masonry.cases.{params['scene']}")
    p = scene_params(case.PARAMS, case.FAST, params["args"].split(), case.__doc__,
                     params["scene"])
    p.update(h5=None, progress=False)
    sim, stages = case.build(p)[:2]   # a scene with its own data returns it third
    out = split_rows(sim, stages, params["rows"])
    total, cross, nodal, blocks, resw = (sum(r[k] for r in out) for k in (
        "joints", "crossing", "joints_nodal", "blocks", "residual"))
    last = out[-1]
    print(f"\nbalance error at the last row {last['balance_error']:.3%} of the gross work "
          f"{last['W_gross']:.4g} J = {last['balance_error'] * last['W_gross']:.4g} J; joints' "
          f"work rule {total:.4g} J, of which {cross:.4g} J at points that changed between "
          f"closed and open; with nodal forces {nodal:.4g} J; blocks {blocks:.4g} J; "
          f"out-of-balance forces {resw:.4g} J")
    common.report(out, "balance_split", f"Energy-balance error by joint points, {params['scene']} "
                  f"{params['args']}")


if __name__ == "__main__":
    main()

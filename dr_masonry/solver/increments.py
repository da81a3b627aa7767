"""The increment loop: the increments of a stage, each relaxed to rest and committed, or cut in
two and retried, with the predictor that starts an increment from the previous one's motion and
the step memory that starts an increment split into the parts that converged last."""
from __future__ import annotations

import time
import warnings

import numpy as np

from . import certificate as cert
from . import controls as C
from .relaxing import opening_gain, relax_increment, relax_opening
from .rows import commit

#: the predictor does not continue the motion of a block that an accepted increment leaves out of
#: balance by more than this fraction of the forces on it (``kernels.relaxation.block_imbalance``)
LOOSE_BLOCK = 0.1
#: step memory (``Increments.adapt``): a part that converged within this fraction of stall_iter
#: iterations is quick, and ``QUICK_PARTS`` quick parts in a row take one halving back
QUICK = 0.1
QUICK_PARTS = 8


def run_stage(sim, stage, where, first=0, starts=None):
    """Run the increments ``first`` ... of ``stage``, number ``where[0]`` of the ``where[1]``
    stages of this ``run``; ``starts``: the controls' values at the stage's start when it is
    continued from a checkpoint (default: their current values)."""
    n = stage.increments
    targets = {}
    indirect = None
    resumed = starts is not None
    starts = dict(starts) if resumed else {}
    for ctl in stage.controls:
        key = C.key(ctl)
        start = starts.setdefault(key, sim.values.get(key, C.current(sim, ctl)))
        targets[key] = (ctl, ctl.values(start, n))
        if isinstance(ctl, (C.L.Indirect, C.L.Opening)):
            indirect = ctl
            if first == 0 and sim.factors.get(ctl.pattern.name) is not None:
                sim.lam[0] = sim.factors[ctl.pattern.name]
            C.pattern_forces(sim, ctl.pattern)
    start_values = [[list(key), float(starts[key])] for key in targets]
    if not resumed:   # a new load path: no step memory from the last stage
        sim.split = sim.quick = 0
    if not (resumed and sim._checkpoint_inside):
        sim.pending = []
    sim.stage_name = stage.name
    until = stage.until
    side = None if until is None else np.sign(until.value - until.position(sim))
    for i in range(first, n):
        sim.stage_position = (where[0], i, start_values, where[1], n)
        goal = {key: vals[i] for key, (ctl, vals) in targets.items()}
        if resumed and i == first and sim._checkpoint_inside:
            # a checkpoint inside increment i (after a committed part of a cut increment)
            # continues it with the parts it had left
            resume_inside(sim, stage, targets, goal, indirect)
        else:
            advance(sim, stage, targets, goal, indirect)
        reached = bool(side) and side * (until.value - until.position(sim)) <= 0.0
        # (a stage its Until ends is done: a resume goes on with the next)
        sim.stage_position = (where[0], n if reached else i + 1, start_values, where[1], n)
        if (i + 1) % stage.frames == 0 or i == n - 1 or i + 1 in stage.frame_at or reached:
            sim.write_frame()
        elif sim.checkpoints.due(sim):
            sim.checkpoints.write(sim)
        sim.progress.increment_done()
        if reached:
            break
    else:
        if side:
            warnings.warn(f"stage {stage.name!r} ended at its last increment with "
                          f"{until.target.name}.u{until.dof} = {until.position(sim):.6g}, short "
                          f"of its Until value {until.value:.6g}: give the stage's control a "
                          f"longer path", RuntimeWarning, stacklevel=2)
    if indirect is not None:
        C.release(sim, indirect)


def advance(sim, stage, targets, goal, indirect):
    """Move the controls from their current values to ``goal`` in ``2 ** sim.split`` equal
    parts, each an :func:`increment` at that cut depth (so each may still be cut
    ``max_cuts - sim.split`` times)."""
    split = sim.split
    parts = 2 ** split
    start = {key: sim.values.get(key, 0.0) for key in goal}
    base = len(sim.pending)
    for j in range(parts, 0, -1):   # the last part at the bottom of the work stack
        sim.pending.append(({k: start[k] + (goal[k] - start[k]) * j / parts for k in goal}
                            if j < parts else dict(goal), split, None))
    drain(sim, stage, targets, indirect, base)


def drain(sim, stage, targets, indirect, base=0):
    """Run the parts on the work stack ``sim.pending`` above its first ``base`` entries, the
    top one first: (goal, cut depth, parent's dissipation) each, as :func:`increment` takes
    them. An increment cut in two pushes its halves, so the stack always holds what is left of
    the increment in progress, and a checkpoint inside it stores that."""
    while len(sim.pending) > base:
        goal, depth, diss = sim.pending.pop()
        increment(sim, stage, targets, goal, indirect, depth, diss)


def resume_inside(sim, stage, targets, goal, indirect):
    """Finish increment ``goal`` from a checkpoint inside it: the parts it stored
    (``sim.pending``), the same ones the interrupted run had left. A checkpoint written before
    it stored them (``sim.pending`` None) moves the controls on to ``goal`` in new parts, unless
    that part was its last (the controls at their goal: the increment done)."""
    if sim.pending is None:
        sim.pending = []
        if not all(sim.values.get(k) == v for k, v in goal.items()):
            advance(sim, stage, targets, goal, indirect)
        return
    drain(sim, stage, targets, indirect)


def adapt_split(sim, depth, iterations):
    """The step memory after a part accepted at cut depth ``depth`` in ``iterations``: one
    reached by a cut splits the next increments as finely (at most max_cuts - 1 halvings);
    ``QUICK_PARTS`` quick ones in a row take one halving back (``Increments.adapt``)."""
    inc = sim.options.increments
    if not inc.adapt or inc.stall_iter <= 0:
        return
    if depth > sim.split:
        sim.split = min(depth, max(inc.max_cuts - 1, 0))
        sim.quick = 0
    elif iterations <= QUICK * inc.stall_iter:
        sim.quick += 1
        if sim.quick >= QUICK_PARTS and sim.split > 0:
            sim.split -= 1
            sim.quick = 0
    else:
        sim.quick = 0


def increment(sim, stage, targets, goal, indirect, depth, parent_diss=None):
    """Relax one increment to ``goal`` and commit it, or cut it in two: push both halves on
    the work stack ``sim.pending`` (:func:`drain` runs them); ``parent_diss``: the damage
    dissipation (J) of the attempt this half replaces when that one was cut for dissipating
    too much."""
    inc = sim.options.increments
    snap = C.snapshot(sim)
    start = {key: sim.values.get(key, 0.0) for key in goal}
    ctrl, pc, dctl = _set_up(sim, targets, goal, start, indirect, snap[0])
    max_iter = stage.max_iter or inc.max_iter
    tol = stage.tol or sim.options.convergence.tol
    stall = inc.stall_iter if depth < inc.max_cuts else 0
    t0 = time.perf_counter()
    coarse0 = coarse_counts(sim)
    if isinstance(indirect, C.L.Opening):
        key = C.key(indirect)
        con = C.constraint(sim, indirect, goal[key], opening_gain(sim, indirect))
        out = relax_opening(sim, con, tol, max_iter, stall)
    else:
        out = relax_increment(sim, ctrl, pc, tol, max_iter, stall)
    elapsed = time.perf_counter() - t0
    coarse = tuple(b - a for a, b in zip(coarse0, coarse_counts(sim)))
    failed = cert.failure(sim, stage, out)
    if failed:
        C.restore(sim, snap)
        sim.fail(failed)
    v = cert.verdict(sim, out, depth, parent_diss)
    if not v.accept:
        C.restore(sim, snap)
        sim._cut_work[0] += out.iterations
        sim._cut_work[1] += elapsed
        if depth >= inc.max_cuts:
            sim.fail(cert.not_converged(sim, stage, out, v, tol, max_iter, depth))
        diss = v.energies.diss if v.too_much else None
        sim.pending.append((goal, depth + 1, diss))
        sim.pending.append(({k: 0.5 * (start[k] + goal[k]) for k in goal}, depth + 1, diss))
        return
    if v.floor:
        warnings.warn(f"increment {sim.increment + 1} of stage {stage.name!r} accepted at "
                      f"residual ratio {out.residual:.2e} (tol {tol:.1e}, floor_tol "
                      f"{sim.options.convergence.floor_tol:.1e}) after {out.iterations} "
                      f"iterations, out-of-balance resultant {v.balance.ratio:.2%} of the "
                      f"driving force", RuntimeWarning, stacklevel=2)
    sim.du_prev = predictor_motion(sim, snap[0])
    sim.dctl_prev = dctl
    sim.dlam_prev = float(sim.lam[0] - snap[7][0])
    commit(sim, out, elapsed, v.energies, v.balance, C.control_code(indirect), coarse)
    adapt_split(sim, depth, out.iterations)
    if depth > 0 and sim.checkpoints.due(sim):
        sim.checkpoints.write(sim, inside=True)   # a part of a cut increment (hours, some)


def coarse_counts(sim):
    """(accepted, rejected) coarse corrections of the run so far (0, 0 before the first)."""
    co = sim.coarse
    return (0, 0) if co is None else (co.n_corrections - co.n_rejected, co.n_rejected)


def _set_up(sim, targets, goal, start, indirect, u_before):
    """Impose the controls at ``goal``, assemble the loads, predict the displacements (and an
    opening control's factor) and mark what drives the increment; returns (ctrl (3,) int64,
    pc N: the indirect control of ``R.relax``, the control's change)."""
    for key, val in goal.items():
        C.apply(sim, targets[key][0], val)
        sim.values[key] = val
    C.assemble_loads(sim, indirect)
    ctrl = np.zeros(3, dtype=np.int64)
    pc = 1.0
    if isinstance(indirect, C.L.Indirect):
        ctrl[:], pc = C.control_dof(sim, indirect)
    # predictor: continue the previous increment's motion (and an opening control's change of
    # factor) when the control keeps its direction
    dctl = sum(goal[k] - start[k] for k in goal)
    r = _ratio(sim, dctl)
    if r and sim.du_prev is not None:
        sim.dyn.U[:] += r * sim.du_prev * sim.dyn.free
    if isinstance(indirect, C.L.Opening):
        sim.lam[0] += r * sim.dlam_prev
    C.drive(sim, [targets[k][0] for k in goal if goal[k] != start[k]], indirect)
    return ctrl, pc, dctl


def _ratio(sim, dctl):
    """The predictor's share of the previous increment's motion and change of factor for an
    increment that moves the controls by ``dctl``: their ratio, at most 2, where the control
    keeps its direction; else 0."""
    if (sim.options.increments.predictor and sim.dctl_prev != 0.0
            and dctl * sim.dctl_prev > 0):
        return min(dctl / sim.dctl_prev, 2.0)
    return 0.0


def predictor_motion(sim, u_before):
    """The accepted increment's displacement (n_nodes, 3) m from ``u_before`` on the free DOFs,
    for the next increment's predictor; zero on the blocks still out of balance by more than
    ``LOOSE_BLOCK``: they moved because they are loose, not because the load moved them
    (continued row after row, S5 cyclic carried bricks out of the wall's plane a few mm per row:
    docs/validation.md). The ratios are those ``R.relax`` left in ``dyn.bratio`` for the
    accepted state."""
    d = sim.dyn
    du = (d.U - u_before) * d.free
    du[np.repeat(d.bratio > LOOSE_BLOCK, np.diff(d.bstart))] = 0.0
    return du


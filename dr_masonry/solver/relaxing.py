"""Relaxing one load increment to rest: the compiled loop (``kernels.relaxation.relax``, or
``kernels.damping_schemes.relax_scheme`` for a non-default damping scheme) in spans between coarse
corrections, in calls short enough to keep Python responsive.

:func:`relax_increment` is the only caller of the loop kernels in a run; it returns the attempt's
``kernels.relaxation.Exit`` with the attempt's totals.

The loop kernels are called with SIGINT and SIGTERM held to their return
(:func:`~dr_masonry.interrupts.uninterrupted`): Numba boxes a returned namedtuple (``Exit``,
``Progress``) by calling its class, Python code in which a signal's handler runs, and the
``KeyboardInterrupt`` it raises there ended the process with a segmentation fault (Numba 0.68)
instead of the stop between two calls that a run promises (``tests/test_interrupts.py``).
"""
from __future__ import annotations

from contextlib import contextmanager

import numba
import numpy as np

from ..interrupts import uninterrupted
from ..kernels import relaxation as R

#: most iterations of one compiled ``relax`` call (rounded down to a multiple of check_every):
#: Python regains control at least this often (progress bar, Ctrl-C: seconds, not the tens of
#: minutes one long increment of S6 or S7 runs)
CALL_ITERATIONS = 2000
#: models with fewer nodes relax on one thread: below it the second thread's wake-ups in the three
#: parallel regions of an iteration cost more than it computes (docs/internals.md, "Decisions");
#: a run is the same on any thread count, so this changes the run time only
SERIAL_NODES = 500


@contextmanager
def threads_for(n_nodes):
    """Numba threads for relaxing a model of ``n_nodes`` nodes: one below ``SERIAL_NODES``, else
    as set; restored afterwards."""
    threads = numba.get_num_threads()
    if n_nodes < SERIAL_NODES:
        numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(threads)


def _loop(damping, con):
    """``loop(mesh, cont, dyn, lam, ctrl, pc, crit, pr, state) -> (Exit, Progress, state)`` for
    the scheme ``damping`` (a :class:`~dr_masonry.options.Damping`) and the held constraint
    ``con`` (viscous damping only); the other schemes' module is imported (and compiled) only by
    a run that uses one."""
    if damping.scheme == "viscous":
        def loop(mesh, cont, dyn, lam, ctrl, pc, crit, pr, state):
            return R.relax(mesh, cont, dyn, lam, ctrl, pc, damping.alpha, damping.ring, crit,
                           pr, con) + (state,)
        return loop, None
    from ..kernels import damping_schemes as D
    code = {"kinetic": D.DAMP_KINETIC, "local": D.DAMP_LOCAL, "fire": D.DAMP_FIRE}[damping.scheme]

    def loop(mesh, cont, dyn, lam, ctrl, pc, crit, pr, state):
        return D.relax_scheme(mesh, cont, dyn, lam, ctrl, pc, code, damping.alpha, crit, pr,
                              state)
    with uninterrupted():   # a namedtuple returned (module docstring)
        return loop, D.start_state(code, damping.alpha)


def relax_increment(sim, ctrl, pc, tol, max_iter, stall, con=None):
    """Relax the increment set up on ``sim``'s arrays; returns its ``R.Exit`` with the attempt's
    iterations and damped energy J. ``con``: an ``R.Constraint`` to hold (None: none); one with
    a gain starts from twice the multiple of it that the last attempt ended with
    (``sim.opening_gmul``, at most 1) and leaves its own there: a factor that overshot the
    structure's equilibrium at the last increment would again.

    With ``sim.use_coarse``, in spans of ``coarse_every`` iterations (doubled after a rejected
    correction and after the tenth of an increment, up to 64 x; none after two rejections in a
    row), each preceded by a coarse correction on the blocks' affine motions
    (:mod:`dr_masonry.coarse`). ``ctrl`` (3,) int64 and ``pc`` N: the indirect control
    (``R.relax``); ``stall``: the kernel's ``stall_iter``. A span runs as compiled calls of at
    most ``CALL_ITERATIONS`` (the same iterates as one call: ``Progress.seg``), between which
    ``sim.monitors`` run, the progress bar is updated and Ctrl-C is honoured.
    """
    o, d = sim.options, sim.dyn
    c, k = o.convergence, o.coarse
    loop, state = _loop(o.damping, R.no_constraint() if con is None else con)
    rejected = 0 if sim.use_coarse else 2
    if sim.use_coarse:
        if sim.coarse is None:
            from ..coarse import BlockCoarse
            sim.coarse = BlockCoarse(sim)
        rpres = np.zeros((d.rpX.shape[0], 6))
        sim.coarse.refresh()
    call = max(c.check_every, CALL_ITERATIONS - CALL_ITERATIONS % c.check_every)
    done, damped, every, tries, span_end = 0, 0.0, k.every, 0, 0
    moving = con is not None and con.gain != 0.0
    pr = R.start_progress(min(1.0, 2.0 * sim.opening_gmul) if moving else 1.0)
    with threads_for(d.U.shape[0]):
        while True:
            if done >= span_end:   # a new span, after a coarse correction while they help
                if rejected < 2:
                    R.place_rigid_nodes(d)
                    R.internal_forces(sim.mesh, sim.cont, d)
                    R.residual(d, sim.lam[0], rpres)
                    ok = sim.coarse.correct(sim.lam, rpres, ctrl)
                    rejected = 0 if ok else rejected + 1
                    tries += 1
                # a rejected correction, and every one after the first ten of an increment (in
                # softening, accepted steps may keep restarting the relaxation without finishing
                # it), let the relaxation run twice as long before the next try; after two
                # rejections in a row (or without the coarse correction) plain relaxation
                # finishes the increment
                if rejected >= 2:
                    every = max_iter
                elif ok and tries <= 10:
                    every = k.every
                else:
                    every = min(2 * every, 64 * k.every)
                span_end = min(done + every, max_iter)
                pr = pr._replace(seg=0)
            crit = R.Criteria(float(tol), float(sim.ref_floor), float(c.block_tol),
                              float(c.gap_tol), c.check_every, int(stall), 0.5 * sim.size,
                              float(max_iter - done), min(span_end - done, call))
            with uninterrupted():   # namedtuples returned (module docstring)
                out, pr, state = loop(sim.mesh, sim.cont, d, sim.lam, ctrl, pc, crit, pr, state)
            done += out.iterations
            damped += out.damped
            total = out._replace(iterations=done, damped=damped)
            if moving:
                sim.opening_gmul = pr.gmul
            for monitor in sim.monitors:
                monitor(sim, total, done)
            if out.status != R.ST_MAXITER or done >= max_iter:
                return total
            sim.progress.working(sim, out.residual, done)


#: secant steps on the load factor of an opening control before the attempt counts as stalled
SECANT_STEPS = 12
#: a relaxation of an opening control's secant runs to tol / POLISH once the constraint's reaction
#: is within POLISH x its tolerance (:func:`relax_opening`)
POLISH = 4.0


def pattern_slope(sim):
    """The opening constraint's reaction per unit factor (N) estimated without a relaxation:
    minus the total force of the increment's pattern (``dyn.P``, ``rpP``)."""
    return -(np.abs(sim.dyn.P).sum() + np.abs(sim.dyn.rpP).sum())


def opening_gain(sim, ctl):
    """``R.Constraint.gain`` of Opening ``ctl``: its ``rate`` over :func:`pattern_slope`; 0 for
    the secant (rate 0)."""
    return ctl.rate / pattern_slope(sim) if ctl.rate else 0.0


def relax_opening(sim, con, tol, max_iter, stall):
    """Relax an increment of an opening control: hold the constraint ``con`` (``R.Constraint``)
    and find the factor ``sim.lam`` of the control's pattern at which the constraint carries no
    force. With ``con.gain`` the factor relaxes with the motion in one relaxation
    (``Opening.rate``); else by a secant iteration on its reaction, each step one relaxation
    from the last one's state (docs/internals.md, "Decisions"). Returns the last relaxation's
    ``R.Exit`` with the increment's iterations and damped energy; a secant that does not bring
    the reaction within ``tol`` x the reference force in ``SECANT_STEPS`` steps ends as
    ``ST_STALLED``.

    The first trial is the factor the increment starts with (the predictor's: the last
    increment's change continued, ``increments._set_up``); the second steps it by the slope kept from
    the previous increment (``sim.opening_slope``, reaction N per unit factor: that of its
    widest secant pair, the least disturbed by the relaxations' own residual) or, at the first
    increment, by :func:`pattern_slope`. Once the reaction is within
    ``POLISH`` x its tolerance the relaxations run to ``tol / POLISH``: the reaction of a
    relaxation stopped at ``tol`` is uncertain by about its tolerance."""
    ctrl = np.zeros(3, dtype=np.int64)
    if con.gain != 0.0:
        return relax_increment(sim, ctrl, 1.0, tol, max_iter, stall, con)
    done, damped = 0, 0.0
    lam_a, mu_a, wide = None, None, 0.0
    inner = tol
    for step in range(SECANT_STEPS):
        out = relax_increment(sim, ctrl, 1.0, inner, max_iter - done, stall, con)
        done += out.iterations
        damped += out.damped
        total = out._replace(iterations=done, damped=damped)
        if out.status != R.ST_CONVERGED:
            return total
        lam_b, mu_b = float(sim.lam[0]), out.reaction
        if abs(mu_b) <= tol * out.ref:
            return total
        near = abs(mu_b) <= POLISH * tol * out.ref
        if near:
            inner = tol / POLISH
        if near and lam_a is not None and mu_a * mu_b < 0 and sim.opening_slope and (
                abs((lam_b - lam_a) * sim.opening_slope) <= tol * out.ref):
            return total   # the factor is bracketed to within its tolerance
        if lam_a is None or mu_b == mu_a:
            slope = sim.opening_slope
            if slope is None or slope == 0.0:
                slope = pattern_slope(sim)
        else:
            slope = (mu_b - mu_a) / (lam_b - lam_a)
            if abs(lam_b - lam_a) >= wide:
                wide = abs(lam_b - lam_a)
                sim.opening_slope = slope
        lam_a, mu_a = lam_b, mu_b
        sim.lam[0] = lam_b - mu_b / slope
        if done >= max_iter:
            break
    return total._replace(status=R.ST_STALLED)

"""The equilibrium certificate of an attempt at an increment: whether it is accepted (converged,
or at the residual floor with its resultant balanced), cut, or a failure with a diagnosis; the
out-of-balance resultant against the driving force; and the checks of an accepted state (block
balance, joint overhang, return mapping) that warn once per run."""
from __future__ import annotations

import warnings
from collections import namedtuple

import numpy as np

from ..kernels import relaxation as R
from ..kernels.hex8 import inverted_element
from ..kernels.plastic_damage import FLAG_RETURN, MS_FLAG

#: a row's overall balance (:func:`resultant`): the reference points' generalised out-of-balance
#: forces ``rpres`` (n_rp, 6), the out-of-balance resultant ``gap`` (3,) N, the driving force
#: ``drive`` (3,) N (NaN on the axes no control drives), their largest ratio and its axis (0-2)
Balance = namedtuple("Balance", "rpres gap drive ratio axis")
#: what an attempt's outcome means: ``accept`` it or cut it; at the residual ``floor``; its
#: ``energies`` and ``balance`` (None unless converged or at the floor); ``unbalanced``: at the
#: floor with its resultant beyond gap_tol; ``too_much``: dissipated beyond max_dissipation
Verdict = namedtuple("Verdict", "accept floor energies balance unbalanced too_much")
#: warn (once per run) when a joint node has slid off its master block's face by more than this
#: fraction of the face's shortest edge: contact points are paired in the reference configuration
OVERHANG_WARN = 0.05
#: warn (once per run) beyond this imbalance of a block: with block_tol a converged increment
#: leaves none above block_tol, so only a row accepted at the residual floor can
BLOCK_IMBALANCE_WARN = 0.5
#: load-step control: a half step that dissipates this fraction of its whole step's dissipation
#: or more holds a jump (smooth softening gives about one half) and is not cut again
JUMP = 0.75
#: the statuses of a relaxation stopped short of tol, to cut or accept at the floor
SHORT = (R.ST_MAXITER, R.ST_STALLED, R.ST_SLOW)


def verdict(sim, out, depth, parent_diss):
    """The :data:`Verdict` of the attempt that ended with ``out`` (``R.Exit``) at cut depth
    ``depth``; ``parent_diss``: the damage dissipation (J) of the attempt this half replaces when
    that one was cut for dissipating too much."""
    c, i = sim.options.convergence, sim.options.increments
    short = out.status in SHORT
    floor = short and 0.0 < out.ratio <= c.floor_tol
    energies = sim.energy.energies(sim) if out.status == R.ST_CONVERGED or floor else None
    balance = resultant(sim) if energies is not None else None
    # a row at the floor whose out-of-balance resultant is a large part of the driving force
    unbalanced = floor and c.gap_tol > 0 and balance.ratio > c.gap_tol
    # a half that dissipates as much as the whole step holds a jump (a crack that runs
    # unstably): smaller steps would only repeat it, so it is accepted
    too_much = (energies is not None and not unbalanced and i.max_dissipation > 0
                and depth < i.max_cuts and energies.ratio > i.max_dissipation
                and not (parent_diss is not None and energies.diss >= JUMP * parent_diss))
    accept = not ((short and not floor) or unbalanced or too_much)
    return Verdict(accept, floor, energies, balance, unbalanced, too_much)


def resultant(sim):
    """The overall balance of the current state as :data:`Balance` (after the energies, which
    leave the internal forces of these displacements): the out-of-balance resultant, the
    driving force (NaN on undriven axes) and their ratio of ``R.resultant``, with the driving set
    by ``controls.drive``. The residual ratio weighs every DOF against loads that gravity may
    dominate, so a row at the residual floor can keep a resultant of several per cent of a
    lateral load (docs/validation.md)."""
    d = sim.dyn
    rpres = np.zeros((d.rpX.shape[0], 6))
    R.residual(d, sim.lam[0], rpres)
    ratio, axis = R.resultant(d, sim.lam[0], rpres)
    drive = np.where(d.gspec[0] > 0.0, d.gspec[3], np.nan)
    return Balance(rpres, d.gspec[2].copy(), drive, ratio, axis)


def failure(sim, stage, out):
    """The diagnosis of a guard that stopped the relaxation (non-finite, run-away, unstable
    step), or None for an attempt that ran normally."""
    o = sim.options
    row = f"increment {sim.increment + 1} of stage {stage.name!r}"
    if out.status in (R.ST_NONFINITE, R.ST_RUNAWAY):
        inv = inverted(sim) if out.status == R.ST_NONFINITE else ""
        what = ("non-finite force or displacement" if out.status == R.ST_NONFINITE else
                f"run-away displacement {out.quantity:.3e} m (limit {0.5 * sim.size:.3e} m)")
        return (f"{row}: {what} at {place(sim, out)} after {out.iterations} iterations{inv}; "
                f"the time step is unstable (safety factor {o.damping.safety}) or the "
                f"structure lost equilibrium (collapse under load control)")
    if out.status == R.ST_UNSTABLE:
        node = out.where
        return (f"{row}: unstable time step after {out.iterations} iterations: the motion's "
                f"stiffness-to-mass ratio (omega dt)^2 = {out.quantity:.3g} stayed above the "
                f"central-difference limit 4 (fastest node {node}, block "
                f"{sim.model.node_block[node]}); the fictitious masses are too small for the "
                f"stiffness: raise SolverOptions.safety (now {o.damping.safety})")
    return None


def not_converged(sim, stage, out, v, tol, max_iter, depth):
    """The diagnosis of an increment that could not be cut again (:data:`Verdict` ``v``)."""
    c = sim.options.convergence
    if v.unbalanced:
        k = v.balance.axis
        hint = (f"; at the floor, its out-of-balance resultant {v.balance.gap[k]:.4g} N along "
                f"{'xyz'[k]} is {v.balance.ratio:.2%} of the driving force (gap_tol "
                f"{c.gap_tol}): continue with a larger gap_tol, max_iter or max_cuts")
    elif out.residual >= 1.0:
        hint = ("; the out-of-balance force exceeds the loads: an unstable step (safety "
                f"factor {sim.options.damping.safety}) or a structure that lost equilibrium")
    else:
        hint = ("; to go on, continue from the last checkpoint (scenes: resume=true) with a "
                "looser tol, a larger max_iter or more max_cuts")
    return (f"increment {sim.increment + 1} of stage {stage.name!r} did not converge in "
            f"{max_iter} iterations after {depth} cuts (residual ratio {out.residual:.2e} > tol "
            f"{tol:.1e}){hint}")


def place(sim, out):
    """The place a relaxation guard named (``out.where``, ``out.where_kind``), in words."""
    i, kind = out.where, out.where_kind
    if kind == R.WHERE_RP:
        return f"reference point {sim.rigid_points[i].name!r}"
    if kind == R.WHERE_LOAD:
        return "the load factor of the indirectly controlled pattern"
    return f"node {i} (block {sim.model.node_block[i]})"


def inverted(sim):
    """`` (element e of block b inverted: ...)`` if an active hexahedron has turned inside out in
    the current displacements (a corotational element then has NaN forces), else ``""``."""
    mesh = sim.mesh
    bad = inverted_element(sim.dyn.X + sim.dyn.U, mesh.conn, mesh.active)
    if bad is None:
        return ""
    e, g, det = bad
    return (f" (element {e} of block {sim.model.element_block[e]} inverted: Jacobian "
            f"determinant {det:.3e} m^3 at Gauss point {g})")


def check_block_balance(sim, out):
    """The accepted state's largest block imbalance ratio (``out.block_ratio``); warns once per
    run beyond ``BLOCK_IMBALANCE_WARN``."""
    ratio, b = float(out.block_ratio), int(out.block)
    if ratio > BLOCK_IMBALANCE_WARN and "balance" not in sim._warned:
        sim._warned.add("balance")
        tol = sim.options.convergence.block_tol
        warnings.warn(f"increment {sim.increment}: block {b} is out of balance by "
                      f"{ratio:.0%} of the forces on it at residual ratio "
                      f"{out.residual:.1e} (the global ratio weighs it against the whole "
                      f"model's load): a loose block, whose position and joint forces are "
                      f"approximate"
                      + (f" (accepted at the floor; block_tol {tol})" if tol > 0 else
                         "; SolverOptions.block_tol (scene parameter block_tol) relaxes "
                         "every block to balance"), RuntimeWarning)
    return ratio


def check_overhang(sim):
    """Largest distance (m) by which a joint node has slid off its master block's face (the
    start's partial overlaps subtracted); warns once per run beyond ``OVERHANG_WARN``."""
    from ..contact_search import overhang
    cont = sim.cont
    if cont.slave.size == 0:
        return 0.0
    ov = np.maximum(overhang(sim.dyn.X + sim.dyn.U, cont.slave, sim._sides)
                    - sim._overhang0, 0.0) * (cont.area > 0.0)   # not the points off a face
    k = int(np.argmax(ov / sim._side_size))
    if ov[k] > OVERHANG_WARN * sim._side_size[k] and "overhang" not in sim._warned:
        sim._warned.add("overhang")
        node = int(cont.slave[k])
        why = ("no other face is under it, so it still pushes on that face until it is half an "
               "element beyond it, then on nothing" if sim.sliding is not None else
               "contact points are paired in the reference configuration "
               "(SolverOptions.redetect=False), so such a node still pushes on that face")
        warnings.warn(f"increment {sim.increment}: joint node {node} (block "
                      f"{sim.model.node_block[node]}) has slid {ov[k] * 1e3:.3g} mm off the face "
                      f"of block {sim.model.node_block[cont.master[k, 0]]} "
                      f"({ov[k] / sim._side_size[k]:.0%} of its shortest edge): {why}; joint "
                      f"forces near the block ends are approximate from here on", RuntimeWarning)
    return float(ov.max())


def check_return_mapping(sim):
    """Warns once per run when a Gauss point's plastic-damage return mapping has stopped short
    of its tolerance (the sticky ``FLAG_RETURN`` bit of its committed state): its stress is
    approximate there."""
    if "return" in sim._warned:
        return
    flags = sim.mesh.s_old[:, :, MS_FLAG].astype(np.int64) & FLAG_RETURN
    bad = np.flatnonzero(flags)
    if bad.size:
        sim._warned.add("return")
        e, g = divmod(int(bad[0]), flags.shape[1])
        more = f" (and {bad.size - 1} other points)" if bad.size > 1 else ""
        warnings.warn(f"increment {sim.increment}: the plastic-damage return mapping stopped "
                      f"short of its tolerance at Gauss point {g} of element {e} (block "
                      f"{sim.model.element_block[e]}){more}: the stress there is approximate",
                      RuntimeWarning)

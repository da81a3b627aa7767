"""From the stage's controls to the arrays: load patterns per unit factor, the check that no two
controls act on one DOF, the imposed values, the assembled loads, the indirect control's DOF,
and what drives an increment (for the out-of-balance resultant)."""
from __future__ import annotations

import numpy as np

from .. import loading as L
from ..model import quad_area_vector


def pattern_forces(sim, pat):
    """(P (n_nodes, 3) N, rpP (n_rp, 6)) of a load pattern per unit factor, cached by name."""
    known = sim.patterns.get(pat.name)
    if known is not None:
        if known[0] is pat or isinstance(known[0], L.StoredPattern):
            if known[0] is not pat:  # a pattern restored from a checkpoint, named again
                sim.patterns[pat.name] = (pat,) + known[1:]
            return known[1:]
        raise L.LoadingError(f"two different load patterns are named {pat.name!r}; give each "
                             f"pattern a distinct name")
    m = sim.model
    n = m.n_nodes
    P = np.zeros((n, 3))
    rpP = np.zeros((len(sim.rigid_points), 6))
    if isinstance(pat, (L.Gravity, L.BodyForce)):
        acc = (np.array([0.0, 0.0, -pat.g]) if isinstance(pat, L.Gravity)
               else np.asarray(pat.accel, float))
        blocks = getattr(pat, "blocks", None)
        blocks = np.nonzero(~m.block_fixed)[0] if blocks is None else np.asarray(blocks)
        nodes = m.block_nodes(blocks)
        P[nodes] = sim.mass[nodes, None] * acc[None, :]
    elif isinstance(pat, L.Pressure):
        q = np.asarray(pat.quads, dtype=np.int64)
        if q.size and q.max() >= n:
            raise L.LoadingError(f"Pressure {pat.name!r}: node id {q.max()} in quads, the "
                                 f"model has {n} nodes")
        x = m.nodes[q]
        av = quad_area_vector(x)   # outward (corners counter-clockwise seen from outside)
        flat = np.flatnonzero(np.linalg.norm(av, axis=1) == 0.0)
        if flat.size:
            raise L.LoadingError(f"Pressure {pat.name!r}: quad {flat[0]} {q[flat[0]].tolist()} "
                                 "has zero area")
        for a in range(4):
            np.add.at(P, q[:, a], -0.25 * av)
    elif isinstance(pat, L.PointLoad):
        own(sim, pat.target, f"PointLoad {pat.name!r}")
        k = L.dof_index(pat.dof, rotations=isinstance(pat.target, L.RigidPoint))
        if isinstance(pat.target, L.RigidPoint):
            rpP[pat.target.index, k] = pat.value
        else:
            P[pat.target.nodes, k] = pat.value / pat.target.nodes.size
    elif isinstance(pat, L.Combined):
        for part, w in pat.parts:
            p1, r1 = pattern_forces(sim, part)
            P += w * p1
            rpP += w * r1
    else:
        raise L.LoadingError(f"unknown load pattern {pat!r}")
    sim.patterns[pat.name] = (pat, P, rpP)
    return P, rpP


def key(ctl):
    """The control's identity in ``sim.values``: (is a Force, target name, DOF) or ("load",
    pattern name)."""
    if isinstance(ctl, (L.Displacement, L.Force, L.Indirect)):
        t = ctl.target   # a RigidPoint or NodeSet: checked when the control was made
        return (type(ctl).__name__ == "Force", t.name,
                L.dof_index(ctl.dof, isinstance(t, L.RigidPoint)))
    if isinstance(ctl, L.Opening):
        return ("opening", ctl.a.name, ctl.b.name, L.dof_index(ctl.dof, rotations=False))
    return ("load", ctl.pattern.name)


def check_controls(sim, stage):
    """LoadingError when two controls of ``stage`` act on one DOF (a Force and a
    Displacement too) or on one pattern's factor (a Load and an Indirect): the last would
    silently win."""
    seen = {}
    for ctl in stage.controls:
        if hasattr(ctl, "target"):
            own(sim, ctl.target, f"control {ctl.label}")
        moves = np.any(ctl.path) if ctl.path is not None else bool(ctl.to)
        if isinstance(ctl, L.Displacement) and isinstance(ctl.target, L.NodeSet) and moves:
            k = L.dof_index(ctl.dof, rotations=False)
            held = ctl.target.nodes[sim._fixed[ctl.target.nodes, k]]
            if held.size:   # (a zero displacement there records the support's reaction)
                raise L.LoadingError(f"control {ctl.label}: node {held[0]} (block "
                                     f"{sim.model.node_block[held[0]]}) is fixed in "
                                     f"{ctl.dof} (a fixed block or Simulation.fix): a "
                                     f"non-zero prescribed displacement would move a support")
        if isinstance(ctl, L.Opening):
            check_opening(sim, ctl)
        if isinstance(ctl, L.Load):
            P, rpP = pattern_forces(sim, ctl.pattern)
            if not (np.any(P[~sim._fixed]) or np.any(rpP)):
                raise L.LoadingError(f"control {ctl.label}: pattern {ctl.pattern.name!r} "
                                     f"puts no force on any free DOF (its blocks, faces or "
                                     f"nodes are fixed, or it is empty)")
        acts = [key(ctl)[1:]]    # (target, dof), (pattern,) or (set, set, dof)
        if isinstance(ctl, (L.Indirect, L.Opening)):
            acts.append((ctl.pattern.name,))
        for what in acts:
            if what in seen:
                on = (f"DOF {what[1]} of {what[0]!r}" if len(what) == 2
                      else f"the factor of pattern {what[0]!r}")
                raise L.LoadingError(f"stage {stage.name!r}: controls {seen[what].label} and "
                                     f"{ctl.label} both act on {on}")
            seen[what] = ctl


def check_opening(sim, ctl):
    """LoadingError unless the node sets of Opening ``ctl`` are this simulation's, free in its
    DOF (not fixed, not tied to a rigid point), and its pattern loads a free DOF; and unless the
    damping is viscous (the held constraint is in that loop only)."""
    for side in (ctl.a, ctl.b):
        own(sim, side, f"control {ctl.label}")
        for k, _ in opening_axes(ctl):
            held = side.nodes[sim._fixed[side.nodes, k] | (sim.dyn.tied[side.nodes] >= 0)]
            if held.size:
                raise L.LoadingError(f"control {ctl.label}: node {held[0]} of {side.name!r} is "
                                     f"fixed or tied to a rigid point in {'xyz'[k]}: an opening "
                                     f"control moves its nodes")
    if sim.options.damping.scheme != "viscous":
        raise L.LoadingError(f"control {ctl.label}: an opening control needs damping='viscous', "
                             f"not {sim.options.damping.scheme!r}")
    P, rpP = pattern_forces(sim, ctl.pattern)
    if not (np.any(P[~sim._fixed]) or np.any(rpP)):
        raise L.LoadingError(f"control {ctl.label}: pattern {ctl.pattern.name!r} puts no force on "
                             f"any free DOF")


def opening_axes(ctl):
    """[(axis 0-2, weight)] of the opening of Opening ``ctl``: its DOF's axis, or the nonzero
    components of its ``direction``."""
    if ctl.direction is None:
        return [(L.dof_index(ctl.dof, rotations=False), 1.0)]
    return [(k, float(w)) for k, w in enumerate(ctl.direction) if w != 0.0]


def constraint(sim, ctl, target, gain=0.0):
    """The ``R.Constraint`` holding Opening ``ctl`` at ``target`` m: the mean displacement of
    ``ctl.b`` minus that of ``ctl.a`` along its DOF (or its direction); ``gain``: the load factor's
    change per N of the constraint's reaction and iteration (0: the factor is held), its
    ``settle`` 1 / ``ctl.rate`` iterations."""
    from ..kernels.relaxation import Constraint
    a, b = ctl.a.nodes, ctl.b.nodes
    node, dof, coef = [], [], []
    for k, w in opening_axes(ctl):
        node += [a, b]
        dof.append(np.full(a.size + b.size, k, np.int64))
        coef += [np.full(a.size, -w / a.size), np.full(b.size, w / b.size)]
    return Constraint(np.concatenate(node).astype(np.int64), np.concatenate(dof),
                      np.concatenate(coef), float(target), float(gain),
                      1.0 / ctl.rate if ctl.rate else 0.0)


def own(sim, target, what):
    """LoadingError naming ``what`` unless ``target`` is one of this simulation's rigid
    points or node sets (one of another simulation would act on the point of that index)."""
    if isinstance(target, L.RigidPoint):
        ok = 0 <= target.index < len(sim.rigid_points) and sim.rigid_points[target.index] is target
    else:
        ok = sim.node_sets.get(target.name) is target
    if not ok:
        kind = "rigid point" if isinstance(target, L.RigidPoint) else "node set"
        raise L.LoadingError(f"{what}: {kind} {target.name!r} is not one of this "
                             f"simulation's (made by another Simulation's rigid_point or "
                             f"node_set, or by hand)")


def opening(sim, ctl):
    """The present opening (m) of Opening ``ctl``: the mean displacement of ``ctl.b`` minus that
    of ``ctl.a`` along its DOF (or its direction)."""
    U = sim.dyn.U
    return float(sum(w * (U[ctl.b.nodes, k].mean() - U[ctl.a.nodes, k].mean())
                     for k, w in opening_axes(ctl)))


def current(sim, ctl):
    """Where a control that no earlier stage set starts: a Displacement of a rigid point's DOF at
    the point's present displacement (so that ``Displacement(target=point, dof=d)`` without
    ``to`` or ``path`` holds the point where the earlier stages left it), an Opening at the
    present opening (``to`` then ramps it from there), every other control at 0."""
    if isinstance(ctl, L.Displacement) and isinstance(ctl.target, L.RigidPoint):
        return float(sim.dyn.rpU[ctl.target.index, L.dof_index(ctl.dof, True)])
    if isinstance(ctl, L.Opening):
        return opening(sim, ctl)
    return 0.0


def apply(sim, ctl, value):
    """Impose one control value on the arrays (before relaxing an increment)."""
    d = sim.dyn
    if isinstance(ctl, (L.Displacement, L.Indirect)):
        k = L.dof_index(ctl.dof, isinstance(ctl.target, L.RigidPoint))
        if isinstance(ctl.target, L.RigidPoint):
            d.rpfree[ctl.target.index, k] = 0.0
            d.rpU[ctl.target.index, k] = value
            d.rpV[ctl.target.index, k] = 0.0
        else:
            nodes = ctl.target.nodes
            if (d.tied[nodes] >= 0).any():
                raise L.LoadingError(f"control {ctl.label}: nodes are tied to a rigid point")
            d.free[nodes, k] = 0.0
            d.U[nodes, k] = value
            d.V[nodes, k] = 0.0
    elif isinstance(ctl, L.Force):
        k = L.dof_index(ctl.dof)
        if not isinstance(ctl.target, L.RigidPoint):
            raise L.LoadingError(f"control {ctl.label}: Force acts on a RigidPoint; use Load with "
                                 f"a PointLoad pattern for node sets")
        d.rpfree[ctl.target.index, k] = 1.0
        sim.rp_force[ctl.target.index, k] = value
    elif isinstance(ctl, L.Load):
        pattern_forces(sim, ctl.pattern)
        sim.factors[ctl.pattern.name] = value
    elif isinstance(ctl, L.Opening):   # held by the relaxation (``constraint``)
        pattern_forces(sim, ctl.pattern)


def assemble_loads(sim, indirect):
    """``dyn.fext``, ``rpf`` from the load factors and forces, and with the stage's ``indirect``
    control its pattern in ``dyn.P``, ``rpP`` (its factor is ``sim.lam``)."""
    d = sim.dyn
    d.fext[:] = 0.0
    d.P[:] = 0.0
    d.rpP[:] = 0.0
    rpf_loads = np.zeros_like(d.rpf)
    for name, fac in sim.factors.items():
        if indirect is not None and name == indirect.pattern.name:
            continue
        P, rpP = sim.patterns[name][1:]
        d.fext[:] += fac * P
        rpf_loads += fac * rpP
    d.rpf[:] = sim.rp_force * d.rpfree + rpf_loads
    if indirect is not None:
        P, rpP = pattern_forces(sim, indirect.pattern)
        d.P[:] = P
        d.rpP[:] = rpP


#: history column ``control``: what a row's increment ran under
CONTROL_CODES = {"prescribed": 0, "indirect": 1, "opening": 2}


def control_code(indirect):
    """The ``control`` history code of an increment whose stage's Indirect or Opening control is
    ``indirect`` (None: prescribed values only)."""
    if indirect is None:
        return CONTROL_CODES["prescribed"]
    return CONTROL_CODES["opening" if isinstance(indirect, L.Opening) else "indirect"]


def control_dof(sim, indirect):
    """([kind, index, dof], pattern force on that DOF) of an indirect control."""
    t = indirect.target
    k = L.dof_index(indirect.dof, isinstance(t, L.RigidPoint))
    P, rpP = pattern_forces(sim, indirect.pattern)
    if isinstance(t, L.RigidPoint):
        pc = rpP[t.index, k]
        if k < 3:
            pc += P[t.nodes, k].sum()
        else:
            arm = sim.model.nodes[t.nodes] - t.position
            pc += np.cross(arm, P[t.nodes])[:, k - 3].sum()
        ctrl = (2, t.index, k)
    else:
        if t.nodes.size != 1:
            raise L.LoadingError(f"control {indirect.label}: indirect control needs a single "
                                 f"node or a rigid point, got {t.nodes.size} nodes")
        pc = P[t.nodes[0], k]
        ctrl = (1, t.nodes[0], k)
    scale = max(np.max(np.abs(P), initial=0.0), np.max(np.abs(rpP), initial=0.0), 1e-300)
    if abs(pc) < 1e-12 * scale:
        raise L.LoadingError(f"control {indirect.label}: the pattern {indirect.pattern.name!r} "
                             f"puts no force on the controlled DOF {indirect.dof}; control a DOF "
                             f"that the pattern loads (e.g. a rigid point of the loaded blocks)")
    return ctrl, pc


def release(sim, indirect):
    """At the end of a stage with an indirect or opening control: the pattern keeps its last
    factor, an indirectly controlled DOF is released."""
    sim.factors[indirect.pattern.name] = float(sim.lam[0])
    if isinstance(indirect, L.Opening):
        return
    t = indirect.target
    k = L.dof_index(indirect.dof, isinstance(t, L.RigidPoint))
    if isinstance(t, L.RigidPoint):
        sim.dyn.rpfree[t.index, k] = 1.0
    else:
        sim.dyn.free[t.nodes, k] = 1.0


def drive(sim, moved, indirect):
    """Mark what drives the increment for ``R.resultant`` (``dyn.gnode``, ``grp``, ``gspec``
    rows 0-1): the translations of the controls it moves (``moved``: ``Displacement`` and
    ``Indirect`` controls; one that holds its value is a support), the prescribed DOFs whose
    reactions drive it (``indirect``, the stage's indirect control, drives by its pattern),
    and each driven axis's largest |driving force| of the run so far (history ``drive.f*``)."""
    d = sim.dyn
    d.gnode[:] = 0.0
    d.grp[:] = 0.0
    d.gspec[:] = 0.0
    for ctl in moved:
        if not isinstance(ctl, (L.Displacement, L.Indirect, L.Opening)):
            continue
        rigid = isinstance(getattr(ctl, "target", None), L.RigidPoint)
        k = L.dof_index(ctl.dof, rigid)
        if k >= 3:
            continue
        d.gspec[0, k] = 1.0
        past = np.asarray(sim.history.get(f"drive.f{'xyz'[k]}", []))
        d.gspec[1, k] = np.nanmax(np.abs(past), initial=0.0)
        if ctl is indirect:   # (an Indirect or Opening drives by its pattern)
            continue
        if rigid:
            d.grp[ctl.target.index, k] = 1.0
        else:
            d.gnode[ctl.target.nodes, k] = 1.0


def snapshot(sim):
    """The state an attempt at an increment changes, to restore when it is cut."""
    d = sim.dyn
    return (d.U.copy(), d.V.copy(), d.rpU.copy(), d.rpV.copy(), d.free.copy(), d.rpfree.copy(),
            sim.rp_force.copy(), sim.lam.copy(), dict(sim.values), dict(sim.factors))


def restore(sim, snap):
    """Back to a :func:`snapshot`."""
    d = sim.dyn
    d.U[:], d.V[:], d.rpU[:], d.rpV[:], d.free[:], d.rpfree[:], sim.rp_force[:] = snap[:7]
    sim.lam[:] = snap[7]
    sim.values = dict(snap[8])
    sim.factors = dict(snap[9])

"""Loading: supports, rigid reference points, load patterns, controls and stages.

A run is a list of :class:`Stage` objects. A stage has a number of load increments and a list of
controls; every control ramps its value linearly from where the previous stage left it to ``to``
over the stage's increments, or follows an explicit ``path`` (one value per increment, e.g. a
cyclic protocol). Controls that a stage does not mention keep their last value: a pre-compression
force applied in stage 1 stays while stage 2 moves the beam.

Controls
--------
:class:`Displacement`  prescribed displacement (m) or rotation (rad) of a DOF of a node set or of a
                       rigid reference point; its reaction is recorded.
:class:`Force`         a constant-magnitude generalised force (N or N m) on a reference-point DOF.
:class:`Load`          a load pattern whose factor is prescribed (gravity, pressure, body forces).
:class:`Indirect`      indirect displacement control: the factor of a load pattern is the unknown
                       chosen so that a control DOF follows its target (softening branches under
                       pressure, equal floor forces, rocking peaks).
:class:`Opening`       opening control: the factor of a load pattern chosen so that the relative
                       displacement of two node sets follows its target (a joint's opening, a
                       wall's diagonal elongation), snap-backs included.

:class:`Until` ends a stage early, at the increment where a displacement reaches a value (an
opening-controlled push that ends at its target drift).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import units

DOFS = {"x": 0, "y": 1, "z": 2, "rx": 3, "ry": 4, "rz": 5}


class LoadingError(ValueError):
    """Invalid loading input; the message names the control and the value."""


def is_number(x):
    """Whether ``x`` is a finite real number (not a bool)."""
    return (isinstance(x, (int, float, np.integer, np.floating))
            and not isinstance(x, (bool, np.bool_)) and bool(np.isfinite(x)))


def is_count(x, low):
    """Whether ``x`` is an integral finite number >= ``low`` (2e5 counts; 2.5 and bools do not)."""
    return is_number(x) and float(x).is_integer() and x >= low


def finite_vector(what, x, n=None):
    """``x`` as a finite float64 array (of ``n`` values when given), else LoadingError naming it."""
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise LoadingError(f"{what}: {x!r} is not a list of numbers") from None
    if a.ndim > 1 or (n is not None and a.size != n):
        raise LoadingError(f"{what}: {x!r} must be {n or 'a list of'} finite numbers")
    a = a.ravel()
    if not np.all(np.isfinite(a)):
        k = int(np.argmax(~np.isfinite(a)))
        raise LoadingError(f"{what}: value {k} of {a.size} is {a[k]} (must be finite)")
    return a


def dof_index(dof, rotations=True):
    """Index 0..5 of a DOF name ``x, y, z, rx, ry, rz``."""
    if dof not in DOFS or (not rotations and DOFS[dof] > 2):
        valid = list(DOFS)[: 6 if rotations else 3]
        raise LoadingError(f"unknown DOF {dof!r}; valid: {valid}")
    return DOFS[dof]


@dataclass(eq=False)
class RigidPoint:
    """A reference point tied rigidly to a set of nodes (loading beams, slabs): 6 DOFs.

    Created by ``Simulation.rigid_point``; all DOFs are free and unloaded until a control acts.
    """
    name: str
    nodes: np.ndarray
    position: np.ndarray
    index: int = -1


@dataclass(eq=False)
class NodeSet:
    """A named set of node ids (int64 array)."""
    name: str
    nodes: np.ndarray


# ------------------------------------------------------------------ load patterns
@dataclass(eq=False)
class Gravity:
    """Self-weight: body force density * g along -z on every non-fixed block (factor 1 = 1 g)."""
    g: float = units.g
    name: str = "gravity"

    def __post_init__(self):
        if not is_number(self.g):
            raise LoadingError(f"Gravity {self.name!r}: g={self.g!r} must be a finite number "
                               "(m/s^2)")


@dataclass(eq=False)
class BodyForce:
    """Mass-proportional body force, acceleration ``accel`` (3,) m/s^2 per unit factor.

    ``blocks``: block ids (None = every non-fixed block). Used for seismic-like pushover patterns.
    """
    accel: tuple
    blocks: object = None
    name: str = "body"

    def __post_init__(self):
        self.accel = tuple(finite_vector(f"BodyForce {self.name!r}: accel", self.accel, 3))


@dataclass(eq=False)
class Pressure:
    """Pressure (Pa per unit factor) on element faces ``quads`` (m, 4) node ids, acting against
    their normal (positive pressure pushes into the face's block), reference configuration."""
    quads: np.ndarray
    name: str = "pressure"

    def __post_init__(self):
        q = np.asarray(self.quads)
        if q.ndim != 2 or q.shape[1] != 4 or q.dtype.kind not in "iu" or (q.size and q.min() < 0):
            raise LoadingError(f"Pressure {self.name!r}: quads must be an (m, 4) array of node ids "
                               f">= 0, got shape {q.shape}, dtype {q.dtype}")


@dataclass(eq=False)
class PointLoad:
    """A force (N per unit factor) on a DOF of a rigid point, or shared equally by a node set."""
    target: object
    dof: str
    value: float = 1.0
    name: str = "point"

    def __post_init__(self):
        if not is_number(self.value):
            raise LoadingError(f"PointLoad {self.name!r}: value={self.value!r} must be a finite "
                               "number (N)")
        if not isinstance(self.target, (RigidPoint, NodeSet)):
            raise LoadingError(f"PointLoad {self.name!r}: target must be a RigidPoint or NodeSet, "
                               f"got {self.target!r}")


@dataclass(eq=False)
class StoredPattern:
    """A pattern restored from a checkpoint: its nodal vectors as they were assembled."""
    name: str
    P: np.ndarray
    rpP: np.ndarray


@dataclass(eq=False)
class Combined:
    """Several patterns summed with weights: ``Combined([(pattern, weight), ...])``."""
    parts: list
    name: str = "combined"

    def __post_init__(self):
        if not isinstance(self.parts, (list, tuple)) or not self.parts:
            raise LoadingError(f"Combined {self.name!r}: parts must be a non-empty list of "
                               f"(pattern, weight) pairs, got {self.parts!r}")
        for part in self.parts:
            if not (isinstance(part, (tuple, list)) and len(part) == 2
                    and isinstance(part[0], PATTERNS) and is_number(part[1])):
                raise LoadingError(f"Combined {self.name!r}: parts must be (pattern, finite "
                                   f"weight) pairs, got {part!r}")


#: the load pattern types a :class:`Load`, :class:`Indirect` or :class:`Combined` takes
PATTERNS = (Gravity, BodyForce, Pressure, PointLoad, StoredPattern, Combined)


# ------------------------------------------------------------------ controls
@dataclass(eq=False)
class _Control:
    to: float = None
    path: object = None
    name: str = None

    def __post_init__(self):
        if self.to is not None and not is_number(self.to):
            raise LoadingError(f"control {self.label}: to={self.to!r} must be a finite number")
        if self.path is not None:
            if self.to is not None:
                raise LoadingError(f"control {self.label}: give to or path, not both")
            self.path = finite_vector(f"control {self.label}: path", self.path)
        if hasattr(self, "target") and not isinstance(self.target, (RigidPoint, NodeSet)):
            raise LoadingError(f"control {self.label}: target must be a RigidPoint or NodeSet "
                               f"(Simulation.rigid_point, node_set), got {self.target!r}")
        if hasattr(self, "pattern") and not isinstance(self.pattern, PATTERNS):
            raise LoadingError(f"control {self.label}: pattern must be one of "
                               f"{[t.__name__ for t in PATTERNS]}, got {self.pattern!r}")

    def values(self, start, n):
        """Target values (n,) of this control over a stage of n increments starting at ``start``."""
        if self.path is not None:   # finite, checked when the control was made
            if self.path.size != n:
                raise LoadingError(f"control {self.label}: path has {self.path.size} values, "
                                   f"stage has {n} increments")
            return self.path
        if self.to is None:
            return np.full(n, start)
        return start + (self.to - start) * np.arange(1, n + 1) / n

    @property
    def label(self):
        """The control's name for messages: ``name``, else its class name."""
        return self.name or type(self).__name__


@dataclass(eq=False)
class Displacement(_Control):
    """Prescribed displacement (m) or rotation (rad) of DOF ``dof`` of ``target`` (RigidPoint or NodeSet)."""
    target: object = None
    dof: str = "x"


@dataclass(eq=False)
class Force(_Control):
    """Generalised force (N, or N m for rotations) on DOF ``dof`` of RigidPoint ``target``."""
    target: object = None
    dof: str = "z"


@dataclass(eq=False)
class Load(_Control):
    """Prescribed factor of load pattern ``pattern``."""
    pattern: object = None


@dataclass(eq=False)
class Indirect(_Control):
    """Factor of ``pattern`` chosen so that DOF ``dof`` of ``target`` follows the target values."""
    pattern: object = None
    target: object = None
    dof: str = "x"


#: largest ``Opening.rate``: the factor has to move slower than the structure it loads relaxes
#: (measured: 1e-3 and 1e-2 trace the snap-back bar, 1e-3 pushes the S5 wall; 0.1 x the
#: Rayleigh-quotient frequency ran away on the wall)
MAX_OPENING_RATE = 0.01


@dataclass(eq=False)
class Opening(_Control):
    """Opening control (crack-opening control, de Borst 1987): the factor of ``pattern`` found so
    that the mean displacement along ``dof`` of node set ``b`` minus that of node set ``a``
    follows the target values (m), e.g. the two faces of a joint that opens. The opening is held
    during each relaxation (a constraint the relaxation is projected onto) and the factor is
    found by a secant iteration on the constraint's reaction, so that a softening branch that
    turns back (a snap-back) is traced: docs/internals.md, "Decisions". ``direction``: a vector
    (3,) along which the opening is measured instead (normalised; e.g. a wall's diagonal, as a
    diagonal transducer measures it); ``dof`` then names the axis of the pattern whose
    out-of-balance the row checks. ``rate`` (0 <= rate <= MAX_OPENING_RATE; 0: the secant): the
    factor relaxes with the motion instead, every iteration by ``rate`` x the constraint's
    reaction over the pattern's total force, one relaxation per increment; where friction makes
    the reaction at a fixed factor scatter (walls), the secant cannot converge and this can;
    where the structure relaxes more slowly than the factor moves (near a peak) the factor's
    rate is halved at every overshoot (``kernels.relaxation.adapt_gain``), so that ``rate`` is
    the fastest it moves (BENCHMARKS.md, "Path-following controls")."""
    pattern: object = None
    a: object = None
    b: object = None
    dof: str = "x"
    direction: object = None
    rate: float = 0.0

    def __post_init__(self):
        super().__post_init__()
        if self.direction is not None:
            v = finite_vector(f"control {self.label}: direction", self.direction, 3)
            if not np.any(v):
                raise LoadingError(f"control {self.label}: direction is the zero vector")
            self.direction = v / np.linalg.norm(v)
        for side in ("a", "b"):
            if not isinstance(getattr(self, side), NodeSet):
                raise LoadingError(f"control {self.label}: {side} must be a NodeSet "
                                   f"(Simulation.node_set), got {getattr(self, side)!r}")
        if not (is_number(self.rate) and 0.0 <= self.rate <= MAX_OPENING_RATE):
            raise LoadingError(f"control {self.label}: rate={self.rate!r} must be a number in "
                               f"[0, {MAX_OPENING_RATE}] (0: the secant on the factor)")
        if np.intersect1d(self.a.nodes, self.b.nodes).size:
            raise LoadingError(f"control {self.label}: node sets {self.a.name!r} and "
                               f"{self.b.name!r} share nodes")
        dof_index(self.dof, rotations=False)


@dataclass(eq=False)
class Until:
    """The end of a stage at a displacement: the stage stops after the first increment at which
    DOF ``dof`` of rigid point ``target`` has reached ``value`` (m, or rad for a rotation) from
    the side it was on when the stage began (or was resumed). Under an opening control the
    target drift is reached at an increment the stage's path cannot know."""
    target: object = None
    dof: str = "x"
    value: float = 0.0

    def __post_init__(self):
        if not isinstance(self.target, RigidPoint):
            raise LoadingError(f"Until: target must be a RigidPoint (Simulation.rigid_point), got "
                               f"{self.target!r}")
        dof_index(self.dof)
        if not is_number(self.value):
            raise LoadingError(f"Until {self.target.name}.{self.dof}: value={self.value!r} must be "
                               f"a finite number (m or rad)")

    def position(self, sim):
        """The DOF's displacement now (m or rad)."""
        return float(sim.dyn.rpU[self.target.index, dof_index(self.dof)])


#: the most increments one stage or protocol path may have: an increment relaxes in 10^2-10^5
#: iterations of about a millisecond, so a million is at least a day's run; more is a typo or a
#: step far too fine, and a path of 10^9 targets would not even fit in memory
MAX_INCREMENTS = 1_000_000
#: largest residual tolerance taken (stage ``tol``, ``SolverOptions.tol`` and ``floor_tol``): the
#: out-of-balance force relative to the applied ones; above it a row is no equilibrium
MAX_TOL = 0.1


def tol_ok(v):
    """True if ``v`` is a residual tolerance in (0, MAX_TOL]."""
    return is_number(v) and 0.0 < v <= MAX_TOL


def check_increments(n, what):
    """Raise :class:`LoadingError` naming ``what`` if ``n`` increments exceed MAX_INCREMENTS."""
    if n > MAX_INCREMENTS:
        raise LoadingError(f"{what}: {n:,} increments exceed MAX_INCREMENTS = {MAX_INCREMENTS:,} "
                           "(an increment relaxes in 10^2-10^5 iterations: use a coarser step or "
                           "fewer increments)")


@dataclass(eq=False)
class Stage:
    """A loading stage: ``increments`` load increments over which ``controls`` move.

    ``frames``: write a field frame every this many increments (and at the stage's end);
    ``frame_at``: also after these increments of the stage (counted from 1; e.g. a cyclic path's
    turning points, :func:`dr_masonry.protocols.turning_points`); ``max_iter``/``tol`` override
    the solver options for this stage; ``until``: an :class:`Until` that ends the stage early.
    """
    name: str
    increments: int
    controls: list = field(default_factory=list)
    frames: int = 1
    max_iter: int = None
    tol: float = None
    frame_at: tuple = ()
    until: object = None

    def __post_init__(self):
        for key, low in (("increments", 1), ("frames", 1), ("max_iter", 1)):
            v = getattr(self, key)
            if not (v is None and key == "max_iter" or is_count(v, low)):
                raise LoadingError(f"stage {self.name!r}: {key}={v!r} must be an integer >= {low}")
        self.increments = int(self.increments)
        check_increments(self.increments, f"stage {self.name!r}")
        self.frames = int(self.frames)
        at = self.frame_at
        if not (isinstance(at, (list, tuple, np.ndarray)) and all(
                is_count(k, 1) and k <= self.increments for k in at)):
            raise LoadingError(f"stage {self.name!r}: frame_at={at!r} must be a list of increments "
                               f"of the stage, integers in 1..{self.increments}")
        self.frame_at = tuple(int(k) for k in at)
        self.max_iter = None if self.max_iter is None else int(self.max_iter)
        if self.tol is not None and not tol_ok(self.tol):
            raise LoadingError(f"stage {self.name!r}: tol={self.tol!r} must be a finite number in "
                               f"(0, {MAX_TOL}] (a relative residual)")
        if not isinstance(self.controls, (list, tuple)) or not all(isinstance(c, _Control)
                                                                    for c in self.controls):
            raise LoadingError(f"stage {self.name!r}: controls must be a list of Displacement, "
                               f"Force, Load, Indirect and Opening controls, got "
                               f"{self.controls!r}")
        if self.until is not None:
            if not isinstance(self.until, Until):
                raise LoadingError(f"stage {self.name!r}: until must be an Until, got "
                                   f"{self.until!r}")
            self.until.__post_init__()
        if sum(isinstance(c, (Indirect, Opening)) for c in self.controls) > 1:
            raise LoadingError(f"stage {self.name!r}: at most one Indirect or Opening control per "
                               f"stage")


def check_stage(stage):
    """Check ``stage``, its controls and their load patterns again (:class:`LoadingError`): their
    fields can be changed after they were made (``stage.frames = 0``, ``control.to = nan``,
    ``Gravity.g = nan``), which the checks at their creation did not see."""
    stage.__post_init__()
    seen = set()

    def check_pattern(pat):
        if id(pat) in seen:
            raise LoadingError(f"stage {stage.name!r}: load pattern {pat.name!r} contains "
                               f"itself")
        seen.add(id(pat))
        if hasattr(pat, "__post_init__"):
            pat.__post_init__()
        for part, _ in getattr(pat, "parts", ()):
            check_pattern(part)
        seen.discard(id(pat))

    for ctl in stage.controls:
        ctl.__post_init__()
        if getattr(ctl, "pattern", None) is not None:
            check_pattern(ctl.pattern)


def cyclic_path(amplitudes, cycles=2, points_per_quarter=4, start_negative=False):
    """Target values of a cyclic protocol: ``cycles`` full cycles 0 -> +a -> -a -> 0 per amplitude.

    Returns an array of targets (one per increment); ``points_per_quarter`` increments on every
    quarter cycle.
    """
    amps = np.asarray(amplitudes, dtype=np.float64).ravel()
    if amps.size == 0 or np.any(amps <= 0) or not np.all(np.isfinite(amps)):
        raise LoadingError(f"cyclic protocol: amplitudes must be positive and finite, got {amps}")
    for name, v in (("points_per_quarter", points_per_quarter), ("cycles", cycles)):
        if not is_count(v, 1):
            raise LoadingError(f"cyclic protocol: {name}={v!r} must be a whole number >= 1")
    k = int(points_per_quarter)
    check_increments(4 * k * int(cycles) * amps.size, "cyclic protocol")
    sgn = -1.0 if start_negative else 1.0
    q = np.arange(1, k + 1) / k
    out = []
    for a in amps:
        for _ in range(int(cycles)):
            out += list(sgn * a * q) + list(sgn * a * (1 - q))
            out += list(-sgn * a * q) + list(-sgn * a * (1 - q))
    return np.asarray(out)

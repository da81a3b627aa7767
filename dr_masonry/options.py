"""Solver settings: :class:`SolverOptions`, six groups of fields (:class:`Convergence`,
:class:`Increments`, :class:`Damping`, :class:`Coarse`, :class:`Sliding`, :class:`Output`), each
field checked when a run starts. docs/solver.md says what each field does and when to change it;
the measurements behind the defaults are in docs/internals.md ("Decisions").

Every field has one flat name, the keyword of ``SolverOptions(...)``, the scene parameter and
the key stored in a result file (``config["solver"]``): the field's own name, except the damping
scheme (``damping``) and the coarse correction's switch and span (``coarse``, ``coarse_every``).
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from . import loading as L

#: the damping schemes (``SolverOptions.damping``): "viscous" is the production scheme
#: (``kernels.relaxation``), the others are in ``kernels.damping_schemes``
DAMPING = ("viscous", "kinetic", "local", "fire")
#: the default ``alpha`` of each scheme
ALPHA_DEFAULT = {"viscous": 0.7, "local": 0.8, "kinetic": 0.0, "fire": 0.1}
#: valid ``SolverOptions.alpha`` of each damping scheme: (test, what the message says)
ALPHA_RANGE = {"viscous": (lambda a: a > 0, "> 0 (fraction of critical damping)"),
               "local": (lambda a: 0 <= a < 1, "in [0, 1) (Cundall's coefficient)"),
               "kinetic": (lambda a: True, "(unused by kinetic damping)"),
               "fire": (lambda a: 0 < a <= 1, "in (0, 1] (FIRE's alpha_start)")}


#: "auto" coarse correction from this many movable blocks on (walls; not couplets and triplets)
COARSE_MIN_BLOCKS = 30


class OptionsError(ValueError):
    """A bad :class:`SolverOptions` field; the message names the field, the value and what is
    valid."""


@dataclass
class Convergence:
    """When an increment is converged.

    tol : residual ratio ||out-of-balance|| / ||loads + reactions|| at most this (5e-5: on the
        S5 wall 1e-4 left softening rows a few per cent of the peak short of their equilibrium;
        docs/internals.md, "Decisions")
    block_tol : and every block's imbalance ratio (net out-of-balance force over the magnitudes
        of its forces) at most this (0: off)
    gap_tol : and the out-of-balance resultant along each driven axis at most this fraction of
        the driving force, the largest so far (0: off; also bounds a row accepted at the
        floor). 0.004 keeps every row's drive force and support reaction within 0.4 % of the
        run's peak; on the S5 wall it changes neither the curve nor the iterations
    floor_tol : an increment stopped short of tol with its ratio at or below this is accepted
        with a warning instead of cut (0: off)
    energy_tol : energy-balance error (of the gross external work) above which a run warns
    check_every : iterations between convergence checks
    """
    tol: float = 5e-5
    block_tol: float = 0.1
    gap_tol: float = 0.004
    floor_tol: float = 0.0
    energy_tol: float = 0.01
    check_every: int = 10


@dataclass
class Increments:
    """How increments are stepped and cut.

    max_iter : iteration cap of one attempt before it is cut in two
    max_cuts : halvings of an increment before the run stops
    stall_iter : an attempt whose ratio has not fallen 10 % below its best for this many
        iterations, or that at its rate would not reach tol within max_iter, is cut (0: never)
    max_dissipation : a converged increment that dissipates more than this fraction of the
        external work so far is cut (0: off)
    predictor : start an increment from the previous one's displacement increment
    adapt : step memory: after a cut the next increments start split into the parts that
        converged (up to max_cuts - 1 halvings); ``QUICK_PARTS`` parts in a row that converged
        in at most ``QUICK`` x stall_iter iterations each take one halving back (off with
        stall_iter 0) (:mod:`dr_masonry.solver.increments`)
    """
    max_iter: int = 200_000
    max_cuts: int = 4
    stall_iter: int = 10_000
    max_dissipation: float = 0.0
    predictor: bool = True
    adapt: bool = True


@dataclass
class Damping:
    """The relaxation's damping and fictitious masses.

    scheme : "viscous" (production) | "kinetic" | "local" | "fire" (flat name ``damping``)
    alpha : the scheme's parameter (None: ``ALPHA_DEFAULT``): viscous, fraction of critical
        damping; local, Cundall's coefficient; fire, alpha_start; kinetic, unused
    ring : viscous: coefficient on DOFs whose velocity reverses more often than every 5
        iterations (0 <= ring < 2; 0: off)
    safety : fictitious masses = safety x Gershgorin row sum / 4 (stable for safety >= 1)
    allow_unstable : accept safety < 1 (the stability stress test only)
    """
    scheme: str = "viscous"
    alpha: float = None
    ring: float = 1.0
    safety: float = 1.1
    allow_unstable: bool = False


@dataclass
class Coarse:
    """The two-level relaxation: a Galerkin correction on the blocks' affine motions
    (:mod:`dr_masonry.coarse`).

    enabled : True, False or "auto" (on from ``COARSE_MIN_BLOCKS`` movable blocks; flat name
        ``coarse``)
    every : iterations between corrections (flat name ``coarse_every``)
    test : what accepts a step (flat name ``coarse_test``): "energy", it lowers the stored
        energy minus the load work; "residual", the out-of-balance force at its end still does
        positive work along it (on the S4 wall 0.45 x the iterations, on the S5 wall the peak
        row past the snap: docs/internals.md, "Decisions")
    """
    enabled: object = "auto"
    every: int = 200
    test: str = "energy"


@dataclass
class Sliding:
    """Finite sliding of the joints.

    redetect : after every increment, re-pair contact points whose slave node slid off its
        master face (:mod:`dr_masonry.sliding`); False keeps the reference pairing
    """
    redetect: bool = True


@dataclass
class Output:
    """Restart data and the progress bar.

    checkpoint_s : between frames, write the restart data again after this many seconds of wall
        time (0: after every increment)
    keep_checkpoint_s : keep a copy of the restart data at most once per this many seconds
        (0: never), to continue from further back
    progress : show a progress bar
    """
    checkpoint_s: float = 60.0
    keep_checkpoint_s: float = 3600.0
    progress: bool = False


#: what accepts a coarse step (``Coarse.test``)
COARSE_TESTS = ("energy", "residual")
#: the groups, by attribute name of :class:`SolverOptions`
GROUPS = {"convergence": Convergence, "increments": Increments, "damping": Damping,
          "coarse": Coarse, "sliding": Sliding, "output": Output}
#: flat name -> (group, field)
FLAT = {("damping" if (g, f.name) == ("damping", "scheme") else
         "coarse" if (g, f.name) == ("coarse", "enabled") else
         "coarse_every" if (g, f.name) == ("coarse", "every") else
         "coarse_test" if (g, f.name) == ("coarse", "test") else f.name): (g, f.name)
        for g, cls in GROUPS.items() for f in fields(cls)}


class SolverOptions:
    """Dynamic-relaxation settings in six groups (attributes ``convergence``, ``increments``,
    ``damping``, ``coarse``, ``sliding``, ``output``).

    ``SolverOptions(tol=1e-3, max_cuts=6)`` sets fields by their flat names (:data:`FLAT`);
    a group may also be given whole (``increments=Increments(max_iter=60_000)``). Fields may be
    changed afterwards (``options.increments.max_iter = 60_000``): :meth:`check` runs again when
    a run starts.
    """

    def __init__(self, **kw):
        for g, cls in GROUPS.items():
            # a group given whole; ``damping`` and ``coarse`` otherwise are the flat names of the
            # scheme and the switch
            given = kw.pop(g) if isinstance(kw.get(g), cls) else None
            if g in kw and g not in FLAT:
                raise OptionsError(f"SolverOptions.{g}={kw[g]!r}: must be a {cls.__name__}")
            setattr(self, g, given if given is not None else cls())
        for name, value in kw.items():
            if name not in FLAT:
                raise OptionsError(f"SolverOptions: unknown option {name!r}; valid names are "
                                   f"{sorted(FLAT)}")
            g, f = FLAT[name]
            setattr(getattr(self, g), f, value)
        self.check()

    def __setattr__(self, name, value):
        if name not in GROUPS:
            where = f"options.{'.'.join(FLAT[name])}" if name in FLAT else "a group's field"
            raise OptionsError(f"SolverOptions.{name}: set {where} (the fields are in groups: "
                               f"{list(GROUPS)})")
        super().__setattr__(name, value)

    def __getattr__(self, name):   # only for names that are not attributes
        if name in FLAT:
            raise AttributeError(f"SolverOptions has no attribute {name!r}: it is "
                                 f"options.{'.'.join(FLAT[name])}")
        raise AttributeError(f"SolverOptions has no attribute {name!r}")

    @classmethod
    def defaults(cls):
        """{flat name: default} of every field (``alpha``: None, the scheme's default)."""
        return {name: getattr(GROUPS[g](), f) for name, (g, f) in FLAT.items()}

    def as_dict(self):
        """{flat name: value}: the options as stored in a result file and given to scenes."""
        return {name: getattr(getattr(self, g), f) for name, (g, f) in FLAT.items()}

    def replace(self, **changes):
        """A copy with the fields ``changes`` (flat names) changed; a new ``damping`` scheme
        without an ``alpha`` takes its own default."""
        flat = self.as_dict()
        if "damping" in changes and "alpha" not in changes:
            flat["alpha"] = None
        return SolverOptions(**{**flat, **changes})

    def __repr__(self):
        changed = {k: v for k, v in self.as_dict().items() if v != self.defaults()[k]
                   and k != "alpha"}
        return "SolverOptions(" + ", ".join(f"{k}={v!r}" for k, v in changed.items()) + ")"

    def __eq__(self, other):
        return isinstance(other, SolverOptions) and self.as_dict() == other.as_dict()

    def check(self):
        """Validate every field (OptionsError naming the flat name, the value and what is
        valid) and normalise: integral counts to int, ``alpha`` None to its scheme's default."""
        c, i, d, k, s, o = (self.convergence, self.increments, self.damping, self.coarse,
                            self.sliding, self.output)
        if not isinstance(d.scheme, str) or d.scheme not in DAMPING:
            raise OptionsError(f"SolverOptions.damping={d.scheme!r}: valid values are "
                               f"{list(DAMPING)}")
        if d.alpha is None:
            d.alpha = ALPHA_DEFAULT[d.scheme]
        for group, name, flat in ((s, "redetect", "redetect"), (i, "predictor", "predictor"),
                                  (i, "adapt", "adapt"),
                                  (o, "progress", "progress"),
                                  (d, "allow_unstable", "allow_unstable")):
            if not isinstance(getattr(group, name), (bool, np.bool_)):
                raise OptionsError(f"SolverOptions.{flat}={getattr(group, name)!r}: must be True "
                                   "or False")
        if not (isinstance(k.enabled, (bool, np.bool_))
                or isinstance(k.enabled, str) and k.enabled == "auto"):
            raise OptionsError(f"SolverOptions.coarse={k.enabled!r}: must be True, False or "
                               "'auto'")
        if k.test not in COARSE_TESTS:
            raise OptionsError(f"SolverOptions.coarse_test={k.test!r}: valid values are "
                               f"{list(COARSE_TESTS)}")
        for group, name, flat, low in ((i, "max_iter", "max_iter", 1),
                                       (c, "check_every", "check_every", 1),
                                       (k, "every", "coarse_every", 1),
                                       (i, "max_cuts", "max_cuts", 0),
                                       (i, "stall_iter", "stall_iter", 0)):
            v = getattr(group, name)   # an integral number, as Stage takes it
            if not L.is_count(v, low):
                raise OptionsError(f"SolverOptions.{flat}={v!r}: must be an integer >= {low}")
            setattr(group, name, int(v))
        for group, name, ok, what in (
                (c, "tol", L.tol_ok, f"in (0, {L.MAX_TOL}] (a relative residual)"),
                (d, "safety", lambda v: v >= 1.0 or d.allow_unstable and v > 0.0,
                 ">= 1 for a stable step (> 0 with allow_unstable)"),
                (c, "energy_tol", lambda v: v > 0, "> 0"),
                (c, "floor_tol", lambda v: v == 0.0 or v >= c.tol and L.tol_ok(v),
                 f"0 (off) or in [tol = {c.tol}, {L.MAX_TOL}]"),
                (c, "gap_tol", lambda v: 0.0 <= v < 1.0, "in [0, 1) (0: off)"),
                (d, "ring", lambda v: 0.0 <= v < 2.0, "in [0, 2) (0: off)"),
                (i, "max_dissipation", lambda v: v >= 0, ">= 0 (0: off)"),
                (c, "block_tol", lambda v: 0.0 <= v < 1.0, "in [0, 1) (0: off)"),
                (o, "checkpoint_s", lambda v: v >= 0, ">= 0 s"),
                (o, "keep_checkpoint_s", lambda v: v >= 0, ">= 0 s"),
                (d, "alpha", ALPHA_RANGE[d.scheme][0], ALPHA_RANGE[d.scheme][1])):
            v = getattr(group, name)
            if not (L.is_number(v) and ok(v)):
                raise OptionsError(f"SolverOptions.{name}={v!r}: must be a finite number {what}")

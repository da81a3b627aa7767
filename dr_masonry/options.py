"""Solver settings: :class:`SolverOptions`, each field checked on construction, and the
names of the damping schemes (``DAMPING``: the codes of ``kernels.relaxation``)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import loading as L
from .kernels import relaxation as R

#: the damping schemes by name (``SolverOptions.damping``) and their kernel codes
DAMPING = {"kinetic": R.DAMP_KINETIC, "viscous": R.DAMP_VISCOUS, "local": R.DAMP_LOCAL,
           "fire": R.DAMP_FIRE}
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
class SolverOptions:
    """Dynamic-relaxation settings (defaults chosen by the benchmarks, see BENCHMARKS.md).

    damping : "viscous" (default) | "kinetic" | "local" | "fire" (FIRE, Bitzek et al. 2006:
        converges everywhere tested but needs 1.5-10x the iterations of "viscous")
    alpha : damping parameter (local: Cundall's coefficient, 0.8; viscous: fraction of the
        critical damping of the Rayleigh-quotient frequency, 1.0; fire: initial velocity-mixing
        factor alpha_start, 0.1)
    ring : viscous damping: coefficient for the DOFs whose velocity reverses more often than every
        5 iterations (0 <= ring < 2; 0: off). The damping of the whole motion follows its
        Rayleigh quotient, which a local high-frequency oscillation dominates (frictional joints
        that slide and stick keep one going); 1.0 damps it where it rings and leaves the rest to
        the slow motion: the main job's first 30 rows need 27 % fewer iterations and the house's
        plateau rows converge (BENCHMARKS.md section 27); 1.9 changed the peak's branch
    tol : an increment is converged when ||out-of-balance|| <= tol * ||applied loads + reactions||
    safety : fictitious masses = safety * Gershgorin row sum / 4 (stable for safety >= 1)
    allow_unstable : accept ``safety`` < 1, a step beyond the stable one, for the stability
        stress test (``benchmarks/stability.py``: the guards must catch what follows)
    max_iter : iteration cap of one increment before it is cut in two
    max_cuts : how many times an increment may be halved before the run stops
    stall_iter : an increment whose residual ratio has not fallen 10 % below its best value
        (``R.STALL_DROP``) for this many iterations is cut in two before ``max_iter`` (0: never).
        At a mechanism's onset the relaxation can hover just above ``tol`` for the whole cap
        while the two halves converge in a few thousand iterations each (BENCHMARKS.md, section
        10); a relaxation that converges steadily is left alone (section 13) unless, at its rate
        of the last ``stall_iter`` iterations, it would not reach ``tol`` within ``max_iter``
        (then it is cut at once, section 15); at the last allowed cut the increment runs to
        ``max_iter``
    floor_tol : an increment that stops short of ``tol`` (stalled, too slow, or at ``max_iter``)
        with its residual ratio at or below ``floor_tol`` is accepted instead of cut, with a
        warning; 0 (default): never. Where joints chatter at a mechanism, the relaxation can
        settle on a floor at 1-9 x ``tol`` that smaller steps do not remove; an accepted row is
        then the middle of a snap, its load a few per cent off (BENCHMARKS.md sections 13 and
        29), and the path after it can differ from the converged one (the S4 double-clamped
        cyclic protocol with 1e-3 from its start took its first 0.2 % peak at 5.8e-4, -19.9 kN,
        where cutting converged at -20.5 kN): set it on resuming a run that stopped, not
        before; the history's ``residual`` column shows each row's ratio
    gap_tol : also require the out-of-balance resultant along each translation that a control
        drives to be at most this fraction of the driving force (that axis's largest of the run
        so far where larger; ``kernels.relaxation.resultant``, history ``gap_ratio``) for an
        increment to converge, and for a row at the floor to be accepted (the floor loosens
        only the norm: a row stopped short above it is cut in two); 0 (default): off. The
        residual ratio is a norm over every DOF against loads that gravity may dominate, so the
        house's rows at the floor kept resultants of up to 17 % of the lateral load (median 6 %,
        docs/validation.md, "Rows accepted at the residual floor"); the resultant bounds how far
        the curve's force is from the converged one. Every row records ``gap.f*``, ``drive.f*``
        and ``gap_ratio`` whatever this setting
    block_tol : also require every block's imbalance ratio (``kernels.relaxation.
        block_imbalance``: the net out-of-balance force of the block over the sum of the
        magnitudes of its joints' forces and loads, the "local ratio" of block codes) to be at
        most this for an increment to converge (default 0.1; 0: off, only the global ratio
        ``tol`` counts; the S5 main job's largest ratio is 0.084, so it never binds there). The
        global norm weighs a loose brick's imbalance against the whole model's load, so a brick
        held by little more than its weight can stay tens of per cent out of balance and creep
        (continued by the predictor before it left such blocks alone, ``solver.LOOSE_BLOCK``, bricks
        left the S5 wall's plane over a few rows of a cyclic run: docs/validation.md); the
        history column ``block_imbalance`` records every row's largest ratio, and a run warns
        once when it passes ``solver.BLOCK_IMBALANCE_WARN``
    max_dissipation : load-step control, off by default (0): a converged increment whose damage
        dissipation (blocks, and joints without friction) exceeds this fraction of the external
        work done so far is cut in two (accepted at the last allowed cut). Where many joints
        soften at once a large step jumps across the peak; with 0.05 a single joint's peak is
        found in 8 increments, but on the S5 wall the refined steps cost 5 x the iterations of
        twice as many uniform ones (BENCHMARKS.md section 12). Each accepted increment's ratio
        is the history column ``dissipation_ratio``
    check_every : iterations between convergence checks
    energy_tol : energy-balance error above which a warning is recorded; the error is
        W_ext - E_stored - D_blocks - D_joints relative to the gross external work
        (sum over DOFs of |f du|, which equals W_ext on monotonic paths and stays meaningful
        when works of opposite sign cancel, as gravity and the push of a rocking block do).
        An increment that alone moves the error by more than this names the joint points and
        the element that dissipated most in it, or says that no few points hold the move (a few
        such warnings per run)
    predictor : start each increment from the previous one's displacement increment (same
        direction), except on blocks that ended it out of balance (``solver.LOOSE_BLOCK``)
    coarse : two-level relaxation: a Galerkin coarse correction on the blocks' affine motions
        (:mod:`dr_masonry.coarse`) before every span of ``coarse_every`` iterations; True, False
        or "auto" (default: on for models of at least ``COARSE_MIN_BLOCKS`` movable blocks, where
        it saves 2-4 x the iterations before the peak, BENCHMARKS.md section 6; on a few
        blocks it only adds work)
    checkpoint_s : between frames, write the restart data again once this many seconds of wall
        time have passed since the last time (0: after every increment, and after each committed
        part of a cut increment), so that an interrupted long run loses at most about this much
        work
    keep_checkpoint_s : keep a copy of the restart data (``/checkpoints/NNNNNN``) at most once
        per this many seconds of wall time (0: never), so that a long run can be continued from
        further back (``Simulation.resume(path, increment)``), e.g. with other solver settings
        or after a fix; each copy is as large as the checkpoint (S4 wall 1.6 MB, house 12 MB)
    redetect : finite sliding of the joints: after every increment, contact points whose slave
        node slid off its master quad are paired with the quad now under it, and points that slid
        off every face carry no force until one takes them back (:mod:`dr_masonry.sliding`;
        nothing runs while no node leaves its quad). False keeps the pairing of the reference
        configuration (small sliding)
    progress : show a progress bar
    """
    damping: str = "viscous"
    alpha: float = None
    ring: float = 1.0
    tol: float = 1e-4
    safety: float = 1.1
    allow_unstable: bool = False
    max_iter: int = 200_000
    max_cuts: int = 4
    stall_iter: int = 10_000
    floor_tol: float = 0.0
    gap_tol: float = 0.0
    block_tol: float = 0.1
    max_dissipation: float = 0.0
    check_every: int = 10
    energy_tol: float = 0.01
    predictor: bool = True
    coarse: object = "auto"
    coarse_every: int = 200
    checkpoint_s: float = 60.0
    keep_checkpoint_s: float = 3600.0
    redetect: bool = True
    progress: bool = False

    def __post_init__(self):
        if not isinstance(self.damping, str) or self.damping not in DAMPING:
            raise OptionsError(f"SolverOptions.damping={self.damping!r}: valid values are "
                               f"{list(DAMPING)}")
        if self.alpha is None:
            self.alpha = {"viscous": 1.0, "local": 0.8, "kinetic": 0.0, "fire": 0.1}[self.damping]
        for name in ("redetect", "predictor", "progress", "allow_unstable"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise OptionsError(f"SolverOptions.{name}={getattr(self, name)!r}: must be True or "
                                   "False")
        if not (isinstance(self.coarse, (bool, np.bool_))
                or isinstance(self.coarse, str) and self.coarse == "auto"):
            raise OptionsError(f"SolverOptions.coarse={self.coarse!r}: must be True, False or "
                               "'auto'")
        for name, low in (("max_iter", 1), ("check_every", 1), ("coarse_every", 1),
                          ("max_cuts", 0), ("stall_iter", 0)):
            v = getattr(self, name)   # an integral number, as Stage takes it
            if not L.is_count(v, low):
                raise OptionsError(f"SolverOptions.{name}={v!r}: must be an integer >= {low}")
            setattr(self, name, int(v))
        for name, ok, what in (
                ("tol", L.tol_ok, f"in (0, {L.MAX_TOL}] (a relative residual)"),
                ("safety", lambda v: v >= 1.0 or self.allow_unstable and v > 0.0,
                 ">= 1 for a stable step (> 0 with allow_unstable)"),
                ("energy_tol", lambda v: v > 0, "> 0"),
                ("floor_tol", lambda v: v == 0.0 or v >= self.tol and L.tol_ok(v),
                 f"0 (off) or in [tol = {self.tol}, {L.MAX_TOL}]"),
                ("gap_tol", lambda v: 0.0 <= v < 1.0, "in [0, 1) (0: off)"),
                ("ring", lambda v: 0.0 <= v < 2.0, "in [0, 2) (0: off)"),
                ("max_dissipation", lambda v: v >= 0, ">= 0 (0: off)"),
                ("block_tol", lambda v: 0.0 <= v < 1.0, "in [0, 1) (0: off)"),
                ("checkpoint_s", lambda v: v >= 0, ">= 0 s"),
                ("keep_checkpoint_s", lambda v: v >= 0, ">= 0 s"),
                ("alpha", ALPHA_RANGE[self.damping][0], ALPHA_RANGE[self.damping][1])):
            v = getattr(self, name)
            if not (L.is_number(v) and ok(v)):
                raise OptionsError(f"SolverOptions.{name}={v!r}: must be a finite number {what}")

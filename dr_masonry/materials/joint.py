"""Cohesive-frictional joint law of the contacts (MODEL.md section 2): parameters and validation.

The physics lives in ``dr_masonry.kernels.joint_law``; this class only checks the parameters and
packs them for the kernel.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..kernels import joint_law as jk
from ..units import MPa, mm

#: default compression penalty as a multiple of knn. 10 knn (7.5e11 Pa/m for Table 2) keeps the
#: overclosure at 1.3 um per MPa, about 8 % of the compliance of an 81 mm block course
#: (E = 4800 MPa), so the joints add little deformability in compression (paper Sec. 2.3).
#: Measured (docs/internals.md, "Decisions", ``benchmarks/penalty.py``): peaks of S2, S5 and S6 within
#: 0.2-0.8 % of a rigid closed joint, initial stiffness 0.3-4.4 % low; 30 knn costs 1.4-4 x the
#: iterations, and at 100 knn the S6 softening branch no longer converges (MODEL.md: 10-100 knn).
KC_PEN_FACTOR = 10.0

_SHEAR_MODES = {"calibrated": jk.SHEAR_CALIBRATED, "paper": jk.SHEAR_PAPER}


class JointLawError(ValueError):
    """Invalid joint-law parameter; the message names the parameter and its value."""


@dataclass(frozen=True)
class JointLaw:
    """Parameters of the cohesive-frictional joint law (SI units).

    Attributes
    ----------
    ft : float, Pa
        tensile strength.
    u_k : float, m
        opening at which the tension vanishes (> u0 = ft / knn).
    zeta : float, -
        exponent of the tensile softening (> 0).
    knn : float, Pa/m
        normal stiffness in tension.
    c : float, Pa
        cohesion.
    tan_phi : float, -
        friction coefficient of the strength ``fs = c - tan_phi * sigma``.
    delta_k : float, m
        slip at which the cohesion vanishes (> c / kss).
    xi : float, -
        exponent of the shear softening (> 0).
    mu : float, -
        residual friction coefficient.
    kss : float, Pa/m
        shear stiffness.
    kc_pen : float or None, Pa/m
        compression penalty stiffness; None gives ``KC_PEN_FACTOR * knn``. ``with_changes(knn=..)``
        keeps the stored value; pass ``kc_pen=None`` to derive it again.
    shear_damage : {"calibrated", "paper"}
        D_s of MODEL.md ("calibrated": monotonic envelope exactly ``fs (1-g) + g mu<-sigma>``) or
        eq (7) literally ("paper": overshoots the Mohr-Coulomb strength under compression).

    ``ft = c = 0`` is a dry joint (D = 1 from the start); ``ft = c = inf`` a tied one (see
    :meth:`dry`, :meth:`tied`).
    """
    ft: float
    u_k: float
    zeta: float
    knn: float
    c: float
    tan_phi: float
    delta_k: float
    xi: float
    mu: float
    kss: float
    kc_pen: float | None = None
    shear_damage: str = "calibrated"

    # ------------------------------------------------------------------ construction
    def __post_init__(self):
        names = ("ft", "u_k", "zeta", "knn", "c", "tan_phi", "delta_k", "xi", "mu", "kss")
        for name in names + ("kc_pen",):
            v = getattr(self, name)
            if name == "kc_pen" and v is None:
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
                raise JointLawError(f"JointLaw.{name} must be a number, got {v!r}")
            if math.isnan(v):
                raise JointLawError(f"JointLaw.{name} is NaN")
            object.__setattr__(self, name, float(v))
        if self.shear_damage not in _SHEAR_MODES:
            raise JointLawError(f"JointLaw.shear_damage must be one of {sorted(_SHEAR_MODES)}, "
                                f"got {self.shear_damage!r}")
        for name in ("knn", "kss", "kc_pen"):
            if name == "kc_pen" and self.kc_pen is None:
                object.__setattr__(self, "kc_pen", KC_PEN_FACTOR * self.knn)
            v = getattr(self, name)
            if not (0.0 < v < math.inf):
                raise JointLawError(f"JointLaw.{name} must be a finite stiffness > 0 Pa/m, got {v}")
        for name in ("tan_phi", "mu"):
            v = getattr(self, name)
            if not (0.0 <= v < math.inf):
                raise JointLawError(f"JointLaw.{name} must be finite and >= 0, got {v}")
        if self.is_tied:
            return
        if math.isinf(self.ft) or math.isinf(self.c):
            raise JointLawError(f"JointLaw: ft and c must both be finite, or both inf for a tied "
                                f"joint, got ft={self.ft}, c={self.c}")
        for name in ("ft", "c"):
            v = getattr(self, name)
            if v < 0.0:
                raise JointLawError(f"JointLaw.{name} must be >= 0 Pa, got {v}")
        if self.is_dry:
            return
        for name in ("zeta", "xi"):
            v = getattr(self, name)
            if not (0.0 < v < math.inf):
                raise JointLawError(f"JointLaw.{name} must be finite and > 0, got {v}")
        u0 = self.ft / self.knn
        if not (u0 < self.u_k < math.inf):
            raise JointLawError(f"JointLaw.u_k must be finite and > u0 = ft/knn = {u0:.6g} m, "
                                f"got {self.u_k}")
        d0 = self.c / self.kss
        if not (d0 < self.delta_k < math.inf):
            raise JointLawError(f"JointLaw.delta_k must be finite and > c/kss = {d0:.6g} m, "
                                f"got {self.delta_k}")

    @classmethod
    def reference(cls, **changes):
        """The calibrated joint of the paper (Table 2); keyword arguments override fields."""
        law = cls(ft=0.12 * MPa, u_k=1.0 * mm, zeta=8.0, knn=75e9, c=0.11 * MPa, tan_phi=0.52,
                  delta_k=1.0 * mm, xi=4.0, mu=0.55, kss=7.5e9)
        return law.with_changes(**changes) if changes else law

    @classmethod
    def dry(cls, mu, knn=75e9, kss=7.5e9, kc_pen=None):
        """Dry joint: no tension, no cohesion (D = 1 from the start), penalty compression and
        Coulomb friction ``mu <-sigma>`` behind a stick stiffness kss (Pa/m)."""
        return cls(ft=0.0, u_k=0.0, zeta=1.0, knn=knn, c=0.0, tan_phi=0.0, delta_k=0.0, xi=1.0,
                   mu=mu, kss=kss, kc_pen=kc_pen)

    @classmethod
    def tied(cls, knn, kss, kc_pen=None):
        """Elastic, unbreakable joint (glues loading beams and slabs): ``sigma = knn u`` for
        u >= 0, ``kc_pen u`` for u < 0 (default ``kc_pen = knn``: linear), ``tau = kss d``."""
        return cls(ft=math.inf, u_k=math.inf, zeta=1.0, knn=knn, c=math.inf, tan_phi=0.0,
                   delta_k=math.inf, xi=1.0, mu=0.0, kss=kss,
                   kc_pen=knn if kc_pen is None else kc_pen)

    def with_changes(self, **changes):
        """A copy with some fields replaced (validated again)."""
        unknown = set(changes) - {f.name for f in dataclasses.fields(self)}
        if unknown:
            raise JointLawError(f"JointLaw.with_changes: unknown fields {sorted(unknown)}; valid: "
                                f"{[f.name for f in dataclasses.fields(self)]}")
        return dataclasses.replace(self, **changes)

    # ------------------------------------------------------------------ queries
    @property
    def is_tied(self):
        """True for an unbreakable elastic joint (ft = c = inf)."""
        return math.isinf(self.ft) and math.isinf(self.c) and self.ft > 0 and self.c > 0

    @property
    def is_dry(self):
        """True for a dry joint (ft = c = 0)."""
        return self.ft == 0.0 and self.c == 0.0

    def fs(self, sigma):
        """Mohr-Coulomb shear strength ``c - tan_phi * sigma`` (Pa) at normal traction sigma (Pa)."""
        return self.c - self.tan_phi * sigma

    def params_array(self):
        """Parameters for the kernel, (NJP,) float64 (index constants ``P_*`` of the kernel)."""
        p = np.zeros(jk.NJP)
        p[jk.P_KNN] = self.knn
        p[jk.P_KSS] = self.kss
        p[jk.P_KC] = self.kc_pen
        p[jk.P_MU] = self.mu
        p[jk.P_SHEAR] = _SHEAR_MODES[self.shear_damage]
        if self.is_tied:
            p[jk.P_MODE] = jk.MODE_TIED
            return p
        p[jk.P_MODE] = jk.MODE_DRY if self.is_dry else jk.MODE_COHESIVE
        p[jk.P_FT] = self.ft
        p[jk.P_UK] = self.u_k
        p[jk.P_ZETA] = self.zeta
        p[jk.P_C] = self.c
        p[jk.P_TANPHI] = self.tan_phi
        p[jk.P_DK] = self.delta_k
        p[jk.P_XI] = self.xi
        p[jk.P_U0] = self.ft / self.knn
        p[jk.P_EZ] = -math.expm1(-self.zeta)
        p[jk.P_EX] = -math.expm1(-self.xi)
        return p

    def stiffness_bound(self):
        """Largest tangent stiffness (Pa/m): max(knn, kss, kc_pen).

        Softening only lowers the tangent; the friction coupling d(tau)/du makes the tangent
        lower-triangular, so its eigenvalues stay the diagonal ones.
        """
        return max(self.knn, self.kss, self.kc_pen)

    def initial_state(self):
        """Virgin history, (NJS,) float64 (D = 1 for a dry joint)."""
        s = np.zeros(jk.NJS)
        if self.is_dry:
            s[jk.JS_D] = 1.0
        return s

"""Lee-Fenves plastic-damage block material (MODEL.md section 3): parameters and validation.

Units: SI (Pa, m, kg/m^3). The uniaxial curves are Abaqus-style tables of rows
(stress Pa, inelastic strain, damage); inelastic strain = total strain - stress / E0. They are
converted to plastic strain eps_p = eps_in - d / (1 - d) * stress / E0, densified to
``NTAB`` points (linear in inelastic strain between input rows) and handed to the kernel
``dr_masonry.kernels.plastic_damage``. The post-peak part of each table is the softening branch
at the characteristic length ``h_ref``; an element of length h uses it with the inelastic-strain
axis scaled by h_ref / h (crack band), so the energy per unit crack area does not depend on h.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace

import numpy as np

from ..kernels import plastic_damage as kpd
from ..units import MPa, mm


class MaterialError(ValueError):
    """Invalid block-material input; the message names the parameter and its value."""


def _rows(name, table):
    try:
        t = np.array(table, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise MaterialError(f"{name}: rows must be (stress Pa, inelastic strain, damage), got {table!r}") from exc
    if t.ndim != 2 or t.shape[1] != 3 or t.shape[0] < 1:
        raise MaterialError(f"{name}: need rows (stress Pa, inelastic strain, damage), got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise MaterialError(f"{name}: contains NaN or Inf: {t.tolist()}")
    if t.shape[0] > (kpd.NTAB - 1) // 4 + 1:
        raise MaterialError(f"{name}: at most {(kpd.NTAB - 1) // 4 + 1} rows, got {t.shape[0]}")
    if np.any(t[:, 0] <= 0):
        raise MaterialError(f"{name}: stresses must be > 0 Pa (use a small residual stress), got {t[:, 0].tolist()}")
    if t[0, 1] != 0.0 or t[0, 2] != 0.0:
        raise MaterialError(f"{name}: the first row must have inelastic strain 0 and damage 0, got {t[0].tolist()}")
    if np.any(np.diff(t[:, 1]) <= 0):
        raise MaterialError(f"{name}: inelastic strains must increase strictly, got {t[:, 1].tolist()}")
    if np.any(t[:, 2] < 0) or np.any(t[:, 2] >= 1) or np.any(np.diff(t[:, 2]) < 0):
        raise MaterialError(f"{name}: damage must be non-decreasing in [0, 1), got {t[:, 2].tolist()}")
    return t


@dataclass(frozen=True)
class PlasticDamage:
    """Lee-Fenves (concrete damaged plasticity) material of the blocks.

    Parameters
    ----------
    E : float
        Young's modulus E0, Pa.
    nu : float
        Poisson ratio, in (-1, 0.5).
    density : float
        mass density, kg/m^3.
    tension, compression : tuple of (stress Pa, inelastic strain, damage) rows
        uniaxial curves at the characteristic length ``h_ref``; first row = initial yield.
    eccentricity : float
        flow-potential eccentricity (default 0.1).
    dilation : float
        dilation angle psi, degrees (default 10).
    fb0_fc0 : float
        equal-biaxial to uniaxial compressive strength ratio (default 1.16).
    Kc : float
        ratio of the second-invariant radii on the tensile and compressive meridians (2/3).
    damage_cap : float
        upper bound of dt and dc (default 0.9).
    h_ref : float
        characteristic length of the tables, m (default 55 mm).
    stays_elastic : bool
        linear elastic material (the tables are then ignored); see :meth:`elastic`.
    """
    E: float
    nu: float
    density: float
    tension: tuple = ((1.5 * MPa, 0.0, 0.0), (0.1 * MPa, 0.01, 0.9))
    compression: tuple = ((6.8 * MPa, 0.0, 0.0), (0.9 * MPa, 0.06, 0.9))
    eccentricity: float = 0.1
    dilation: float = 10.0
    fb0_fc0: float = 1.16
    Kc: float = 2.0 / 3.0
    damage_cap: float = 0.9
    h_ref: float = 55.0 * mm
    stays_elastic: bool = False
    _params: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        for name in ("E", "nu", "density", "eccentricity", "dilation", "fb0_fc0", "Kc",
                     "damage_cap", "h_ref"):
            v = getattr(self, name)
            if (not isinstance(v, (int, float, np.floating, np.integer))
                    or isinstance(v, (bool, np.bool_)) or not math.isfinite(v)):
                raise MaterialError(f"PlasticDamage.{name} must be a finite number, got {v!r}")
        if self.E <= 0:
            raise MaterialError(f"PlasticDamage.E must be > 0 Pa, got {self.E}")
        if not -1.0 < self.nu < 0.5:
            raise MaterialError(f"PlasticDamage.nu must be in (-1, 0.5), got {self.nu}")
        if self.density <= 0:
            raise MaterialError(f"PlasticDamage.density must be > 0 kg/m^3, got {self.density}")
        if not isinstance(self.stays_elastic, (bool, np.bool_)):   # "no" would count as True
            raise MaterialError(f"PlasticDamage.stays_elastic must be True or False, got "
                                f"{self.stays_elastic!r}")
        p = np.zeros(kpd.NMP)
        lam = self.E * self.nu / ((1 + self.nu) * (1 - 2 * self.nu))
        p[kpd.MP_E], p[kpd.MP_NU], p[kpd.MP_LAM] = self.E, self.nu, lam
        p[kpd.MP_MU] = self.E / (2 * (1 + self.nu))
        p[kpd.MP_K] = self.E / (3 * (1 - 2 * self.nu))
        p[kpd.MP_RHO] = self.density
        if self.stays_elastic:
            p[kpd.MP_ELASTIC] = 1.0
        else:
            self._plastic_params(p)
        object.__setattr__(self, "_params", p)

    def _plastic_params(self, p):
        if self.eccentricity <= 0:
            raise MaterialError(f"PlasticDamage.eccentricity must be > 0, got {self.eccentricity}")
        if not 0.0 < self.dilation < 90.0:
            raise MaterialError(f"PlasticDamage.dilation must be in (0, 90) degrees, got {self.dilation}")
        if self.fb0_fc0 < 1.0:
            raise MaterialError(f"PlasticDamage.fb0_fc0 must be >= 1, got {self.fb0_fc0}")
        if not 0.5 < self.Kc <= 1.0:
            raise MaterialError(f"PlasticDamage.Kc must be in (0.5, 1], got {self.Kc}")
        if not 0.0 < self.damage_cap < 1.0:
            raise MaterialError(f"PlasticDamage.damage_cap must be in (0, 1), got {self.damage_cap}")
        if self.h_ref <= 0:
            raise MaterialError(f"PlasticDamage.h_ref must be > 0 m, got {self.h_ref}")
        alpha = (self.fb0_fc0 - 1) / (2 * self.fb0_fc0 - 1)
        tanpsi = math.tan(math.radians(self.dilation))
        t = _rows("PlasticDamage.tension", self.tension)
        c = _rows("PlasticDamage.compression", self.compression)
        p[kpd.MP_ALPHA] = alpha
        p[kpd.MP_GAMMA] = 3 * (1 - self.Kc) / (2 * self.Kc - 1)
        p[kpd.MP_ECC] = self.eccentricity * t[0, 0] * tanpsi
        p[kpd.MP_TANPSI] = tanpsi
        p[kpd.MP_HREF] = self.h_ref
        p[kpd.MP_FTOL] = 1e-10 * c[0, 0]
        smin = 0.0
        for name, rows, off, key in (("tension", t, kpd.MP_TAB, kpd.MP_NT),
                                     ("compression", c, kpd.MP_TAB + 4 * kpd.NTAB, kpd.MP_NC)):
            n, s_need = self._table(name, rows, p, off)
            p[key] = n
            smin = max(smin, s_need)
        sbt_max = max(self._effective(t))
        sbc_min = min(self._effective(c))
        if sbc_min / sbt_max * (1 - alpha) - (1 + alpha) <= 0:
            raise MaterialError(
                f"PlasticDamage: effective compressive strength {sbc_min:.4g} Pa too small against the "
                f"effective tensile strength {sbt_max:.4g} Pa (need beta > 0 in the yield function)")
        p[kpd.MP_HMAX] = self.h_ref / (smin * 1.001) if smin > 0 else np.inf

    def _effective(self, rows):
        d = np.minimum(rows[:, 2], self.damage_cap)
        return rows[:, 0] / (1 - d)

    def _table(self, name, rows, p, off):
        """Densify one table into p[off:off + 4 NTAB]; returns (points, smallest admissible h_ref/h)."""
        nseg = rows.shape[0] - 1
        if nseg == 0:
            ein = rows[:, 1].copy()
            sg = rows[:, 0].copy()
            dm = rows[:, 2].copy()
        else:
            nsub = (kpd.NTAB - 1) // nseg
            tt = np.linspace(0.0, 1.0, nsub + 1)[:-1]
            ein = np.concatenate([rows[i, 1] + tt * (rows[i + 1, 1] - rows[i, 1]) for i in range(nseg)]
                                 + [rows[-1:, 1]])
            sg = np.interp(ein, rows[:, 1], rows[:, 0])
            dm = np.interp(ein, rows[:, 1], rows[:, 2])
        dm = np.minimum(dm, self.damage_cap)
        ipk = int(np.argmax(rows[:, 0]))
        ein_pk = rows[ipk, 1]
        post = ein > ein_pk
        a = np.where(post, ein_pk, ein) - dm / (1 - dm) * sg / self.E
        b = np.where(post, ein - ein_pk, 0.0)
        n = ein.size
        s_need = 0.0
        da, db, dsg = np.diff(a), np.diff(b), np.diff(sg)
        pre = db == 0
        if np.any(da[pre] <= 0):
            raise MaterialError(f"PlasticDamage.{name}: plastic strain eps_in - d/(1-d) sigma/E0 decreases "
                                f"before the peak; damage grows too fast in rows {rows.tolist()}")
        if np.any(~pre):
            s_need = max(0.0, float(np.max(-da[~pre] / db[~pre])), float(np.max(-dsg[~pre] / (self.E * db[~pre]))))
        if s_need * 1.001 >= 1.0:
            raise MaterialError(f"PlasticDamage.{name}: the table snaps back (or its plastic strain decreases) at "
                                f"its own length h_ref = {self.h_ref} m; rows {rows.tolist()}")
        p[off:off + n] = a
        p[off + kpd.NTAB:off + kpd.NTAB + n] = b
        p[off + 2 * kpd.NTAB:off + 2 * kpd.NTAB + n] = sg
        p[off + 3 * kpd.NTAB:off + 3 * kpd.NTAB + n] = dm
        return n, s_need

    # ------------------------------------------------------------------ constructors
    @classmethod
    def reference(cls):
        """Calibrated block material of the paper (Table 2; MODEL.md section 4)."""
        return cls(E=4800 * MPa, nu=0.17, density=1800.0,
                   tension=((1.5 * MPa, 0.0, 0.0), (0.1 * MPa, 0.01, 0.9)),
                   compression=((6.8 * MPa, 0.0, 0.0), (0.9 * MPa, 0.06, 0.9)),
                   h_ref=55 * mm)

    @classmethod
    def elastic(cls, E, nu, density):
        """A material that stays linear elastic (E Pa, nu, density kg/m^3); a run computes its
        elements as corotational linear hexahedra (docs/internals.md)."""
        return cls(E=E, nu=nu, density=density, stays_elastic=True)

    def with_changes(self, **kw):
        """A copy with some parameters changed (validated again)."""
        valid = [f.name for f in fields(self) if f.init]
        unknown = set(kw) - set(valid)
        if unknown:
            raise MaterialError(f"PlasticDamage.with_changes: unknown fields {sorted(unknown)}; "
                                f"valid: {valid}")
        return replace(self, **kw)

    # ------------------------------------------------------------------ kernel data
    def params_array(self):
        """Kernel parameters (NMP,) float64 (a fresh copy)."""
        return self._params.copy()

    def initial_state(self):
        """Virgin Gauss-point state (NMS,) float64."""
        s = np.zeros(kpd.NMS)
        if not self.stays_elastic:
            s[kpd.MS_SBT] = self._params[kpd.MP_SBT0]
            s[kpd.MS_SBC] = self._params[kpd.MP_SBC0]
        return s

    @property
    def max_element_size(self):
        """Largest element characteristic length (m) the crack band allows without snap-back."""
        return math.inf if self.stays_elastic else float(self._params[kpd.MP_HMAX])

    def check_element_size(self, h):
        """Raise :class:`MaterialError` unless 0 < h <= max_element_size (h in m)."""
        if not (np.isfinite(h) and h > 0):
            raise MaterialError(f"element characteristic length must be > 0 m, got {h}")
        if h > self.max_element_size:
            raise MaterialError(
                f"element characteristic length {h:.4g} m exceeds {self.max_element_size:.4g} m: the "
                f"crack-band softening branch would snap back; refine the mesh")

    def fracture_energy(self, which="tension"):
        """Area under stress vs inelastic strain of the ``which`` ("tension" or "compression")
        table times h_ref (N/m = J/m^2)."""
        if which not in ("tension", "compression"):
            raise MaterialError(f"PlasticDamage.fracture_energy: which={which!r} must be "
                                f"'tension' or 'compression'")
        rows = np.asarray(self.tension if which == "tension" else self.compression, dtype=np.float64)
        return float(np.sum(0.5 * (rows[1:, 0] + rows[:-1, 0]) * np.diff(rows[:, 1])) * self.h_ref)

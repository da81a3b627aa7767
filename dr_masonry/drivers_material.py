"""Single-Gauss-point drivers of the block material over the kernel ``gp_update``.

Every step is one committed increment (``s_old`` -> ``s_new`` -> commit), as in the solver.
Strains are small-strain tensors (Voigt order [xx, yy, zz, yz, xz, xy], engineering shears);
stresses in Pa.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .kernels import plastic_damage as kpd
from .loading import is_number
from .materials.plastic_damage import MaterialError, PlasticDamage

_VOIGT = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))


class DriverError(RuntimeError):
    """A mixed-control step did not converge (the message names the step)."""


@dataclass
class MaterialPath:
    """Result of a driven path of n steps.

    ``strain`` (n, 6) total strain (Voigt, engineering shears); ``stress_voigt`` (n, 6) Pa;
    ``stress`` (n,) Pa (xx component for a uniaxial drive) or (n, 3, 3) for a strain path;
    ``dt``, ``dc`` (n,) damage; ``eps_p`` (n, 6) plastic strain; ``kappa_t``, ``kappa_c`` (n,)
    equivalent plastic strains; ``dissipated`` (n,) cumulative dissipated energy density, J/m^3;
    ``flags`` (n,) kernel flag bits.
    """
    strain: np.ndarray
    stress_voigt: np.ndarray
    stress: np.ndarray
    dt: np.ndarray
    dc: np.ndarray
    eps_p: np.ndarray
    kappa_t: np.ndarray
    kappa_c: np.ndarray
    dissipated: np.ndarray
    flags: np.ndarray


def _h(what, material, h):
    """The element length of a drive: ``h`` (m) checked against ``material``, or its h_ref."""
    if not isinstance(material, PlasticDamage):
        raise MaterialError(f"{what}: material must be a PlasticDamage, got {material!r}")
    if h is None:
        return material.h_ref
    if not is_number(h):
        raise MaterialError(f"{what}: h={h!r} must be a finite number of m (the element "
                            "characteristic length) or None")
    material.check_element_size(h)
    return float(h)


def _floats(what, name, value):
    """``value`` as a float64 array, else :class:`MaterialError` naming ``what`` and ``name``."""
    try:
        return np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise MaterialError(f"{what}: {name} must be an array of numbers, got {value!r}") from None


def drive_mixed(material, eps, free, h=None, tol=1e-8, max_iter=200):
    """Drive one Gauss point with mixed control.

    Parameters
    ----------
    material : PlasticDamage
    eps : (n, 6) array_like
        prescribed strains (Voigt, engineering shears); entries of free components are ignored.
    free : (6,) bool
        components whose stress is held at zero (their strain is solved for by Broyden's
        method started from the elastic stiffness, with step halving; secant updates cope with
        the corners of the yield surface where a finite-difference tangent fails).
    h : float or None
        element characteristic length, m (None = the tables' h_ref).
    tol : float
        convergence of the free stresses, relative to max(|stress|, 1e-4 E0).
    """
    h = _h("drive_mixed", material, h)
    eps = _floats("drive_mixed", "eps", eps)
    if eps.ndim != 2 or eps.shape[1] != 6 or not np.all(np.isfinite(eps)):
        raise MaterialError(f"eps must be a finite (n, 6) array, got shape {eps.shape}")
    free = np.asarray(free)
    if free.shape != (6,) or free.dtype != bool:
        raise MaterialError(f"free must be a (6,) bool array, got {free!r}")
    if not (isinstance(tol, float) and 0 < tol < 1):
        raise MaterialError(f"tol={tol!r} must be a float in (0, 1)")
    if not (isinstance(max_iter, (int, np.integer)) and max_iter >= 1):
        raise MaterialError(f"max_iter={max_iter!r} must be an integer >= 1")
    p = material.params_array()
    n = eps.shape[0]
    s_old = material.initial_state()
    s_new = s_old.copy()
    sig = np.zeros(6)
    out_e = np.zeros((n, 6))
    out_s = np.zeros((n, 6))
    out_st = np.zeros((n, kpd.NMS))
    cur = np.zeros(6)
    fi = np.flatnonzero(free)
    E = material.E
    lam, mu = p[kpd.MP_LAM], p[kpd.MP_MU]
    Ke = np.diag([lam + 2 * mu] * 3 + [mu] * 3)
    Ke[:3, :3] += lam * (1 - np.eye(3))
    Ke = Ke[np.ix_(fi, fi)]

    def resid(x):
        e = cur.copy()
        e[fi] = x
        kpd.gp_update(p, h, e, s_old, s_new, sig)
        return sig[fi].copy()

    J = Ke.copy()
    for k in range(n):
        cur[~free] = eps[k, ~free]
        if fi.size:
            x = cur[fi].copy()
            r = resid(x)
            ok = False
            for _ in range(max_iter):
                rmax = np.max(np.abs(r))
                if rmax <= tol * max(np.max(np.abs(sig)), 1e-4 * E):
                    ok = True
                    break
                for attempt in range(2):
                    try:
                        step = np.linalg.solve(J, -r)
                    except np.linalg.LinAlgError:
                        raise DriverError(
                            f"step {k}: the secant tangent of the free components became singular "
                            f"at strain {cur.tolist()} (a material damaged through cannot hold "
                            "them at zero stress)") from None
                    t = 1.0
                    for _ in range(20):
                        rn = resid(x + t * step)
                        if np.max(np.abs(rn)) < rmax:
                            break
                        t *= 0.5
                    if np.max(np.abs(rn)) < rmax or attempt == 1:
                        break
                    J = Ke.copy()  # the secant tangent went stale: restart from the elastic one
                dx = t * step
                J += np.outer(rn - r - J @ dx, dx) / (dx @ dx)
                x = x + dx
                r = rn
            if not ok:
                raise DriverError(f"step {k}: free stresses {r} Pa did not vanish in {max_iter} "
                                  f"iterations: the strain step to {eps[k, ~free].tolist()} is too "
                                  "large; a path of more, smaller steps converges")
            cur[fi] = x
        kpd.gp_update(p, h, cur, s_old, s_new, sig)
        out_e[k] = cur
        out_s[k] = sig
        out_st[k] = s_new
        s_old[:] = s_new
    ten = np.zeros((n, 3, 3))
    for i, (a, b) in enumerate(_VOIGT):
        ten[:, a, b] = out_s[:, i]
        ten[:, b, a] = out_s[:, i]
    return MaterialPath(strain=out_e, stress_voigt=out_s, stress=ten, dt=out_st[:, kpd.MS_DT],
                        dc=out_st[:, kpd.MS_DC], eps_p=out_st[:, kpd.MS_EPSP:kpd.MS_EPSP + 6],
                        kappa_t=out_st[:, kpd.MS_KT], kappa_c=out_st[:, kpd.MS_KC],
                        dissipated=out_st[:, kpd.MS_DISS], flags=out_st[:, kpd.MS_FLAG].astype(np.int64))


def drive_material(material, eps_xx, h=None):
    """Uniaxial-stress path: prescribed eps_xx (n,), every other stress component held at zero.

    Returns a :class:`MaterialPath` whose ``stress`` is sigma_xx (n,) Pa.
    """
    _h("drive_material", material, h)
    e = _floats("drive_material", "eps_xx", eps_xx)
    if e.ndim != 1:
        raise MaterialError(f"drive_material: eps_xx must be a 1-D path of strains (n,), got "
                            f"shape {e.shape}")
    if not np.all(np.isfinite(e)):
        i = int(np.argmax(~np.isfinite(e)))
        raise MaterialError(f"drive_material: eps_xx[{i}] = {e[i]} is not finite")
    eps = np.zeros((e.size, 6))
    eps[:, 0] = e
    res = drive_mixed(material, eps, [False, True, True, True, True, True], h)
    res.stress = res.stress_voigt[:, 0].copy()
    return res


def drive_strain_path(material, eps, h=None):
    """Prescribed total strain tensors ``eps`` (n, 3, 3); returns a :class:`MaterialPath` with
    ``stress`` (n, 3, 3) Pa."""
    _h("drive_strain_path", material, h)
    eps = _floats("drive_strain_path", "eps", eps)
    if eps.ndim != 3 or eps.shape[1:] != (3, 3):
        raise MaterialError(f"eps must have shape (n, 3, 3), got {eps.shape}")
    if not np.all(np.isfinite(eps)):
        i = int(np.argmax(~np.isfinite(eps).all(axis=(1, 2))))
        raise MaterialError(f"eps[{i}] is not finite: {eps[i].tolist()}")
    if not np.allclose(eps, eps.transpose(0, 2, 1)):
        raise MaterialError("eps must be symmetric")
    v = np.stack([eps[:, 0, 0], eps[:, 1, 1], eps[:, 2, 2],
                  2 * eps[:, 1, 2], 2 * eps[:, 0, 2], 2 * eps[:, 0, 1]], axis=1)
    return drive_mixed(material, v, np.zeros(6, bool), h)

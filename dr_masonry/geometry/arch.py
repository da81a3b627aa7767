"""Voussoir arches on top of :meth:`Model.add_block`: semicircular or segmental, on two abutments.

Conventions
-----------
* SI units (m). The arch spans along x, symmetric about x = 0; its depth runs along y from 0 to
  ``depth``; z up, the ground (the abutments' feet) at z = 0.
* ``span`` and ``rise`` are those of the intrados (the clear opening); ``rise = span / 2`` is the
  semicircular arch. The intrados circle has radius ``Ri = (span^2 / 4 + rise^2) / (2 rise)``, the
  extrados ``Ri + thickness``; the arch embraces ``2 alpha`` with ``sin(alpha) = span / (2 Ri)``.
* Voussoir ``k`` (left springing first) lies between the radial joints at angles
  ``theta_k = pi/2 + alpha - 2 alpha k / n`` from +x; its corners are on the two circles (flat
  faces). It is meshed ``(along the arch, through the depth, through the thickness)``.
* Each abutment is a hexahedron under a springing joint: vertical faces below the intrados and
  extrados springing points, its foot on z = 0, its top the springing joint.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..loading import is_count
from .walls import GeometryError, _choice, _length, _material


@dataclass
class Arch:
    """What :func:`add_arch` built: block ids (``voussoirs`` left to right, ``abutments`` (left,
    right), ``base`` or None), the circles' ``centre`` (x, z) (m), ``radius`` of the centreline
    and ``thickness`` (m), ``angles`` (n + 1,) of the joints from +x (rad)."""
    voussoirs: list
    abutments: list
    base: int | None
    centre: tuple
    radius: float
    thickness: float
    angles: np.ndarray

    @property
    def blocks(self):
        """All block ids: voussoirs, abutments, base."""
        return list(self.voussoirs) + list(self.abutments) + ([] if self.base is None else
                                                             [self.base])

    @property
    def embrace(self):
        """Angle the arch embraces (rad): pi for a semicircular arch."""
        return float(self.angles[0] - self.angles[-1])


def add_arch(model, material, span, rise, thickness, depth, n, abutment_height, *,
             abutment_material=None, support="fixed", base_height=None, joint=None,
             divisions=(1, 1, 1)):
    """Add a voussoir arch on two abutments; returns an :class:`Arch`.

    Parameters
    ----------
    model : Model
    material : PlasticDamage
        voussoirs' material (and the abutments' when ``abutment_material`` is None).
    span, rise : float, m
        clear span and rise of the intrados, ``0 < rise <= span / 2``.
    thickness, depth : float, m
        radial thickness of the ring and its depth along y.
    n : int
        number of voussoirs (>= 1).
    abutment_height : float, m
        height of the intrados springing above the ground (> 0).
    support : {"fixed", "base"}
        clamp the abutments (``"fixed"``) or stand them on a clamped base slab (``"base"``) of
        height ``base_height`` (m, default ``thickness``) through ordinary joints.
    joint : JointLaw or None
        joint law of every contact of the arch's blocks (e.g. ``JointLaw.dry(mu)``); None keeps
        the model's default joint law (mortared joints).
    divisions : (n_along, n_depth, n_thick) ints
        hexahedra per voussoir; abutments get ``(n_thick, n_depth, n_thick)``.
    """
    span = _length("span", span)
    rise = _length("rise", rise)
    if rise > 0.5 * span * (1 + 1e-12):
        raise GeometryError(f"rise {rise} m exceeds half the span ({0.5 * span} m): only "
                            f"semicircular (rise = span / 2) or segmental arches")
    rise = min(rise, 0.5 * span)
    t = _length("thickness", thickness)
    d = _length("depth", depth)
    h = _length("abutment_height", abutment_height)
    if not is_count(n, 1):
        raise GeometryError(f"n (voussoirs) must be an integer >= 1, got {n!r}")
    n = int(n)
    _material("material", material)
    abut_mat = material if abutment_material is None else abutment_material
    _material("abutment_material", abut_mat)
    _choice("support", support, ("fixed", "base"))
    hb = t if base_height is None else _length("base_height", base_height)
    div = tuple(np.atleast_1d(np.asarray(divisions, dtype=object)))
    if len(div) != 3 or not all(is_count(v, 1) for v in div):
        raise GeometryError(f"divisions must be three integers >= 1, got {divisions!r}")
    na, nd, nt = (int(v) for v in div)

    ri = (0.25 * span ** 2 + rise ** 2) / (2.0 * rise)
    re = ri + t
    alpha = math.asin(min(1.0, 0.5 * span / ri))
    zc = h + rise - ri
    theta = 0.5 * math.pi + alpha - 2.0 * alpha * np.arange(n + 1) / n
    chord = 2.0 * ri * math.sin(alpha / n)  # intrados length of a voussoir, m
    if chord < 1e-3 * t:
        raise GeometryError(f"n = {n} voussoirs are {chord:.3g} m long at the intrados, under "
                            f"a thousandth of the thickness; use fewer voussoirs")

    def ring(r, a, y):
        return np.array([r * math.cos(a), y, zc + r * math.sin(a)])

    planned = []
    for k in range(n):
        a0, a1 = theta[k], theta[k + 1]
        c = [ring(ri, a0, 0), ring(ri, a1, 0), ring(ri, a1, d), ring(ri, a0, d),
             ring(re, a0, 0), ring(re, a1, 0), ring(re, a1, d), ring(re, a0, d)]
        planned.append(np.array(c))
    z0 = hb if support == "base" else 0.0
    abut = []
    for side, a in ((-1, theta[0]), (1, theta[-1])):
        pi_, pe = ring(ri, a, 0), ring(re, a, 0)
        if pe[2] < z0 + 1e-3 * t:
            raise GeometryError(f"abutment_height {h} m leaves no abutment under the extrados "
                                f"springing (z = {pe[2]:.4g} m)")
        # corners: x from the intrados to the extrados springing (0->1), y (0->3), up (0->4)
        xs = (pi_[0], pe[0]) if side > 0 else (pe[0], pi_[0])
        zs = (pi_[2], pe[2]) if side > 0 else (pe[2], pi_[2])
        c = [(xs[0], 0, z0), (xs[1], 0, z0), (xs[1], d, z0), (xs[0], d, z0),
             (xs[0], 0, zs[0]), (xs[1], 0, zs[1]), (xs[1], d, zs[1]), (xs[0], d, zs[0])]
        abut.append(np.array(c, dtype=np.float64))

    vous = [model.add_block(c, material, (na, nd, nt), joint=joint, group="arch")
            for c in planned]
    abutments = [model.add_block(c, abut_mat, (nt, nd, nt), fixed=(support == "fixed"),
                                 joint=joint, group="abutment") for c in abut]
    base = None
    if support == "base":
        x0, x1 = abut[0][0, 0], abut[1][1, 0]
        pad = t
        base = model.add_box((x0 - pad, 0.0, 0.0), (x1 - x0 + 2 * pad, d, hb), abut_mat,
                             (max(1, round((x1 - x0) / t)), nd, 1), fixed=True, joint=joint,
                             group="base")
    return Arch(vous, abutments, base, (0.0, zc), ri + 0.5 * t, t, theta)

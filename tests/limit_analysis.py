"""Thrust-line lower bound for an arch of rigid voussoirs (no tension, no sliding), as an LP.

Written independently of the solver: the references of the arch scenes and tests.

The arch lies in the (x, z) plane, centre of the circles at the origin, crown on +z. Joint ``i``
(``0..n``, left springing to right springing) is the radial segment at angle ``theta_i`` from +x,
between the intrados (radius ``R - t/2``) and extrados (``R + t/2``) circles; voussoir ``k`` is the
quadrilateral between joints ``k`` and ``k + 1``. Unknowns per joint: the force ``F_i = (Fx, Fz)``
the left part exerts on the right part and its moment ``M_i`` about the joint's centre. No
tension: ``N_i = F_i . n_i >= 0``; the thrust line inside the joint: ``|M_i| <= N_i t / 2``;
friction unbounded.
Loads: each voussoir's weight ``W_k`` (N per m of depth, unit weight ``gamma``) down and ``lam W_k``
along +x (a tilting table, ``lam = tan(tilt)``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq, linprog


@dataclass(frozen=True)
class ArchLP:
    """Result of a limit-analysis LP: ``value`` (t_min in m, or the load factor), ``hinges``
    (joint indices where the thrust line touches a face), ``faces`` (+1 extrados, -1 intrados, per
    hinge), ``angles`` (the hinges' joint angles from the crown, rad, negative on the left)."""
    value: float
    hinges: tuple
    faces: tuple
    angles: tuple


def joint_angles(n, embrace=math.pi):
    """Joint angles (n + 1,) from +x, rad, left springing first, of an arch spanning ``embrace`` rad
    symmetric about the crown (pi: semicircular)."""
    if not (isinstance(n, int) and n >= 1):
        raise ValueError(f"n must be an integer >= 1, got {n!r}")
    if not (0.0 < embrace <= math.pi):
        raise ValueError(f"embrace must be in (0, pi] rad, got {embrace!r}")
    return 0.5 * math.pi + 0.5 * embrace - embrace * np.arange(n + 1) / n


def voussoirs(R, t, theta):
    """Areas (n,) m^2 per m of depth and centroids (n, 2) m of the flat-faced voussoirs."""
    ri, re = R - 0.5 * t, R + 0.5 * t
    a, b = theta[:-1], theta[1:]
    poly = np.stack([np.stack([ri * np.cos(a), ri * np.sin(a)], -1),
                     np.stack([ri * np.cos(b), ri * np.sin(b)], -1),
                     np.stack([re * np.cos(b), re * np.sin(b)], -1),
                     np.stack([re * np.cos(a), re * np.sin(a)], -1)], axis=1)  # (n, 4, 2)
    x, z = poly[..., 0], poly[..., 1]
    x1, z1 = np.roll(x, -1, axis=1), np.roll(z, -1, axis=1)
    cr = x * z1 - x1 * z
    area = 0.5 * cr.sum(1)
    cx = ((x + x1) * cr).sum(1) / (6 * area)
    cz = ((z + z1) * cr).sum(1) / (6 * area)
    return np.abs(area), np.stack([cx, cz], -1)


def _system(R, t, theta, gamma):
    """Equilibrium ``A_eq [F, M] + lam * b_lam = b_w`` and the band rows, variables per joint
    ``(Fx, Fz, M)`` then ``lam``."""
    n = len(theta) - 1
    area, g = voussoirs(R, t, theta)
    w = gamma * area
    c = R * np.stack([np.cos(theta), np.sin(theta)], -1)
    nrm = np.stack([np.sin(theta), -np.cos(theta)], -1)
    nv = 3 * (n + 1) + 1
    A = np.zeros((3 * n, nv))
    b = np.zeros(3 * n)
    for k in range(n):
        for j, s in ((k, 1.0), (k + 1, -1.0)):
            A[3 * k, 3 * j] = s
            A[3 * k + 1, 3 * j + 1] = s
            A[3 * k + 2, 3 * j] = -s * c[j, 1]      # moment about O of (Fx, Fz) at c_j
            A[3 * k + 2, 3 * j + 1] = s * c[j, 0]
            A[3 * k + 2, 3 * j + 2] = s
        # load (lam w, -w) at g_k
        A[3 * k, -1] = w[k]
        b[3 * k + 1] = w[k]
        A[3 * k + 2, -1] = -g[k, 1] * w[k]
        b[3 * k + 2] = g[k, 0] * w[k]
    band = np.zeros((2 * (n + 1), nv))  # +-M_i - N_i t/2 <= 0
    for i in range(n + 1):
        for r, s in ((2 * i, 1.0), (2 * i + 1, -1.0)):
            band[r, 3 * i:3 * i + 2] = -0.5 * t * nrm[i]
            band[r, 3 * i + 2] = s
    return A, b, band, w


def _hinges(x, t, theta, rtol=1e-6):
    """Joints where the thrust line of the LP solution ``x`` touches a face (its eccentricity is
    within ``rtol t/2`` of ``+-t/2``)."""
    n = len(theta) - 1
    f = x[:3 * (n + 1)].reshape(n + 1, 3)
    nrm = np.stack([np.sin(theta), -np.cos(theta)], -1)
    N = np.einsum("ij,ij->i", f[:, :2], nrm)
    e = -f[:, 2] / np.where(N > 0, N, np.inf)  # M = -e N
    touch = np.flatnonzero(np.abs(e) >= 0.5 * t * (1 - rtol))
    faces = tuple(1 if e[i] > 0 else -1 for i in touch)
    angles = tuple(float(0.5 * math.pi - theta[i]) for i in touch)
    return tuple(int(i) for i in touch), faces, angles


def collapse_factor(R, t, n, embrace=math.pi, gamma=1.0):
    """Largest horizontal load factor ``lam`` (tilting table, load along +x) the arch carries."""
    theta = joint_angles(n, embrace)
    A, b, band, _ = _system(R, t, theta, gamma)
    cost = np.zeros(A.shape[1])
    cost[-1] = -1.0
    bounds = [(None, None)] * (A.shape[1] - 1) + [(0.0, 1e3)]
    res = linprog(cost, A_ub=band, b_ub=np.zeros(len(band)), A_eq=A, b_eq=b, bounds=bounds,
                  method="highs")
    if res.status != 0:
        raise RuntimeError(f"arch R={R} t={t} n={n}: not even stable under self-weight "
                           f"({res.message})")
    return ArchLP(float(res.x[-1]), *_hinges(res.x, t, theta))


def _margin(R, t, n, embrace, gamma):
    """Largest moment margin ``d`` (N m per m, per unit weight scale) with ``|M_i| + d <= N_i t/2``
    under self-weight, and the LP result."""
    theta = joint_angles(n, embrace)
    A, b, band, w = _system(R, t, theta, gamma)
    A = np.hstack([A, np.zeros((len(A), 1))])
    band = np.hstack([band, np.ones((len(band), 1))])
    cost = np.zeros(A.shape[1])
    cost[-1] = -1.0
    scale = w.sum() * t
    bounds = [(None, None)] * (A.shape[1] - 2) + [(0.0, 0.0), (None, scale)]
    res = linprog(cost, A_ub=band, b_ub=np.zeros(len(band)), A_eq=A, b_eq=b, bounds=bounds,
                  method="highs")
    return res.x[-1] / scale, res, theta


def minimum_thickness(R, n, embrace=math.pi, gamma=1.0):
    """Smallest thickness (m) at which the arch of centreline radius ``R`` (m) stands under its
    own weight, with the hinges of its mechanism."""
    t = brentq(lambda tt: _margin(R, tt, n, embrace, gamma)[0], 1e-4 * R, 0.9 * R, xtol=1e-10 * R)
    _, res, theta = _margin(R, t, n, embrace, gamma)
    return ArchLP(float(t), *_hinges(res.x, t, theta))

"""8-node hexahedron: geometry, internal forces, lumped mass, stiffness bound.

Conventions
-----------
* Corner order is VTK's (``CORNERS[a]`` = natural coordinates of corner a; ``dr_masonry.model``
  takes it from here as ``HEX_NATURAL``).
* 2x2x2 Gauss rule, unit weights; Gauss point g sits at ``CORNERS[g] / sqrt(3)``.
* ``dN`` (nt, 8, 8, 3) 1/m: dN_a/dX_i in the reference configuration, indexed
  [table, gauss point, node, direction]; element e reads table ``geo[e]``. Elements equal up to
  a translation (the bricks of a wall) share one table, found by :func:`hex_geometry_shared`;
  :func:`hex_geometry` gives one table per element (``geo = arange(ne)``, for tests and
  reference solutions).
  ``wdet`` (ne, 8) m^3: Gauss weight x det(dX/dxi), per element.
* Runs compute every element as a corotational hexahedron (:func:`corot_local`): linear in the
  frame of the rotation of its mean deformation gradient, K d for an elastic material
  (:func:`corot_global`), the Gauss-point update of the linear local strains for a damaging one
  (:func:`corot_damaging`); tables by :func:`corot_tables`.
* :func:`gauss_forces` (the tests' and benchmarks' reference, never a run's) computes an element
  as total-Lagrangian: F = I + sum_a u_a (x) dN_a,
  Green-Lagrange strain E = (H + H^T + H^T H) / 2 with H = F - I (no cancellation at small
  strain), Voigt order [xx, yy, zz, yz, xz, xy] with engineering shears; the material returns
  the second Piola-Kirchhoff stress S (Pa) in the same order; nodal internal force
  f_a = sum_g wdet_g F S dN_a (N).
"""
import numpy as np

from .config import ijit, jit, pjit, prange
from .plastic_damage import (MP_E, MP_ELASTIC, MP_NU, MP_SBC0, MP_SBT0, MS_EPSP, NMS,
                             elastic_stress, gp_update, surely_elastic, trial_stress)

#: natural coordinates of the 8 corners (8, 3), VTK order: 0-3 at zeta = -1 counter-clockwise
#: seen from +zeta, 4-7 above them
CORNERS = np.array(
    [[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
     [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=np.float64)


def trilinear_shape(nat):
    """Trilinear shape functions (m, 8) of the corners at natural points ``nat`` (m, 3)."""
    nat = np.atleast_2d(nat)
    return 0.125 * np.prod(1.0 + nat[:, None, :] * CORNERS[None, :, :], axis=2)


#: natural coordinates of the 8 Gauss points (8, 3)
GAUSS = CORNERS / np.sqrt(3.0)
#: shape functions at the Gauss points (8 gauss points, 8 nodes)
N_GAUSS = trilinear_shape(GAUSS)

CHUNK = 64  #: elements per parallel task (scratch arrays allocated once per task)
SHARE_RTOL = 1e-9  #: corner offsets equal to this fraction of the smallest element share a table


class HexMeshError(ValueError):
    """Invalid hexahedral mesh input; the message names the parameter, element and value."""


# ---------------------------------------------------------------------------- geometry
@ijit
def inverse_transpose3(m00, m01, m02, m10, m11, m12, m20, m21, m22):
    """det M and the entries of M^-T (row by row) of a 3 x 3 matrix M, as cofactors / det.

    Returns (det, t00, t01, t02, t10, t11, t12, t20, t21, t22); inf or NaN entries where
    det = 0 (the caller checks det).
    """
    c00 = m11 * m22 - m12 * m21
    c01 = m12 * m20 - m10 * m22
    c02 = m10 * m21 - m11 * m20
    det = m00 * c00 + m01 * c01 + m02 * c02
    return (det, c00 / det, c01 / det, c02 / det,
            (m02 * m21 - m01 * m22) / det, (m00 * m22 - m02 * m20) / det,
            (m01 * m20 - m00 * m21) / det, (m01 * m12 - m02 * m11) / det,
            (m02 * m10 - m00 * m12) / det, (m00 * m11 - m01 * m10) / det)


@jit
def hex_gauss_derivatives(xe, g, dng):
    """Reference derivatives at Gauss point ``g`` of the hexahedron with corners ``xe`` (8, 3) m.

    Writes ``dng`` (8, 3) 1/m = dN_a/dX_i and returns det(dX/dxi) (m^3 per unit natural volume).
    """
    r, s, t = GAUSS[g, 0], GAUSS[g, 1], GAUSS[g, 2]
    j00 = j01 = j02 = j10 = j11 = j12 = j20 = j21 = j22 = 0.0
    for a in range(8):
        ca, cb, cc = CORNERS[a, 0], CORNERS[a, 1], CORNERS[a, 2]
        fr, fs, ft = 1.0 + ca * r, 1.0 + cb * s, 1.0 + cc * t
        d0 = 0.125 * ca * fs * ft
        d1 = 0.125 * cb * fr * ft
        d2 = 0.125 * cc * fr * fs
        dng[a, 0], dng[a, 1], dng[a, 2] = d0, d1, d2
        j00 += xe[a, 0] * d0
        j01 += xe[a, 0] * d1
        j02 += xe[a, 0] * d2
        j10 += xe[a, 1] * d0
        j11 += xe[a, 1] * d1
        j12 += xe[a, 1] * d2
        j20 += xe[a, 2] * d0
        j21 += xe[a, 2] * d1
        j22 += xe[a, 2] * d2
    # inverse K = J^-1 = (J^-T)^T (K[k, i] = dxi_k / dX_i)
    det, k00, k10, k20, k01, k11, k21, k02, k12, k22 = inverse_transpose3(
        j00, j01, j02, j10, j11, j12, j20, j21, j22)
    for a in range(8):
        d0, d1, d2 = dng[a, 0], dng[a, 1], dng[a, 2]
        dng[a, 0] = d0 * k00 + d1 * k10 + d2 * k20
        dng[a, 1] = d0 * k01 + d1 * k11 + d2 * k21
        dng[a, 2] = d0 * k02 + d1 * k12 + d2 * k22
    return det


@pjit
def _hex_geometry(X, conn, dN, wdet, h):
    """Fill ``dN``, ``wdet`` (det J, unit weights) and ``h`` for every element (parallel)."""
    ne = conn.shape[0]
    for e in prange(ne):
        xe = np.empty((8, 3))
        for a in range(8):
            for i in range(3):
                xe[a, i] = X[conn[e, a], i]
        vol = 0.0
        for g in range(8):
            wdet[e, g] = hex_gauss_derivatives(xe, g, dN[e, g])
            vol += wdet[e, g]
        h[e] = np.cbrt(vol) if vol > 0.0 else 0.0


def _check_mesh(X, conn):
    X = np.ascontiguousarray(X, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != 3:
        raise HexMeshError(f"X must have shape (n_nodes, 3), got {X.shape}")
    if not np.all(np.isfinite(X)):
        raise HexMeshError("X contains NaN or Inf")
    c = np.asarray(conn)
    if c.ndim != 2 or c.shape[1] != 8 or not np.issubdtype(c.dtype, np.integer):
        raise HexMeshError(f"conn must be an integer array of shape (n_elements, 8), got "
                           f"{c.dtype} {c.shape}")
    if c.size and (c.min() < 0 or c.max() >= X.shape[0]):
        bad = int(np.argmax(np.any((c < 0) | (c >= X.shape[0]), axis=1)))
        raise HexMeshError(f"conn: element {bad} has node ids {c[bad].tolist()} outside "
                           f"[0, {X.shape[0]})")
    return X, np.ascontiguousarray(c, dtype=np.int64)


def _tables(X, conn, elems):
    """Geometry of the elements ``elems`` (ids into ``conn``), checked for positive Jacobians."""
    sub = conn[elems]
    nt = sub.shape[0]
    dN = np.empty((nt, 8, 8, 3))
    wdet = np.empty((nt, 8))
    h = np.empty(nt)
    _hex_geometry(X, sub, dN, wdet, h)
    bad = _first_bad(~(wdet > 0.0), wdet, elems)
    if bad is not None:
        e, g, det = bad
        raise HexMeshError(f"conn: element {e} (nodes {conn[e].tolist()}) has a non-positive "
                           f"Jacobian det = {det:.6g} at Gauss point {g} (inverted or "
                           f"degenerate hexahedron, or corners not in VTK order)")
    return dN, wdet, h


def _first_bad(bad, wdet, elems):
    """(element, Gauss point, det J) of the lowest element id of ``elems`` (nt,) with a point
    flagged in ``bad`` (nt, 8) bool, or None."""
    if not np.any(bad):
        return None
    rows = np.flatnonzero(bad.any(axis=1))
    t = rows[np.argmin(elems[rows])]
    g = int(np.argmax(bad[t]))
    return int(elems[t]), g, float(wdet[t, g])


def inverted_element(x, conn, elems, chunk=4096):
    """The first of the elements ``elems`` (int64 ids into ``conn`` (ne, 8)) that is inverted in
    the configuration ``x`` (n_nodes, 3) m: a finite, non-positive Jacobian determinant at a
    Gauss point. Returns (element, Gauss point, det J m^3) or None (a diagnosis after a run
    failed; elements with non-finite corners are skipped)."""
    for lo in range(0, elems.shape[0], chunk):
        part = elems[lo:lo + chunk]
        nt = part.shape[0]
        dN = np.empty((nt, 8, 8, 3))
        wdet = np.empty((nt, 8))
        _hex_geometry(x, conn[part], dN, wdet, np.empty(nt))
        bad = _first_bad(np.isfinite(wdet) & (wdet <= 0.0), wdet, part)
        if bad is not None:
            return bad
    return None


def hex_geometry(X, conn):
    """Reference-configuration geometry of hexahedra at the 2x2x2 Gauss points, one table each
    (:func:`hex_geometry_shared` without the sharing).

    Parameters
    ----------
    X : (n_nodes, 3) float64, m
        reference coordinates.
    conn : (ne, 8) int
        node ids per element, VTK corner order.

    Returns
    -------
    dN : (ne, 8, 8, 3) float64, 1/m
        dN_a/dX_i [element, gauss point, node, direction].
    geo : (ne,) int64
        ``arange(ne)``: element e reads table e.
    wdet : (ne, 8) float64, m^3
        Gauss weight x det J (sums to the element volume).
    h : (ne,) float64, m
        characteristic length, cube root of the element volume.

    Raises
    ------
    HexMeshError
        on malformed input or a non-positive Jacobian at a Gauss point (names the element).
    """
    X, conn = _check_mesh(X, conn)
    geo = np.arange(conn.shape[0], dtype=np.int64)
    dN, wdet, h = _tables(X, conn, geo)
    return dN, geo, wdet, h


def hex_geometry_shared(X, conn):
    """Geometry as :func:`hex_geometry`, one derivative table per distinct element shape.

    Elements whose corner offsets from their corner 0 agree within ``SHARE_RTOL`` x the
    smallest element extent (translated copies: the bricks of a wall) share the table of the
    first of them; ``wdet`` and ``h`` are those of the table, given per element.

    Returns
    -------
    dN : (nt, 8, 8, 3) float64, 1/m
        dN_a/dX_i [table, gauss point, node, direction].
    geo : (ne,) int64
        table of each element.
    wdet : (ne, 8) float64, m^3
        Gauss weight x det J per element.
    h : (ne,) float64, m
        characteristic length per element.

    Raises
    ------
    HexMeshError
        as :func:`hex_geometry`.
    """
    X, conn = _check_mesh(X, conn)
    if conn.shape[0] == 0:
        return np.empty((0, 8, 8, 3)), np.empty(0, np.int64), np.empty((0, 8)), np.empty(0)
    off = X[conn[:, 1:]] - X[conn[:, :1]]  # (ne, 7, 3)
    extent = np.abs(off).max(axis=(1, 2))
    pos = extent[extent > 0.0]  # a degenerate element gets its own table, refused by _tables
    quantum = SHARE_RTOL * (pos.min() if pos.size else 1.0)
    key = np.round(off.reshape(-1, 21) / quantum).astype(np.int64)
    _, first, geo = np.unique(key, axis=0, return_index=True, return_inverse=True)
    dN, wdet, h = _tables(X, conn, first)
    geo = geo.ravel().astype(np.int64)
    return dN, geo, wdet[geo], h[geo]


# ---------------------------------------------------------------------------- internal forces
@ijit
def displacement_gradient(ue, dn, v0, v1, v2):
    """H = sum_a (u_a - v) (x) dn_a (row by row, 9 values) of nodal displacements ``ue`` (8, 3) m
    less a common vector ``v`` (m; zero for the plain gradient) and derivatives ``dn`` (8, 3) 1/m."""
    h00 = h01 = h02 = h10 = h11 = h12 = h20 = h21 = h22 = 0.0
    for a in range(8):
        d0, d1, d2 = dn[a, 0], dn[a, 1], dn[a, 2]
        u0, u1, u2 = ue[a, 0] - v0, ue[a, 1] - v1, ue[a, 2] - v2
        h00 += u0 * d0
        h01 += u0 * d1
        h02 += u0 * d2
        h10 += u1 * d0
        h11 += u1 * d1
        h12 += u1 * d2
        h20 += u2 * d0
        h21 += u2 * d1
        h22 += u2 * d2
    return h00, h01, h02, h10, h11, h12, h20, h21, h22


@ijit
def hex_gauss_strain(ue, dng, F, eps):
    """Deformation gradient ``F`` (3, 3) and Green-Lagrange strain ``eps`` (6,) at one Gauss point.

    ``ue`` (8, 3) m nodal displacements, ``dng`` (8, 3) 1/m reference derivatives.
    ``eps`` in Voigt order [xx, yy, zz, yz, xz, xy], engineering shears.
    """
    h00, h01, h02, h10, h11, h12, h20, h21, h22 = displacement_gradient(ue, dng, 0.0, 0.0, 0.0)
    eps[0] = h00 + 0.5 * (h00 * h00 + h10 * h10 + h20 * h20)
    eps[1] = h11 + 0.5 * (h01 * h01 + h11 * h11 + h21 * h21)
    eps[2] = h22 + 0.5 * (h02 * h02 + h12 * h12 + h22 * h22)
    eps[3] = h12 + h21 + h01 * h02 + h11 * h12 + h21 * h22
    eps[4] = h02 + h20 + h00 * h02 + h10 * h12 + h20 * h22
    eps[5] = h01 + h10 + h00 * h01 + h10 * h11 + h20 * h21
    F[0, 0], F[0, 1], F[0, 2] = 1.0 + h00, h01, h02
    F[1, 0], F[1, 1], F[1, 2] = h10, 1.0 + h11, h12
    F[2, 0], F[2, 1], F[2, 2] = h20, h21, 1.0 + h22


@ijit
def hex_add_gauss_force(F, sig, dng, w, fe):
    """Add the Gauss point's contribution w F S dN_a to the element forces ``fe`` (8, 3) N.

    ``F`` (3, 3) deformation gradient, ``sig`` (6,) Pa second Piola-Kirchhoff stress (Voigt),
    ``dng`` (8, 3) 1/m, ``w`` m^3 weight x det J.
    """
    s00, s11, s22, s12, s02, s01 = sig[0], sig[1], sig[2], sig[3], sig[4], sig[5]
    for i in range(3):
        f0, f1, f2 = w * F[i, 0], w * F[i, 1], w * F[i, 2]
        p0 = f0 * s00 + f1 * s01 + f2 * s02
        p1 = f0 * s01 + f1 * s11 + f2 * s12
        p2 = f0 * s02 + f1 * s12 + f2 * s22
        for a in range(8):
            fe[a, i] += p0 * dng[a, 0] + p1 * dng[a, 1] + p2 * dng[a, 2]


@ijit
def gauss_point_update(p, he, eps, s_old_e, s_new_e, g, sig):
    """The material update of Gauss point ``g`` of an element (``gp_update``: stress ``sig`` (6,)
    Pa and trial state ``s_new_e[g]`` written; states (8, NMS)) and twice its stored energy
    density sigma . (eps - eps_p), J/m^3."""
    gp_update(p, he, eps, s_old_e[g], s_new_e[g], sig)
    acc = 0.0
    for m in range(6):
        acc += sig[m] * (eps[m] - s_new_e[g, MS_EPSP + m])
    return acc


@ijit
def gather_element(U, conn, e, ue, fe):
    """Displacements ``ue`` (8, 3) m of element ``e``'s nodes from ``U``; its forces ``fe`` (8, 3)
    zeroed."""
    for a in range(8):
        n = conn[e, a]
        for i in range(3):
            ue[a, i] = U[n, i]
            fe[a, i] = 0.0


@ijit
def hex_chunk(lo, hi, U, conn, active, dN, geo, wdet, h, elem_mat, params, s_old, s_new, pristine,
              dirty, ke, kbt, kxo, kdn, kid, f_elem, energy):
    """Elements ``active[lo:hi]`` of the force kernel (one parallel task, its own scratch), each a
    corotational hexahedron (table ``kid[e]`` of :func:`corot_tables`; an element without one
    gets NaN forces, which the run's guards stop on)."""
    ue = np.empty((8, 3))
    F = np.empty((3, 3))
    eps = np.empty(6)
    sig = np.empty(6)
    # local displacements, rotations and table of each slot of the task, and the Gauss-point
    # strains of the damaging ones
    ns = hi - lo
    dl = np.empty((ns, 24))
    fl = np.empty((ns, 24))
    rot = np.empty((ns, 3, 3))
    slot = np.full(ns, -1, dtype=np.int64)
    strains = np.empty((ns, 48))
    for k in range(lo, hi):
        e = active[k]
        gather_element(U, conn, e, ue, f_elem[e])
        t = kid[e]
        if t >= 0 and corot_local(ue, kxo[t], kdn[t], rot[k - lo], dl[k - lo]) > 0.0:
            slot[k - lo] = t   # K d (and the damaging ones' strains) below
        else:   # no table, or inverted: NaN for the run's guards
            f_elem[e, :, :] = np.nan
            energy[e] = np.nan
    j = 0
    while j < ns:   # K d of each run of slots with one table: one matrix product (BLAS)
        t = slot[j]
        j1 = j + 1
        while j1 < ns and slot[j1] == t:
            j1 += 1
        if t >= 0:
            np.dot(dl[j:j1], ke[t], fl[j:j1])   # K symmetric: (K d)^T = d^T K
            p = params[elem_mat[active[lo + j]]]   # a table's elements share one material
            if p[MP_ELASTIC] == 1.0:
                for jj in range(j, j1):
                    e = active[lo + jj]
                    energy[e] = corot_global(rot[jj], dl[jj], fl[jj], f_elem[e])
            else:
                np.dot(dl[j:j1], kbt[t], strains[j:j1])   # the 8 points' strains B_g d
                for jj in range(j, j1):
                    e = active[lo + jj]
                    fast = pristine[e] != 0   # virgin committed state
                    if fast and corot_surely_elastic(p, strains[jj]):   # K d, no state
                        energy[e] = corot_global(rot[jj], dl[jj], fl[jj], f_elem[e])
                        if dirty[e] != 0:   # trial state = committed state again
                            s_new[e] = s_old[e]
                            dirty[e] = 0
                    else:
                        energy[e] = corot_damaging(p, h[e], s_old[e], s_new[e], dN[geo[e]],
                                                   wdet[e], strains[jj], rot[jj], f_elem[e], F,
                                                   eps, sig, ue)
                        if fast:
                            dirty[e] = 1
        j = j1


@pjit
def gauss_forces(U, conn, active, dN, geo, wdet, h, elem_mat, params, s_old, s_new, pristine,
                 dirty, f_elem, energy):
    """Every element of ``active`` as a total-Lagrangian hexahedron at its Gauss points: the
    reference that the corotational element of a run is tested and benchmarked against (arguments
    those of :func:`.forces.hex_forces` without tables; runs never call it, so it is compiled
    apart from their force kernel: 7 s of their cold start, BENCHMARKS.md section 62)."""
    na = active.shape[0]
    for t in prange((na + CHUNK - 1) // CHUNK):   # tasks of CHUNK elements, scratch per task
        ue = np.empty((8, 3))
        F = np.empty((3, 3))
        eps = np.empty(6)
        sig = np.empty(6)
        for k in range(t * CHUNK, min(na, (t + 1) * CHUNK)):
            e = active[k]
            fe = f_elem[e]
            gather_element(U, conn, e, ue, fe)
            p = params[elem_mat[e]]
            plastic = p[MP_ELASTIC] != 1.0
            fast = plastic and pristine[e] != 0   # virgin state: no state to read while elastic
            dne = dN[geo[e]]
            en = 0.0
            for g in range(8):
                dng = dne[g]
                hex_gauss_strain(ue, dng, F, eps)
                w = wdet[e, g]
                acc = 0.0
                if fast:   # the committed state is the virgin one: the material's strengths
                    i1, q, d0, d1, d2, d3, d4, d5 = trial_stress(p, eps[0], eps[1], eps[2], eps[3],
                                                                 eps[4], eps[5])
                    if surely_elastic(p, i1, q, p[MP_SBT0], p[MP_SBC0]):
                        m0 = i1 / 3.0
                        sig[0] = m0 + d0
                        sig[1] = m0 + d1
                        sig[2] = m0 + d2
                        sig[3] = d3
                        sig[4] = d4
                        sig[5] = d5
                    else:   # the element leaves its virgin state: the full update from here on
                        fast = False
                        for gg in range(g):
                            for m in range(NMS):
                                s_new[e, gg, m] = s_old[e, gg, m]
                        dirty[e] = 1
                if not plastic:
                    elastic_stress(p, eps, sig)
                if plastic and not fast:
                    acc = gauss_point_update(p, h[e], eps, s_old[e], s_new[e], g, sig)
                else:   # elastic stress from the total strain (no plastic strain)
                    for m in range(6):
                        acc += sig[m] * eps[m]
                hex_add_gauss_force(F, sig, dng, w, fe)
                en += 0.5 * w * acc
            if fast and dirty[e] != 0:   # trial state = committed state again
                for g in range(8):
                    for m in range(NMS):
                        s_new[e, g, m] = s_old[e, g, m]
                dirty[e] = 0
            energy[e] = en


@ijit
def corot_surely_elastic(p, strains):
    """Whether all 8 Gauss points of a virgin corotational element of material ``p`` are surely
    elastic at local strains ``strains`` (48,) (Voigt, engineering shears, point g at 6 g)."""
    for g in range(8):
        o = 6 * g
        i1, q, _, _, _, _, _, _ = trial_stress(p, strains[o], strains[o + 1], strains[o + 2],
                                               strains[o + 3], strains[o + 4], strains[o + 5])
        if not surely_elastic(p, i1, q, p[MP_SBT0], p[MP_SBC0]):
            return False
    return True


# a call, not inlined: inlined it added 2.5 s to the cold compile to save the call's 80 ns of a
# damaged element's 1,000 in its elastic range (6,600 in plastic flow, section 63), within the
# noise of whole runs (BENCHMARKS.md section 61)
@jit
def corot_damaging(p, he, s_old_e, s_new_e, dne, we, strains, R, fe, eye, eps, sig, floc):
    """Forces ``fe`` (8, 3) N of one corotational element of a damaging material.

    In the element's rotated frame (:func:`corot_local`: rotation ``R``) the strain of Gauss
    point g is linear, ``strains[6 g:6 g + 6]`` = B_g d (Voigt, engineering shears); the
    material updates it (``gp_update``: committed states ``s_old_e`` (8, NMS), trial
    ``s_new_e``, written) and the local forces sum_g w_g B_g^T sigma_g (``dne`` (8, 8, 3) 1/m,
    ``we`` (8,) m^3) turn back with ``R``. Scratch: ``eye`` (3, 3) (set to I here), ``eps``,
    ``sig`` (6,), ``floc`` (8, 3). Returns the stored energy, J.
    """
    for i in range(3):
        for k in range(3):
            eye[i, k] = 1.0 if i == k else 0.0
    floc[:, :] = 0.0
    en = 0.0
    for g in range(8):
        for m in range(6):
            eps[m] = strains[6 * g + m]
        en += 0.5 * we[g] * gauss_point_update(p, he, eps, s_old_e, s_new_e, g, sig)
        hex_add_gauss_force(eye, sig, dne[g], we[g], floc)
    for a in range(8):
        g0, g1, g2 = floc[a, 0], floc[a, 1], floc[a, 2]
        for i in range(3):
            fe[a, i] = R[i, 0] * g0 + R[i, 1] * g1 + R[i, 2] * g2
    return en


def pristine_elements(s_old, s_virgin, h, h_max):
    """Elements whose committed Gauss-point states are all virgin: (ne,) uint8 for
    :func:`.forces.hex_forces`.

    ``s_old`` (ne, 8, NMS) committed states, ``s_virgin`` (ne, NMS) each element's material's
    initial state, ``h`` (ne,) m element lengths and ``h_max`` (ne,) m their materials' largest
    length (an element outside (0, h_max] is not pristine: its update flags the clamp).
    """
    virgin = np.all(s_old == s_virgin[:, None, :], axis=(1, 2))
    return (virgin & (h > 0.0) & (h <= h_max)).astype(np.uint8)


# ---------------------------------------------------------------------------- corotational elements
#: change of the rotation's largest entry that ends the polar iteration: the iteration converges
#: quadratically, so the step after a change of 1e-9 is at rounding level
POLAR_TOL = 1e-9
POLAR_MAX = 50  #: iterations at most (3-4 at strains up to 1e-3; far more only for gross distortion)


@ijit
def polar_rotation(f00, f01, f02, f10, f11, f12, f20, f21, f22, R):
    """Rotation ``R`` (3, 3) of the polar decomposition F = R S (S symmetric positive definite).

    Newton's iteration R <- (R + R^-T) / 2 from R = F. Returns det F; for det F <= 0 (an
    inverted element) ``R`` is not written.
    """
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = f00, f01, f02, f10, f11, f12, f20, f21, f22
    det = 0.0
    for it in range(POLAR_MAX):
        d, c00, c01, c02, c10, c11, c12, c20, c21, c22 = inverse_transpose3(
            r00, r01, r02, r10, r11, r12, r20, r21, r22)
        if it == 0:
            det = d
            if not det > 0.0:
                return det
        change = max(abs(c00 - r00), abs(c01 - r01), abs(c02 - r02), abs(c10 - r10),
                     abs(c11 - r11), abs(c12 - r12), abs(c20 - r20), abs(c21 - r21),
                     abs(c22 - r22))
        r00, r01, r02 = 0.5 * (r00 + c00), 0.5 * (r01 + c01), 0.5 * (r02 + c02)
        r10, r11, r12 = 0.5 * (r10 + c10), 0.5 * (r11 + c11), 0.5 * (r12 + c12)
        r20, r21, r22 = 0.5 * (r20 + c20), 0.5 * (r21 + c21), 0.5 * (r22 + c22)
        if 0.5 * change <= POLAR_TOL:
            break
    R[0, 0], R[0, 1], R[0, 2] = r00, r01, r02
    R[1, 0], R[1, 1], R[1, 2] = r10, r11, r12
    R[2, 0], R[2, 1], R[2, 2] = r20, r21, r22
    return det


@ijit
def corot_local(ue, xo, dnc, R, dl):
    """Rotation and local displacements of one corotational linear element; returns det F.

    The element's rotation ``R`` (3, 3) is that of the polar decomposition of its volume-averaged
    deformation gradient F = I + sum_a u_a (x) ``dnc``_a; in the rotated frame the element is
    linear: local displacements ``dl`` (24,) m, d_a = R^T (x_a - x_0) - (X_a - X_0) (dof 3 a + i),
    local forces K d, global forces f_a = R (K d)_a (:func:`corot_global`), energy d.K d / 2.
    Exact under any rigid motion, equal to the total-Lagrangian element to first order in the
    strain.

    ``ue`` (8, 3) m nodal displacements; ``xo`` (8, 3) m corner offsets X_a - X_0; ``dnc``
    (8, 3) 1/m volume-averaged dN_a/dX. det F <= 0 (an inverted element): nothing written.
    """
    # sum_a dnc_a = 0: displacements relative to corner 0 (a rigid translation drops out exactly)
    h00, h01, h02, h10, h11, h12, h20, h21, h22 = displacement_gradient(ue, dnc, ue[0, 0], ue[0, 1],
                                                                        ue[0, 2])
    det = polar_rotation(1.0 + h00, h01, h02, h10, 1.0 + h11, h12, h20, h21, 1.0 + h22, R)
    if not det > 0.0:
        return det
    a00, a11, a22 = R[0, 0] - 1.0, R[1, 1] - 1.0, R[2, 2] - 1.0   # exact: R - I, small
    for a in range(8):   # d_a = (R^T - I) xo_a + R^T (u_a - u_0)
        x0, x1, x2 = xo[a, 0], xo[a, 1], xo[a, 2]
        w0, w1, w2 = ue[a, 0] - ue[0, 0], ue[a, 1] - ue[0, 1], ue[a, 2] - ue[0, 2]
        dl[3 * a] = (a00 * x0 + R[1, 0] * x1 + R[2, 0] * x2
                     + R[0, 0] * w0 + R[1, 0] * w1 + R[2, 0] * w2)
        dl[3 * a + 1] = (R[0, 1] * x0 + a11 * x1 + R[2, 1] * x2
                         + R[0, 1] * w0 + R[1, 1] * w1 + R[2, 1] * w2)
        dl[3 * a + 2] = (R[0, 2] * x0 + R[1, 2] * x1 + a22 * x2
                         + R[0, 2] * w0 + R[1, 2] * w1 + R[2, 2] * w2)
    return det


@ijit
def corot_global(R, dl, fl, fe):
    """Global forces ``fe`` (8, 3) N = R (K d)_a of one corotational element from its local
    displacements ``dl`` and local forces ``fl`` = K d (24,) N; returns its energy d.K d / 2 (J)."""
    en = 0.0
    for r in range(24):
        en += dl[r] * fl[r]
    for a in range(8):
        g0, g1, g2 = fl[3 * a], fl[3 * a + 1], fl[3 * a + 2]
        for i in range(3):
            fe[a, i] = R[i, 0] * g0 + R[i, 1] * g1 + R[i, 2] * g2
    return 0.5 * en


def corot_tables(X, conn, dN, geo, wdet, elem_mat, params, elems):
    """Tables of the corotational path (:func:`corot_local`, :func:`corot_global`,
    :func:`corot_damaging`) for the elements ``elems``.

    One table per distinct (geometry table, material) pair. ``X`` (n_nodes, 3) m; ``conn``,
    ``dN``, ``geo``, ``wdet`` as for :func:`.forces.hex_forces`; ``elem_mat`` (ne,) rows of
    ``params`` (nmat, NMP), whose ``MP_E``, ``MP_NU`` give the stiffness; ``elems`` int ids.

    Returns ``ke`` (nk, 24, 24) N/m, ``kbt`` (nk, 24, 48) 1/m, ``kxo`` (nk, 8, 3) m, ``kdn``
    (nk, 8, 3) 1/m and ``kid`` (ne,) int64: the table of each element, -1 outside ``elems``
    (those the force kernel must not be given: :func:`.forces.hex_forces` refuses them).
    ``kbt`` maps local displacements to the Gauss-point strains, ``strains[6 g + m] =
    sum_r d[r] kbt[r, 6 g + m]`` (Voigt, engineering shears); all zero for a table of an
    elastic material (never read).
    """
    ne = conn.shape[0]
    elems = np.asarray(elems, dtype=np.int64)
    kid = np.full(ne, -1, dtype=np.int64)
    pair = np.stack([geo[elems], elem_mat[elems]], axis=1).reshape(-1, 2)
    _, first, inv = np.unique(pair, axis=0, return_index=True, return_inverse=True)
    kid[elems] = inv.ravel()
    nk = first.size
    ke = np.empty((nk, 24, 24))
    kbt = np.zeros((nk, 24, 48))
    kxo = np.empty((nk, 8, 3))
    kdn = np.empty((nk, 8, 3))
    for k, j in enumerate(first):
        e = elems[j]
        t = geo[e]
        p = params[elem_mat[e]]
        hex_stiffness(dN[t], wdet[e], p[MP_E], p[MP_NU], ke[k])
        if p[MP_ELASTIC] != 1.0:
            strain_operator(dN[t], kbt[k])
        kxo[k] = X[conn[e]] - X[conn[e, 0]]
        kdn[k] = np.einsum("g,gai->ai", wdet[e], dN[t]) / wdet[e].sum()
    return ke, kbt, kxo, kdn, kid


def strain_operator(dne, kbt):
    """Write the transposed strain-displacement matrices of the 8 Gauss points into ``kbt``
    (24, 48) 1/m: column 6 g + m is strain m (Voigt [xx, yy, zz, yz, xz, xy], engineering
    shears) of point g, row 3 a + i displacement i of node a; ``dne`` (8, 8, 3) 1/m."""
    for g in range(8):
        for a in range(8):
            d0, d1, d2 = dne[g, a]
            c = 6 * g
            r = 3 * a
            kbt[r, c] = d0
            kbt[r + 1, c + 1] = d1
            kbt[r + 2, c + 2] = d2
            kbt[r + 1, c + 3], kbt[r + 2, c + 3] = d2, d1
            kbt[r, c + 4], kbt[r + 2, c + 4] = d2, d0
            kbt[r, c + 5], kbt[r + 1, c + 5] = d1, d0


# ---------------------------------------------------------------------------- mass
def lumped_mass(conn, wdet, rho_elem, n_nodes):
    """Row-sum lumped nodal masses m_a = sum_e rho_e int N_a dV (kg), shape (n_nodes,).

    Equals rho V / 8 per corner for parallelepipeds; the total is rho V for any hexahedron.
    ``conn`` (ne, 8) int, ``wdet`` (ne, 8) m^3, ``rho_elem`` (ne,) kg/m^3.
    """
    rho = np.asarray(rho_elem, dtype=np.float64)
    if rho.shape != (wdet.shape[0],) or not np.all(rho > 0.0) or not np.all(np.isfinite(rho)):
        raise HexMeshError(f"rho_elem must be ({wdet.shape[0]},) positive finite densities, got "
                           f"shape {rho.shape}, min {rho.min() if rho.size else None}")
    me = rho[:, None] * (wdet @ N_GAUSS)
    return np.bincount(np.asarray(conn).ravel(), weights=me.ravel(), minlength=n_nodes)


# ---------------------------------------------------------------------------- stiffness
@jit
def hex_stiffness(dne, we, E, nu, ke):
    """Linear elastic stiffness ``ke`` (24, 24) N/m of one element at the reference state.

    ``dne`` (8, 8, 3) 1/m, ``we`` (8,) m^3 of the element; ``E`` Pa, ``nu``. Dof order 3 a + i.
    K_ai,bj = sum_g w (lam dN_a,i dN_b,j + mu dN_a,j dN_b,i + mu delta_ij dN_a . dN_b).
    """
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = 0.5 * E / (1.0 + nu)
    ke[:, :] = 0.0
    for g in range(8):
        w = we[g]
        for a in range(8):
            for b in range(8):
                dd = mu * (dne[g, a, 0] * dne[g, b, 0] + dne[g, a, 1] * dne[g, b, 1]
                           + dne[g, a, 2] * dne[g, b, 2])
                for i in range(3):
                    ke[3 * a + i, 3 * b + i] += w * dd
                    for j in range(3):
                        ke[3 * a + i, 3 * b + j] += w * (lam * dne[g, a, i] * dne[g, b, j]
                                                         + mu * dne[g, a, j] * dne[g, b, i])


@pjit
def _stiffness_rowsum_elem(dN, geo, wdet, E, nu, r):
    """Per element corner bound ``r`` (ne, 8): max over the corner's 3 dofs of sum_j |K_ij|."""
    ne = wdet.shape[0]
    for e in prange(ne):
        ke = np.empty((24, 24))
        hex_stiffness(dN[geo[e]], wdet[e], E[e], nu[e], ke)
        for a in range(8):
            best = 0.0
            for i in range(3):
                s = 0.0
                for j in range(24):
                    s += abs(ke[3 * a + i, j])
                best = max(best, s)
            r[e, a] = best


def stiffness_rowsum(conn, dN, geo, wdet, E, nu, n_nodes):
    """Gershgorin bound of the assembled linear stiffness per node (N/m), shape (n_nodes,).

    For each element, the absolute row sums of its 24x24 reference stiffness, max over the
    node's 3 dofs, summed over the node's elements: bounds every row sum of the assembled K.
    ``dN``, ``wdet``, ``geo`` as for :func:`.forces.hex_forces`; ``E`` (ne,) Pa and ``nu`` (ne,) per
    element.
    """
    ne = wdet.shape[0]
    geo = np.ascontiguousarray(geo, dtype=np.int64)
    if geo.shape != (ne,) or (ne and (geo.min() < 0 or geo.max() >= dN.shape[0])):
        raise HexMeshError(f"geo must be ({ne},) table ids in [0, {dN.shape[0]}), got shape "
                           f"{geo.shape}")
    E = np.ascontiguousarray(E, dtype=np.float64)
    nu = np.ascontiguousarray(nu, dtype=np.float64)
    if E.shape != (ne,) or not np.all(E > 0.0) or not np.all(np.isfinite(E)):
        raise HexMeshError(f"E must be ({ne},) positive finite Young's moduli, got shape "
                           f"{E.shape}")
    if nu.shape != (ne,) or not np.all((nu > -1.0) & (nu < 0.5)):
        raise HexMeshError(f"nu must be ({ne},) Poisson ratios in (-1, 0.5), got shape "
                           f"{nu.shape}")
    r = np.empty((ne, 8))
    _stiffness_rowsum_elem(dN, geo, wdet, E, nu, r)
    return np.bincount(np.asarray(conn).ravel(), weights=r.ravel(), minlength=n_nodes)

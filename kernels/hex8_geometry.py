"""8-node hexahedron: corners and shape functions, the 2x2x2 Gauss rule, the reference-geometry
tables (``dN``, ``wdet``, shared between elements equal up to a translation), the displacement
gradient, lumped mass and the stiffness bound.

Conventions (corner order, Gauss rule, table layout) are those of :mod:`dr_masonry.kernels.hex8`.
"""
import numpy as np

from .config import ijit, jit, pjit, prange

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


# ---------------------------------------------------------------------------- gradient
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

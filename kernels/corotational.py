"""Corotational 8-node hexahedron: the polar rotation of an element's mean deformation gradient,
the local displacements in the rotated frame and the forces rotated back, and the per-element
tables (stiffness, strain operator) a run computes elements from.

Conventions are those of :mod:`dr_masonry.kernels.hex8`; the element forces that use these
functions are there.
"""
import numpy as np

from .config import ijit
from .hex8_geometry import displacement_gradient, hex_stiffness, inverse_transpose3
from .plastic_damage import MP_E, MP_ELASTIC, MP_NU

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

"""Slow numpy reference of the total-Lagrangian hexahedron with a St.Venant-Kirchhoff law.

Written independently of ``kernels/hex8.py``: Voigt B-matrix form of the virtual work
(f = sum_g w B(F)^T S), strain from F^T F, Gauss rules built from numpy's Legendre nodes.
"""
import numpy as np

CORNERS = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                    [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=float)


def gauss_points(n):
    """Tensor Gauss rule on [-1, 1]^3: points (n^3, 3) and weights (n^3,)."""
    x, w = np.polynomial.legendre.leggauss(n)
    pts = np.array([[a, b, c] for c in x for b in x for a in x])
    wts = np.array([wa * wb * wc for wc in w for wb in w for wa in w])
    return pts, wts


def kernel_gauss_points():
    """The 2x2x2 rule in the kernel's point order (point g at corner g / sqrt(3))."""
    return CORNERS / np.sqrt(3.0), np.ones(8)


def shape(p):
    """Shape functions (8,) at natural point p (3,)."""
    return np.array([0.125 * (1 + c[0] * p[0]) * (1 + c[1] * p[1]) * (1 + c[2] * p[2])
                     for c in CORNERS])


def dshape_nat(p):
    """dN_a/dxi_k (8, 3) at p by numerical differentiation of the exact (trilinear) shape."""
    d = np.zeros((8, 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1.0
        d[:, k] = 0.5 * (shape(p + e) - shape(p - e))  # exact: linear in each coordinate
    return d


def geometry(xe, pts=None):
    """dN/dX (ng, 8, 3) and weight x detJ (ng,) of one element with corners xe (8, 3)."""
    if pts is None:
        pts, wts = kernel_gauss_points()
    else:
        pts, wts = pts
    dn = np.empty((len(pts), 8, 3))
    wd = np.empty(len(pts))
    for g, p in enumerate(pts):
        dnat = dshape_nat(p)
        J = xe.T @ dnat  # J[i, k] = dX_i / dxi_k
        dn[g] = dnat @ np.linalg.inv(J)
        wd[g] = wts[g] * np.linalg.det(J)
    return dn, wd


def svk_D(E, nu):
    """Isotropic elasticity matrix (6, 6) for Voigt [xx, yy, zz, yz, xz, xy], engineering shears."""
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E / (2 * (1 + nu))
    D = np.zeros((6, 6))
    D[:3, :3] = lam
    D[[0, 1, 2], [0, 1, 2]] += 2 * mu
    D[[3, 4, 5], [3, 4, 5]] = mu
    return D


def green_voigt(F):
    """Green-Lagrange strain of F in Voigt order, engineering shears."""
    Et = 0.5 * (F.T @ F - np.eye(3))
    return np.array([Et[0, 0], Et[1, 1], Et[2, 2], 2 * Et[1, 2], 2 * Et[0, 2], 2 * Et[0, 1]])


def b_matrix(F, dn):
    """Nonlinear strain-displacement matrix (6, 24): dE_voigt = B du."""
    B = np.zeros((6, 24))
    for a in range(8):
        for i in range(3):
            c = 3 * a + i
            B[0, c] = F[i, 0] * dn[a, 0]
            B[1, c] = F[i, 1] * dn[a, 1]
            B[2, c] = F[i, 2] * dn[a, 2]
            B[3, c] = F[i, 1] * dn[a, 2] + F[i, 2] * dn[a, 1]
            B[4, c] = F[i, 0] * dn[a, 2] + F[i, 2] * dn[a, 0]
            B[5, c] = F[i, 0] * dn[a, 1] + F[i, 1] * dn[a, 0]
    return B


def element_forces(xe, ue, E, nu):
    """Internal forces (8, 3), stored energy, Gauss strains (8, 6) and stresses (8, 6) (SVK)."""
    dn, wd = geometry(xe)
    D = svk_D(E, nu)
    f = np.zeros(24)
    energy = 0.0
    strains, stresses = np.zeros((8, 6)), np.zeros((8, 6))
    for g in range(8):
        F = np.eye(3) + ue.T @ dn[g]
        Ev = green_voigt(F)
        S = D @ Ev
        f += wd[g] * b_matrix(F, dn[g]).T @ S
        energy += wd[g] * 0.5 * S @ Ev
        strains[g], stresses[g] = Ev, S
    return f.reshape(8, 3), energy, strains, stresses


def element_stiffness(xe, E, nu):
    """Linear stiffness (24, 24) at the reference configuration."""
    dn, wd = geometry(xe)
    D = svk_D(E, nu)
    return sum(wd[g] * b_matrix(np.eye(3), dn[g]).T @ D @ b_matrix(np.eye(3), dn[g])
               for g in range(8))


def element_mass(xe, rho):
    """Row sums of the consistent mass matrix (8,), 3x3x3 Gauss rule."""
    pts, wts = gauss_points(3)
    m = np.zeros(8)
    for p, w in zip(pts, wts):
        J = xe.T @ dshape_nat(p)
        N = shape(p)
        m += rho * w * np.linalg.det(J) * N * N.sum()
    return m

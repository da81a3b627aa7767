"""Geometry of one node-to-face contact pair: the master point and its local frame.

The master face is a bilinear quad with nodes ``xq`` (4, 3) ordered so that its normal points out
of the master block (towards the slave); natural coordinates (r, s) in [-1, 1]^2 with corners
(-1,-1), (1,-1), (1,1), (-1,1). At (r, s): a1 = dx/dr, a2 = dx/ds, n = a1 x a2 / |a1 x a2|,
t1 = a1 / |a1|, t2 = n x t1. The local gap of slave position ``xs`` is
[u, d1, d2] = [(xs - xm) . n, (xs - xm) . t1, (xs - xm) . t2] (m), u > 0 opening.
"""
import numpy as np

from .config import ijit, jit


@ijit
def quad_shape(r, s):
    """Bilinear shape functions (N0, N1, N2, N3) of a quad at (r, s), as four scalars.

    The numpy code calls ``plain(quad_shape)`` with arrays ``r``, ``s`` (n,): four (n,) arrays.
    """
    return (0.25 * (1.0 - r) * (1.0 - s), 0.25 * (1.0 + r) * (1.0 - s),
            0.25 * (1.0 + r) * (1.0 + s), 0.25 * (1.0 - r) * (1.0 + s))


@ijit
def quad_dshape(r, s):
    """Natural derivatives of :func:`quad_shape` at (r, s): ((dN0/dr, .., dN3/dr),
    (dN0/ds, .., dN3/ds)), two tuples of four scalars (``plain(quad_dshape)``: of (n,) arrays).
    """
    return ((-0.25 * (1.0 - s), 0.25 * (1.0 - s), 0.25 * (1.0 + s), -0.25 * (1.0 + s)),
            (-0.25 * (1.0 - r), -0.25 * (1.0 + r), 0.25 * (1.0 + r), 0.25 * (1.0 - r)))


@ijit
def quad_tangents(xq, r, s):
    """Tangents a1 = dx/dr and a2 = dx/ds (m per unit natural length) of quad ``xq`` (4, 3) at
    (r, s), as six scalars (a1x, a1y, a1z, a2x, a2y, a2z): no allocation in the hot loop.

    Summed over the edges (a1 from x1 - x0 and x2 - x3), not as sum_a dN_a x_a: the two differ in
    rounding. The numpy code passes quads (n, 4, 3) as ``np.moveaxis(xq, 0, -1)`` (4, 3, n) to
    ``plain(quad_tangents)`` with (n,) arrays ``r``, ``s``: six (n,) arrays."""
    a10 = 0.25 * ((1.0 - s) * (xq[1, 0] - xq[0, 0]) + (1.0 + s) * (xq[2, 0] - xq[3, 0]))
    a11 = 0.25 * ((1.0 - s) * (xq[1, 1] - xq[0, 1]) + (1.0 + s) * (xq[2, 1] - xq[3, 1]))
    a12 = 0.25 * ((1.0 - s) * (xq[1, 2] - xq[0, 2]) + (1.0 + s) * (xq[2, 2] - xq[3, 2]))
    a20 = 0.25 * ((1.0 - r) * (xq[3, 0] - xq[0, 0]) + (1.0 + r) * (xq[2, 0] - xq[1, 0]))
    a21 = 0.25 * ((1.0 - r) * (xq[3, 1] - xq[0, 1]) + (1.0 + r) * (xq[2, 1] - xq[1, 1]))
    a22 = 0.25 * ((1.0 - r) * (xq[3, 2] - xq[0, 2]) + (1.0 + r) * (xq[2, 2] - xq[1, 2]))
    return a10, a11, a12, a20, a21, a22


@ijit
def contact_frame(xq, r, s, xm, frame):
    """Master point ``xm`` (3,) and frame rows [n, t1, t2] ``frame`` (3, 3) of quad ``xq`` (4, 3) at (r, s).

    Returns the area Jacobian |a1 x a2| (m^2 per unit natural area).
    """
    n0, n1, n2, n3 = quad_shape(r, s)
    for k in range(3):
        xm[k] = n0 * xq[0, k] + n1 * xq[1, k] + n2 * xq[2, k] + n3 * xq[3, k]
    a10, a11, a12, a20, a21, a22 = quad_tangents(xq, r, s)
    nx = a11 * a22 - a12 * a21
    ny = a12 * a20 - a10 * a22
    nz = a10 * a21 - a11 * a20
    jac = np.sqrt(nx * nx + ny * ny + nz * nz)
    la1 = np.sqrt(a10 * a10 + a11 * a11 + a12 * a12)
    frame[0, 0] = nx / jac
    frame[0, 1] = ny / jac
    frame[0, 2] = nz / jac
    frame[1, 0] = a10 / la1
    frame[1, 1] = a11 / la1
    frame[1, 2] = a12 / la1
    frame[2, 0] = frame[0, 1] * frame[1, 2] - frame[0, 2] * frame[1, 1]
    frame[2, 1] = frame[0, 2] * frame[1, 0] - frame[0, 0] * frame[1, 2]
    frame[2, 2] = frame[0, 0] * frame[1, 1] - frame[0, 1] * frame[1, 0]
    return jac


@ijit
def frame_gap(xs, xm, frame, a):
    """Component ``a`` of the local gap, (xs - xm) . frame[a] (m), of slave point ``xs`` (3,)
    against master point ``xm`` (3,) in the frame rows ``frame`` (3, 3) of :func:`contact_frame`."""
    return ((xs[0] - xm[0]) * frame[a, 0] + (xs[1] - xm[1]) * frame[a, 1]
            + (xs[2] - xm[2]) * frame[a, 2])


@jit
def local_gap(xs, xq, r, s, gap):
    """Local gap ``gap`` (3,) = [u, d1, d2] (m) of slave point ``xs`` against quad ``xq`` at (r, s)."""
    xm = np.empty(3)
    frame = np.empty((3, 3))
    contact_frame(xq, r, s, xm, frame)
    for a in range(3):
        gap[a] = frame_gap(xs, xm, frame, a)

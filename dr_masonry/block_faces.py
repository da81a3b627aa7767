"""Geometry of block faces and of bilinear quads, for contact detection and sliding.

Block faces of a :class:`~dr_masonry.model.Model` (corner tables, centres, outward normals, areas,
grid sizes), in-plane coordinates and batched clipping of polygons against convex quads, the
closest point on a bilinear quad (natural coordinates), the canonical node order of master quads,
element sizes, and the master block face of a contact with the distance a slave node overhangs it.
Lengths in m, areas in m^2.
"""
from __future__ import annotations

import numpy as np

from .kernels.config import plain
from .kernels.contact_frame import quad_shape, quad_tangents
from .model import (BLOCK_FACES, HEX_NATURAL, block_corner_nodes, grid_index, quad_area_vector,
                    quad_normal)


# ---------------------------------------------------------------------------- block faces
def _face_tables():
    """(6, 4) VTK corner ids of each block face in its grid order and (6, 2) its grid axes."""
    corners = np.empty((6, 4), np.int64)
    axes = np.empty((6, 2), np.int64)
    for f, (axis, side) in enumerate(BLOCK_FACES):
        u, v = (a for a in range(3) if a != axis)
        axes[f] = (u, v)
        for k, (su, sv) in enumerate(((-1, -1), (1, -1), (1, 1), (-1, 1))):
            nat = np.zeros(3)
            nat[[axis, u, v]] = side, su, sv
            corners[f, k] = np.flatnonzero((HEX_NATURAL == nat).all(axis=1))[0]
    return corners, axes


FACE_CORNERS, FACE_AXES = _face_tables()


def _faces(model, x):
    """Geometry of all 6 * n_blocks block faces (face id = 6 * block + f) at coordinates ``x``.

    Returns a dict of arrays: ``nodes`` (nf, 4) corner node ids in grid order, ``X`` (nf, 4, 3)
    their coordinates (m), ``centre`` (nf, 3), ``normal`` (nf, 3) unit outward, ``area`` (nf,) m^2,
    ``radius`` (nf,) m (largest centre-corner distance), ``block`` (nf,), ``dims`` (nf, 2) element
    divisions of the face grid.
    """
    nb = model.n_blocks
    div = model.block_divisions
    cnode = block_corner_nodes(model.block_node_start[:-1], div)             # (nb, 8)
    nodes = cnode[:, FACE_CORNERS].reshape(6 * nb, 4)
    X = x[nodes]
    centre = X.mean(axis=1)
    nrm = quad_area_vector(X)
    area = np.linalg.norm(nrm, axis=1)
    nrm /= area[:, None]
    block_centre = np.repeat(x[cnode].mean(axis=1), 6, axis=0)
    nrm *= np.where(np.einsum("ij,ij->i", nrm, centre - block_centre) < 0, -1.0, 1.0)[:, None]
    return {"nodes": nodes, "X": X, "centre": centre, "normal": nrm, "area": area,
            "radius": np.linalg.norm(X - centre[:, None], axis=2).max(axis=1),
            "block": np.repeat(np.arange(nb, dtype=np.int64), 6),
            "dims": div[:, FACE_AXES].reshape(6 * nb, 2)}


# ---------------------------------------------------------------------------- planar clipping
def _plane_frame(F, fid):
    """Origin (n, 3) and in-plane unit axes e1, e2 (n, 3) of faces ``fid`` (e1 x e2 = normal)."""
    n = F["normal"][fid]
    e1 = F["X"][fid, 1] - F["X"][fid, 0]
    e1 -= np.einsum("ij,ij->i", e1, n)[:, None] * n
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    return F["centre"][fid], e1, np.cross(n, e1)


def _to_plane(p, origin, e1, e2):
    """In-plane coordinates (..., 2) of points ``p`` (..., 3); frame arrays broadcast against p."""
    d = p - origin
    return np.stack([np.sum(d * e1, axis=-1), np.sum(d * e2, axis=-1)], axis=-1)


def _ccw(poly):
    """Polygons (n, k, 2) reordered counter-clockwise."""
    a = np.sum(poly[:, :, 0] * np.roll(poly[:, :, 1], -1, axis=1)
               - np.roll(poly[:, :, 0], -1, axis=1) * poly[:, :, 1], axis=1)
    return np.where((a < 0)[:, None, None], poly[:, ::-1], poly)


def clipped_area(subject, clip):
    """Areas (m^2) of polygons clipped against convex polygons (batched Sutherland-Hodgman).

    Parameters
    ----------
    subject : (n, k, 2) float64
        polygons (any orientation, simple; need not be convex).
    clip : (n, 4, 2) float64
        convex quadrilaterals, counter-clockwise.

    Returns
    -------
    (n,) float64, area of each subject inside its clip polygon.
    """
    n = subject.shape[0]
    if n == 0:
        return np.zeros(0)
    P = subject
    cnt = np.full(n, subject.shape[1])
    rows = np.arange(n)[:, None]
    for k in range(clip.shape[1]):
        a = clip[:, k, None, :]
        e = clip[:, (k + 1) % clip.shape[1], None, :] - a
        m = P.shape[1]
        idx = np.arange(m)[None, :]
        valid = idx < cnt[:, None]
        nxt = np.where(idx + 1 < cnt[:, None], idx + 1, 0)
        d = e[..., 1] * (P[..., 0] - a[..., 0]) - e[..., 0] * (P[..., 1] - a[..., 1])  # > 0 outside
        dn = d[rows, nxt]
        inside = d <= 0.0
        keep = inside & valid
        cross = (inside != (dn <= 0.0)) & valid
        t = np.where(cross, d / np.where(cross, d - dn, 1.0), 0.0)
        X = P + t[..., None] * (P[rows, nxt] - P)
        nout = keep.astype(np.int64) + cross
        pos = np.cumsum(nout, axis=1) - nout
        cnt = nout.sum(axis=1)
        Q = np.zeros((n, max(int(cnt.max()), 1), 2))
        r, c = np.nonzero(keep)
        Q[r, pos[r, c]] = P[r, c]
        r, c = np.nonzero(cross)
        Q[r, pos[r, c] + keep[r, c]] = X[r, c]
        P = Q
    P = np.where(np.arange(P.shape[1])[None, :, None] < cnt[:, None, None], P, P[:, :1])
    P = P - P[:, :1]
    Pn = np.roll(P, -1, axis=1)
    return 0.5 * np.abs(np.sum(P[..., 0] * Pn[..., 1] - Pn[..., 0] * P[..., 1], axis=1))


# ---------------------------------------------------------------------------- projection
def quad_points(xq, r, s):
    """Points (n, 3) m of bilinear quads ``xq`` (n, 4, 3) m at natural coordinates ``r``, ``s``
    (n,) (:func:`~.kernels.contact_frame.quad_shape`)."""
    n0, n1, n2, n3 = plain(quad_shape)(r, s)
    return (n0[:, None] * xq[:, 0] + n1[:, None] * xq[:, 1] + n2[:, None] * xq[:, 2]
            + n3[:, None] * xq[:, 3])


def project_bilinear(xq, p, iters=30):
    """Natural coordinates (r, s) of the closest point to ``p`` on bilinear quads ``xq``.

    Gauss-Newton on the bilinear map, not clamped (|r| > 1 means outside the quad).

    Parameters
    ----------
    xq : (n, 4, 3) float64, m
        quad corners, corner order (-1,-1), (1,-1), (1,1), (-1,1).
    p : (n, 3) float64, m
        points.

    Returns
    -------
    r, s : (n,) float64
    """
    r = np.zeros(p.shape[0])
    s = np.zeros(p.shape[0])
    xqt = np.ascontiguousarray(np.moveaxis(xq, 0, -1))   # (4, 3, n), for quad_tangents
    for _ in range(iters):
        tan = plain(quad_tangents)(xqt, r, s)
        a1 = np.column_stack(tan[:3])
        a2 = np.column_stack(tan[3:])
        res = quad_points(xq, r, s) - p
        g1 = np.einsum("ij,ij->i", a1, res)
        g2 = np.einsum("ij,ij->i", a2, res)
        j11 = np.einsum("ij,ij->i", a1, a1)
        j12 = np.einsum("ij,ij->i", a1, a2)
        j22 = np.einsum("ij,ij->i", a2, a2)
        det = j11 * j22 - j12 * j12
        dr = -(j22 * g1 - j12 * g2) / det
        ds = -(j11 * g2 - j12 * g1) / det
        r += dr
        s += ds
        if np.all(np.abs(dr) + np.abs(ds) < 1e-13):
            break
    return r, s


def _canonical_quads(quads, x, normal):
    """Cyclic shift of quads (n, 4) so that edge 0 -> 1 is closest to a reference tangent.

    The reference tangent is the global x axis projected on the plane of unit ``normal`` (n, 3),
    or the y axis where |normal_x| > 0.9; it depends on the normal only, so coplanar quads of
    different blocks get the same local frame.
    """
    ref = np.where((np.abs(normal[:, 0]) > 0.9)[:, None], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0])
    ref = ref - np.einsum("ij,ij->i", ref, normal)[:, None] * normal
    xq = x[quads]
    edges = np.roll(xq, -1, axis=1) - xq
    score = np.einsum("nkj,nj->nk", edges, ref) / np.linalg.norm(edges, axis=2)
    k = np.argmax(score, axis=1)
    return quads[np.arange(quads.shape[0])[:, None], (k[:, None] + np.arange(4)) % 4]


# ---------------------------------------------------------------------------- master sides
def element_edge(model):
    """Largest element edge (n_blocks,) m of every block, as built."""
    c = model.block_corners
    edge = np.stack([np.linalg.norm(c[:, 1] - c[:, 0], axis=1),
                     np.linalg.norm(c[:, 3] - c[:, 0], axis=1),
                     np.linalg.norm(c[:, 4] - c[:, 0], axis=1)], axis=1)
    return (edge / model.block_divisions).max(axis=1)


def _face_of_quads(model, blocks, quads):
    """Block face (0..5) of master quads (n, 4) of ``blocks`` (n,): the face holding all 4 nodes."""
    div = model.block_divisions[blocks]
    ijk = np.stack(grid_index(quads, model.block_node_start[blocks][:, None], div[:, 0, None],
                              div[:, 1, None]), axis=2)                          # (n, 4, 3)
    f = np.full(blocks.shape[0], -1, np.int64)
    for face, (axis, side) in enumerate(BLOCK_FACES):
        level = 0 if side < 0 else div[:, axis]
        f[(f < 0) & np.all(ijk[:, :, axis] == np.reshape(level, (-1, 1)), axis=1)] = face
    return f


def master_sides(model, contacts):
    """Corner node ids (nc, 4) of the master block face that holds each contact's master quad,
    in the face's grid order (a convex polygon, counter-clockwise about its normal)."""
    if contacts.n == 0:
        return np.zeros((0, 4), np.int64)
    mb = contacts.blocks[:, 1]
    face = _face_of_quads(model, mb, contacts.master)
    return _faces(model, model.nodes)["nodes"][6 * mb + face]


def overhang(x, slave, sides):
    """How far (nc,) m each slave node lies outside its master block face, in the face's plane.

    ``x`` (n_nodes, 3) m current coordinates, ``slave`` (nc,) node ids, ``sides`` (nc, 4) from
    :func:`master_sides`. 0 for a node over the face; otherwise the distance beyond the nearest
    violated edge line (a node that slid off its master block's face with no other face under
    it still pushes on it: :mod:`dr_masonry.sliding`).
    """
    q = x[sides]                                                   # (nc, 4, 3)
    n = quad_normal(q)
    p = x[slave]
    inside = np.full(slave.shape[0], np.inf)
    for e in range(4):
        edge = q[:, (e + 1) % 4] - q[:, e]
        sd = np.einsum("ij,ij->i", np.cross(edge, p - q[:, e]), n) / np.linalg.norm(edge, axis=1)
        inside = np.minimum(inside, sd)
    return np.maximum(0.0, -inside) + 0.0   # + 0.0: no -0.0

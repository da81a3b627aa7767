"""Automatic node-to-face contact detection between the blocks of a :class:`~dr_masonry.model.Model`.

Every pair of touching block faces (of different blocks, opposite normals, coplanar within
``tol``, positive overlap area) gets ONE one-sided set of contact points: the nodes of the slave
face against the element quads of the master face. A slave node gets one contact point per master
block face its tributary region (the union of its quarter-quads: node, adjacent edge midpoints,
quad centre) overlaps, with the clipped tributary area, so the areas of one slave face against
one master face sum to their overlap area (to round-off).

Choices (documented here once):

* Slave side: the face with the finer mesh (smaller element-face area); on a tie (relative
  difference below 1e-9) the face of the lower block id.
* Joint law of a pair: the law named by one of its blocks (``block_joint >= 0``); if both blocks
  name different laws, the law of the lower block id wins (independent of the slave/master
  choice, hence of the meshes); else ``model.default_joint``. No law at all raises
  :class:`ModelError` naming the two blocks.
* Pairs of two fixed blocks get no contact points.
* Master quads are stored with a canonical cyclic node order (normal out of the master block,
  first edge closest to a reference tangent fixed by the normal, see
  :func:`~dr_masonry.block_faces._canonical_quads`), so that coplanar master quads of different
  blocks share the local frame of ``kernels/contact_frame.py`` and a slip vector keeps its
  meaning when a node slides across.
* A slave node outside its master face (its tributary region only partly overlaps) is projected
  on the nearest master quad with (r, s) clamped to [-1, 1]; ``gap0`` holds the offset.
* Rows are sorted by slave node, then master block.

The geometry of block faces and bilinear quads (face tables, polygon clipping, projection, master
sides and overhang) is in :mod:`dr_masonry.block_faces`; ``clipped_area``, ``project_bilinear``,
``element_edge``, ``master_sides`` and ``overhang`` are imported here for the callers that name
this module.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from scipy.spatial import cKDTree

from .block_faces import (_canonical_quads, _ccw, _face_of_quads, _faces, _plane_frame, _to_plane,
                          clipped_area, element_edge, master_sides, overhang, project_bilinear,
                          quad_points)  # noqa: F401 (master_sides, overhang: re-exported)
from .kernels.contact_frame import local_gap
from .model import ModelError, quad_normal

#: default coplanarity / separation tolerance relative to the model size (bounding-box diagonal)
REL_TOL = 1e-6
#: default angle tolerance (rad) for two faces to count as opposite
ANGLE_TOL = 1e-3
#: clipped areas below this fraction of the slave element-face area are round-off (dropped)
AREA_TOL = 1e-12
#: slack on the natural coordinates before a slid slave node is re-assigned by :func:`redetect`
SLIDE_SLACK = 1e-3


@dataclass
class ContactSet:
    """Node-to-face contact points (layout of docs/internals.md).

    Attributes
    ----------
    slave : (nc,) int64
        slave node id.
    master : (nc, 4) int64
        node ids of the master element quad, normal pointing out of the master block.
    xi : (nc, 2) float64
        natural coordinates (r, s) in [-1, 1] of the slave node's projection on that quad.
    area : (nc,) float64, m^2
        tributary area of the contact point.
    law : (nc,) int64
        index into ``model.joint_laws``.
    blocks : (nc, 2) int64
        (slave block, master block).
    gap0 : (nc, 3) float64, m
        local gap [u, d1, d2] in the reference configuration (subtracted by the force kernel).
    """
    slave: np.ndarray
    master: np.ndarray
    xi: np.ndarray
    area: np.ndarray
    law: np.ndarray
    blocks: np.ndarray
    gap0: np.ndarray

    def __post_init__(self):
        for f in fields(self):
            a = np.ascontiguousarray(getattr(self, f.name),
                                     dtype=np.float64 if f.name in ("xi", "area", "gap0") else np.int64)
            setattr(self, f.name, a)
        n = self.slave.shape[0]
        shapes = {"slave": (n,), "master": (n, 4), "xi": (n, 2), "area": (n,), "law": (n,),
                  "blocks": (n, 2), "gap0": (n, 3)}
        for name, shape in shapes.items():
            if getattr(self, name).shape != shape:
                raise ValueError(f"ContactSet.{name}: shape {getattr(self, name).shape}, "
                                 f"expected {shape}")

    @property
    def n(self):
        """Number of contact points."""
        return self.slave.shape[0]

    def subset(self, mask):
        """The contact points selected by ``mask`` (bool (nc,) or an index array) as a new set."""
        return ContactSet(**{f.name: getattr(self, f.name)[mask] for f in fields(self)})

    @classmethod
    def empty(cls):
        """A set with no contact points."""
        return cls(np.zeros(0), np.zeros((0, 4)), np.zeros((0, 2)), np.zeros(0), np.zeros(0),
                   np.zeros((0, 2)), np.zeros((0, 3)))


# ---------------------------------------------------------------------------- candidate face pairs


def _ball_pairs(tree, centre, radius, ids):
    """Pairs (i, tree index j) for points ``centre`` (k, 3) of faces ``ids`` within ``radius`` (k,)."""
    hits = tree.query_ball_point(centre, radius)
    cnt = np.fromiter((len(h) for h in hits), np.int64, len(hits))
    if cnt.sum() == 0:
        return np.zeros((0, 2), np.int64)
    return np.column_stack([np.repeat(ids, cnt), np.concatenate(hits).astype(np.int64)])


def _small_radius(radius):
    """Largest radius (m) of a "small" face: 1.25 x the 90 % quantile of the face radii."""
    return 1.25 * float(np.quantile(radius, 0.9))


def _candidate_pairs(centre, radius, tol):
    """Face pairs (i < j) whose bounding spheres (``radius`` + ``tol``) intersect, (np, 2).

    Small faces (:func:`_small_radius`, the bricks) pair through one fixed-radius query; the few
    larger faces (slabs, beams, foundations) query individually.
    """
    tree = cKDTree(centre)
    r_cut = _small_radius(radius)
    pairs = [tree.query_pairs(2.0 * r_cut + tol, output_type="ndarray").astype(np.int64)]
    large = np.flatnonzero(radius > r_cut)
    if large.size:
        pairs.append(_ball_pairs(tree, centre[large], radius[large] + r_cut + tol, large))
        ltree = cKDTree(centre[large])
        pl = _ball_pairs(ltree, centre[large], radius[large] + radius[large].max() + tol, large)
        pairs.append(np.column_stack([pl[:, 0], large[pl[:, 1]]]))
    p = np.sort(np.vstack(pairs), axis=1)
    key = np.sort(p[:, 0] * centre.shape[0] + p[:, 1])
    key = key[np.r_[True, key[1:] != key[:-1]]]
    p = np.column_stack([key // centre.shape[0], key % centre.shape[0]])
    p = p[p[:, 0] != p[:, 1]]
    d = np.linalg.norm(centre[p[:, 0]] - centre[p[:, 1]], axis=1)
    return p[d <= radius[p[:, 0]] + radius[p[:, 1]] + tol]


# ---------------------------------------------------------------------------- master quads and laws


def _locate(model, F, fid, p, x, slack):
    """Master quad and its (r, s) for points ``p`` (n, 3) on block faces ``fid`` (n,) at ``x``.

    Returns ``quads`` (n, 4) canonical node ids, ``xi`` (n, 2) clamped to [-1, 1], and
    ``outside`` (n,) the in-plane distance (m) of the point outside its face (0 inside, within
    ``slack`` on the face's natural coordinates).
    """
    R, S = project_bilinear(F["X"][fid], p)
    dims = F["dims"][fid]
    i = np.clip(np.floor((R + 1.0) * 0.5 * dims[:, 0]).astype(np.int64), 0, dims[:, 0] - 1)
    j = np.clip(np.floor((S + 1.0) * 0.5 * dims[:, 1]).astype(np.int64), 0, dims[:, 1] - 1)
    faces, inv = np.unique(fid, return_inverse=True)
    fq = [model.block_face(f // 6, f % 6)[1] for f in faces]
    offset = np.cumsum([0] + [q.shape[0] for q in fq])[:-1]
    quads = np.concatenate(fq)[offset[inv] + i * dims[:, 1] + j]
    quads = _canonical_quads(quads, x, F["normal"][fid])
    r, s = project_bilinear(x[quads], p)
    Rc, Sc = np.clip(R, -1.0, 1.0), np.clip(S, -1.0, 1.0)
    dp = p - quad_points(F["X"][fid], Rc, Sc)
    dp -= np.einsum("ij,ij->i", dp, F["normal"][fid])[:, None] * F["normal"][fid]
    inside = (np.abs(R) <= 1.0 + slack) & (np.abs(S) <= 1.0 + slack)
    outside = np.where(inside, 0.0, np.linalg.norm(dp, axis=1))
    return quads, np.column_stack([np.clip(r, -1.0, 1.0), np.clip(s, -1.0, 1.0)]), outside


def local_gaps(x, slave, master, xi):
    """Local gaps (nc, 3) [u, d1, d2] (m) from ``kernels.contact_frame.local_gap``."""
    g = np.empty((slave.shape[0], 3))
    xs = x[slave]
    xq = x[master]
    for c in range(slave.shape[0]):
        local_gap(xs[c], xq[c], xi[c, 0], xi[c, 1], g[c])
    return g


def _laws(model, bs, bm):
    """Joint-law index of block pairs (slave ``bs``, master ``bm``), see the module notes."""
    bj = model.block_joint
    js, jm = bj[bs], bj[bm]
    both = (js >= 0) & (jm >= 0)
    law = np.where(both, np.where(bs < bm, js, jm),
                   np.where(js >= 0, js, np.where(jm >= 0, jm, model.default_joint)))
    if np.any(law < 0):
        k = int(np.flatnonzero(law < 0)[0])
        raise ModelError(f"blocks {int(bs[k])} and {int(bm[k])} touch but no joint law is given: "
                         "call Model.set_joint_law(...) or give a block joint")
    return law.astype(np.int64)


# ---------------------------------------------------------------------------- detection
def _quarter_quads(uv):
    """Quarter-quads of a stack of face grids ``uv`` (P, m1+1, m2+1, 2).

    Returns polygons (P, m1, m2, 4, 4, 2) and the grid index (i, j) offsets (4, 2) of their owner
    node (corner 0 of each polygon) relative to the element's (i, j).
    """
    c00, c10, c11, c01 = uv[:, :-1, :-1], uv[:, 1:, :-1], uv[:, 1:, 1:], uv[:, :-1, 1:]
    mid = 0.25 * (c00 + c10 + c11 + c01)
    ma, mb, mc, md = 0.5 * (c00 + c10), 0.5 * (c10 + c11), 0.5 * (c11 + c01), 0.5 * (c01 + c00)
    polys = np.stack([np.stack([c00, ma, mid, md], axis=-2), np.stack([c10, mb, mid, ma], axis=-2),
                      np.stack([c11, mc, mid, mb], axis=-2), np.stack([c01, md, mid, mc], axis=-2)],
                     axis=-3)
    return polys, np.array([[0, 0], [1, 0], [1, 1], [0, 1]])


def detect_contacts(model, tol=None, angle_tol=ANGLE_TOL):
    """Find all node-to-face contact points of ``model`` in its reference configuration.

    Sets ``model.contacts`` and returns it.

    Parameters
    ----------
    model : Model
    tol : float or None, m
        coplanarity tolerance: two opposite faces touch if their planes are at most ``tol``
        apart. None: ``REL_TOL`` (1e-6) times the diagonal of the model's bounding box (far above
        the round-off of generated geometry, far below any physical gap).
    angle_tol : float, rad
        two faces are opposite if the angle between one normal and the reverse of the other is
        below ``angle_tol``.

    Returns
    -------
    ContactSet
    """
    x = model.nodes
    if model.n_blocks < 2:
        model.contacts = ContactSet.empty()
        return model.contacts
    if tol is None:
        tol = REL_TOL * float(np.linalg.norm(np.ptp(x, axis=0)))
    if not (np.isfinite(tol) and tol >= 0.0):
        raise ModelError(f"detect_contacts: tol must be a finite length >= 0 m, got {tol}")
    if not (np.isfinite(angle_tol) and 0.0 <= angle_tol < 0.5 * np.pi):
        raise ModelError(f"detect_contacts: angle_tol must be in [0, pi/2) rad, got {angle_tol}")
    model.check_overlaps(tol)
    F = _faces(model, x)
    blk = F["block"]
    p = _candidate_pairs(F["centre"], F["radius"], tol)
    a, b = p[:, 0], p[:, 1]
    nrm, cen = F["normal"], F["centre"]
    fixed = model.block_fixed
    ok = ((blk[a] != blk[b]) & ~(fixed[blk[a]] & fixed[blk[b]])
          & (np.einsum("ij,ij->i", nrm[a], nrm[b]) < -np.cos(angle_tol))
          & (np.abs(np.einsum("ij,ij->i", cen[b] - cen[a], nrm[a])) <= tol)
          & (np.abs(np.einsum("ij,ij->i", cen[a] - cen[b], nrm[b])) <= tol))
    a, b = a[ok], b[ok]
    # slave = finer face mesh (smaller element-face area), tie -> lower block id
    h = F["area"] / F["dims"].prod(axis=1)
    ha, hb = h[a], h[b]
    tie = np.abs(ha - hb) <= 1e-9 * np.maximum(ha, hb)
    a_slave = np.where(tie, blk[a] < blk[b], ha < hb)
    fs, fm = np.where(a_slave, a, b), np.where(a_slave, b, a)
    # overlap of the two face polygons in the master plane
    org, e1, e2 = _plane_frame(F, fm)
    clip = _ccw(_to_plane(F["X"][fm], org[:, None], e1[:, None], e2[:, None]))
    overlap = clipped_area(_to_plane(F["X"][fs], org[:, None], e1[:, None], e2[:, None]), clip)
    keep = overlap > AREA_TOL * np.minimum(h[fs], h[fm])
    fs, fm, org, e1, e2, clip = fs[keep], fm[keep], org[keep], e1[keep], e2[keep], clip[keep]
    if fs.size == 0:
        model.contacts = ContactSet.empty()
        return model.contacts
    # tributary areas of the slave nodes, grouped by slave face grid shape
    rows_pair, rows_node, rows_area = [], [], []
    dims_s = F["dims"][fs]
    for m1, m2 in np.unique(dims_s, axis=0):
        g = np.flatnonzero((dims_s[:, 0] == m1) & (dims_s[:, 1] == m2))
        grids = np.stack([model.block_face(f // 6, f % 6)[0] for f in fs[g]])  # (P, m1+1, m2+1)
        uv = _to_plane(x[grids], org[g, None, None], e1[g, None, None], e2[g, None, None])
        polys, off = _quarter_quads(uv)
        P = g.size
        ii, jj = np.meshgrid(np.arange(m1), np.arange(m2), indexing="ij")
        owner = ((ii[..., None] + off[:, 0]) * (m2 + 1) + jj[..., None] + off[:, 1])  # (m1, m2, 4)
        cl = np.broadcast_to(clip[g, None, None, None], (P, m1, m2, 4, 4, 2))
        ar = clipped_area(polys.reshape(-1, 4, 2), cl.reshape(-1, 4, 2)).reshape(P, -1)
        ngrid = (m1 + 1) * (m2 + 1)
        key = (np.arange(P)[:, None] * ngrid + owner.reshape(1, -1)).ravel()
        node_area = np.bincount(key, weights=ar.ravel(), minlength=P * ngrid).reshape(P, ngrid)
        pp, nn = np.nonzero(node_area > AREA_TOL * h[fs[g]][:, None])
        rows_pair.append(g[pp])
        rows_node.append(grids.reshape(P, ngrid)[pp, nn])
        rows_area.append(node_area[pp, nn])
    pair = np.concatenate(rows_pair)
    slave = np.concatenate(rows_node)
    area = np.concatenate(rows_area)
    fmr = fm[pair]
    master, xi, _ = _locate(model, F, fmr, x[slave], x, SLIDE_SLACK)
    bl = np.column_stack([blk[fs[pair]], blk[fmr]])
    order = np.lexsort((bl[:, 1], slave))
    cs = ContactSet(slave[order], master[order], xi[order], area[order],
                    _laws(model, bl[order, 0], bl[order, 1]), bl[order], np.zeros((slave.size, 3)))
    cs.gap0 = local_gaps(x, cs.slave, cs.master, cs.xi)
    model.contacts = cs
    return cs


def redetect(model, contacts, x_current, slack=SLIDE_SLACK, reach=None, rows=None):
    """Re-assign slave nodes that slid off their master quad (finite sliding).

    A contact point whose slave node now projects outside its master quad (|r| or |s| >
    1 + ``slack``) moves to the quad of the block face (of any block but its own, facing the old
    master face) that now contains the projection and lies within ``reach`` along its normal,
    the nearest such face if several; its ``xi`` becomes the new projection and ``gap0`` is reset
    so that the local gap [u, d1, d2] seen by the force kernel is unchanged at the switch (the
    joint history carries over). If no face contains the projection, the point stays as it is
    while the projection is at most ``reach`` outside its old master face (its tributary region
    still overlaps), and is dropped beyond (the node has slid off the surface).

    Parameters
    ----------
    model : Model
    contacts : ContactSet
    x_current : (n_nodes, 3) float64, m
        current nodal coordinates.
    slack : float
        tolerance on the natural coordinates.
    reach : float or None, m
        normal and in-plane search distance; None: half the largest element edge of the slave
        block, per contact point.
    rows : (nc,) bool or None
        the rows that may be re-assigned (None: all); the others are kept as they are.

    Returns
    -------
    new : ContactSet
        the updated set (same row order, dropped rows removed).
    src : (new.n,) int64
        row of ``contacts`` each row of ``new`` comes from (carry the joint history with it).
    """
    x = np.asarray(x_current, dtype=np.float64)
    if x.shape != (model.n_nodes, 3) or not np.all(np.isfinite(x)):
        raise ModelError(f"redetect: x_current must be finite with shape ({model.n_nodes}, 3), "
                         f"got shape {x.shape}")
    nc = contacts.n
    src = np.arange(nc, dtype=np.int64)
    if nc == 0:
        return contacts, src
    xs = x[contacts.slave]
    cand = np.arange(nc) if rows is None else np.flatnonzero(np.asarray(rows, dtype=bool))
    r, s = project_bilinear(x[contacts.master[cand]], xs[cand])
    moved = cand[(np.abs(r) > 1.0 + slack) | (np.abs(s) > 1.0 + slack)]
    if moved.size == 0:
        return contacts, src
    bs = contacts.blocks[moved, 0]
    if reach is None:
        reach = 0.5 * element_edge(model)[bs]
    reach = np.broadcast_to(np.asarray(reach, dtype=np.float64), moved.shape)
    if not np.all(np.isfinite(reach) & (reach > 0)):
        raise ModelError(f"redetect: reach must be positive lengths (m), got {reach}")
    F = _faces(model, x)
    # normal of the old master quad, current configuration
    n_old = quad_normal(x[contacts.master[moved]])
    row, fid = _near_faces(F, xs[moved], reach)
    u = np.einsum("ij,ij->i", xs[moved][row] - F["centre"][fid], F["normal"][fid])
    ok = ((F["block"][fid] != bs[row]) & (np.einsum("ij,ij->i", F["normal"][fid], n_old[row]) > 0.5)
          & (np.abs(u) <= reach[row]))
    row, fid, u = row[ok], fid[ok], u[ok]
    R, S = project_bilinear(F["X"][fid], xs[moved][row])
    ok = (np.abs(R) <= 1.0 + slack) & (np.abs(S) <= 1.0 + slack)
    row, fid, u = row[ok], fid[ok], u[ok]
    best = np.lexsort((np.abs(u), row))
    row, fid = row[best], fid[best]
    first = np.ones(row.size, bool)
    first[1:] = row[1:] != row[:-1]
    row, fid = row[first], fid[first]
    new = contacts.subset(np.arange(nc))
    if row.size:
        k = moved[row]
        quads, xi, _ = _locate(model, F, fid, xs[k], x, slack)
        g_old = (local_gaps(x, contacts.slave[k], contacts.master[k], contacts.xi[k])
                 - contacts.gap0[k])
        new.master[k], new.xi[k] = quads, xi
        new.blocks[k, 1] = F["block"][fid]
        new.law[k] = _laws(model, new.blocks[k, 0], new.blocks[k, 1])
        new.gap0[k] = local_gaps(x, new.slave[k], quads, xi) - g_old
    # points no face took: keep while their old master face is within reach, else drop
    lost = np.setdiff1d(np.arange(moved.size), row)
    drop = np.zeros(nc, bool)
    if lost.size:
        k = moved[lost]
        fm = 6 * contacts.blocks[k, 1] + _face_of_quads(model, contacts.blocks[k, 1],
                                                        contacts.master[k])
        _, _, outside = _locate(model, F, fm, xs[k], x, slack)
        drop[k] = outside > reach[lost]
    keep = np.flatnonzero(~drop)
    return new.subset(keep), src[keep]


def _near_faces(F, p, reach):
    """Pairs (point row, face id) with point ``p`` (n, 3) within face radius + ``reach`` (n,)."""
    radius = F["radius"]
    r_cut = _small_radius(radius)
    pr = _ball_pairs(cKDTree(F["centre"]), p, r_cut + reach, np.arange(p.shape[0]))
    large = np.flatnonzero(radius > r_cut)
    pr = np.vstack([pr[radius[pr[:, 1]] <= r_cut],
                    np.column_stack([np.repeat(np.arange(p.shape[0]), large.size),
                                     np.tile(large, p.shape[0])])])
    d = np.linalg.norm(p[pr[:, 0]] - F["centre"][pr[:, 1]], axis=1)
    pr = pr[d <= radius[pr[:, 1]] + reach[pr[:, 0]]]
    return pr[:, 0], pr[:, 1]

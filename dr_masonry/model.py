"""The block assembly as arrays: nodes, hexahedra, blocks. No physics here.

Conventions
-----------
* SI units: coordinates in m.
* Global axes: x along a wall, y through its thickness, z up (gravity acts along -z).
* Hexahedron corner order is VTK's: corners 0-3 on the bottom face (natural zeta = -1)
  counter-clockwise seen from above, 4-7 above them. Natural coordinates of corner a are
  ``HEX_NATURAL[a]``.
* A block is meshed by the trilinear map of its 8 corners into ``nx * ny * nz`` hexahedra
  (``nx`` along natural xi = corner 0 -> 1, ``ny`` along eta = 0 -> 3, ``nz`` along zeta = 0 -> 4).
  Its nodes are numbered ``i + (nx+1) * (j + (ny+1) * k)`` from the block's first node
  (:func:`grid_node`, inverse :func:`grid_index`).
* Blocks share no nodes: every block owns a contiguous range of nodes and of elements.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .kernels.hex8 import CORNERS as HEX_NATURAL
from .kernels.hex8 import trilinear_shape

#: the six faces of a block: (natural axis 0/1/2 held fixed, side -1/+1)
BLOCK_FACES = ((2, -1), (2, 1), (1, -1), (1, 1), (0, -1), (0, 1))
#: corner indices (6, 4) of the faces of a hexahedron in ``BLOCK_FACES`` order, counter-clockwise
#: seen from outside (their :func:`quad_area_vector` points out)
HEX_FACE_CORNERS = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [2, 3, 7, 6],
                             [0, 4, 7, 3], [1, 2, 6, 5]])


def grid_node(start, nx, ny, i, j, k):
    """Global node id of grid point (i, j, k) of a block's structured grid: ``start + i +
    (nx+1) * (j + (ny+1) * k)``, with ``start`` the block's first node and (nx, ny) its
    divisions along xi and eta. Integer arguments or arrays that broadcast together."""
    return start + i + (nx + 1) * (j + (ny + 1) * k)


def grid_index(node, start, nx, ny):
    """Grid point (i, j, k) of global node id ``node`` of a block: the inverse of
    :func:`grid_node`, same arguments, three integer arrays of the broadcast shape."""
    loc = node - start
    return loc % (nx + 1), (loc // (nx + 1)) % (ny + 1), loc // ((nx + 1) * (ny + 1))


def block_corner_nodes(start, divisions):
    """Global node ids (nb, 8) int64 of the block corners in VTK hexahedron order, from the
    blocks' first nodes ``start`` (nb,) and their divisions (nb, 3)."""
    ijk = ((HEX_NATURAL + 1.0) * 0.5).astype(np.int64)[None] * divisions[:, None, :]  # (nb, 8, 3)
    return grid_node(start[:, None], divisions[:, None, 0], divisions[:, None, 1],
                     ijk[..., 0], ijk[..., 1], ijk[..., 2])


def quad_area_vector(q):
    """Area vector (..., 3) m^2 of quads ``q`` (..., 4, 3) m: half the cross product of the
    diagonals 0->2 and 1->3 (exact for warped quads too), along the normal about which
    corners 0-3 turn counter-clockwise."""
    return 0.5 * np.cross(q[..., 2, :] - q[..., 0, :], q[..., 3, :] - q[..., 1, :])


def quad_normal(q):
    """Unit normal (..., 3) of quads ``q`` (..., 4, 3): :func:`quad_area_vector` normalised."""
    av = quad_area_vector(q)
    return av / np.linalg.norm(av, axis=-1)[..., None]


def size_summary(n_blocks, n_elements, n_nodes, n_contacts):
    """One-line description of a model's size (of :meth:`Model.summary` and a results file's)."""
    return (f"{n_blocks} blocks, {n_elements} hexahedra, {n_nodes} nodes, "
            f"{n_contacts} contact points")


def id_array(what, ids, n, error=None):
    """``ids`` (one id or an iterable of them) as an int64 array, each an integer in [0, n);
    else ``error`` (default :class:`ModelError`) naming ``what`` and the first bad id. Negative
    ids are refused (numpy would count them from the end)."""
    error = error or ModelError
    a = np.atleast_1d(np.asarray(ids)).ravel()
    if a.dtype.kind in "iu":
        bad = (a < 0) | (a >= n)
    elif a.dtype.kind == "f":
        with np.errstate(invalid="ignore"):
            bad = ~np.isfinite(a) | (a != np.round(a)) | (a < 0) | (a >= n)
    else:   # bools, strings, objects: none of them is an id
        bad = np.ones(a.shape, dtype=bool)
    if bad.any():
        v = a[np.argmax(bad)]
        raise error(f"{what}: id {v.item() if hasattr(v, 'item') else v!r} is not an integer "
                    f"in [0, {n})")
    return a.astype(np.int64)


class ModelError(ValueError):
    """Invalid model input; the message names the block, parameter and value."""


#: the most hexahedra one block may have: a run relaxes about 10^6 element-steps per second on
#: 2 cores, so more is a typo in ``divisions`` (10^5 x 10^5 x 10^5 asked for 7 PiB of memory)
MAX_BLOCK_ELEMENTS = 10_000_000


def _numbers(what, value, shape):
    """``value`` as a float64 array of ``shape``; ModelError naming ``what`` when it is not."""
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ModelError(f"{what} must be numbers in m, got {value!r}") from None
    if a.shape != shape:
        raise ModelError(f"{what} must have shape {shape}, got {a.shape}: {value!r}")
    return a


def check_material(what, material, error=None):
    """``material`` if it looks like a PlasticDamage (has ``params_array``), else ``error``
    (default :class:`ModelError`) "<what> must be a PlasticDamage, got <material>"."""
    if material is None or not hasattr(material, "params_array"):
        raise (error or ModelError)(f"{what} must be a PlasticDamage, got {material!r}")
    return material


def trilinear_jacobian(corners, nat):
    """Jacobians dX/dnat (m, 3, 3) of the trilinear map of ``corners`` (8, 3) at ``nat`` (m, 3)."""
    nat = np.atleast_2d(nat)
    dn = np.empty((nat.shape[0], 8, 3))
    for a in range(3):
        fac = 1.0 + nat[:, None, :] * HEX_NATURAL[None, :, :]
        fac[:, :, a] = HEX_NATURAL[None, :, a]
        dn[:, :, a] = 0.125 * np.prod(fac, axis=2)
    return np.einsum("ai,mak->mik", corners, dn)


def box_corners(origin, size):
    """Corners (8, 3) of the axis-aligned box with minimum corner ``origin`` and edge lengths ``size``."""
    origin = np.asarray(origin, dtype=np.float64)
    size = np.asarray(size, dtype=np.float64)
    return origin + 0.5 * (HEX_NATURAL + 1.0) * size


def _inside_block(corners, pts, tol):
    """Which points (m, 3) lie inside the convex block ``corners`` (8, 3) by more than ``tol``."""
    q = corners[HEX_FACE_CORNERS]                               # (6, 4, 3)
    n = quad_area_vector(q)     # normal sign fixed by the centroid below (any corner order)
    fc = q.mean(axis=1)
    n *= np.sign(np.einsum("ij,ij->i", n, fc - corners.mean(axis=0)))[:, None]
    n /= np.linalg.norm(n, axis=1)[:, None]
    d = np.einsum("fk,mfk->mf", n, pts[:, None, :] - fc[None, :, :])
    return np.all(d < -tol, axis=1)


@dataclass
class Block:
    """One block: its node and element ranges and its properties (read-only view)."""
    index: int
    nodes: slice
    elements: slice
    divisions: tuple
    material: int
    fixed: bool
    joint: int
    group: str


@dataclass
class Model:
    """An assembly of blocks meshed by hexahedra, with its materials and joint laws.

    Arrays (built by :meth:`add_block`, read them through the properties):

    ``nodes`` (n_nodes, 3) float64, m
        reference coordinates.
    ``elements`` (n_elements, 8) int64
        global node ids of each hexahedron, VTK order.
    ``element_block`` (n_elements,) int64
        owning block.
    ``block_node_start`` / ``block_element_start`` (n_blocks + 1,) int64
        CSR offsets: block b owns nodes ``[start[b], start[b+1])``.
    ``block_divisions`` (n_blocks, 3) int64, ``block_corners`` (n_blocks, 8, 3) float64 m,
    ``block_material`` (n_blocks,) int64 index into ``materials``,
    ``block_fixed`` (n_blocks,) bool (all nodes of a fixed block are clamped),
    ``block_joint`` (n_blocks,) int64 index into ``joint_laws`` used for every contact of the
    block, or -1 for the model's default joint law.
    """
    materials: list = field(default_factory=list)
    joint_laws: list = field(default_factory=list)
    default_joint: int = -1
    groups: dict = field(default_factory=dict)
    contacts: object = None

    def __post_init__(self):
        self._node_chunks = []
        self._elem_chunks = []
        self._corners = []
        self._divisions = []
        self._material = []
        self._fixed = []
        self._joint = []
        self._group = []
        self._node_start = [0]
        self._elem_start = [0]
        self._cache = {}

    # ------------------------------------------------------------------ materials
    def _register(self, registry, item):
        for i, it in enumerate(registry):
            if it is item:
                return i
        registry.append(item)
        return len(registry) - 1

    def set_joint_law(self, law):
        """Set the default joint law for contacts between blocks that name none."""
        self.default_joint = self._register(self.joint_laws, law)
        return self.default_joint

    # ------------------------------------------------------------------ blocks
    def add_block(self, corners, material, divisions=(1, 1, 1), fixed=False, joint=None,
                  group="block"):
        """Add one block meshed by a trilinear map; returns its block id.

        Parameters
        ----------
        corners : (8, 3) array_like, m
            block corners in VTK hexahedron order (0-3 bottom, counter-clockwise from above).
        material : PlasticDamage
            block material.
        divisions : (nx, ny, nz) ints
            hexahedra along natural xi (corner 0->1), eta (0->3), zeta (0->4).
        fixed : bool
            clamp every node of the block (foundations).
        joint : JointLaw or None
            joint law of every contact this block takes part in (e.g. a tied beam interface);
            None uses the model's default joint law.
        group : str
            name of a block group (``"wall"``, ``"beam"``, ...), see :attr:`groups`.
        """
        b = len(self._corners)
        c = _numbers(f"block {b}: corners", corners, (8, 3))
        if not np.all(np.isfinite(c)):
            raise ModelError(f"block {b}: corners contain NaN or Inf: {c.tolist()}")
        div = tuple(np.atleast_1d(np.asarray(divisions, dtype=object)))
        if len(div) != 3 or any(isinstance(v, (bool, np.bool_)) or not isinstance(
                v, (int, np.integer)) or v < 1 for v in div):
            raise ModelError(f"block {b}: divisions must be three integers >= 1, got {divisions!r}")
        div = tuple(int(v) for v in div)
        if div[0] * div[1] * div[2] > MAX_BLOCK_ELEMENTS:
            raise ModelError(f"block {b}: divisions {div} make {div[0] * div[1] * div[2]:,} "
                             f"hexahedra, more than MAX_BLOCK_ELEMENTS = {MAX_BLOCK_ELEMENTS:,}")
        check_material(f"block {b}: material", material)
        if not isinstance(fixed, (bool, np.bool_)):
            raise ModelError(f"block {b}: fixed must be True or False, got {fixed!r}")
        self._check_corners(b, c)
        nx, ny, nz = div
        gi = np.linspace(-1.0, 1.0, nx + 1)
        gj = np.linspace(-1.0, 1.0, ny + 1)
        gk = np.linspace(-1.0, 1.0, nz + 1)
        kk, jj, ii = np.meshgrid(gk, gj, gi, indexing="ij")
        nat = np.column_stack([ii.ravel(), jj.ravel(), kk.ravel()])
        xyz = trilinear_shape(nat) @ c
        n0 = self._node_start[-1]
        i, j, k = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
        i, j, k = (a.transpose(2, 1, 0).ravel() for a in (i, j, k))

        def nid(a, bb, cc):
            return grid_node(n0, nx, ny, a, bb, cc)

        conn = np.column_stack([
            nid(i, j, k), nid(i + 1, j, k), nid(i + 1, j + 1, k), nid(i, j + 1, k),
            nid(i, j, k + 1), nid(i + 1, j, k + 1), nid(i + 1, j + 1, k + 1), nid(i, j + 1, k + 1)])
        self._node_chunks.append(xyz)
        self._elem_chunks.append(conn.astype(np.int64))
        self._corners.append(c)
        self._divisions.append(div)
        self._material.append(self._register(self.materials, material))
        self._fixed.append(bool(fixed))
        self._joint.append(-1 if joint is None else self._register(self.joint_laws, joint))
        self._group.append(group)
        self.groups.setdefault(group, []).append(b)
        self._node_start.append(n0 + xyz.shape[0])
        self._elem_start.append(self._elem_start[-1] + conn.shape[0])
        self._cache.clear()
        self.contacts = None
        return b

    def add_box(self, origin, size, material, divisions=(1, 1, 1), **kw):
        """Add an axis-aligned box block (minimum corner ``origin``, edge lengths ``size``, m)."""
        b = self.n_blocks
        origin = _numbers(f"block {b}: box origin", origin, (3,))
        size = _numbers(f"block {b}: box size", size, (3,))
        if not np.all(size > 0):
            raise ModelError(f"block {b}: box size must be 3 positive lengths, got {size}")
        return self.add_block(box_corners(origin, size), material, divisions, **kw)

    @staticmethod
    def _check_corners(b, c):
        scale = np.max(np.ptp(c, axis=0))
        if scale <= 0:
            raise ModelError(f"block {b}: all corners coincide")
        pts = np.vstack([HEX_NATURAL, np.zeros((1, 3))])
        det = np.linalg.det(trilinear_jacobian(c, pts)) * 8.0  # volume-like, m^3
        if np.any(det <= 1e-9 * scale ** 3):
            bad = int(np.argmin(det))
            where = f"corner {bad}" if bad < 8 else "centre"
            raise ModelError(
                f"block {b}: corners are inverted or degenerate (Jacobian {det[bad]:.3e} m^3 at "
                f"{where}); give corners 0-3 counter-clockwise seen from +z, 4-7 above them")

    # ------------------------------------------------------------------ arrays
    def _cat(self, key, fn):
        if key not in self._cache:
            self._cache[key] = fn()
        return self._cache[key]

    @property
    def n_blocks(self):
        return len(self._corners)

    @property
    def n_nodes(self):
        return self._node_start[-1]

    @property
    def n_elements(self):
        return self._elem_start[-1]

    @property
    def nodes(self):
        return self._cat("nodes", lambda: np.ascontiguousarray(
            np.vstack(self._node_chunks) if self._node_chunks else np.zeros((0, 3))))

    @property
    def elements(self):
        return self._cat("elements", lambda: np.ascontiguousarray(
            np.vstack(self._elem_chunks) if self._elem_chunks else np.zeros((0, 8), np.int64)))

    @property
    def block_node_start(self):
        return self._cat("bns", lambda: np.asarray(self._node_start, dtype=np.int64))

    @property
    def block_element_start(self):
        return self._cat("bes", lambda: np.asarray(self._elem_start, dtype=np.int64))

    @property
    def element_block(self):
        return self._cat("eb", lambda: np.repeat(
            np.arange(self.n_blocks, dtype=np.int64), np.diff(self.block_element_start)))

    @property
    def node_block(self):
        return self._cat("nb", lambda: np.repeat(
            np.arange(self.n_blocks, dtype=np.int64), np.diff(self.block_node_start)))

    @property
    def block_divisions(self):
        return self._cat("bd", lambda: np.asarray(self._divisions, dtype=np.int64).reshape(-1, 3))

    @property
    def block_corners(self):
        return self._cat("bc", lambda: np.asarray(self._corners, dtype=np.float64).reshape(-1, 8, 3))

    @property
    def block_material(self):
        return self._cat("bm", lambda: np.asarray(self._material, dtype=np.int64))

    @property
    def block_fixed(self):
        return self._cat("bf", lambda: np.asarray(self._fixed, dtype=bool))

    @property
    def block_joint(self):
        return self._cat("bj", lambda: np.asarray(self._joint, dtype=np.int64))

    @property
    def block_group(self):
        return list(self._group)

    def block(self, b):
        """A read-only :class:`Block` view of block ``b``."""
        if not (isinstance(b, (int, np.integer)) and not isinstance(b, (bool, np.bool_))
                and 0 <= b < self.n_blocks):
            raise ModelError(f"block {b!r} does not exist (model has {self.n_blocks} blocks)")
        s = self._node_start
        e = self._elem_start
        return Block(b, slice(s[b], s[b + 1]), slice(e[b], e[b + 1]), self._divisions[b],
                     self._material[b], self._fixed[b], self._joint[b], self._group[b])

    def block_nodes(self, blocks):
        """Global node ids (sorted int64 array) of one block id or an iterable of them."""
        blocks = id_array("block_nodes: block", blocks, self.n_blocks)
        s = self.block_node_start
        return np.concatenate([np.arange(s[b], s[b + 1]) for b in blocks]) if blocks.size \
            else np.zeros(0, np.int64)

    def block_face(self, b, f):
        """Surface mesh of face ``f`` (0..5, see ``BLOCK_FACES``) of block ``b``.

        Returns
        -------
        grid : (m1 + 1, m2 + 1) int64
            global node ids of the face nodes, a structured grid.
        quads : (m1 * m2, 4) int64
            global node ids of the element faces, ordered so that their normal points out of
            the block.
        """
        b = int(id_array("block_face: block", b, self.n_blocks)[0])
        f = int(id_array("block_face: face", f, len(BLOCK_FACES))[0])
        axis, side = BLOCK_FACES[f]
        nx, ny, nz = self._divisions[b]
        n0 = self._node_start[b]
        n = (nx + 1, ny + 1, nz + 1)
        idx = grid_node(n0, nx, ny, *np.indices(n, dtype=np.int64))   # (nx+1, ny+1, nz+1)
        fixed = 0 if side < 0 else n[axis] - 1
        grid = np.take(idx, fixed, axis=axis)
        q = np.column_stack([grid[:-1, :-1].ravel(), grid[1:, :-1].ravel(),
                             grid[1:, 1:].ravel(), grid[:-1, 1:].ravel()])
        x = self.nodes
        centre = x[n0:self._node_start[b + 1]].mean(axis=0)
        out = np.einsum("ij,ij->i", quad_area_vector(x[q]), x[q].mean(axis=1) - centre) < 0
        q[out] = q[out][:, ::-1]
        return grid, q

    def check_overlaps(self, tol):
        """Raise ModelError if two blocks overlap by more than ``tol`` (m).

        Candidates are pairs whose bounding boxes overlap by more than ``tol`` along every axis
        (touching blocks do not); for them, the nodes of each block, pulled 1e-3 of the way to
        its centroid, are tested against the face planes of the other (blocks are convex with
        planar faces).
        """
        from scipy.spatial import cKDTree
        if not (isinstance(tol, (int, float, np.integer, np.floating))
                and not isinstance(tol, (bool, np.bool_)) and np.isfinite(tol) and tol >= 0):
            raise ModelError(f"check_overlaps: tol={tol!r} must be a finite length >= 0 m")
        c = self.block_corners
        if c.shape[0] < 2:
            return
        lo, hi = c.min(axis=1), c.max(axis=1)
        centre = c.mean(axis=1)
        radius = float(np.linalg.norm(hi - lo, axis=1).max())
        pairs = cKDTree(centre).query_pairs(radius, output_type="ndarray")
        if pairs.size == 0:
            return
        a, b = pairs[:, 0], pairs[:, 1]
        keep = np.all(np.minimum(hi[a], hi[b]) - np.maximum(lo[a], lo[b]) > tol, axis=1)
        x = self.nodes
        for i, j in pairs[keep]:
            for p, q in ((i, j), (j, i)):
                pts = x[self._node_start[p]:self._node_start[p + 1]]
                pts = pts + 1e-3 * (centre[p] - pts)
                if np.any(_inside_block(c[q], pts, tol)):
                    raise ModelError(f"blocks {i} and {j} overlap (by more than {tol:.2e} m); "
                                     f"blocks may touch but not interpenetrate")

    def summary(self):
        """One-line description of the model size."""
        nc = 0 if self.contacts is None else self.contacts.n
        return size_summary(self.n_blocks, self.n_elements, self.n_nodes, nc)

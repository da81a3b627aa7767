"""Beams, foundations and slabs (single box blocks) and node selection by plane. SI units (m)."""
from __future__ import annotations

import numpy as np

from ..loading import is_number
from .walls import BrickSpec, GeometryError, _material, _point

#: default hexahedron edge lengths (x, y, z) of beams: those of the reference brick, so that a
#: beam's mesh matches the bricks it touches.
DEFAULT_ELEMENT_SIZE = BrickSpec.reference().element_size


def add_beam(model, origin, size, material, divisions=None, element_size=None, group="beam",
             joint=None, fixed=False):
    """Add a box block (loading beam, lintel, slab, foundation); returns its block id.

    Parameters
    ----------
    origin : (3,) array_like, m
        minimum corner.
    size : (3,) array_like, m
        edge lengths along x, y, z.
    material : PlasticDamage
        usually an elastic one.
    divisions : (nx, ny, nz) ints, optional
        hexahedra along x, y, z; default ``round(size / element_size)`` (at least 1).
    element_size : float or (3,) floats, m, optional
        target hexahedron edge lengths; default :data:`DEFAULT_ELEMENT_SIZE`.
    group, joint, fixed : see :meth:`Model.add_block`.
    """
    origin = _point("origin", origin)
    size = _point("size", size)
    if not np.all(size > 0):
        raise GeometryError(f"size must be 3 positive lengths in m, got {size.tolist()}")
    _material("material", material)
    if divisions is None:
        e = np.broadcast_to(np.asarray(DEFAULT_ELEMENT_SIZE if element_size is None
                                       else element_size, dtype=np.float64), (3,))
        if not np.all(np.isfinite(e) & (e > 0)):
            raise GeometryError(f"element_size must be positive lengths in m, got {element_size!r}")
        divisions = tuple(max(1, int(round(v))) for v in size / e)
    return model.add_box(origin, size, material, divisions, fixed=fixed, joint=joint, group=group)


def add_foundation(model, origin, size, material, group="foundation", **kw):
    """A fixed (fully clamped) :func:`add_beam` block under walls; returns its block id."""
    return add_beam(model, origin, size, material, group=group, fixed=True, **kw)


def add_slab(model, origin, size, material, group="slab", **kw):
    """A floor slab, an :func:`add_beam` block in group ``"slab"``; returns its block id."""
    return add_beam(model, origin, size, material, group=group, **kw)


def plane_nodes(model, axis, value, blocks=None, tol=1.0e-7):
    """Node ids (sorted int64) lying on the plane ``x[axis] == value`` (m, within ``tol``).

    ``blocks`` restricts the search to these block ids (default: all blocks).
    """
    if not (isinstance(axis, (int, np.integer)) and not isinstance(axis, (bool, np.bool_))
            and axis in (0, 1, 2)):
        raise GeometryError(f"plane_nodes: axis must be 0, 1 or 2, got {axis!r}")
    if not is_number(value):
        raise GeometryError(f"plane_nodes: value must be a finite coordinate in m, got {value!r}")
    ids = np.arange(model.n_nodes) if blocks is None else model.block_nodes(blocks)
    return ids[np.abs(model.nodes[ids, axis] - float(value)) <= tol].astype(np.int64)

"""Brick walls on top of :meth:`Model.add_box`: courses, bonds, openings with lintels, corners.

Conventions
-----------
* SI units (m). Axes: x along a wall, y through its thickness, z up.
* A wall is described in its own coordinates: ``s`` along the wall from its start (m), ``z`` up
  from its base (m); course ``k`` occupies ``z in [k h, (k + 1) h]`` with ``h`` the brick height.
* Every course is the wall's extent minus its voids (openings, lintels, the other wall's share of
  a corner); each remaining segment is cut at the bond's vertical joints ``offset + i * length``.
  Pieces shorter than a quarter brick are merged into their neighbour, so
  jambs and ends stay straight and no sliver units appear.
* Blocks are axis-aligned boxes meshed ``(along, thickness, height)`` =
  ``(round(nx_along * piece / length), ny_thick, nz_height)`` hexahedra, mapped to (x, y, z) for a
  wall along x and to (y, x, z) for a wall along y (the long side of its bricks runs along y).
* A generator validates everything and plans all its blocks before it adds the first one, so a
  call that raises leaves the model untouched.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from ..loading import is_count, is_number
from ..model import ModelError, check_material

TOL = 1.0e-7  # m, geometric tolerance for coincident joints and edges


class GeometryError(ModelError):
    """Invalid generator input; the message names the parameter and its value."""


@dataclass(frozen=True)
class BrickSpec:
    """Expanded brick size (block + half a mortar joint all round, m) and its mesh.

    ``nx_along``, ``ny_thick``, ``nz_height`` are the hexahedra of a full brick along its length,
    through its thickness and over its height; a half or cut brick gets
    ``max(1, round(nx_along * piece_length / length))`` along its length.
    """
    length: float = 0.22
    height: float = 0.081
    thickness: float = 0.102
    nx_along: int = 4
    nz_height: int = 1
    ny_thick: int = 2

    def __post_init__(self):
        for name in ("length", "height", "thickness"):
            v = getattr(self, name)
            if not (is_number(v) and v > 0):
                raise GeometryError(f"BrickSpec.{name} must be a positive length in m, got {v!r}")
        for name in ("nx_along", "nz_height", "ny_thick"):
            v = getattr(self, name)
            if not is_count(v, 1):
                raise GeometryError(f"BrickSpec.{name} must be an integer >= 1, got {v!r}")

    @classmethod
    def reference(cls):
        """The 220 x 81 x 102 mm expanded brick of CASES.md, meshed 4 x 1 x 2."""
        return cls()

    @property
    def half_length(self):
        """Length of a half brick (m)."""
        return 0.5 * self.length

    def along_divisions(self, piece_length):
        """Hexahedra along a (full, half or cut) unit of length ``piece_length`` (m)."""
        return max(1, int(round(self.nx_along * piece_length / self.length)))

    @property
    def element_size(self):
        """(x, y, z) edge lengths (m) of a full brick's hexahedra in a wall along x."""
        return (self.length / self.nx_along, self.thickness / self.ny_thick,
                self.height / self.nz_height)


@dataclass(frozen=True)
class Lintel:
    """An elastic block over an opening: ``height`` (m, rounded to whole courses), bearing
    ``bearing`` (m) on each jamb; ``joint`` the JointLaw of its contacts (None: model default)."""
    material: object
    height: float
    bearing: float
    joint: object = None
    group: str = "lintel"


@dataclass(frozen=True)
class Opening:
    """A rectangular hole in a wall, in the wall's own coordinates (m): ``x0`` along the wall from
    its start, ``z0`` above its base; the bottom and top are rounded to course joints."""
    x0: float
    z0: float
    width: float
    height: float
    lintel: Lintel | None = None


@dataclass
class Wall:
    """What a wall generator built.

    ``courses`` lists the masonry block ids of each course, bottom course first; ``lintels`` the
    lintel block ids; ``origin``/``size`` the global bounding box (m); ``length``/``height``/
    ``thickness`` the built dimensions (m), which may differ from the requested ones (snapping).
    """
    courses: list
    lintels: list
    origin: np.ndarray
    size: np.ndarray
    length: float
    height: float
    thickness: float

    @property
    def blocks(self):
        """All block ids of the wall (masonry then lintels)."""
        return [b for c in self.courses for b in c] + list(self.lintels)

    @property
    def top(self):
        """z of the wall's top face (m)."""
        return float(self.origin[2] + self.size[2])


# ---------------------------------------------------------------------------------- validation
def _length(name, value, allow_zero=False):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise GeometryError(f"{name} must be a length in m, got {value!r}") from None
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise GeometryError(f"{name} must be a {'non-negative' if allow_zero else 'positive'} "
                            f"length in m, got {value!r}")
    return v


def _point(name, value):
    p = np.asarray(value, dtype=np.float64)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise GeometryError(f"{name} must be 3 finite coordinates in m, got {value!r}")
    return p


def _material(name, material):
    return check_material(name, material, GeometryError)


def _brick(brick):
    brick = BrickSpec() if brick is None else brick
    if not isinstance(brick, BrickSpec):
        raise GeometryError(f"brick must be a BrickSpec, got {brick!r}")
    return brick


def _choice(name, value, options):
    if value not in options:
        raise GeometryError(f"{name} must be one of {options}, got {value!r}")
    return value


def _built_length(length, brick, fit, name="length"):
    """Built length (m): the requested one (``fit='cut'``) or the nearest half-brick multiple."""
    length = _length(name, length)
    _choice("fit", fit, ("snap", "cut"))
    if fit == "cut":
        return length
    n = int(round(length / brick.half_length))
    if n < 1:
        raise GeometryError(f"{name} {length} m is shorter than half a brick "
                            f"({brick.half_length} m); use fit='cut'")
    built = n * brick.half_length
    if abs(built - length) > TOL:
        warnings.warn(f"{name} {length} m built as {n} half bricks = {built:.6g} m "
                      f"(fit='cut' keeps {length} m with cut end units)", stacklevel=3)
    return built


def _courses(height, brick, name="height"):
    """Number of courses closest to ``height`` (m); warns when it differs."""
    height = _length(name, height)
    n = int(round(height / brick.height))
    if n < 1:
        raise GeometryError(f"{name} {height} m is less than half a course ({brick.height} m)")
    if abs(n * brick.height - height) > TOL:
        warnings.warn(f"{name} {height} m built as {n} courses = {n * brick.height:.6g} m",
                      stacklevel=3)
    return n


@dataclass(frozen=True)
class _Rect:
    """A void of the wall plan: ``[s0, s1]`` along, courses ``[c0, c1)``."""
    s0: float
    s1: float
    c0: int
    c1: int
    what: str
    lintel: Lintel | None = None


def _plan_openings(openings, length, n_courses, brick, reserved=()):
    """Validate openings against a wall of ``length`` (m) and ``n_courses``; return void rects.

    ``reserved`` lists ``(s0, s1)`` intervals (corners) that no opening or lintel may touch.
    """
    h = brick.height
    rects = []
    if not isinstance(openings, (list, tuple)):
        raise GeometryError(f"openings must be a list of Opening, got {openings!r}")
    for i, o in enumerate(openings):
        if not isinstance(o, Opening):
            raise GeometryError(f"openings[{i}] must be an Opening, got {o!r}")
        x0 = _length(f"openings[{i}].x0", o.x0, allow_zero=True)
        z0 = _length(f"openings[{i}].z0", o.z0, allow_zero=True)
        w = _length(f"openings[{i}].width", o.width)
        hh = _length(f"openings[{i}].height", o.height)
        if x0 + w > length + TOL or z0 + hh > n_courses * h + TOL:
            raise GeometryError(
                f"openings[{i}] ({x0} .. {x0 + w} m along, {z0} .. {z0 + hh} m up) lies outside "
                f"the wall ({length:.6g} m x {n_courses * h:.6g} m)")
        c0, c1 = int(round(z0 / h)), int(round((z0 + hh) / h))
        if c1 <= c0:
            raise GeometryError(f"openings[{i}].height {hh} m is less than half a course ({h} m)")
        if abs(c0 * h - z0) > TOL or abs(c1 * h - z0 - hh) > TOL:
            warnings.warn(f"openings[{i}] rows {z0:.6g} .. {z0 + hh:.6g} m rounded to course "
                          f"joints {c0 * h:.6g} .. {c1 * h:.6g} m", stacklevel=3)
        rects.append(_Rect(x0, x0 + w, c0, c1, f"openings[{i}]"))
        lt = o.lintel
        if lt is not None:
            if not isinstance(lt, Lintel):
                raise GeometryError(f"openings[{i}].lintel must be a Lintel, got {lt!r}")
            _material(f"openings[{i}].lintel.material", lt.material)
            b = _length(f"openings[{i}].lintel.bearing", lt.bearing, allow_zero=True)
            nl = int(round(_length(f"openings[{i}].lintel.height", lt.height) / h))
            if nl < 1:
                raise GeometryError(f"openings[{i}].lintel.height {lt.height} m is less than half "
                                    f"a course ({h} m)")
            if x0 - b < -TOL or x0 + w + b > length + TOL or c1 + nl > n_courses:
                raise GeometryError(
                    f"openings[{i}].lintel ({x0 - b:.6g} .. {x0 + w + b:.6g} m along, "
                    f"{nl} courses above the opening) lies outside the wall ({length:.6g} m x "
                    f"{n_courses} courses)")
            rects.append(_Rect(x0 - b, x0 + w + b, c1, c1 + nl, f"openings[{i}].lintel", lt))
    for a in range(len(rects)):
        ra = rects[a]
        for s0, s1 in reserved:
            if ra.s0 < s1 - TOL and s0 < ra.s1 - TOL:
                raise GeometryError(f"{ra.what} ({ra.s0:.6g} .. {ra.s1:.6g} m along) cuts into "
                                    f"the corner at {s0:.6g} .. {s1:.6g} m")
        for rb in rects[a + 1:]:
            if (ra.s0 < rb.s1 - TOL and rb.s0 < ra.s1 - TOL
                    and ra.c0 < rb.c1 and rb.c0 < ra.c1):
                raise GeometryError(f"{ra.what} and {rb.what} overlap")
    return rects


# ---------------------------------------------------------------------------------- courses
def _cut(a, b, offset, unit, min_piece):
    """Pieces ``[(s0, s1), ...]`` of the segment ``[a, b]`` cut at joints ``offset + i * unit``."""
    i0 = math.ceil((a + TOL - offset) / unit)
    cuts = [a]
    s = offset + i0 * unit
    while s < b - TOL:
        if s > a + TOL:
            cuts.append(s)
        s += unit
    cuts.append(b)
    pieces = [[cuts[i], cuts[i + 1]] for i in range(len(cuts) - 1)]
    if len(pieces) > 1 and pieces[0][1] - pieces[0][0] < min_piece - TOL:
        first = pieces.pop(0)
        pieces[0][0] = first[0]
    if len(pieces) > 1 and pieces[-1][1] - pieces[-1][0] < min_piece - TOL:
        last = pieces.pop()
        pieces[-1][1] = last[1]
    return [tuple(p) for p in pieces]


def _segments(length, voids):
    """``[0, length]`` minus the union of the intervals ``voids``, as a sorted list of intervals."""
    segs, s = [], 0.0
    for a, b in sorted(voids):
        if a > s + TOL:
            segs.append((s, min(a, length)))
        s = max(s, b)
    if s < length - TOL:
        segs.append((s, length))
    return segs


@dataclass(frozen=True)
class _Frame:
    """Maps wall coordinates (s along, t through the thickness, z up) to global axis-aligned boxes.

    ``start`` is the global point at s = t = z = 0; the wall runs along global axis ``axis``
    (0 = x, 1 = y) with sign ``sign`` and its thickness grows along the other horizontal axis with
    sign ``tsign``.
    """
    start: np.ndarray
    axis: int
    sign: int = 1
    tsign: int = 1

    def box(self, s0, s1, t0, t1, z0, z1):
        """(origin, size) of the global box of the wall-coordinate box."""
        lo, hi = np.empty(3), np.empty(3)
        for ax, sg, a, b in ((self.axis, self.sign, s0, s1), (1 - self.axis, self.tsign, t0, t1)):
            p, q = self.start[ax] + sg * a, self.start[ax] + sg * b
            lo[ax], hi[ax] = min(p, q), max(p, q)
        lo[2], hi[2] = self.start[2] + z0, self.start[2] + z1
        return lo, hi - lo

    def divisions(self, along, thick, height):
        """Divisions in global (x, y, z) order."""
        return (along, thick, height) if self.axis == 0 else (thick, along, height)


def _build(model, frame, length, n_courses, brick, material, rects, offset, end_voids,
           group="wall", joint=None):
    """Plan and add the blocks of one wall; returns a :class:`Wall`.

    ``offset(k)`` gives the bond's joint offset (m) of course k, ``end_voids(k)`` extra void
    intervals of course k (corners); ``group`` is a name or a callable ``(s0, s1) -> name``.
    """
    h, t = brick.height, brick.thickness
    min_piece = 0.25 * brick.length
    group_of = group if callable(group) else (lambda s0, s1: group)
    plan = []  # (course or -1, origin, size, divisions, material, joint, group)
    for k in range(n_courses):
        voids = [(r.s0, r.s1) for r in rects if r.c0 <= k < r.c1] + list(end_voids(k))
        for a, b in _segments(length, voids):
            for s0, s1 in _cut(a, b, offset(k), brick.length, min_piece):
                o, sz = frame.box(s0, s1, 0.0, t, k * h, (k + 1) * h)
                div = frame.divisions(brick.along_divisions(s1 - s0), brick.ny_thick,
                                      brick.nz_height)
                plan.append((k, o, sz, div, material, joint, group_of(s0, s1)))
    for r in rects:
        if r.lintel is not None:
            lt = r.lintel
            o, sz = frame.box(r.s0, r.s1, 0.0, t, r.c0 * h, r.c1 * h)
            div = frame.divisions(brick.along_divisions(r.s1 - r.s0), brick.ny_thick,
                                  brick.nz_height * (r.c1 - r.c0))
            plan.append((-1, o, sz, div, lt.material, lt.joint, lt.group))
    if not any(k >= 0 for k, *_ in plan):
        raise GeometryError(f"wall of {length:.3f} x {n_courses * h:.3f} m: its openings leave "
                            f"no brick")
    courses, lintels = [[] for _ in range(n_courses)], []
    for k, o, sz, div, mat, jnt, grp in plan:
        b = model.add_box(o, sz, mat, div, joint=jnt, group=grp)
        (lintels if k < 0 else courses[k]).append(b)
    lo, size = frame.box(0.0, length, 0.0, t, 0.0, n_courses * h)
    return Wall(courses, lintels, lo, size, length, n_courses * h, t)


def _running(bond, brick, phase=0):
    """The joint offset of course k for a bond."""
    _choice("bond", bond, ("running", "stack"))
    if bond == "stack":
        return lambda k: 0.0
    return lambda k: ((k + phase) % 2) * brick.half_length


# ---------------------------------------------------------------------------------- public API
def add_wall(model, origin, length, height, material, brick=None, bond="running", direction="x",
             openings=(), group="wall", joint=None, fit="snap"):
    """Add a single-leaf brick wall; returns a :class:`Wall` (block ids by course).

    Parameters
    ----------
    model : Model
    origin : (3,) array_like, m
        minimum corner of the wall's bounding box.
    length, height : float, m
        requested size; the height is rounded to whole courses, the length to whole half bricks
        (``fit='snap'``, a warning when it changes) or kept exactly with cut end units
        (``fit='cut'``). ``Wall.length``/``Wall.height`` report what was built.
    material : PlasticDamage
        brick material.
    brick : BrickSpec, optional
        brick size and mesh (default :meth:`BrickSpec.reference`).
    bond : {"running", "stack"}
        running (stretcher) bond starts even courses with a full brick at the wall's start and odd
        courses with a half brick, so both ends are straight; stack bond aligns all joints.
    direction : {"x", "y"}
        the wall's axis; the thickness grows along +y (resp. +x) from ``origin``.
    openings : sequence of Opening
        holes in wall coordinates (m from the wall's start and base); bricks are cut at their
        edges, an optional :class:`Lintel` fills ``lintel.height`` above the opening and bears
        ``lintel.bearing`` on each side.
    group : str
        block group of the bricks (lintels use ``Lintel.group``).
    joint : JointLaw or None
        joint law of the bricks' contacts (None: the model's default).
    fit : {"snap", "cut"}
    """
    brick = _brick(brick)
    origin = _point("origin", origin)
    _material("material", material)
    _choice("direction", direction, ("x", "y"))
    offset = _running(bond, brick)
    length = _built_length(length, brick, fit)
    n = _courses(height, brick)
    rects = _plan_openings(openings, length, n, brick)
    frame = _Frame(origin, 0 if direction == "x" else 1)
    return _build(model, frame, length, n, brick, material, rects, offset, lambda k: (),
                  group, joint)


def add_corner(model, corner, length_x, length_y, height, material, brick=None, openings_x=(),
               openings_y=(), first="x", group="wall", joint=None, fit="snap"):
    """Add two walls meeting at a right angle with toothing; returns ``(wall_x, wall_y)``.

    The corner square (one wall thickness by one wall thickness) belongs alternately to the two
    walls: the wall named by ``first`` runs through it in even courses, the other in odd ones.
    Both walls are in running bond, offset so that the brick running through the corner is a full
    one.

    Parameters
    ----------
    corner : (3,) array_like, m
        the outer corner at the base of the walls.
    length_x, length_y : float, m, signed
        the wall along x spans ``corner.x .. corner.x + length_x`` and the wall along y
        ``corner.y .. corner.y + length_y`` (both include the corner square); the sign gives the
        direction, and each wall's thickness lies on the side of the other wall.
    openings_x, openings_y : sequence of Opening
        openings of each wall, ``x0`` measured from the corner along that wall; they may not
        touch the corner square.
    first : {"x", "y"}
        the wall that runs through the corner in course 0.
    height, material, brick, group, joint, fit : see :func:`add_wall`.
    """
    brick = _brick(brick)
    corner = _point("corner", corner)
    _material("material", material)
    _choice("first", first, ("x", "y"))
    t = brick.thickness
    walls = []
    signs = []
    for name, lv in (("length_x", length_x), ("length_y", length_y)):
        try:
            lv = float(lv)
        except (TypeError, ValueError):
            raise GeometryError(f"{name} must be a signed length in m, got {lv!r}") from None
        signs.append(1 if lv > 0 else -1)
        walls.append(_built_length(abs(lv), brick, fit, name))
    n = _courses(height, brick)
    for name, lv in zip(("length_x", "length_y"), walls):
        if lv < t + 0.25 * brick.length - TOL:
            raise GeometryError(f"|{name}| = {lv} m leaves less than a quarter brick beyond the "
                                f"corner (wall thickness {t} m)")
    plans = [_plan_openings(op, lv, n, brick, reserved=[(0.0, t)])
             for op, lv in zip((openings_x, openings_y), walls)]
    out = []
    for axis in (0, 1):
        owner = 0 if (first == "x") == (axis == 0) else 1  # parity of the courses it owns
        frame = _Frame(corner, axis, signs[axis], signs[1 - axis])
        offset = _running("running", brick, phase=owner)
        out.append(_build(model, frame, walls[axis], n, brick, material, plans[axis], offset,
                          lambda k, o=owner: () if k % 2 == o else ((0.0, t),), group, joint))
    return tuple(out)

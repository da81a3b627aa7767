"""The two-storey terraced house of CASES.md S7 (after the TU Delft calcium-silicate house).

Plan (m): the facades run along x over ``length`` (outer size), the two transversal (party) walls
along y over ``depth``; all walls are one brick thick (``brick.thickness``).

* Transversal wall W1 at ``x in [0, t]`` (next to the wide pier), W2 at ``x in [length - t,
  length]``; they carry the slabs.
* Front facade at ``y in [0, t]``: pier P1 ``x in [0, pier_wide]``, pier P2
  ``x in [length - pier_narrow, length]`` (widths include the corner), one opening per storey
  between them with a lintel bearing on the piers, masonry (spandrels) above and below it.
  Piers and transversal walls interlock (toothing): the facade runs through the corner squares in
  even courses, the transversal walls in odd ones.
* Each storey is ``n_masonry`` courses of walls, then a slab band of ``n_slab`` courses: the slabs
  (elastic, ``slab_material``) rest on the transversal walls only, ``slab_gap`` clear of the
  facade, while the facade continues through the band. Each floor has ``slabs_per_floor`` slabs
  side by side along y over the full depth.
* A fixed foundation block (``beam_material``) under the whole footprint, top at z = 0.

Half model (``half=True``, the default): only ``y <= depth / 2`` is built (front facade, half
of each transversal wall and of the slabs). The symmetry plane is ``y = depth / 2``, parallel to
the facades and to the load; its nodes (``groups["symmetry_nodes"]``) must get ``u_y = 0``. With
two slabs per floor the slab joint lies on that plane, so the half model holds one slab per floor.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..loading import is_count, is_number
from .beams import add_foundation, add_slab, plane_nodes
from .walls import (TOL, BrickSpec, GeometryError, Lintel, Opening, _build, _Frame, _material,
                    _plan_openings, _running)


@dataclass(frozen=True)
class HouseParams:
    """Dimensions of the terraced house (m); defaults approximate the TU Delft house.

    ``sills``/``heads``: bottom/top of each storey's facade opening above the storey's base;
    ``lintel_height``/``lintel_bearing``: the lintel over each opening; ``slab_thickness`` is
    rounded to whole courses (see :meth:`layout`); ``slab_element``: hexahedron edge (m) of the
    slabs and foundation in plan.
    """
    length: float = 5.4
    depth: float = 5.3
    storey_height: float = 2.7
    n_storeys: int = 2
    pier_wide: float = 1.1
    pier_narrow: float = 0.6
    sills: tuple = (0.0, 0.729)
    heads: tuple = (2.187, 2.187)
    lintel_height: float = 0.162
    lintel_bearing: float = 0.1
    slab_thickness: float = 0.2
    slabs_per_floor: int = 2
    slab_gap: float = 0.01
    slab_element: float = 0.11
    foundation_thickness: float = 0.2
    brick: BrickSpec = field(default_factory=BrickSpec)
    half: bool = True

    def __post_init__(self):
        if not isinstance(self.half, (bool, np.bool_)):   # "no" would count as True
            raise GeometryError(f"HouseParams.half must be True or False, got {self.half!r}")
        for name in ("length", "depth", "storey_height", "pier_wide", "pier_narrow",
                     "lintel_height", "slab_thickness", "slab_element", "foundation_thickness"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                    and v > 0):
                raise GeometryError(f"HouseParams.{name} must be a positive length in m, got {v!r}")
        for name in ("lintel_bearing", "slab_gap"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise GeometryError(f"HouseParams.{name} must be a length >= 0 m, got {v!r}")
        for name in ("n_storeys", "slabs_per_floor"):
            v = getattr(self, name)
            if not is_count(v, 1):
                raise GeometryError(f"HouseParams.{name} must be an integer >= 1, got {v!r}")
        for name in ("sills", "heads"):
            v = getattr(self, name)
            if not (isinstance(v, (list, tuple)) and all(is_number(x) for x in v)):
                raise GeometryError(f"HouseParams.{name} must be a list of heights in m, got "
                                    f"{v!r}")
            if len(v) != self.n_storeys:
                raise GeometryError(f"HouseParams.{name} needs one value per storey "
                                    f"({self.n_storeys}), got {getattr(self, name)!r}")
        if not isinstance(self.brick, BrickSpec):
            raise GeometryError(f"HouseParams.brick must be a BrickSpec, got {self.brick!r}")
        t = self.brick.thickness
        if self.pier_wide + self.pier_narrow + 2 * self.lintel_bearing >= self.length - TOL:
            raise GeometryError(
                f"HouseParams: piers {self.pier_wide} + {self.pier_narrow} m leave no opening in "
                f"the {self.length} m facade")
        for name in ("pier_wide", "pier_narrow"):
            if getattr(self, name) - self.lintel_bearing < t + 0.25 * self.brick.length - TOL:
                raise GeometryError(f"HouseParams.{name} = {getattr(self, name)} m is too narrow "
                                    f"for the corner ({t} m) and the lintel bearing")
        if 0.5 * self.depth < t + self.slab_gap + 0.25 * self.brick.length:
            raise GeometryError(f"HouseParams.depth = {self.depth} m is too small")
        for i, (s, h) in enumerate(zip(self.sills, self.heads)):
            if not (0 <= s < h):
                raise GeometryError(f"HouseParams storey {i}: need 0 <= sill < head, got sill {s} "
                                    f"m, head {h} m")

    def scaled(self, coarse=True):
        """A tiny smoke-test house: half the plan, 0.44 x 0.243 x 0.102 m blocks, 5 courses a
        storey; one hexahedron per block if ``coarse`` else 2 x 1 x 1."""
        brick = BrickSpec(0.44, 0.243, 0.102, 1 if coarse else 2, 1, 1)
        return replace(self, length=2.64, depth=2.4, storey_height=5 * 0.243, pier_wide=0.66,
                       pier_narrow=0.55, sills=(0.0,) + (0.243,) * (self.n_storeys - 1),
                       heads=(0.729,) * self.n_storeys, lintel_height=0.243, lintel_bearing=0.11,
                       slab_thickness=0.243, slab_element=0.44, foundation_thickness=0.2,
                       brick=brick)

    def layout(self):
        """The built levels: a :class:`HouseLayout`."""
        h = self.brick.height
        n_slab = max(1, int(round(self.slab_thickness / h)))
        n_storey = int(round(self.storey_height / h))
        if n_storey - n_slab < 2:
            raise GeometryError(f"HouseParams.storey_height = {self.storey_height} m leaves no "
                                f"wall under a {n_slab}-course slab")
        base = [i * n_storey * h for i in range(self.n_storeys)]
        return HouseLayout(
            course_height=h, n_storey=n_storey, n_slab=n_slab, n_masonry=n_storey - n_slab,
            storey_base=tuple(base),
            slab_bottom=tuple(z + (n_storey - n_slab) * h for z in base),
            slab_top=tuple(z + n_storey * h for z in base),
            slab_thickness=n_slab * h, height=self.n_storeys * n_storey * h,
            model_depth=0.5 * self.depth if self.half else self.depth,
            symmetry_y=0.5 * self.depth if self.half else None)


@dataclass(frozen=True)
class HouseLayout:
    """Built levels of a house (m): course counts, z of each storey's base and of each floor
    slab's bottom and top, the built slab thickness (scale the slab density by
    ``params.slab_thickness / slab_thickness`` to keep the nominal floor weight), the built depth
    and the symmetry plane ``y = symmetry_y`` (None for the full model)."""
    course_height: float
    n_storey: int
    n_slab: int
    n_masonry: int
    storey_base: tuple
    slab_bottom: tuple
    slab_top: tuple
    slab_thickness: float
    height: float
    model_depth: float
    symmetry_y: float | None


def terraced_house(model, params, material, beam_material, slab_material):
    """Build the terraced house (module docstring) into ``model``; returns its groups.

    Parameters
    ----------
    model : Model
    params : HouseParams
    material : PlasticDamage
        brick material.
    beam_material : PlasticDamage
        lintels and foundation (elastic).
    slab_material : PlasticDamage
        floor slabs (elastic).

    Returns
    -------
    dict
        block id lists ``"transversal_walls"``, ``"transversal_wall_1"`` (x = 0, by the wide
        pier), ``"transversal_wall_2"``, ``"facade"`` (all facade bricks), ``"piers"``,
        ``"pier_wide"``, ``"pier_narrow"``, ``"spandrels"``, ``"lintels"``, ``"masonry"``,
        ``"slabs"``, ``"slabs_floor1"``, ``"slabs_floor2"``, ... (one per storey),
        ``"foundation"``; and ``"symmetry_nodes"``, the node ids (int64 array) on the symmetry
        plane (empty for the full model).
    """
    if not isinstance(params, HouseParams):
        raise GeometryError(f"params must be a HouseParams, got {params!r}")
    for name, mat in (("material", material), ("beam_material", beam_material),
                      ("slab_material", slab_material)):
        _material(name, mat)
    p, lay = params, params.layout()
    brick, t, L = p.brick, p.brick.thickness, p.length
    n_total = p.n_storeys * lay.n_storey
    in_band = [k % lay.n_storey >= lay.n_masonry for k in range(n_total)]

    # facades: the facade owns the corners in even courses and in the slab bands
    openings = []
    for i in range(p.n_storeys):
        z0 = lay.storey_base[i] + p.sills[i]
        openings.append(Opening(p.pier_wide, z0, L - p.pier_wide - p.pier_narrow,
                                p.heads[i] - p.sills[i],
                                Lintel(beam_material, p.lintel_height, p.lintel_bearing)))
    rects = _plan_openings(openings, L, n_total, brick, reserved=[(0.0, t), (L - t, L)])
    corner_voids = ((0.0, t), (L - t, L))

    def facade_group(s0, s1):
        c = 0.5 * (s0 + s1)
        return "pier_wide" if c < p.pier_wide else "pier_narrow" if c > L - p.pier_narrow \
            else "spandrel"

    walls = []
    for y0 in [0.0] + ([] if p.half else [p.depth - t]):
        walls.append(_build(model, _Frame(np.array([0.0, y0, 0.0]), 0), L, n_total, brick,
                            material, rects, _running("running", brick),
                            lambda k: () if k % 2 == 0 or in_band[k] else corner_voids,
                            facade_group))
    # transversal walls, one piece per storey; they own the corners in odd courses
    D = lay.model_depth
    ends = [(0.0, t)] + ([] if p.half else [(D - t, D)])
    transversal = {1: [], 2: []}
    for i in range(p.n_storeys):
        k0 = i * lay.n_storey
        for w, x0 in ((1, 0.0), (2, L - t)):
            wall = _build(model, _Frame(np.array([x0, 0.0, lay.storey_base[i]]), 1), D,
                          lay.n_masonry, brick, material, [], _running("running", brick, k0 + 1),
                          lambda k, k0=k0: ends if (k0 + k) % 2 == 0 else (),
                          f"transversal_wall_{w}")
            transversal[w] += wall.blocks
    # slabs on the transversal walls, clear of the facades
    y_lo, y_hi = t + p.slab_gap, p.depth - t - p.slab_gap
    edges = np.linspace(y_lo, y_hi, p.slabs_per_floor + 1)
    slabs = []
    for i in range(p.n_storeys):
        floor = []
        for a, b in zip(edges[:-1], edges[1:]):
            b = min(b, D)
            if b > a + TOL:
                floor.append(add_slab(model, (0.0, a, lay.slab_bottom[i]),
                                      (L, b - a, lay.slab_thickness), slab_material,
                                      element_size=(p.slab_element, p.slab_element,
                                                    0.5 * lay.slab_thickness),
                                      group=f"slabs_floor{i + 1}"))
        slabs.append(floor)
    fnd = add_foundation(model, (0.0, 0.0, -p.foundation_thickness),
                         (L, D, p.foundation_thickness), beam_material,
                         element_size=(p.slab_element, p.slab_element, p.foundation_thickness))

    grp = model.block_group
    facade = [b for w in walls for c in w.courses for b in c]
    pick = {name: [b for b in facade if grp[b] == name]
            for name in ("pier_wide", "pier_narrow", "spandrel")}
    out = {
        "transversal_walls": transversal[1] + transversal[2],
        "transversal_wall_1": transversal[1],
        "transversal_wall_2": transversal[2],
        "facade": facade,
        "piers": pick["pier_wide"] + pick["pier_narrow"],
        "pier_wide": pick["pier_wide"],
        "pier_narrow": pick["pier_narrow"],
        "spandrels": pick["spandrel"],
        "lintels": [b for w in walls for b in w.lintels],
        "masonry": facade + transversal[1] + transversal[2],
        "slabs": [b for f in slabs for b in f],
        "foundation": [fnd],
    }
    for i, f in enumerate(slabs):
        out[f"slabs_floor{i + 1}"] = f
    house = out["masonry"] + out["lintels"] + out["slabs"]
    out["symmetry_nodes"] = (plane_nodes(model, 1, lay.symmetry_y, house) if p.half
                             else np.zeros(0, np.int64))
    return out

"""Masonry generators: bonds by hand, tiling (volume + no overlap), openings, corners, house."""
import warnings

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from dr_masonry.geometry import (BrickSpec, GeometryError, HouseParams, Lintel, Opening,
                                 add_beam, add_corner, add_foundation, add_slab, add_wall,
                                 plane_nodes, terraced_house)
from dr_masonry.contact_search import detect_contacts
from dr_masonry.model import Model, ModelError

L, H, T = 0.22, 0.081, 0.102
EPS = 1e-9


class Mat:
    """Stand-in for PlasticDamage: the generators only pass it through."""

    def params_array(self):
        return np.zeros(1)


MAT, STEEL = Mat(), Mat()


def boxes(model, ids=None):
    c = model.block_corners if ids is None else model.block_corners[np.asarray(ids, dtype=int)]
    return c.min(axis=1), c.max(axis=1)


def volume(model, ids=None):
    lo, hi = boxes(model, ids)
    return float(np.prod(hi - lo, axis=1).sum())


def assert_no_overlap(model, ids=None):
    """No two blocks share a volume (their boxes may touch)."""
    lo, hi = boxes(model, ids)
    n = len(lo)
    for i0 in range(0, n, 256):
        sl = slice(i0, i0 + 256)
        ov = np.minimum(hi[sl, None], hi[None]) - np.maximum(lo[sl, None], lo[None])
        bad = np.all(ov > 1e-9, axis=2)
        bad[np.arange(bad.shape[0]), np.arange(i0, i0 + bad.shape[0])] = False
        assert not bad.any(), f"blocks overlap: {np.argwhere(bad)[:5] + [i0, 0]}"


def x_intervals(model, ids):
    lo, hi = boxes(model, ids)
    return sorted((round(a, 9), round(b, 9)) for a, b in zip(lo[:, 0], hi[:, 0]))


def test_brick_reference():
    b = BrickSpec.reference()
    assert (b.length, b.height, b.thickness) == (0.22, 0.081, 0.102)
    assert (b.nx_along, b.nz_height, b.ny_thick) == (4, 1, 2)
    assert b.half_length == pytest.approx(0.11)
    assert b.along_divisions(b.half_length) == 2
    assert b.element_size == pytest.approx((0.055, 0.051, 0.081))
    with pytest.raises(GeometryError, match="height"):
        BrickSpec(height=-0.08)
    with pytest.raises(GeometryError, match="nx_along"):
        BrickSpec(nx_along=0)


def test_running_bond_wallet_by_hand():
    """S3 wallet: 2 bricks x 5 courses = 2 + 3 + 2 + 3 + 2 blocks, straight ends."""
    m = Model()
    w = add_wall(m, (0, 0, 0), 0.44, 0.405, MAT)
    assert [len(c) for c in w.courses] == [2, 3, 2, 3, 2]
    assert m.n_blocks == 12 and w.lintels == []
    assert (w.length, w.height, w.thickness) == pytest.approx((0.44, 0.405, T))
    assert w.size == pytest.approx([0.44, T, 0.405]) and w.top == pytest.approx(0.405)
    assert x_intervals(m, w.courses[0]) == [(0, 0.22), (0.22, 0.44)]
    assert x_intervals(m, w.courses[1]) == [(0, 0.11), (0.11, 0.33), (0.33, 0.44)]
    div = {tuple(d) for d in m.block_divisions[w.courses[1]]}
    assert div == {(2, 2, 1), (4, 2, 1)}
    lo, hi = boxes(m, w.courses[3])
    assert np.allclose(lo[:, 2], 3 * H) and np.allclose(hi[:, 2], 4 * H)
    assert np.allclose(lo[:, 1], 0) and np.allclose(hi[:, 1], T)
    assert volume(m) == pytest.approx(0.44 * 0.405 * T, rel=1e-12)


def test_odd_half_units_and_stack_bond():
    m = Model()
    w = add_wall(m, (1, 2, 3), 0.55, 2 * H, MAT)
    assert x_intervals(m, w.courses[0]) == [(1, 1.22), (1.22, 1.44), (1.44, 1.55)]
    assert x_intervals(m, w.courses[1]) == [(1, 1.11), (1.11, 1.33), (1.33, 1.55)]
    m = Model()
    w = add_wall(m, (0, 0, 0), 0.66, 4 * H, MAT, bond="stack")
    assert [len(c) for c in w.courses] == [3] * 4
    assert all(x_intervals(m, c) == [(0, .22), (.22, .44), (.44, .66)] for c in w.courses)
    assert (m.block_divisions == [4, 2, 1]).all()


def test_wall_along_y_has_bricks_along_y():
    m = Model()
    w = add_wall(m, (0.5, 0, 0), 0.44, 2 * H, MAT, direction="y")
    lo, hi = boxes(m)
    assert np.allclose(lo[:, 0], 0.5) and np.allclose(hi[:, 0], 0.5 + T)
    full = np.isclose(hi[:, 1] - lo[:, 1], L)
    assert full.sum() == 3 and (m.block_divisions[full] == [2, 4, 1]).all()
    assert (m.block_divisions[~full] == [2, 2, 1]).all()
    assert w.size == pytest.approx([T, 0.44, 2 * H])


def test_snap_and_cut():
    m = Model()
    with pytest.warns(UserWarning, match="half bricks"):
        w = add_wall(m, (0, 0, 0), 0.5, 3 * H, MAT)
    assert w.length == pytest.approx(0.55)
    with pytest.warns(UserWarning, match="courses"):
        w = add_wall(Model(), (0, 0, 0), 0.44, 0.4, MAT)
    assert w.height == pytest.approx(5 * H)
    for length in (0.5, 0.45, 0.3333):
        m = Model()
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            w = add_wall(m, (0, 0, 0), length, 4 * H, MAT, fit="cut")
        assert w.length == length
        assert volume(m) == pytest.approx(length * 4 * H * T, rel=1e-12)
        lo, hi = boxes(m)
        assert (hi[:, 0] - lo[:, 0]).min() >= 0.25 * L - 1e-9  # slivers merged
        assert hi[:, 0].max() == pytest.approx(length) and lo[:, 0].min() == pytest.approx(0)
        assert_no_overlap(m)


def test_opening_with_lintel():
    m = Model()
    lt = Lintel(STEEL, H, 0.1)
    w = add_wall(m, (0, 0, 0), 1.1, 10 * H, MAT, openings=[Opening(0.35, 2 * H, 0.4, 4 * H, lt)])
    assert len(w.lintels) == 1
    lo, hi = boxes(m, w.lintels)
    assert lo[0] == pytest.approx([0.25, 0, 6 * H]) and hi[0] == pytest.approx([0.85, T, 7 * H])
    assert m.block_group[w.lintels[0]] == "lintel"
    assert m.materials[m.block_material[w.lintels[0]]] is STEEL
    assert volume(m) == pytest.approx((1.1 * 10 * H - 0.4 * 4 * H) * T, rel=1e-12)
    assert_no_overlap(m)
    # nothing inside the hole; the jambs are straight
    lo, hi = boxes(m)
    inside = np.all((np.minimum(hi, [0.75, T, 6 * H]) - np.maximum(lo, [0.35, 0, 2 * H])) > EPS, 1)
    assert not inside.any()
    for k in range(2, 6):
        xs = x_intervals(m, w.courses[k])
        assert any(b == pytest.approx(0.35) for a, b in xs)
        assert any(a == pytest.approx(0.75) for a, b in xs)
    # courses crossed by the lintel are cut at its ends
    xs = x_intervals(m, w.courses[6])
    assert any(b == pytest.approx(0.25) for a, b in xs)
    assert any(a == pytest.approx(0.85) for a, b in xs)


@settings(max_examples=40, deadline=None)
@given(n_half=st.integers(1, 14), n_courses=st.integers(1, 9),
       bond=st.sampled_from(["running", "stack"]),
       direction=st.sampled_from(["x", "y"]), hole=st.one_of(st.none(), st.tuples(
           st.floats(0, 1), st.floats(0.1, 1), st.integers(0, 8), st.integers(1, 4))))
def test_wall_tiles_its_box(n_half, n_courses, bond, direction, hole):
    """Volume = box - openings; no overlaps; every block inside the wall's box."""
    length, height = n_half * 0.11, n_courses * H
    openings, area = [], 0.0
    if hole is not None:
        fx, fw, c0, nc = hole
        w_ = fw * length * 0.9
        x0 = fx * (length - w_)
        c0 = min(c0, n_courses - 1)
        nc = min(nc, n_courses - c0)
        openings, area = [Opening(x0, c0 * H, w_, nc * H)], w_ * nc * H
    m = Model()
    w = add_wall(m, (0.3, -0.2, 0.1), length, height, MAT, bond=bond, direction=direction,
                 openings=openings)
    # hole edges closer than the generators' tolerance (1e-7 m) to a wall end snap onto it
    assert volume(m) == pytest.approx(length * height * T - area * T, rel=1e-10,
                                      abs=2e-7 * height * T)
    assert_no_overlap(m)
    lo, hi = boxes(m)
    assert np.all(lo >= w.origin - 1e-12) and np.all(hi <= w.origin + w.size + 1e-12)
    assert sum(len(c) for c in w.courses) == m.n_blocks


@pytest.mark.parametrize("kwargs, match", [
    (dict(length=-0.44), "length"),
    (dict(height=0.0), "height"),
    (dict(height=float("nan")), "height"),
    (dict(bond="flemish"), "bond"),
    (dict(direction="z"), "direction"),
    (dict(material=None), "material"),
    (dict(origin=(0, 0)), "origin"),
    (dict(openings=[Opening(0.9, 0, 0.3, 2 * H)]), "outside"),
    (dict(openings=[Opening(0.1, 0, 0.2, 20 * H)]), "outside"),
    (dict(openings=[Opening(0.1, 0, -0.2, 2 * H)]), "width"),
    (dict(openings=[Opening(0.1, 0, 0.3, 2 * H), Opening(0.3, H, 0.3, 2 * H)]), "overlap"),
    (dict(openings=[Opening(0.1, 0, 0.3, 2 * H, Lintel(STEEL, H, 0.2))]), "lintel"),
    (dict(openings=[Opening(0.3, 0, 0.3, 2 * H, Lintel(STEEL, H, 0.1)),
                    Opening(0.5, 2 * H, 0.3, 2 * H)]), "overlap"),
    (dict(openings=[Opening(0.3, 0, 0.3, 2 * H, Lintel(None, H, 0.1))]), "material"),
    (dict(brick="brick"), "brick"),
    (dict(openings=Opening(0.1, 0, 0.3, 2 * H)), "openings must be a list of Opening"),
    (dict(openings=[Opening(0.0, 0, 1.1, 6 * H)]), "its openings leave no brick"),  # was empty
])
def test_wall_input_errors(kwargs, match):
    args = dict(origin=(0, 0, 0), length=1.1, height=6 * H, material=MAT)
    args.update(kwargs)
    m = Model()
    with pytest.raises(ModelError, match=match):
        add_wall(m, **args)
    assert m.n_blocks == 0  # nothing half-built


def owner_of(model, walls, point):
    """Index of the wall whose block contains ``point``."""
    for i, w in enumerate(walls):
        lo, hi = boxes(model, w.blocks)
        if np.all((lo < point) & (point < hi), axis=1).any():
            return i
    return None


@pytest.mark.parametrize("corner, lx, ly", [((0, 0, 0), 1.1, 0.88), ((5.4, 1, 0), -0.66, 0.99),
                                            ((0, 0, 0.5), 0.77, -1.1)])
@pytest.mark.parametrize("first", ["x", "y"])
def test_corner_toothing_alternates(corner, lx, ly, first):
    m = Model()
    n = 7
    wx, wy = add_corner(m, corner, lx, ly, n * H, MAT, first=first)
    assert_no_overlap(m)
    assert volume(m) == pytest.approx((abs(lx) + abs(ly) - T) * T * n * H, rel=1e-12)
    c = np.asarray(corner, float)
    sq = c + [np.sign(lx) * T / 2, np.sign(ly) * T / 2, 0]
    own = [owner_of(m, (wx, wy), sq + [0, 0, (k + 0.5) * H]) for k in range(n)]
    start = 0 if first == "x" else 1
    assert own == [(start + k) % 2 for k in range(n)]
    # the brick through the corner is a full one; the wall stays on its side of the corner
    for k in range(n):
        w = (wx, wy)[own[k]]
        lo, hi = boxes(m, w.courses[k])
        ax = own[k]
        assert (hi[:, ax] - lo[:, ax]).max() == pytest.approx(L)
    lo, hi = boxes(m)
    assert lo.min(0)[:2] == pytest.approx(np.minimum(c[:2], c[:2] + [lx, ly]))
    assert hi.max(0)[:2] == pytest.approx(np.maximum(c[:2], c[:2] + [lx, ly]))


def test_corner_errors():
    with pytest.raises(GeometryError, match="corner"):
        add_corner(Model(), (0, 0, 0), 1.1, 0.88, 4 * H, MAT, openings_x=[Opening(0.05, 0, 0.3, H)])
    with pytest.raises(GeometryError, match="length_y"):
        add_corner(Model(), (0, 0, 0), 1.1, 0.11, 4 * H, MAT)
    with pytest.raises(GeometryError, match="first"):
        add_corner(Model(), (0, 0, 0), 1.1, 0.88, 4 * H, MAT, first="z")


def test_beams():
    m = Model()
    b = add_beam(m, (0, 0, 2.754), (1.1, T, 0.2), STEEL)
    assert tuple(m.block_divisions[b]) == (20, 2, 2) and m.block_group[b] == "beam"
    f = add_foundation(m, (0, 0, -0.2), (1.1, T, 0.2), STEEL, element_size=0.11)
    assert m.block_fixed[f] and m.block_group[f] == "foundation"
    assert tuple(m.block_divisions[f]) == (10, 1, 2)
    s = add_slab(m, (0, 0, 3), (2, 1, 0.2), STEEL, divisions=(3, 2, 1))
    assert tuple(m.block_divisions[s]) == (3, 2, 1) and not m.block_fixed[s]
    assert m.block_group[s] == "slab"
    for bad, match in [(dict(size=(1, -1, 1)), "size"), (dict(material=None), "material"),
                       (dict(element_size=0.0), "element_size")]:
        kw = dict(origin=(0, 0, 0), size=(1, 1, 1), material=STEEL)
        kw.update(bad)
        with pytest.raises(GeometryError, match=match):
            add_beam(m, **kw)
    ids = plane_nodes(m, 2, -0.2)
    assert len(ids) == 11 * 2 and np.allclose(m.nodes[ids, 2], -0.2)
    assert len(plane_nodes(m, 2, -0.2, blocks=[b])) == 0


def check_house(m, g, p):
    lay = p.layout()
    t = p.brick.thickness
    for k in ("transversal_walls", "transversal_wall_1", "transversal_wall_2", "piers",
              "pier_wide", "pier_narrow", "spandrels", "lintels", "slabs_floor1", "slabs_floor2",
              "foundation"):
        assert len(g[k]) > 0, k
    every = g["masonry"] + g["lintels"] + g["slabs"] + g["foundation"]
    assert sorted(every) == list(range(m.n_blocks))
    assert_no_overlap(m)
    # masonry + lintel volume by hand: facade minus openings, transversal walls minus the
    # corner squares of the courses the facade owns
    D, Lx, h = lay.model_depth, p.length, lay.course_height
    holes = sum((round(hd / h) - round(s / h)) * h * (Lx - p.pier_wide - p.pier_narrow)
                for s, hd in zip(p.sills, p.heads))
    n_fac = 1 if p.half else 2
    owned = sum(1 for i in range(p.n_storeys) for k in range(lay.n_masonry)
                if (i * lay.n_storey + k) % 2 == 0)
    lent = p.n_storeys * lay.n_masonry - owned  # courses whose corners the facade gives away
    fac = n_fac * ((Lx * lay.height - holes) * t - 2 * lent * t * t * h)
    trans = 2 * (p.n_storeys * lay.n_masonry * D * h - n_fac * owned * t * h) * t
    assert volume(m, g["facade"] + g["lintels"] + g["transversal_walls"]) == \
        pytest.approx(fac + trans, rel=1e-10)
    # the piers are where they should be: beside the ground-floor opening exactly, above it
    # (courses without an opening) the bricks whose centre lies within the pier's width
    for name, a, b in (("pier_wide", 0, p.pier_wide), ("pier_narrow", Lx - p.pier_narrow, Lx)):
        lo, hi = boxes(m, g[name])
        c = 0.5 * (lo + hi)
        assert np.all((c[:, 0] > a) & (c[:, 0] < b))
        ground = lo[:, 2] < 1e-9
        assert lo[ground, 0].min() == pytest.approx(a) and hi[ground, 0].max() == pytest.approx(b)
        assert ground.sum() == len(x_intervals(m, np.asarray(g[name])[ground]))
    # slabs rest on the transversal walls only, clear of the facade
    for i in range(p.n_storeys):
        lo, hi = boxes(m, g[f"slabs_floor{i + 1}"])
        assert np.allclose(lo[:, 2], lay.slab_bottom[i]) and np.allclose(hi[:, 2], lay.slab_top[i])
        assert lo[:, 1].min() >= t + p.slab_gap - 1e-9
        assert len(g[f"slabs_floor{i + 1}"]) == (1 if p.half else 2)
    wl, wh = boxes(m, g["transversal_walls"])
    for i in range(p.n_storeys):
        assert np.isclose(wh[:, 2], lay.slab_bottom[i]).sum() > 0
    fl, fh = boxes(m, g["facade"])
    assert fh[:, 2].max() == pytest.approx(lay.height)
    # toothing: the corner square belongs to the facade in even courses and the slab bands
    for k in range(p.n_storeys * lay.n_storey):
        z = (k + 0.5) * h
        for x in (t / 2, Lx - t / 2):
            pt = np.array([x, t / 2, z])
            in_fac = np.all((fl < pt) & (pt < fh), axis=1).any()
            in_tr = np.all((wl < pt) & (pt < wh), axis=1).any()
            band = k % lay.n_storey >= lay.n_masonry
            assert in_fac == (k % 2 == 0 or band) and in_tr == (not in_fac), (k, x)
    # symmetry plane
    if p.half:
        ids = g["symmetry_nodes"]
        assert len(ids) > 0 and np.allclose(m.nodes[ids, 1], p.depth / 2)
        assert np.isclose(m.nodes[:, 1], p.depth / 2).sum() == len(ids) + \
            np.isclose(m.nodes[m.block_nodes(g["foundation"]), 1], p.depth / 2).sum()
        assert m.nodes[:, 1].max() == pytest.approx(p.depth / 2)


@pytest.mark.parametrize("half", [True, False])
@pytest.mark.parametrize("coarse", [True, False])
def test_coarse_house(half, coarse):
    p = HouseParams(half=half).scaled(coarse)
    m = Model()
    g = terraced_house(m, p, MAT, STEEL, STEEL)
    assert m.n_blocks < 250
    check_house(m, g, p)


def test_default_house():
    p = HouseParams()
    lay = p.layout()
    assert (lay.n_storey, lay.n_slab, lay.n_masonry) == (33, 2, 31)
    assert lay.slab_thickness == pytest.approx(0.162) and lay.symmetry_y == pytest.approx(2.65)
    m = Model()
    g = terraced_house(m, p, MAT, STEEL, STEEL)
    check_house(m, g, p)
    assert 1500 < len(g["masonry"]) < 4000


@pytest.mark.parametrize("kw, match", [(dict(pier_wide=3.0, pier_narrow=2.5), "opening"),
                                       (dict(sills=(0.0,)), "sills"),
                                       (dict(pier_narrow=0.15), "pier_narrow"),
                                       (dict(depth=-1.0), "depth"),
                                       (dict(heads=(2.187, 0.5)), "sill"),
                                       (dict(storey_height=0.2), "storey_height"),
                                       (dict(half="no"), "half must be True or False"),
                                       (dict(sills=None), "sills must be a list of heights"),
                                       (dict(length=True), "length must be a positive length")])
def test_house_errors(kw, match):
    m = Model()
    with pytest.raises(GeometryError, match=match):
        terraced_house(m, HouseParams(**kw), MAT, STEEL, STEEL)
    assert m.n_blocks == 0
    with pytest.raises(GeometryError, match="slab_material"):
        terraced_house(m, HouseParams(), MAT, STEEL, None)


def test_contacts_sum_to_joint_areas():
    m = Model()
    m.set_joint_law(object())
    add_wall(m, (0, 0, 0), 0.44, 3 * H, MAT)
    contacts = detect_contacts(m)
    # bed joints: 2 x (0.44 x T); head joints: course 0 one, course 1 two, course 2 one
    assert contacts.area.sum() == pytest.approx(2 * 0.44 * T + 4 * H * T, rel=1e-9)


def test_house_contacts():
    """Slabs touch the transversal walls only; piers and transversal walls are interlocked."""
    p = HouseParams().scaled()
    m = Model()
    m.set_joint_law(object())
    g = terraced_house(m, p, MAT, STEEL, STEEL)
    c = detect_contacts(m)
    grp = np.array(m.block_group)
    pairs = {tuple(sorted(x)) for x in zip(grp[c.blocks[:, 0]], grp[c.blocks[:, 1]])}
    slab_pairs = {q for q in pairs if any(s.startswith("slabs") for s in q)}
    assert slab_pairs == {tuple(sorted((f"slabs_floor{i}", f"transversal_wall_{w}")))
                          for i in (1, 2) for w in (1, 2)}
    assert ("pier_wide", "transversal_wall_1") in pairs
    assert ("pier_narrow", "transversal_wall_2") in pairs
    lay, t = p.layout(), p.brick.thickness
    on_slab = np.isin(c.blocks, g["slabs_floor1"]).any(axis=1)
    # each slab bears on the walls below (x in [0, t] twice, y from the slab edge to the plane)
    # and carries the walls above: 4 bearing areas
    width = lay.model_depth - t - p.slab_gap
    assert c.area[on_slab].sum() == pytest.approx(4 * t * width, rel=1e-9)

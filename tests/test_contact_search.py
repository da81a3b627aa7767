"""Node-to-face contact detection: areas, counts, projections, gaps, laws, sliding, timing."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from dr_masonry.contact_search import (ContactSet, clipped_area, detect_contacts, project_bilinear,
                                       redetect)
from dr_masonry.model import Model, ModelError


class Mat:
    """Stand-in block material (the model only needs ``params_array``)."""

    def params_array(self):
        return np.zeros(3)


MAT = Mat()
LAW = object()


def new_model(law=True):
    m = Model()
    if law:
        m.set_joint_law(LAW)
    return m


def bilinear(xq, r, s):
    """Plain reference of the bilinear map: point (3,) of quad xq (4, 3) at (r, s)."""
    n = 0.25 * np.array([(1 - r) * (1 - s), (1 + r) * (1 - s), (1 + r) * (1 + s), (1 - r) * (1 + s)])
    return n @ xq


def master_points(m, cs):
    return np.array([bilinear(m.nodes[q], *xi) for q, xi in zip(cs.master, cs.xi)])


def face_sums(cs):
    """Sum of the areas per (slave block, master block) pair."""
    out = {}
    for (bs, bm), a in zip(cs.blocks, cs.area):
        out[(int(bs), int(bm))] = out.get((int(bs), int(bm)), 0.0) + a
    return out


def interval(a0, a1, b0, b1):
    return max(0.0, min(a1, b1) - max(a0, b0))


def rotation(a, b, c):
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    rz = np.array([[ca, -sa, 0], [sa, ca, 0], [0, 0, 1]])
    ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    rx = np.array([[1, 0, 0], [0, cc, -sc], [0, sc, cc]])
    return rz @ ry @ rx


# ------------------------------------------------------------------ helpers against references
def test_clipped_area_rectangles_rotated():
    rng = np.random.default_rng(0)
    n = 200
    lo1, lo2 = rng.uniform(-1, 1, (n, 2)), rng.uniform(-1, 1, (n, 2))
    hi1, hi2 = lo1 + rng.uniform(0.1, 1.5, (n, 2)), lo2 + rng.uniform(0.1, 1.5, (n, 2))

    def rect(lo, hi):
        return np.stack([lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]])

    ang = rng.uniform(0, 2 * np.pi, n)
    subj, clip, ref = [], [], []
    for k in range(n):
        c, s = np.cos(ang[k]), np.sin(ang[k])
        rot = np.array([[c, -s], [s, c]])
        sub = rect(lo1[k], hi1[k]) @ rot.T
        subj.append(sub[::-1] if k % 2 else sub)          # either orientation
        clip.append(rect(lo2[k], hi2[k]) @ rot.T)
        ref.append(interval(lo1[k, 0], hi1[k, 0], lo2[k, 0], hi2[k, 0])
                   * interval(lo1[k, 1], hi1[k, 1], lo2[k, 1], hi2[k, 1]))
    np.testing.assert_allclose(clipped_area(np.array(subj), np.array(clip)), ref, atol=1e-13)


def test_clipped_area_triangle_corner():
    # unit square clipped by a square rotated 45 deg around its corner (1, 1): a triangle-free
    # case with a known area: the diamond |x-1|+|y-1| <= 1 inside [0,1]^2 is a right triangle 1/2
    sq = np.array([[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]])
    diamond = np.array([[[1.0, 0.0], [2.0, 1.0], [1.0, 2.0], [0.0, 1.0]]])
    assert clipped_area(sq, diamond)[0] == pytest.approx(0.5, abs=1e-15)


def test_project_bilinear_recovers_points():
    rng = np.random.default_rng(1)
    n = 100
    base = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.2, 0.9, 0.0], [-0.1, 0.8, 0.0]])
    xq = base[None] + rng.uniform(-0.1, 0.1, (n, 4, 3)) * [1, 1, 0]
    R = np.array([rotation(*a) for a in rng.uniform(0, 2 * np.pi, (n, 3))])
    xq = np.einsum("nij,nkj->nki", R, xq)
    rs = rng.uniform(-1.3, 1.3, (n, 2))
    p = np.array([bilinear(xq[k], *rs[k]) for k in range(n)])
    r, s = project_bilinear(xq, p)
    np.testing.assert_allclose(np.column_stack([r, s]), rs, atol=1e-10)


# ------------------------------------------------------------------ simple cases by hand
def test_stack_bond_two_boxes_by_hand():
    m = new_model()
    m.add_box((0, 0, 0), (0.22, 0.1, 0.05), MAT, (4, 1, 2))
    m.add_box((0, 0, 0.05), (0.22, 0.1, 0.05), MAT, (4, 1, 2))
    cs = detect_contacts(m)
    assert m.contacts is cs
    assert cs.n == 10                                # 5 x 2 nodes of the slave face
    assert np.all(cs.blocks == [0, 1])               # tie -> lower block id is slave
    top = m.block_face(0, 1)[0]
    assert set(cs.slave) == set(top.ravel())
    el = 0.055 * 0.1
    xs = m.nodes[cs.slave]
    corner = np.isclose(xs[:, 0], 0.0) | np.isclose(xs[:, 0], 0.22)
    np.testing.assert_allclose(cs.area[corner], el / 4)
    np.testing.assert_allclose(cs.area[~corner], el / 2)
    assert cs.area.sum() == pytest.approx(0.22 * 0.1, rel=1e-14)
    np.testing.assert_allclose(cs.gap0, 0.0, atol=1e-15)
    np.testing.assert_allclose(master_points(m, cs), xs, atol=1e-15)
    assert np.all(np.abs(cs.xi) <= 1.0)
    # master quads are faces of block 1 with their normal out of block 1 (-z)
    assert np.all(np.isin(cs.master, m.block_face(1, 0)[0]))
    xq = m.nodes[cs.master]
    nrm = np.cross(xq[:, 1] - xq[:, 0], xq[:, 3] - xq[:, 0])
    assert np.all(nrm[:, 2] < 0)
    assert np.all(np.diff(cs.slave) >= 0)
    assert np.all(cs.law == 0)


def test_running_bond_half_bricks_by_hand():
    m = new_model()
    m.add_box((0, 0, 0), (0.22, 0.1, 0.05), MAT, (4, 1, 2))
    m.add_box((0, 0, 0.05), (0.11, 0.1, 0.05), MAT, (2, 1, 2))
    m.add_box((0.11, 0, 0.05), (0.11, 0.1, 0.05), MAT, (2, 1, 2))
    cs = detect_contacts(m)
    # bed: 10 nodes, the 2 nodes under the head joint count twice; head joint: 2 x 3 nodes
    assert cs.n == 18
    sums = face_sums(cs)
    assert sums == pytest.approx({(0, 1): 0.011, (0, 2): 0.011, (1, 2): 0.1 * 0.05}, rel=1e-13)
    mid = cs.slave[(cs.blocks[:, 1] == 1) & np.isclose(m.nodes[cs.slave, 0], 0.11)]
    assert mid.size == 2
    for node in mid:
        rows = cs.slave == node
        np.testing.assert_allclose(cs.area[rows], 0.055 * 0.1 / 4)
        assert set(cs.blocks[rows, 1]) == {1, 2}
    np.testing.assert_allclose(master_points(m, cs), m.nodes[cs.slave], atol=1e-15)
    np.testing.assert_allclose(cs.gap0, 0.0, atol=1e-15)
    # canonical master frames: first quad edge along +x on the bed joint (normal -z) of both
    # master blocks, along +y on the head joint (normal -x)
    xq = m.nodes[cs.master]
    e = xq[:, 1] - xq[:, 0]
    e /= np.linalg.norm(e, axis=1)[:, None]
    bed = cs.blocks[:, 0] == 0
    np.testing.assert_allclose(e[bed], np.tile([1.0, 0, 0], (bed.sum(), 1)), atol=1e-15)
    np.testing.assert_allclose(e[~bed], np.tile([0, 1.0, 0], ((~bed).sum(), 1)), atol=1e-15)


def test_coarse_on_fine_mesh_fine_side_is_slave():
    m = new_model()
    m.add_box((0, 0, 0), (0.22, 0.1, 0.05), MAT, (1, 1, 1))        # coarse below
    m.add_box((0, 0, 0.05), (0.22, 0.1, 0.05), MAT, (4, 2, 2))     # fine above
    cs = detect_contacts(m)
    assert np.all(cs.blocks == [1, 0])
    assert cs.n == 5 * 3
    assert cs.area.sum() == pytest.approx(0.022, rel=1e-14)
    np.testing.assert_allclose(master_points(m, cs), m.nodes[cs.slave], atol=1e-15)
    assert np.all(np.isin(cs.master, m.block_face(0, 1)[0]))


@settings(max_examples=40, deadline=None)
@given(dx=st.floats(-0.2, 0.2), dy=st.floats(-0.09, 0.09),
       d1=st.tuples(st.integers(1, 5), st.integers(1, 3), st.integers(1, 2)),
       d2=st.tuples(st.integers(1, 5), st.integers(1, 3), st.integers(1, 2)))
def test_partial_overlap_per_node_areas(dx, dy, d1, d2):
    """Per-node tributary areas against closed-form rectangle intersections."""
    m = new_model()
    o1, s1 = np.array([0.0, 0.0, 0.0]), np.array([0.22, 0.1, 0.05])
    o2, s2 = np.array([dx, dy, 0.05]), np.array([0.21, 0.11, 0.05])
    m.add_box(o1, s1, MAT, d1)
    m.add_box(o2, s2, MAT, d2)
    cs = detect_contacts(m)
    ov = interval(0, 0.22, dx, dx + 0.21) * interval(0, 0.1, dy, dy + 0.11)
    h1 = s1[0] * s1[1] / (d1[0] * d1[1])
    h2 = s2[0] * s2[1] / (d2[0] * d2[1])
    slave = 0 if h1 <= h2 * (1 + 1e-9) else 1
    (os_, ss, ds), (om, sm) = ((o1, s1, d1), (o2, s2)) if slave == 0 else ((o2, s2, d2), (o1, s1))
    ref = {}
    grid = m.block_face(slave, 1 if slave == 0 else 0)[0]
    for node in grid.ravel():
        x, y = m.nodes[node, :2]
        hx, hy = ss[0] / ds[0] / 2, ss[1] / ds[1] / 2
        a = (interval(max(os_[0], x - hx), min(os_[0] + ss[0], x + hx), om[0], om[0] + sm[0])
             * interval(max(os_[1], y - hy), min(os_[1] + ss[1], y + hy), om[1], om[1] + sm[1]))
        if a > 1e-12 * h1:
            ref[int(node)] = a
    assert np.all(cs.blocks[:, 0] == slave)
    got = dict(zip(cs.slave.tolist(), cs.area.tolist()))
    assert set(got) == set(ref)
    for k in ref:
        assert got[k] == pytest.approx(ref[k], rel=1e-9, abs=1e-15)
    assert cs.area.sum() == pytest.approx(ov, rel=1e-12)
    # the master point is the closest point of the master face to the slave node
    xs = m.nodes[cs.slave]
    near = np.column_stack([np.clip(xs[:, 0], om[0], om[0] + sm[0]),
                            np.clip(xs[:, 1], om[1], om[1] + sm[1]), xs[:, 2]])
    np.testing.assert_allclose(master_points(m, cs), near, atol=1e-14)
    assert np.all(np.abs(cs.xi) <= 1.0)
    # gap0 holds the in-plane offset: [u, d1, d2] with u = 0 and |d| = distance to the face
    np.testing.assert_allclose(cs.gap0[:, 0], 0.0, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(cs.gap0[:, 1:], axis=1),
                               np.linalg.norm(xs - near, axis=1), atol=1e-14)


def voussoirs(m, n, ri, ro, t, divs, R=np.eye(3), theta=(0.2, 2.9)):
    """A semicircular-ish ring of n wedge blocks (angles decreasing along natural xi)."""
    th = np.linspace(theta[0], theta[1], n + 1)
    for k in range(n):
        a, b = th[k + 1], th[k]
        c = []
        for rad in (ri, ro):
            for ang, y in ((a, 0.0), (b, 0.0), (b, t), (a, t)):
                c.append([rad * np.cos(ang), y, rad * np.sin(ang)])
        m.add_block(np.array(c) @ R.T, MAT, divs[k])
    return th


@settings(max_examples=15, deadline=None)
@given(angles=st.tuples(*[st.floats(0, 2 * np.pi)] * 3),
       divs=st.lists(st.tuples(st.integers(1, 3), st.integers(1, 2), st.integers(1, 3)),
                     min_size=5, max_size=5))
def test_arch_wedges_rotated(angles, divs):
    R = rotation(*angles)
    m = new_model()
    ri, ro, t = 1.0, 1.3, 0.25
    voussoirs(m, 5, ri, ro, t, divs, R)
    cs = detect_contacts(m)
    sums = face_sums(cs)
    assert len(sums) == 4
    for (bs, bm), a in sums.items():
        assert abs(bs - bm) == 1
        assert a == pytest.approx((ro - ri) * t, rel=1e-12)
        # faces coincide: every slave face node is a contact point, 1 row each
        k = (cs.blocks[:, 0] == bs) & (cs.blocks[:, 1] == bm)
        assert k.sum() == (divs[bs][1] + 1) * (divs[bs][2] + 1)
        # slave = finer radial face mesh, tie -> lower block id
        hs, hm = 1.0 / np.prod(divs[bs][1:]), 1.0 / np.prod(divs[bm][1:])
        assert hs < hm or (hs == hm and bs < bm)
    np.testing.assert_allclose(master_points(m, cs), m.nodes[cs.slave], atol=1e-12)
    np.testing.assert_allclose(cs.gap0, 0.0, atol=1e-12)


def test_separated_and_edge_touching_blocks_give_no_contacts():
    m = new_model()
    m.add_box((0, 0, 0), (0.2, 0.1, 0.05), MAT)
    m.add_box((0, 0, 0.051), (0.2, 0.1, 0.05), MAT)          # 1 mm gap >> default tol
    assert detect_contacts(m).n == 0
    m = new_model()
    m.add_box((0, 0, 0), (0.2, 0.1, 0.05), MAT, (2, 1, 1))
    m.add_box((0.2, 0, 0.05), (0.2, 0.1, 0.05), MAT, (2, 1, 1))   # diagonal: one edge shared
    m.add_box((0.0, 0.1, 0.05), (0.2, 0.1, 0.05), MAT, (2, 1, 1))  # another edge
    assert detect_contacts(m).n == 0
    # a gap below tol is found, and gap0 holds it
    m = new_model()
    m.add_box((0, 0, 0), (0.2, 0.1, 0.05), MAT)
    m.add_box((0, 0, 0.05 + 1e-9), (0.2, 0.1, 0.05), MAT)
    cs = detect_contacts(m)
    assert cs.n == 4
    np.testing.assert_allclose(cs.gap0[:, 0], 1e-9, rtol=1e-5)
    assert detect_contacts(m, tol=1e-10).n == 0


def test_fixed_pairs_skipped_and_laws():
    m = new_model()
    m.add_box((0, 0, -0.1), (0.2, 0.1, 0.1), MAT, fixed=True)
    m.add_box((0.2, 0, -0.1), (0.2, 0.1, 0.1), MAT, fixed=True)
    m.add_box((0, 0, 0), (0.4, 0.1, 0.05), MAT, (2, 1, 1))
    cs = detect_contacts(m)
    assert set(map(tuple, cs.blocks.tolist())) == {(0, 2), (1, 2)}   # no fixed-fixed pair
    assert face_sums(cs) == pytest.approx({(0, 2): 0.02, (1, 2): 0.02})

    tied, other = object(), object()
    m = new_model()
    m.add_box((0, 0, 0), (0.2, 0.1, 0.05), MAT)
    m.add_box((0, 0, 0.05), (0.2, 0.1, 0.05), MAT, joint=tied)
    m.add_box((0, 0, 0.1), (0.2, 0.1, 0.05), MAT, joint=other)
    m.add_box((0, 0, 0.15), (0.2, 0.1, 0.05), MAT)
    cs = detect_contacts(m)
    law = {tuple(sorted(b)): m.joint_laws[k] for b, k in zip(cs.blocks.tolist(), cs.law)}
    assert law == {(0, 1): tied, (1, 2): tied, (2, 3): other}

    m = new_model(law=False)
    m.add_box((0, 0, 0), (0.2, 0.1, 0.05), MAT)
    m.add_box((0, 0, 0.05), (0.2, 0.1, 0.05), MAT)
    with pytest.raises(ModelError, match="blocks 0 and 1"):
        detect_contacts(m)
    with pytest.raises(ModelError, match="tol"):
        detect_contacts(m, tol=-1.0)


def test_contact_set_subset_and_shapes():
    m = new_model()
    m.add_box((0, 0, 0), (0.22, 0.1, 0.05), MAT, (4, 1, 2))
    m.add_box((0, 0, 0.05), (0.22, 0.1, 0.05), MAT, (4, 1, 2))
    cs = detect_contacts(m)
    sub = cs.subset(cs.area > 0.002)                 # the 6 non-corner nodes
    assert sub.n == 6 and np.all(sub.area > 0.002)
    assert sub.master.shape == (6, 4) and sub.gap0.shape == (6, 3)
    with pytest.raises(ValueError, match="master"):
        ContactSet(cs.slave, cs.master[:, :3], cs.xi, cs.area, cs.law, cs.blocks, cs.gap0)


# ------------------------------------------------------------------ finite sliding
def test_redetect_moves_slid_nodes():
    from dr_masonry.kernels.contact_frame import local_gap

    m = new_model()
    m.add_box((0, 0, 0), (0.22, 0.1, 0.05), MAT, (4, 1, 2))      # slave (tie, lower id)
    m.add_box((0, 0, 0.05), (0.11, 0.1, 0.05), MAT, (2, 1, 2))
    m.add_box((0.11, 0, 0.05), (0.11, 0.1, 0.05), MAT, (2, 1, 2))
    cs = detect_contacts(m)
    x = m.nodes.copy()
    x[m.block_nodes(0), 0] += 0.07                               # slide block 0 by 70 mm
    new, src = redetect(m, cs, x)
    x0 = m.nodes[cs.slave[src], 0]
    # by hand: a node at x0 now sits at x0 + 0.07; master block 1 spans [0, 0.11], 2 [0.11, 0.22]
    xn = x0 + 0.07
    head = cs.blocks[src, 0] == 1
    assert np.all(new.blocks[head] == cs.blocks[src][head])       # head joint rows untouched
    b = cs.blocks[src, 0] == 0
    exp = np.where(xn[b] < 0.11 - 1e-9, 1, 2)
    assert np.all(new.blocks[b, 1] == exp)
    # dropped: the two nodes at x0 = 0.22 (now 70 mm beyond the wall end, reach 50 mm)
    dropped = np.setdiff1d(np.arange(cs.n), src)
    np.testing.assert_allclose(m.nodes[cs.slave[dropped], 0], 0.22)
    assert dropped.size == 2
    # the node at x0 = 0.165 is 15 mm beyond block 2's face: kept unchanged
    keep = b & np.isclose(x0, 0.165)
    assert keep.sum() == 2 and np.all(new.xi[keep] == cs.xi[src][keep])
    # switched rows: the master point is under the slave node; the gap seen by the law is
    # continuous (u = 0, |d| = 70 mm slip along x)
    moved = b & ~np.isclose(x0, 0.165)
    assert moved.sum() == 8
    np.testing.assert_allclose(master_points(m, new.subset(moved))[:, :2],
                               x[new.slave[moved]][:, :2], atol=1e-14)
    for k in np.flatnonzero(moved):
        g = np.empty(3)
        local_gap(x[new.slave[k]], x[new.master[k]], new.xi[k, 0], new.xi[k, 1], g)
        np.testing.assert_allclose(g - new.gap0[k], [0.0, 0.07, 0.0], atol=1e-14)
    np.testing.assert_allclose(new.area, cs.area[src])
    # nothing moved: identity
    same, src2 = redetect(m, cs, m.nodes)
    assert same.n == cs.n and np.all(src2 == np.arange(cs.n))


def test_redetect_rejects_bad_coordinates():
    m = new_model()
    m.add_box((0, 0, 0), (0.2, 0.1, 0.05), MAT)
    m.add_box((0, 0, 0.05), (0.2, 0.1, 0.05), MAT)
    cs = detect_contacts(m)
    with pytest.raises(ModelError, match="x_current"):
        redetect(m, cs, m.nodes[:3])


# ------------------------------------------------------------------ scale
def running_bond_wall(nl, nc, length=0.22, t=0.1, h=0.1):
    m = new_model()
    m.add_box((0, 0, -0.2), (nl * length, t, 0.2), MAT, fixed=True)
    for c in range(nc):
        z = c * h
        if c % 2 == 0:
            for i in range(nl):
                m.add_box((i * length, 0, z), (length, t, h), MAT, (4, 1, 2))
        else:
            m.add_box((0, 0, z), (length / 2, t, h), MAT, (2, 1, 2))
            for i in range(nl - 1):
                m.add_box((length / 2 + i * length, 0, z), (length, t, h), MAT, (4, 1, 2))
            m.add_box((nl * length - length / 2, 0, z), (length / 2, t, h), MAT, (2, 1, 2))
    return m


def test_contacts_of_a_3000_block_wall():
    """Every bed and head joint of a 60 x 50 running-bond wall, each slave node on its face."""
    nl, nc, length, t, h = 60, 50, 0.22, 0.1, 0.1
    m = running_bond_wall(nl, nc, length, t, h)
    cs = detect_contacts(m)
    bed = nc * nl * length * t
    head = ((nc + 1) // 2 * (nl - 1) + nc // 2 * nl) * t * h
    assert cs.area.sum() == pytest.approx(bed + head, rel=1e-12)
    np.testing.assert_allclose(master_points(m, cs), m.nodes[cs.slave], atol=1e-12)

"""Block model: meshing of any convex hexahedron and clear errors for malformed input."""
import numpy as np
import pytest

from dr_masonry import JointLaw, Model, ModelError, PlasticDamage
from dr_masonry.contact_search import detect_contacts
from dr_masonry.kernels.hex8 import hex_geometry
from dr_masonry.model import box_corners

MAT = PlasticDamage.elastic(1e9, 0.2, 1000.0)


def test_skewed_block_meshes_with_positive_jacobians():
    c = box_corners((0, 0, 0), (0.3, 0.1, 0.2))
    c[4:, 0] += 0.08          # top face sheared
    c[2, 1] += 0.03           # a wedge-like, non-parallel face
    c[6, 2] += 0.05
    m = Model()
    m.add_block(c, MAT, (5, 2, 3))
    dN, _, wdet, h = hex_geometry(m.nodes, m.elements)
    assert np.all(wdet > 0)
    # sub-meshing follows the block's trilinear map: the volume is that of the single hexahedron
    one = Model()
    one.add_block(c, MAT)
    assert wdet.sum() == pytest.approx(hex_geometry(one.nodes, one.elements)[2].sum(), rel=1e-12)


def test_inverted_corners_are_refused():
    c = box_corners((0, 0, 0), (1, 1, 1))[[4, 5, 6, 7, 0, 1, 2, 3]]
    with pytest.raises(ModelError, match="block 0: corners are inverted or degenerate"):
        Model().add_block(c, MAT)


@pytest.mark.parametrize("bad, msg", [
    (np.zeros((7, 3)), "shape"), (np.full((8, 3), np.nan), "NaN"), (np.zeros((8, 3)), "coincide")])
def test_malformed_corners(bad, msg):
    with pytest.raises(ModelError, match=msg):
        Model().add_block(bad, MAT)


def test_overlapping_blocks_are_refused():
    m = Model()
    m.add_box((0, 0, 0), (0.22, 0.1, 0.08), MAT)
    m.add_box((0.2, 0, 0.05), (0.22, 0.1, 0.08), MAT)   # 20 mm x 30 mm interpenetration
    with pytest.raises(ModelError, match="blocks 0 and 1 overlap"):
        detect_contacts(m)


def test_touching_and_wedge_blocks_are_not_overlaps():
    """Blocks that only touch (faces, edges) pass; so do the wedges of an arch, whose bounding
    boxes overlap although the blocks do not."""
    m = Model()
    m.set_joint_law(JointLaw.reference())
    m.add_box((0, 0, 0), (0.22, 0.1, 0.08), MAT)
    m.add_box((0.22, 0, 0), (0.22, 0.1, 0.08), MAT)
    m.add_box((0.44, 0, 0.08), (0.22, 0.1, 0.08), MAT)
    r0, r1, n = 1.0, 1.3, 6
    t = np.linspace(0, np.pi / 2, n + 1)
    for a0, a1 in zip(t[:-1], t[1:]):
        ring = [(r0 * np.cos(a0), r0 * np.sin(a0)), (r1 * np.cos(a0), r1 * np.sin(a0)),
                (r1 * np.cos(a1), r1 * np.sin(a1)), (r0 * np.cos(a1), r0 * np.sin(a1))]
        c = np.array([[x + 2, y0, y] for x, y in ring for y0 in (0,)] +
                     [[x + 2, 0.1, y] for x, y in ring])
        # corners 0-3 counter-clockwise seen from +z: here the ring lies in x-z; reorder to x-y-z
        c = c[:, [0, 2, 1]][[0, 1, 2, 3, 4, 5, 6, 7]]
        m.add_block(c, MAT)
    cs = detect_contacts(m)
    area = {}
    for (a, b), ar in zip(np.sort(cs.blocks, axis=1), cs.area):
        area[(int(a), int(b))] = area.get((int(a), int(b)), 0.0) + ar
    # the head joint of boxes 0-1 (0.1 x 0.08 m), none where box 2 only touches box 1 along an
    # edge, and each of the 5 joints between the 6 wedges ((r1 - r0) x 0.1 m)
    assert sorted(area) == [(0, 1), (3, 4), (4, 5), (5, 6), (6, 7), (7, 8)]
    assert area[(0, 1)] == pytest.approx(0.1 * 0.08, rel=1e-12)
    for pair in [(3, 4), (4, 5), (5, 6), (6, 7), (7, 8)]:
        assert area[pair] == pytest.approx((r1 - r0) * 0.1, rel=1e-12)

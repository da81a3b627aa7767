"""3-D damage views: the colour at the projected pixel of a brick or joint is that of its damage."""
import colorsys

import numpy as np
import pytest
from matplotlib.image import imread

from dr_masonry.results import model_arrays
from dr_masonry.viz import render
from dr_masonry.viz.render import RenderError, exterior_faces
from dr_masonry.viz.views import (auto_warp, damage_view, joint_patches, node_values,
                                  shrunk_positions, write_views)
from conftest import fake_fields, tiny_model, write_fake_result

needs_vtk = pytest.mark.skipif(not render.vtk_offscreen_available(),
                               reason="no VTK offscreen rendering here")
W, H = 400, 300
GAP = 0.01        # m


@pytest.fixture()
def h5(tmp_path):
    p = tmp_path / "run.h5"
    write_fake_result(p)
    return p


def lut(v):
    """VTK's lookup table of the views at v in [0, 1]: hue 2/3 (1 - v), full saturation, value."""
    return np.array(colorsys.hsv_to_rgb(2 / 3 * (1 - v), 1.0, 1.0))


def pixel(img, x, z):
    """The pixel of point (x, z) m of the tiny model (x 0..0.2, z 0..0.2) in its elevation, by
    hand: the model viewport is 86 % x 93 % of the picture at its lower left, parallel projection
    centred on the bounding box, whose half height (0.1 m) fills 92 % of the viewport's half
    height (the box's half width over the viewport's aspect is smaller)."""
    vw, vh = 0.86 * W, 0.93 * H
    per_m = 0.92 * (vh / 2) / 0.1
    col = vw / 2 + (x - 0.1) * per_m
    row = H - (vh / 2 + (z - 0.1) * per_m)
    return img[int(round(row)), int(round(col))]


def view(h5, path, **kw):
    kw = dict(dict(field="dt", camera="elevation", warp=0.0, gap=GAP, size=(W, H)), **kw)
    return imread(damage_view(h5, path, **kw).path)[..., :3]


#: front-face centres (x, z) of the tiny model's elements, the blocks shrunk by GAP: block 0
#: spans x 0..0.2, z 0..0.1 about its centre (0.1, 0.05), scaled by 0.9 in x and 0.8 in z
CENTRES = [(0.055, 0.05), (0.145, 0.05), (0.055, 0.15), (0.145, 0.15)]


@needs_vtk
def test_bricks_coloured_by_their_smoothed_damage(h5, tmp_path):
    """Element e's front face centre shows the node-averaged value there: in each block the
    nodes at its outer ends carry the element's dt, the middle nodes the mean of the two, so
    the face centre (on either diagonal of its two triangles) has (3 dt_e + dt_other) / 4."""
    img = view(h5, tmp_path / "v.png", joint_field=None, curve={"x": "disp", "y": "force"})
    dt = fake_fields(tiny_model(), 4)["dt"]              # 0 (undamaged) ... 0.4 (damaged)
    want = [(3 * dt[0] + dt[1]) / 4, (dt[0] + 3 * dt[1]) / 4,
            (3 * dt[2] + dt[3]) / 4, (dt[2] + 3 * dt[3]) / 4]
    for e, (x, z) in enumerate(CENTRES):
        np.testing.assert_allclose(pixel(img, x, z), lut(want[e]), atol=0.08,
                                   err_msg=f"element {e}")
    assert np.abs(pixel(img, *CENTRES[3]) - pixel(img, *CENTRES[0])).max() > 0.5
    # the gap between the blocks (no damaged joint drawn) is the white background
    np.testing.assert_allclose(pixel(img, 0.03, 0.1), 1.0)


@needs_vtk
def test_joint_faces_at_their_contact_points(h5, tmp_path):
    """The bed joint's front contact points (y = 0, x = 0, 0.1, 0.2) have D = 0, 0.32, 0.64:
    above the threshold, the point's share of the face fills the gap in the colour of its D."""
    img = view(h5, tmp_path / "j.png", threshold=0.5)
    np.testing.assert_allclose(pixel(img, 0.17, 0.1), lut(0.64), atol=0.08)
    for x in (0.03, 0.1):                               # D below 0.5: nothing in the gap
        np.testing.assert_allclose(pixel(img, x, 0.1), 1.0)
    img = view(h5, tmp_path / "k.png", threshold=0.3)
    np.testing.assert_allclose(pixel(img, 0.1, 0.1), lut(0.32), atol=0.08)
    np.testing.assert_allclose(pixel(img, 0.03, 0.1), 1.0)


@needs_vtk
def test_cut_removes_the_blocks_in_front_and_keeps_the_frame(h5, tmp_path):
    dt = fake_fields(tiny_model(), 4)["dt"]
    img = view(h5, tmp_path / "c.png", cut=(2, 0.1), joint_field=None)
    for x, z in CENTRES[:2]:                            # block 0 (centre z = 0.05) left out
        np.testing.assert_allclose(pixel(img, x, z), 1.0)
    np.testing.assert_allclose(pixel(img, *CENTRES[3]), lut((dt[2] + 3 * dt[3]) / 4), atol=0.08)


@needs_vtk
def test_write_views_names_and_one_magnification(h5, tmp_path):
    paths = write_views(h5, str(tmp_path / "run"), [("peak", 1), ("end", -1)],
                        {"cracks": dict(camera="elevation"), "crushing": dict(field="dc")})
    assert [p.rsplit("/", 1)[1] for p in paths] == [
        "run_cracks_peak.png", "run_crushing_peak.png", "run_cracks_end.png",
        "run_crushing_end.png"]
    assert all(imread(p).shape[:2] == (900, 1200) for p in paths)


def test_joint_patches_and_node_values():
    m = tiny_model()
    a, _ = model_arrays(m)
    _, quads = exterior_faces(a["elements"])
    con = {"slave": m.contacts.slave, "master": m.contacts.master}
    d = np.linspace(0.0, 0.8, m.contacts.n)
    face, corner, value = joint_patches(quads, m.nodes, con, d, 0.3)
    # points 2..5 (D 0.32 ... 0.8): each on block 0's top face, one quarter per element face
    # at its node (the middle nodes x = 0.1 on both element faces)
    at = quads[face, corner]
    assert sorted(at.tolist()) == sorted([m.contacts.slave[2]] * 2 + [m.contacts.slave[3]] * 2
                                         + [m.contacts.slave[4], m.contacts.slave[5]])
    np.testing.assert_allclose(m.nodes[quads[face]][..., 2], 0.1)       # the top faces only
    d_of = dict(zip(m.contacts.slave.tolist(), d))
    np.testing.assert_allclose(value, [d_of[n] for n in at.tolist()])
    assert joint_patches(quads, m.nodes, con, d, 0.9)[0].size == 0
    # node values: nodes at x = 0 carry element 0's value, at x = 0.1 the mean of elements 0, 1
    v = node_values(a["elements"], np.array([0.0, 1.0, 2.0, 4.0]), m.n_nodes)
    x, z = m.nodes[:, 0], m.nodes[:, 2]
    np.testing.assert_allclose(v[(x == 0.1) & (z == 0.15)], 3.0)


def test_shrinking_and_magnification(h5):
    m = tiny_model()
    a, _ = model_arrays(m)
    x = shrunk_positions(a, m.nodes, 0.01)
    # block 0 spans x 0..0.2, z 0..0.1: its corner (0, 0, 0) moves 0.01 in along each axis
    np.testing.assert_allclose(x[0], [0.01, 0.01, 0.01])
    np.testing.assert_allclose(shrunk_positions(a, m.nodes, 1.0)[0], [0.05, 0.025, 0.025])
    # last frame: U_x = 4e-4 * z / 0.2, largest 4e-4 m; 3 % of 0.2 m / 4e-4 = 15 -> 10
    assert auto_warp(h5) == 10.0
    assert auto_warp(h5, 0) == 1.0                       # no displacement


@pytest.mark.parametrize("kw, word", [({"field": "D"}, "field must be"),
                                      ({"camera": "top"}, "camera must be"),
                                      ({"threshold": -1.0}, "threshold"),
                                      ({"cut": (3, 0.0)}, "cut must be"),
                                      ({"gap": -1.0}, "gap=-1.0 must be"),
                                      ({"joint_field": "dt"}, "no contact field")])
def test_bad_arguments(h5, tmp_path, kw, word):
    with pytest.raises(RenderError, match=word):
        damage_view(h5, tmp_path / "x.png", backend="vtk", **kw)

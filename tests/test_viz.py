"""VTK time series, renders and plots, read back and checked against the written data."""
import colorsys
import os
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import vtk
from matplotlib import colormaps
from matplotlib.image import imread
from vtk.util.numpy_support import vtk_to_numpy

from dr_masonry.results import ResultsError, ResultWriter, open_result
from dr_masonry.viz import plots, render
from dr_masonry.viz.render import RenderError, exterior_faces, render_model
from dr_masonry.viz.vtk_series import block_corner_nodes, export_vtk
from conftest import fake_fields, pixels, saved_figures, tiny_model, write_fake_result


@pytest.fixture()
def h5(tmp_path):
    p = tmp_path / "run.h5"
    write_fake_result(p)
    return p


def read_vtu(path):
    r = vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(str(path))
    r.Update()
    return r.GetOutput()


def arrays_of(data):
    return {data.GetArrayName(i): vtk_to_numpy(data.GetArray(i)) for i in range(data.GetNumberOfArrays())}


def test_export_vtk_round_trip(h5):
    m = tiny_model()
    pvd = export_vtk(h5)
    out = os.path.dirname(pvd)
    assert out == str(h5)[:-3] + "_vtk"
    for coll, n in (("blocks.pvd", 3), ("contacts.pvd", 3)):
        ds = ET.parse(os.path.join(out, coll)).getroot().find("Collection").findall("DataSet")
        assert len(ds) == n
        # the "control" attribute increases strictly, so it is the time
        np.testing.assert_allclose([float(d.get("timestep")) for d in ds], [0.0, 2e-4, 4e-4])
        assert all(os.path.isfile(os.path.join(out, d.get("file"))) for d in ds)
    for inc in (0, 2, 4):
        f = fake_fields(m, inc)
        g = read_vtu(os.path.join(out, f"blocks_{inc:06d}.vtu"))
        assert g.GetNumberOfCells() == m.n_elements
        assert all(g.GetCellType(i) == vtk.VTK_HEXAHEDRON for i in range(g.GetNumberOfCells()))
        conn = vtk_to_numpy(g.GetCells().GetConnectivityArray()).reshape(-1, 8)
        np.testing.assert_array_equal(conn, m.elements)
        np.testing.assert_allclose(vtk_to_numpy(g.GetPoints().GetData()), m.nodes + f["U"])
        pd, cd = arrays_of(g.GetPointData()), arrays_of(g.GetCellData())
        np.testing.assert_array_equal(pd["U"], f["U"])
        np.testing.assert_array_equal(cd["dt"], f["dt"])
        np.testing.assert_array_equal(cd["dc"], f["dc"])
        np.testing.assert_array_equal(cd["block_id"], [0, 0, 1, 1])
        c = read_vtu(os.path.join(out, f"contacts_{inc:06d}.vtu"))
        assert c.GetNumberOfCells() == m.contacts.n
        assert all(c.GetCellType(i) == vtk.VTK_VERTEX for i in range(c.GetNumberOfCells()))
        np.testing.assert_allclose(vtk_to_numpy(c.GetPoints().GetData()),
                                   (m.nodes + f["U"])[m.contacts.slave])
        cp = arrays_of(c.GetPointData())
        for k in ("D", "opening", "slip"):
            np.testing.assert_array_equal(cp[k], f[k])
        np.testing.assert_array_equal(cp["master_block"], np.ones(m.contacts.n))


def test_export_reference_configuration_and_increment_times(tmp_path):
    m = tiny_model(with_contacts=False)
    p = tmp_path / "r.h5"
    with ResultWriter(p, m, {}) as w:
        for inc, ctrl in ((3, 1.0), (7, -1.0)):            # cyclic control: not monotonic
            w.write_frame(inc, {"U": np.ones((m.n_nodes, 3))}, attrs={"control": ctrl})
    pvd = export_vtk(p, tmp_path / "out", warp=0.0)
    ds = ET.parse(pvd).getroot().find("Collection").findall("DataSet")
    assert [float(d.get("timestep")) for d in ds] == [3.0, 7.0]
    assert not os.path.exists(tmp_path / "out" / "contacts.pvd")
    g = read_vtu(tmp_path / "out" / "blocks_000007.vtu")
    np.testing.assert_array_equal(vtk_to_numpy(g.GetPoints().GetData()), m.nodes)


def test_export_of_a_file_without_frames_says_so(tmp_path):
    """A run stopped before its first frame: an error naming the file, not an empty series."""
    p = tmp_path / "r.h5"
    ResultWriter(p, tiny_model(), {}).close()
    with pytest.raises(ResultsError, match=r"r.h5' has no frames to write as VTK .*0 history rows"):
        export_vtk(p, tmp_path / "out")
    assert not os.path.exists(tmp_path / "out")


def test_block_corner_nodes_match_corner_coordinates():
    m = tiny_model()
    m.add_box((1, 0, 0), (0.3, 0.2, 0.1), m.materials[0], divisions=(3, 2, 4))
    c = block_corner_nodes({"block_divisions": m.block_divisions,
                            "block_node_start": m.block_node_start})
    for b in range(m.n_blocks):
        np.testing.assert_allclose(m.nodes[c[b]], m.block_corners[b], atol=1e-12)


def test_exterior_faces_closed_and_outward():
    m = tiny_model()
    elem, quads = exterior_faces(m.elements)
    assert len(quads) == 20   # per block: 2 hexahedra x 6 faces - 2 internal
    x = m.nodes
    nrm = np.cross(x[quads[:, 1]] - x[quads[:, 0]], x[quads[:, 3]] - x[quads[:, 0]])
    out = x[quads].mean(axis=1) - x[m.elements[elem]].mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", nrm, out) > 0)
    area = 0.5 * np.linalg.norm(nrm, axis=1) * 2  # rectangles
    assert area.sum() == pytest.approx(2 * 2 * (0.2 * 0.1 + 0.2 * 0.1 + 0.1 * 0.1))


def assert_picture(png, min_colours=5, min_ink=0.05):
    """A PNG exists, is not blank (a fraction ``min_ink`` of non-white pixels), has colours."""
    img = imread(png)[..., :3]
    assert img.shape[0] > 100 and img.shape[1] > 100
    inked = np.any(img < 0.95, axis=2).mean()
    assert inked > min_ink, f"{png}: only {inked:.1%} of the pixels are not white"
    assert len(np.unique(img.reshape(-1, 3), axis=0)) >= min_colours


BACKENDS = ["matplotlib"] + (["vtk"] if render.vtk_offscreen_available() else [])


#: the tiny model's element centres in the front view (x, z), m, and their pixel offsets from the
#: picture's centre (right, up) in a 400 x 300 render, the camera fitted to the model's bounds
ELEMENT_PIXELS = [(-30, -30), (30, -30), (-30, 30), (30, 30)]   # elements 0..3 (x, then z order)


def expected_colour(backend, field, e):
    """The colour element e of the fake result's last frame must have, from its field value: the
    block's group colour, VTK's lookup table (hue 2/3 (1 - dt), full saturation and value) or
    matplotlib's jet at dt."""
    if field is None:
        return render._GROUP_COLOURS[[0, 0, 1, 1][e]]
    dt = fake_fields(tiny_model(), 4)["dt"][e]
    if backend == "vtk":
        return colorsys.hsv_to_rgb(2 / 3 * (1 - dt), 1.0, 1.0)
    return colormaps["jet"](dt)[:3]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("field", [None, "dt"])
def test_render_colours_at_elements(h5, tmp_path, backend, field):
    """Each element's front face, at its projected pixel, has the colour of its own value."""
    png = tmp_path / f"{backend}_{field}.png"
    out = render_model(h5, png, field=field, frame=-1, warp=0.0, view="front", backend=backend,
                       size=(400, 300))
    assert out.backend == backend and out.path == str(png)
    img = imread(png)[..., :3]
    h, w = img.shape[:2]
    for e, (dx, dz) in enumerate(ELEMENT_PIXELS):
        np.testing.assert_allclose(img[h // 2 - dz, w // 2 + dx], expected_colour(backend, field, e),
                                   atol=0.08, err_msg=f"{backend} {field}: element {e}")


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("field", ["U", "D"])
def test_render_png(h5, tmp_path, backend, field):
    png = tmp_path / f"{backend}_{field}.png"
    out = render_model(h5, png, field=field, warp=100.0, backend=backend, size=(400, 300))
    assert out.backend == backend and out.path == str(png)
    assert_picture(png)
    plain = render_model(h5, tmp_path / "plain.png", warp=100.0, backend=backend, size=(400, 300))
    assert not np.array_equal(imread(png), imread(plain.path))   # the field's colours


def test_render_model_object_and_backend_choice(tmp_path, monkeypatch):
    monkeypatch.setenv("DR_MASONRY_RENDER", "matplotlib")
    out = render_model(tiny_model(), tmp_path / "m.png", view="front", size=(300, 300))
    assert out.backend == "matplotlib"
    assert_picture(out.path)
    img = imread(out.path)[..., :3].reshape(-1, 3)
    # the two groups are drawn with the first two group colours
    for colour in render._GROUP_COLOURS[:2]:
        assert np.any(np.all(np.abs(img - colour) < 0.02, axis=1))
    monkeypatch.setenv("DR_MASONRY_RENDER", "opengl")
    with pytest.raises(RenderError, match="'opengl'"):
        render.choose_backend()


def test_render_errors(h5, tmp_path):
    with pytest.raises(RenderError, match="a Model has no fields"):
        render_model(tiny_model(), tmp_path / "x.png", field="dt", backend="matplotlib")
    with pytest.raises(RenderError, match="no field 'sigma'"):
        render_model(h5, tmp_path / "x.png", field="sigma", backend="matplotlib")
    with pytest.raises(RenderError, match="view must be one of"):
        render_model(h5, tmp_path / "x.png", view="diagonal")


def test_render_size_empty_model_and_output(h5, tmp_path):
    """size must be two pixel counts in [1, MAX_PIXELS]; an empty model and a bad output path
    are named; a missing output folder is created."""
    from dr_masonry.model import Model
    for size in [(0, 0), (-5, 100), "big", (100000, 100000), (400.5, 300)]:
        msg = r"size must be \(width, height\), two integers in \[1, 10000\] pixels, got "
        with pytest.raises(RenderError, match=msg + re.escape(repr(size))):
            render_model(h5, tmp_path / "x.png", size=size, backend="matplotlib")
    with pytest.raises(RenderError, match="render_model: the model has no blocks"):
        render_model(Model(), tmp_path / "x.png", backend="matplotlib")
    with pytest.raises(RenderError, match="render_model: png must be a file path, got None"):
        render_model(h5, None, backend="matplotlib")
    with pytest.raises(RenderError, match=r"png='.*x.xyz' must end in one of .*\.png"):
        render_model(h5, tmp_path / "x.xyz", backend="matplotlib")
    with pytest.raises(RenderError, match=r"png='.*x.jpg' must end in one of \.png$"):
        render_model(h5, tmp_path / "x.jpg", backend="vtk")   # VTK writes PNG only
    out = render_model(h5, tmp_path / "new" / "m.png", size=(300, 200), backend="matplotlib")
    assert imread(out.path).shape[:2] == (200, 300)


def test_plot_history_overlay(h5, tmp_path):
    other = tmp_path / "other.h5"
    write_fake_result(other, n_rows=3)
    png = plots.plot_history([h5, open_result(other)], "disp", "force", tmp_path / "h.png",
                             label=["a", "b"])
    assert_picture(png, min_colours=3, min_ink=0.02)
    with pytest.raises(plots.PlotError, match="no history column 'drift'"):
        plots.plot_history(h5, "drift", "force", tmp_path / "x.png")
    with pytest.raises(plots.PlotError, match="2 labels for 1 runs"):
        plots.plot_history(h5, "disp", "force", tmp_path / "x.png", label=["a", "b"])
    for scale in ("xscale", "yscale"):
        for bad in (0, np.nan, "1"):
            with pytest.raises(plots.PlotError, match=f"plot_history: {scale}={bad!r} must be"):
                plots.plot_history(h5, "disp", "force", tmp_path / "x.png", **{scale: bad})
    with pytest.raises(plots.PlotError, match="results is empty"):
        plots.plot_history([], "disp", "force", tmp_path / "x.png")
    with pytest.raises(plots.PlotError, match="plot_history: png must be a file path, got None"):
        plots.plot_history(h5, "disp", "force", None)
    with pytest.raises(plots.PlotError, match=r"plot_history: png='.*x.xyz' must end in one of"):
        plots.plot_history(h5, "disp", "force", tmp_path / "x.xyz")
    (tmp_path / "file").write_text("")
    with pytest.raises(plots.PlotError, match="cannot create the output folder .*file"):
        plots.plot_history(h5, "disp", "force", tmp_path / "file" / "x.png")
    assert_picture(plots.plot_history(h5, "disp", "force", tmp_path / "new" / "h.png"),
                   min_colours=3, min_ink=0.02)


def test_plot_history_marks_rows_accepted_above_tol(tmp_path, monkeypatch):
    """Rows accepted at a residual floor (above the run's tol) get open circles on the curve."""
    p = tmp_path / "floor.h5"
    with ResultWriter(p, tiny_model(), {"solver": {"tol": 1e-4}}) as w:
        for i, res in enumerate([9e-5, 5e-4, 1e-4, 8e-4]):
            w.append_history({"increment": i, "residual": res, "disp": 1e-3 * i, "force": 1e3 * i})
    assert open_result(p).rows_above_tol()[1].tolist() == [1, 3]
    saved = saved_figures(monkeypatch, plots)
    plots.plot_history(p, "disp", "force", tmp_path / "h.png")
    marked = [ln for ln in saved[str(tmp_path / "h.png")].axes[0].get_lines()
              if ln.get_marker() == "o"]
    assert len(marked) == 1 and marked[0].get_xdata().tolist() == [1.0, 3.0]
    assert "2 rows accepted above tol 0.0001 (open)" in marked[0].get_label()
    q = tmp_path / "no_tol.h5"
    with ResultWriter(q, tiny_model(), {}) as w:
        w.append_history({"increment": 0, "residual": 1.0, "disp": 0.0, "force": 0.0})
    assert open_result(q).rows_above_tol() == (None, None)
    plots.plot_history(q, "disp", "force", tmp_path / "h2.png")
    assert not [ln for ln in saved[str(tmp_path / "h2.png")].axes[0].get_lines()
                if ln.get_marker() == "o"]


def test_crack_map(h5, tmp_path, monkeypatch):
    """The shade at the centre of each element's elevation is Greys(dt) of that element (white where
    dt = 0), read at its projected pixel; the joint points above the threshold are red."""
    saved = saved_figures(monkeypatch, plots)
    png = plots.crack_map(h5, -1, tmp_path / "c.png", threshold=0.3)

    def pixel(xz):
        return pixels(png, saved[png], saved[png].axes[0], xz)[0]
    dt = fake_fields(tiny_model(), 4)["dt"]              # elements: x-order, bottom block first
    greys = colormaps["Greys"]
    for e, xz in enumerate([(0.05, 0.05), (0.15, 0.05), (0.05, 0.15), (0.15, 0.15)]):
        want = (1.0, 1.0, 1.0) if dt[e] <= 1e-3 else greys(dt[e])[:3]
        np.testing.assert_allclose(pixel(xz), want, atol=0.02, err_msg=f"element {e}")
    # the bed joint's points with D > 0.3 (x = 0.2 end of the joint at z = 0.1) are red dots
    r, g, b = pixel((0.2, 0.1))
    assert r > 0.4 and r > g + 0.2 and r > b + 0.2
    with pytest.raises(plots.PlotError, match="no block group 'roof'"):
        plots.crack_map(h5, 0, tmp_path / "x.png", blocks="roof")


@pytest.mark.parametrize("kw, word", [
    (dict(field="U"), r"field='U' is not a contact field of frame -1; its contact fields are "
                      r"\['D', 'opening', 'slip'\]"),
    (dict(field="foo"), "field='foo' is not a contact field"),
    (dict(blocks=[99]), r"blocks: id 99 is not an integer in \[0, 2\)"),
    (dict(blocks=[-1]), r"blocks: id -1 is not an integer in \[0, 2\)"),
    (dict(threshold="a"), "threshold='a' must be a finite number >= 0"),
    (dict(threshold=np.nan), "threshold=nan must be a finite number >= 0"),
    (dict(threshold=-0.1), "threshold=-0.1 must be a finite number >= 0"),
    (dict(png=None), "png must be a file path, got None"),
    (dict(png="x.xyz"), "png='x.xyz' must end in one of"),
])
def test_crack_map_errors(h5, tmp_path, kw, word):
    kw = {"png": tmp_path / "x.png", **kw}
    with pytest.raises(plots.PlotError, match=f"crack_map: {word}"):
        plots.crack_map(h5, -1, **kw)
    assert not os.path.exists(tmp_path / "x.png")


def test_crack_map_of_joints_of_some_blocks_into_a_new_folder(h5, tmp_path):
    png = plots.crack_map(h5, -1, tmp_path / "new" / "c.png", field="opening", blocks=[0],
                          threshold=0.0)
    assert png == str(tmp_path / "new" / "c.png")
    assert_picture(png, min_colours=2, min_ink=0.02)

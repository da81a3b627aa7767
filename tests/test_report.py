"""dr-masonry report (an HTML page read back with html.parser, its numbers those of info) and
dr-masonry animate (a GIF whose marker moves along the curve)."""
import base64
from html.parser import HTMLParser

import numpy as np
import pytest
from PIL import Image

from dr_masonry.cli import main
from dr_masonry.results import ResultWriter, open_result
from dr_masonry.viz import render
from dr_masonry.viz.animation import animate
from dr_masonry.viz.render import RenderError
from dr_masonry.viz.report import scene_of
from conftest import fake_fields, tiny_model

needs_vtk = pytest.mark.skipif(not render.vtk_offscreen_available(),
                               reason="no VTK offscreen rendering here")
#: one full cycle of the control displacement (m) and its force (N)
U = 1e-3 * np.array([0.0, 1.0, 2.0, 1.0, 0.0, -1.0, -2.0, -1.0, 0.0])
F = 1e3 * np.array([0.0, 8.0, 10.0, 4.0, -2.0, -7.0, -9.0, -3.0, 1.0])
RESIDUAL = [5e-5, 6e-5, 7e-5, 3e-4, 8e-5, 9e-5, 5e-5, 6e-5, 7e-5]     # row 4 above tol
CURVE = {"x": "top.ux", "y": "top.fx", "stage": None, "xscale": 1e3, "yscale": 1e-3,
         "xlabel": "top displacement (mm)", "ylabel": "force (kN)"}
FRAMES = (2, 6, 8)


def write_run(path):
    """A cyclic run of the tiny model: U, F above; energies growing row by row."""
    m = tiny_model()
    cfg = {"protocol": "cyclic", "drift": 0.01,
           "solver": {"tol": 1e-4, "energy_tol": 0.01, "block_tol": 0.1}}
    with ResultWriter(path, m, cfg) as w:
        for i in range(len(U)):
            w.append_history({"increment": i, "iterations": 100 + 10 * i, "residual": RESIDUAL[i],
                              "time_s": 0.5, "cut_iterations": 0.0, "cut_s": 0.0,
                              "top.ux": U[i], "top.fx": F[i], "W_ext": 2.0 * i,
                              "E_stored": 0.5, "D_blocks": 0.25 * i, "D_joints": 1.25 * i,
                              "D_joint_damage": 1.0 * i, "D_joint_friction": 0.25 * i,
                              "E_damped": 3.0 * i, "E_kinetic": 1e-6, "balance_error": 1e-3 * i,
                              "block_imbalance": 0.01, "max_overhang": 1e-4})
            if i in FRAMES:
                w.write_frame(i, fake_fields(m, i), attrs={"stage": "push",
                                                           "history_rows": i + 1})
    return path


class Page(HTMLParser):
    """The certificate's list items, table rows, image sources and captions of a page."""

    def __init__(self):
        super().__init__()
        self.items, self.rows, self.images, self.captions, self.pre = [], [], [], [], []
        self._in, self._row = None, None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "ul" and a.get("class") == "certificate":
            self._in = "ul"
        elif tag == "li" and self._in == "ul":
            self.items.append("")
        elif tag == "tr":
            self._row = []
            self.rows.append(self._row)
        elif tag in ("td", "th") and self._row is not None:
            self._row.append("")
        elif tag == "img":
            self.images.append(a["src"])
        elif tag == "figcaption":
            self.captions.append("")
            self._in = "caption"
        elif tag == "pre":
            self.pre.append("")
            self._in = "pre"

    def handle_endtag(self, tag):
        if tag in ("ul", "figcaption", "pre"):
            self._in = None
        elif tag == "tr":
            self._row = None

    def handle_data(self, data):
        if self._in == "ul" and self.items:
            self.items[-1] += data
        elif self._in == "caption":
            self.captions[-1] += data
        elif self._in == "pre":
            self.pre[-1] += data
        elif self._row:
            self._row[-1] += data


def info_lines(path, capsys):
    assert main(["info", str(path)]) == 0
    return capsys.readouterr().out.splitlines()


@needs_vtk
def test_report_holds_info_numbers_views_and_cycles(tmp_path, capsys):
    p = write_run(tmp_path / "run.h5")
    assert main(["report", str(p), "--curve", "top.ux,top.fx"]) == 0
    out = capsys.readouterr().out.strip()
    assert out == str(tmp_path / "run_report.html")
    page = Page()
    page.feed(open(out, encoding="utf-8").read())
    info = info_lines(p, capsys)
    # the certificate: the very lines of info
    assert page.items == [ln for ln in info if ln.split(":")[0] in
                          ("residual", "energy", "blocks", "overhang")]
    assert page.items[0].startswith("residual:  1 of 9 rows accepted above tol 0.0001")
    rows = {r[0]: r[1:] for r in page.rows if r}
    assert rows["converged to tol"] == ["8 (tol 0.0001)"]
    assert rows["accepted at a floor (above tol)"] == ["1"]
    # energies and dissipation by mechanism: info's last row
    last = dict(kv.split("=") for kv in
                next(ln for ln in info if ln.startswith("last row:"))[10:].split(", "))
    for k in ("W_ext", "D_blocks", "D_joints", "D_joint_damage", "D_joint_friction",
              "E_damped", "balance_error"):
        assert rows[k][-1] == last[k], k
    assert rows["D_joint_friction"][-1] == "2"                           # 0.25 x 8
    assert rows["relaxation iterations"] == [str(sum(100 + 10 * i for i in range(9)))]
    assert rows["relaxation time (s)"] == ["4.5"]
    # the curve and the views at both peaks (rows 3 and 7: frames 2 and 6) and the end
    assert page.captions[1:] == ["view peak+", "view peak-", "view end"]
    for src in page.images:
        assert src.startswith("data:image/png;base64,")
        assert base64.b64decode(src.split(",", 1)[1])[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(page.images) == 4
    # the cycle table of the cyclic run: one full cycle
    assert len(page.pre) == 1 and "(partial)" not in page.pre[0]


def test_report_of_an_unknown_scene_asks_for_the_curve(tmp_path, capsys):
    p = write_run(tmp_path / "run.h5")
    assert main(["report", str(p)]) == 2
    assert "--curve X,Y" in capsys.readouterr().err
    assert main(["report", str(p), "--curve", "top.ux"]) == 2


def test_scene_of_the_parameters(tmp_path):
    from dr_masonry.cases import slender_wall, squat_wall
    for mod, name in ((squat_wall, "squat_wall"), (slender_wall, "slender_wall")):
        p = tmp_path / f"{name}.h5"
        cfg = dict(mod.PARAMS, h5=str(p), progress=True, solver={"tol": 1e-4})
        ResultWriter(p, tiny_model(), cfg).close()
        assert scene_of(open_result(p))[0] == name
    assert scene_of(open_result(write_run(tmp_path / "run.h5"))) == (None, None)


@needs_vtk
def test_animation_marker_moves_along_the_curve(tmp_path):
    p = write_run(tmp_path / "run.h5")
    gif = animate(p, tmp_path / "a.gif", curve=CURVE, camera="elevation", size=(200, 150),
                  dpi=50)
    im = Image.open(gif)
    assert im.n_frames == len(FRAMES) and im.size == (360, 150)
    where = []
    for k in range(im.n_frames):
        im.seek(k)
        rgb = np.asarray(im.convert("RGB"), dtype=float)[:, 200:] / 255
        red = np.argwhere((rgb[..., 0] > 0.8) & (rgb[..., 1] < 0.3) & (rgb[..., 2] < 0.3))
        assert red.size, f"frame {k}: no marker"
        where.append(red.mean(axis=0))
    # frames at rows 3, 7, 9: (2 mm, 10 kN), (-2 mm, -9 kN), (0, 1 kN): right-high, left-low
    (r0, c0), (r1, c1), (r2, c2) = where
    assert c0 > c2 > c1 and r0 < r2 < r1


def test_animation_errors(tmp_path):
    p = write_run(tmp_path / "run.h5")
    with pytest.raises(RenderError, match=r"must end in one of \.gif, \.mp4"):
        animate(p, tmp_path / "a.avi", curve=CURVE)
    with pytest.raises(RenderError, match="fps=0 must be"):
        animate(p, tmp_path / "a.gif", curve=CURVE, fps=0)

"""Parameter studies through Dask (dr_masonry.study, ``dr-masonry study``)."""
import csv
import os

import numpy as np
import pytest

from dr_masonry.cli import main
from dr_masonry.params import ParameterError
from dr_masonry.results import open_result
from dr_masonry.solver import increments
from dr_masonry.cases import squat_wall
from dr_masonry.study import grid, plot_overlay, run_study
from matplotlib.colors import to_rgb
from matplotlib.image import imread

from conftest import pixels, rocking_shear, saved_figures

#: a fast squat wall with 4 push increments: a few seconds per variant
BASE = dict(fast=True, increments=4)
VARIANTS = grid(variant=["reference", "PAR_B"])
#: its rocking capacity without tension, kN: 0.30 MPa on the 0.88 x 0.102 m top, bricks of
#: 1800 kg/m^3, 0.81 m high
L, T, H = squat_wall.FAST["length"], 0.102, squat_wall.FAST["height"]
ROCKING = rocking_shear(squat_wall.PARAMS["sigma"] * L * T + 1800.0 * 9.81 * L * T * H,
                        L, T, H) / 1e3


def _csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_grid_product_and_labels():
    g = grid(variant=["reference", "PAR_A"], tol=[1e-3, 1e-4])
    assert [label for label, _ in g] == [
        "variant=reference,tol=0.001", "variant=reference,tol=0.0001",
        "variant=PAR_A,tol=0.001", "variant=PAR_A,tol=0.0001"]
    assert g[2][1] == {"variant": "PAR_A", "tol": 1e-3}
    assert grid() == [("base", {})]
    with pytest.raises(ParameterError, match="grid axis tol"):
        grid(tol=[])
    with pytest.raises(ParameterError, match="grid axis variant"):
        grid(variant="PAR_A")


@pytest.fixture(scope="module")
def sync_study(tmp_path_factory):
    out = tmp_path_factory.mktemp("sync")
    return run_study("squat_wall", VARIANTS, base=BASE, out=str(out), scheduler="synchronous",
                     verbose=False)


def test_synchronous_study(sync_study, monkeypatch):
    res = sync_study
    assert [r["status"] for r in res.rows] == ["ok", "ok"], res.table()
    ref, parb = res.rows
    for r in res.rows:
        # at 0.2 % drift the base joint has opened: the wall rocks (measured 1.2 and 3.4 % above
        # the no-tension capacity; 38 % above it the bed joint's tension would hold the heel)
        assert r["peak"] == pytest.approx(ROCKING, rel=0.05)
        assert r["x"].shape == r["y"].shape == (4,)          # the push rows only
        assert r["x_at_peak"] in r["x"] and r["final"] == r["y"][-1]
        h = open_result(r["h5"]).history                   # the curve: the h5's push rows, mm, kN
        push = h["increment"] > 2                          # FAST: 2 pre-compression increments
        assert np.allclose(r["x"], h["beam.ux"][push] * 1e3)
        assert np.allclose(r["y"], h["beam.fx"][push] * 1e-3)
        assert r["increments"] == h["increment"].size and r["iterations"] == h["iterations"].sum()
    assert parb["peak"] >= ref["peak"]                     # doubled cohesion: not weaker
    laws = [open_result(r["h5"]).joint_laws for r in (ref, parb)]   # the variant reached the run
    for key, factor in (("c", 2.0), ("delta_k", 2.0), ("ft", 1.0), ("tan_phi", 1.0)):
        assert [law["params"][key] for law in laws[1]] == [factor * law["params"][key]
                                                          for law in laws[0]], key
    rows = _csv(res.csv)
    assert [r["label"] for r in rows] == ["variant=reference", "variant=PAR_B"]
    assert rows[1]["param.variant"] == "PAR_B" and rows[1]["param.increments"] == "4"
    assert float(rows[1]["peak"]) == pytest.approx(parb["peak"])
    assert_overlay_shows_the_curves(res, monkeypatch)
    assert "peak base shear (kN)" in res.table()


def assert_overlay_shows_the_curves(res, monkeypatch):
    """The study's PNG is the overlay of its curves: drawn again (recording the figure) it is the
    same picture, and at each point of each curve, away from the curves drawn after it, the
    pixel has that curve's colour; the legend names the variants."""
    import matplotlib.figure
    before = imread(res.png)
    saved = saved_figures(monkeypatch, matplotlib.figure)
    plot_overlay(res)
    assert np.array_equal(imread(res.png), before)
    fig = saved[res.png]
    ax = fig.axes[0]
    assert [t.get_text() for t in ax.get_legend().get_texts()] == [r["label"] for r in res.rows]
    xy = [np.column_stack([r["x"], r["y"]]) for r in res.rows]
    px = [ax.transData.transform(p) for p in xy]     # display points of the figure

    def distance(p, line):   # from p to the polyline
        a, b = line[:-1], line[1:]
        t = np.clip(np.einsum("ij,ij->i", p - a, b - a) / np.einsum("ij,ij->i", b - a, b - a),
                    0, 1)
        return np.hypot(*(a + t[:, None] * (b - a) - p).T).min()
    for k, line in enumerate(ax.get_lines()):
        seen = [j for j, p in enumerate(px[k])
                if all(distance(p, later) > 4 for later in px[k + 1:])]
        assert seen, f"curve {k} is hidden by the later ones"
        np.testing.assert_allclose(pixels(res.png, fig, ax, xy[k][seen]),
                                   np.tile(to_rgb(line.get_color()), (len(seen), 1)), atol=0.05)


def test_local_cluster_study_with_a_failing_variant(sync_study, tmp_path):
    """One worker process: the same peaks as in-process; a bad variant fails alone."""
    variants = VARIANTS + [("bad mesh", {"mesh": "nonsense"})]
    res = run_study("squat_wall", variants, base=BASE, out=str(tmp_path), n_workers=1,
                    verbose=False)
    assert [r["status"] for r in res.rows] == ["ok", "ok", "failed"], res.table()
    for r, s in zip(res.rows, sync_study.rows):
        assert r["peak"] == pytest.approx(s["peak"], rel=1e-12)
    bad = res.rows[2]
    assert bad["error"].startswith("ParameterError: parameter mesh='nonsense'")
    rows = _csv(res.csv)
    assert [r["status"] for r in rows] == ["ok", "ok", "failed"]
    assert "mesh='nonsense'" in rows[2]["error"] and rows[2]["peak"] == ""
    assert os.path.exists(os.path.join(tmp_path, "study.png"))


def test_study_on_a_running_scheduler(sync_study, tmp_path):
    """The same study through the address of a running scheduler (an in-process cluster here)."""
    from distributed import LocalCluster
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address=None) as cluster:
        res = run_study("squat_wall", [("ref", {}), ("bad", {"mesh": "nonsense"})], base=BASE,
                        out=str(tmp_path), scheduler=cluster.scheduler_address, verbose=False)
    assert [r["status"] for r in res.rows] == ["ok", "failed"], res.table()
    assert res.rows[0]["peak"] == pytest.approx(sync_study.rows[0]["peak"], rel=1e-12)
    assert "mesh='nonsense'" in res.rows[1]["error"]


def test_failure_mid_run_keeps_the_result_file(tmp_path, monkeypatch):
    """A solver failure after a few increments: reported; the rows written so far stay readable."""
    commit = increments.commit

    def failing(sim, *args, **kwargs):
        if sim.increment == 3:
            sim.fail("injected failure")
        return commit(sim, *args, **kwargs)

    monkeypatch.setattr(increments, "commit", failing)
    res = run_study("squat_wall", [("ref", {})], base=BASE, out=str(tmp_path),
                    scheduler="synchronous", verbose=False)
    (row,) = res.rows
    assert row["status"] == "failed" and row["error"] == "SolverError: injected failure"
    assert open_result(row["h5"]).n_history == 3


def test_bad_input_before_any_run(tmp_path):
    with pytest.raises(ParameterError, match="unknown parameter 'nx' of case 'squat_wall'"):
        run_study("squat_wall", [("a", {"nx": 2})], out=str(tmp_path), scheduler="synchronous")
    with pytest.raises(ParameterError, match="parameter drift='big': cannot convert to float"):
        run_study("squat_wall", [("a", {})], base={"drift": "big"}, out=str(tmp_path))
    with pytest.raises(ParameterError, match="not unique"):
        run_study("squat_wall", [("a b", {}), ("a_b", {})], out=str(tmp_path))
    with pytest.raises(ParameterError, match="n_workers=0: must be >= 1"):
        run_study("squat_wall", [("a", {})], out=str(tmp_path), n_workers=0)
    with pytest.raises(ParameterError, match=r"variant 'fine': parameter step=0.001 shapes the "
                       "cyclic path only; this run is protocol=monotonic"):
        run_study("squat_wall", [("fine", {"step": 0.001})], out=str(tmp_path))
    with pytest.raises(ParameterError, match="case 'joint' cannot run in a study"):
        run_study("joint", [("a", {})], out=str(tmp_path))
    assert not os.listdir(tmp_path)


def test_cli_study(tmp_path, capsys):
    assert main(["study", "squat_wall", "--vary", "nx=1,2", "--out", str(tmp_path)]) == 2
    assert "unknown parameter 'nx'" in capsys.readouterr().err
    assert main(["study", "squat_wall", "--vary", "drift=0.1", "--set", "drift=0.2"]) == 2
    assert "both varied (--vary) and set (--set)" in capsys.readouterr().err
    # two variants that fail in their set-up (cheap): reported, exit status 1
    rc = main(["study", "squat_wall", "--vary", "mesh=nonsense,bogus", "--set", "fast=true",
               "--scheduler", "synchronous", "--out", str(tmp_path)])
    assert rc == 1
    out = capsys.readouterr().out
    assert "mesh=bogus: ParameterError: parameter mesh='bogus'" in out
    rows = _csv(tmp_path / "study.csv")
    assert [(r["label"], r["status"], r["param.fast"]) for r in rows] == [
        ("mesh=nonsense", "failed", "True"), ("mesh=bogus", "failed", "True")]

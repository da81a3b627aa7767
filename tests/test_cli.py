"""Command line and the shared key=value parser of the case scripts."""
import os
import subprocess
import sys
import types

import numpy as np
import pytest

from dr_masonry import cli
from dr_masonry.cli import main
from dr_masonry.params import ParameterError, parse_overrides
from conftest import write_fake_result

PARAMS = {"n": 4, "drift": 0.01, "name": "wall", "cyclic": False, "mesh": (4, 1, 2),
          "amps": [0.1, 0.2], "extra": None, "opts": {"a": 1}}


def test_parse_overrides_types():
    got = parse_overrides(PARAMS, ["n=1e3", "drift=2.5e-2", "name=squat", "cyclic=yes",
                                   "mesh=2,1,1", "amps=[0.5, 1, 2]", "extra=(1, 2)",
                                   'opts={"b": 2}'])
    assert got == {"n": 1000, "drift": 0.025, "name": "squat", "cyclic": True,
                   "mesh": (2, 1, 1), "amps": [0.5, 1.0, 2.0], "extra": (1, 2),
                   "opts": {"b": 2}}
    assert type(got["n"]) is int and type(got["amps"][1]) is float
    assert PARAMS["n"] == 4                      # defaults untouched
    assert parse_overrides(PARAMS, []) == PARAMS
    assert parse_overrides(PARAMS, ["cyclic=OFF", "extra=free text"])["extra"] == "free text"


@pytest.mark.parametrize("arg, msg", [
    ("nx=3", r"unknown parameter 'nx'; valid keys: n, drift, name, cyclic, mesh, amps"),
    ("n", r"argument 'n' is not key=value"),
    ("n=2.5", r"parameter n='2.5': cannot convert to int"),
    ("drift=big", r"parameter drift='big': cannot convert to float"),
    ("cyclic=maybe", r"parameter cyclic='maybe': cannot convert to bool"),
    ("mesh=2,x", r"parameter mesh='x'"),
    ("opts=[1]", r"cannot convert to dict"),
    ("drift=inf", r"parameter drift='inf': .*\(expected a finite number"),   # was "control N:
    ("drift=nan", r"parameter drift='nan'"),                                # to=-inf" later
])
def test_parse_overrides_errors(arg, msg):
    with pytest.raises(ParameterError, match=msg):
        parse_overrides(PARAMS, [arg])


def test_parse_overrides_help(capsys):
    with pytest.raises(SystemExit) as e:
        parse_overrides(PARAMS, ["n=2", "--help"], doc="S9 test scene.\n\nMore text.")
    assert e.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("S9 test scene.") and "drift  = 0.01" in out and "mesh   = (4, 1, 2)" in out


@pytest.fixture()
def fake_case(monkeypatch):
    """A case module dr_masonry.cases.fakecase following the case pattern."""
    mod = types.ModuleType("dr_masonry.cases.fakecase")
    mod.__doc__ = "Fake case: records its parameters.\n\nDetails."
    mod.PARAMS = {"n": 2, "drift": 0.01}
    mod.calls = []

    def _main(argv=None):
        p = parse_overrides(mod.PARAMS, argv, mod.__doc__)
        mod.calls.append(p)
        return 0

    mod.main = _main
    monkeypatch.setitem(sys.modules, "dr_masonry.cases.fakecase", mod)
    monkeypatch.setattr(cli, "available_cases", lambda: ["fakecase"])
    return mod


def test_run_case(fake_case, capsys):
    assert main(["run", "fakecase", "n=5", "drift=0.02"]) == 0
    assert fake_case.calls == [{"n": 5, "drift": 0.02}]
    assert main(["run", "fakecase", "m=1"]) == 2
    assert "unknown parameter 'm'; valid keys: n, drift" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main(["run", "fakecase", "--help"])
    assert e.value.code == 0 and "Fake case" in capsys.readouterr().out


def test_run_unknown_case_and_list(fake_case, capsys):
    assert main(["run", "nosuchcase"]) == 2
    assert "unknown case 'nosuchcase'; available: fakecase" in capsys.readouterr().err
    assert main(["list"]) == 0
    assert capsys.readouterr().out.split() == ["fakecase", "Fake", "case:", "records", "its",
                                               "parameters."]


def test_info(tmp_path, capsys):
    p = tmp_path / "r.h5"
    write_fake_result(p)
    assert main(["info", str(p), "--peak", "force"]) == 0
    out = capsys.readouterr().out
    assert "2 blocks, 4 hexahedra, 24 nodes, 6 contact points" in out
    assert "history:   5 rows (numbered from 1 below, as in the run's messages), columns " \
           "['increment', 'disp', 'force']" in out
    assert "frames:    3 (increments 0 .. 4)" in out
    assert "checkpoint: none" in out
    assert "last row:  increment=4, disp=0.0004, force=-756.802" in out
    # 1e3 sin(i), i = 0..4: max at i = 2, min at i = 4 (rows 3 and 5, counted from 1)
    assert "peak force: max 909.297 (row 3), min -756.802 (row 5)" in out
    assert '"drift": 0.01' in out
    assert main(["info", str(p), "--peak", "drift"]) == 2
    assert "no history column ['drift']" in capsys.readouterr().err
    assert main(["info", str(tmp_path / "none.h5")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_info_checkpoint_after_the_last_frame(tmp_path, capsys):
    """A run stopped between frames: info names its checkpoint, whose fields read as a frame."""
    import numpy as np
    from dr_masonry.kernels.joint_law import JS_D, NJS
    from dr_masonry.kernels.plastic_damage import MS_DT, NMS
    from dr_masonry.results import ResultWriter, open_result
    p = tmp_path / "r.h5"
    write_fake_result(p)
    sb = np.zeros((4, 8, NMS))
    sb[2, 5, MS_DT] = 0.3
    sj = np.zeros((6, NJS))
    sj[1, JS_D] = 0.7
    with ResultWriter(p, None, {}, mode="a") as w:
        w.write_checkpoint(6, {"U": np.full((24, 3), 1e-3), "s_blocks": sb, "s_joints": sj}, {})
    assert main(["info", str(p)]) == 0
    assert "checkpoint: increment 6 (after the last frame" in capsys.readouterr().out
    fields = open_result(p).frame("checkpoint")
    assert fields["dt"].tolist() == [0.0, 0.0, 0.3, 0.0] and fields["D"][1] == 0.7
    assert fields["U"].shape == (24, 3)


def test_info_restarts_and_rows_above_tol(tmp_path, capsys):
    """info says what each restart changed and which rows were accepted above tol (floor_tol)."""
    from conftest import tiny_model
    from dr_masonry.results import ResultWriter
    p = tmp_path / "r.h5"
    cfg = {"max_iter": 200, "floor_tol": 0.0, "solver": {"tol": 1e-4, "max_iter": 200}}
    with ResultWriter(p, tiny_model(), cfg) as w:
        for i, res in enumerate([9e-5, 1e-4, 3e-4]):
            w.append_history({"increment": i, "residual": res})
    assert main(["info", str(p)]) == 0
    out = capsys.readouterr().out
    assert "residual:  1 of 3 rows accepted above tol 0.0001 (floor_tol; largest ratio 0.0003): " \
           "rows 3" in out
    assert "\nrestart " not in out
    later = {"max_iter": 50, "floor_tol": 1e-3, "resume": True,
             "solver": {"tol": 1e-4, "max_iter": 50, "floor_tol": 1e-3}}
    with ResultWriter(p, None, later, mode="a") as w:
        w.append_history({"increment": 3, "residual": 1e-4})
    with ResultWriter(p, None, {}, mode="a"):
        pass
    assert main(["info", str(p)]) == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("restart")]
    assert len(lines) == 2
    # solver.max_iter and solver.floor_tol say what max_iter and floor_tol say
    assert lines[0].endswith(": max_iter 200 -> 50, floor_tol 0.0 -> 0.001")
    assert lines[1].endswith(": same parameters")


def test_info_checks(tmp_path, capsys):
    """info names the largest energy-balance error, block imbalance (rows before the column
    existed are NaN) and overhang with their rows, and counts the rows above the run's limits."""
    from conftest import tiny_model
    from dr_masonry.results import ResultWriter
    p = tmp_path / "r.h5"
    cfg = {"solver": {"tol": 1e-4, "energy_tol": 0.01, "block_tol": 0.1}}
    rows = [(0.02, np.nan, 1e-3), (-0.03, 0.05, 4e-3), (0.001, 0.25, 2e-3), (0.0, 0.12, 0.0)]
    with ResultWriter(p, tiny_model(), cfg) as w:
        for i, (e, b, o) in enumerate(rows):
            w.append_history({"increment": i, "residual": 1e-5, "balance_error": e,
                              "block_imbalance": b, "max_overhang": o})
    assert main(["info", str(p)]) == 0
    out = capsys.readouterr().out
    assert "energy:    balance error at most 0.03 of the gross work (row 2); 2 rows above " \
           "energy_tol 0.01" in out
    assert "blocks:    largest block imbalance ratio 0.25 (row 3); 2 rows above block_tol 0.1" in out
    assert "overhang:  joint nodes slid at most 4 mm off their master faces (row 2)" in out
    q = tmp_path / "old.h5"
    with ResultWriter(q, tiny_model(), cfg) as w:
        w.append_history({"increment": 0, "residual": 1e-5})
    assert main(["info", str(q)]) == 0
    out = capsys.readouterr().out
    assert "blocks:    no block_imbalance column" in out
    assert "energy:" not in out and "overhang:" not in out


def test_vtk_command(tmp_path, capsys):
    p = tmp_path / "r.h5"
    write_fake_result(p)
    assert main(["vtk", str(p), str(tmp_path / "vtk")]) == 0
    assert capsys.readouterr().out.strip() == str(tmp_path / "vtk" / "blocks.pvd")
    assert os.path.isfile(tmp_path / "vtk" / "contacts_000004.vtu")


def test_python_m_info(tmp_path):
    p = tmp_path / "r.h5"
    write_fake_result(p)
    env = dict(os.environ)
    env.pop("OMP_WAIT_POLICY", None)
    proc = subprocess.run([sys.executable, "-m", "dr_masonry", "info", str(p)],
                          capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "24 nodes" in proc.stdout and "frames:    3" in proc.stdout


def test_interrupted_scene_says_where_its_rows_are(capsys, monkeypatch):
    """Ctrl-C during a scene's run: the KeyboardInterrupt carries a note naming the file and
    resume=true, and ``dr-masonry run`` prints it without a traceback, exit status 130."""
    from dr_masonry.scene import run_stages

    class Interrupted:
        increment = 3

        def run(self, stages):
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt) as e:
        run_stages(Interrupted(), [], {"h5": "results/s6.h5"})
    note = e.value.__notes__[0]
    assert "row 4" in note and "results/s6.h5" in note and "resume=true" in note

    def interrupted_main(argv):
        raise e.value
    monkeypatch.setattr(cli, "import_case",
                        lambda name: types.SimpleNamespace(main=interrupted_main))
    assert main(["run", "squat_wall"]) == 130
    err = capsys.readouterr().err
    assert "interrupted" in err and "resume=true" in err and "Traceback" not in err


def test_case_script_bad_input_is_a_message(tmp_path):
    """``python cases/NAME.py`` guards its input as ``dr-masonry run NAME`` does: exit status 2
    and the message naming the parameter, no traceback."""
    script = os.path.join(os.path.dirname(__file__), os.pardir, "cases", "slender_wall.py")
    env = dict(os.environ)
    env.pop("OMP_WAIT_POLICY", None)
    proc = subprocess.run([sys.executable, script, "heigth=3"], capture_output=True, text=True,
                          env=env, timeout=300, cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stderr.startswith("slender_wall.py: error: unknown parameter 'heigth'")
    assert "Traceback" not in proc.stderr


def test_a_run_that_stops_gives_its_diagnosis(tmp_path, capsys):
    """A scene whose increment does not converge: exit status 1, the solver's diagnosis and the
    file of the rows so far, no traceback."""
    out = tmp_path / "s4"
    rc = main(["run", "slender_wall", "fast=true", f"out={out}", "max_iter=5", "max_cuts=0"])
    err = capsys.readouterr().err
    assert rc == 1
    assert "dr-masonry run: stopped: increment 1 of stage" in err and "did not converge" in err
    assert f"0 rows written to {out}.h5" in err and "Traceback" not in err


def test_warnings_print_as_one_line_naming_the_command():
    """A run's warnings (energy balance, overhang, a row accepted at the floor) print as
    ``command: Category: message``, not with the file, line and source line of the
    ``warnings.warn`` call; Python's format is back afterwards."""
    code = ("import sys, warnings\n"
            "from dr_masonry.cli import guarded\n"
            "python_format = warnings.formatwarning\n"
            "rc = guarded('squat_wall.py', warnings.warn, 'increment 3: energy balance 2.1 %')\n"
            "assert warnings.formatwarning is python_format\n"
            "sys.exit(rc)\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == "squat_wall.py: UserWarning: increment 3: energy balance 2.1 %\n"


def test_pack_command(tmp_path, capsys):
    """``pack`` writes the copy and says how to continue from it; bad frames and a file without
    a checkpoint are named, exit status 2."""
    import numpy as np
    from dr_masonry.results import ResultWriter, open_result
    p, q = tmp_path / "r.h5", tmp_path / "c.h5"
    write_fake_result(p)
    assert main(["pack", str(p), str(q)]) == 2
    assert "has no checkpoint" in capsys.readouterr().err
    with ResultWriter(p, None, {}, mode="a") as w:
        w.write_checkpoint(4, {"U": np.zeros((24, 3))}, {})
    assert main(["pack", str(p), str(q), "--frames", "two"]) == 2
    assert "pack --frames two: give increments (integers) or 'all'" in capsys.readouterr().err
    assert main(["pack", str(p), str(q), "--frames", "0", "4"]) == 0
    assert f"continue the run with out={tmp_path / 'c'} resume=true" in capsys.readouterr().out
    assert open_result(q).frame_ids == [0, 4]

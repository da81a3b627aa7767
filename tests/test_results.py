"""HDF5 results file: schema round trip, validation, crash safety, restart."""
import dataclasses
import json
import os
import signal
import subprocess
import sys
import textwrap
from types import SimpleNamespace

import h5py
import numpy as np
import pytest

from dr_masonry.contact_search import ContactSet
from dr_masonry.model import Model
from dr_masonry.results import (CONTACT_ARRAYS, SCHEMA_VERSION, ResultsError, ResultWriter,
                                open_result)

from conftest import StubMaterial, fake_fields, tiny_model, write_fake_result


def test_round_trip(tmp_path):
    p = tmp_path / "r.h5"
    m, cfg = write_fake_result(p)
    r = open_result(p)
    a = r.model_arrays
    for name in ("nodes", "elements", "element_block", "block_node_start", "block_element_start",
                 "block_divisions", "block_corners", "block_material", "block_fixed",
                 "block_joint"):
        np.testing.assert_array_equal(a[name], getattr(m, name), err_msg=name)
    assert r.group_names == ["wall", "beam"]
    np.testing.assert_array_equal(a["block_group"], [0, 1])
    assert {k: v.tolist() for k, v in r.groups.items()} == {"wall": [0], "beam": [1]}
    assert r.materials == [{"type": "StubMaterial", "params": {"E": 10e9, "nu": 0.2}}]
    assert r.joint_laws == [{"type": "StubLaw", "repr": "StubLaw(kn=1e12)"}]
    np.testing.assert_array_equal(a["contacts"]["slave"], m.contacts.slave)
    np.testing.assert_array_equal(a["contacts"]["master"], m.contacts.master)
    assert r.config == cfg
    assert r.attrs["schema_version"] == SCHEMA_VERSION
    np.testing.assert_array_equal(r.history["disp"], 1e-4 * np.arange(5))
    np.testing.assert_array_equal(r.history["force"], 1e3 * np.sin(np.arange(5)))
    assert list(r.history) == ["increment", "disp", "force"]
    assert r.frame_ids == [0, 2, 4] and r.n_frames == 3 and r.n_history == 5
    fr = r.frame(1)
    exp = fake_fields(m, 2)
    assert set(fr) == set(exp)
    for k in exp:
        np.testing.assert_array_equal(fr[k], exp[k], err_msg=k)
    np.testing.assert_array_equal(r.frame(-1)["dt"], fake_fields(m, 4)["dt"])
    at = r.frame_attrs(2)
    assert at["increment"] == 4 and at["control"] == pytest.approx(4e-4) and at["history_rows"] == 5
    with h5py.File(p, "r") as f:
        assert f["frames/000002/U"].attrs["units"] == "m"
        assert f["frames/000002/U"].attrs["location"] == "node"
        assert f["history/disp"].maxshape == (None,)
    with pytest.raises(ResultsError, match="out of range"):
        r.frame(3)


def test_history_keys_must_match(tmp_path):
    with ResultWriter(tmp_path / "r.h5", tiny_model(), {}) as w:
        w.append_history({"a": 1.0, "b": 2.0})
        with pytest.raises(ResultsError, match=r"missing \['b'\], unknown \['c'\]"):
            w.append_history({"a": 1.0, "c": 2.0})
        with pytest.raises(ResultsError, match="'b' value 'x' is not a number"):
            w.append_history({"a": 1.0, "b": "x"})
        w.append_history({"b": 4.0, "a": 3.0})
        assert w.n_history == 2
    h = open_result(tmp_path / "r.h5").history
    np.testing.assert_array_equal(h["a"], [1.0, 3.0])
    np.testing.assert_array_equal(h["b"], [2.0, 4.0])


def test_field_validation(tmp_path):
    m = tiny_model()
    with ResultWriter(tmp_path / "r.h5", m, {}) as w:
        with pytest.raises(ResultsError, match=r"'U' must have shape \(24, 3\)"):
            w.write_frame(0, {"U": np.zeros((24, 2))})
        with pytest.raises(ResultsError, match=r"'D' must have shape \(6,\)"):
            w.write_frame(0, {"D": np.zeros(5)})
        with pytest.raises(ResultsError, match="leading dimension 7"):
            w.write_frame(0, {"foo": np.zeros((7, 2))})
        with pytest.raises(ResultsError, match="increment must be >= 0"):
            w.write_frame(-1, {})
        gp = np.arange(m.n_elements * 8 * 3, dtype=float).reshape(m.n_elements, 8, 3)
        w.write_frame(0, {"gp_state": gp, "V": np.ones((m.n_nodes, 3))})
        with pytest.raises(ResultsError, match="frame 0 already exists"):
            w.write_frame(0, {})
    r = open_result(tmp_path / "r.h5")
    np.testing.assert_array_equal(r.frame(0)["gp_state"], gp)
    with h5py.File(tmp_path / "r.h5", "r") as f:
        assert f["frames/000000/gp_state"].attrs["location"] == "element"


def test_frame_contact_set(tmp_path):
    """A frame may carry its own (re-detected) contact set; contact fields follow its size."""
    m = tiny_model()
    new = SimpleNamespace(**{k: getattr(m.contacts, k)[:3] for k in
                             ("slave", "master", "xi", "area", "law", "blocks", "gap0")})
    with ResultWriter(tmp_path / "r.h5", m, {}) as w:
        w.write_frame(0, {"D": np.zeros(6)})
        w.write_frame(1, {"D": np.ones(3)}, contacts=new)
    r = open_result(tmp_path / "r.h5")
    assert len(r.contacts(0)["slave"]) == 6
    np.testing.assert_array_equal(r.contacts(1)["slave"], m.contacts.slave[:3])


def test_frame_contact_set_complete(tmp_path):
    """The stored contact layout is ContactSet's; a set lacking a field is refused, not cut."""
    assert list(CONTACT_ARRAYS) == [f.name for f in dataclasses.fields(ContactSet)]
    m = tiny_model()
    partial = SimpleNamespace(slave=m.contacts.slave[:3], master=m.contacts.master[:3])
    with ResultWriter(tmp_path / "r.h5", m, {}) as w:
        with pytest.raises(ResultsError, match="frame 1 lack xi, area, law, blocks, gap0"):
            w.write_frame(1, {"D": np.ones(3)}, contacts=partial)


def test_no_contacts(tmp_path):
    m = tiny_model(with_contacts=False)
    with ResultWriter(tmp_path / "r.h5", m, {"x": 1}) as w:
        w.write_frame(0, {"U": np.zeros((m.n_nodes, 3))})
    r = open_result(tmp_path / "r.h5")
    assert r.model_arrays["contacts"] is None and r.contacts(0) is None
    assert r.summary() == "2 blocks, 4 hexahedra, 24 nodes, 0 contact points"


def test_open_errors(tmp_path):
    with pytest.raises(ResultsError, match="does not exist"):
        open_result(tmp_path / "missing.h5")
    (tmp_path / "junk.h5").write_text("not hdf5")
    with pytest.raises(ResultsError, match="cannot be opened as HDF5"):
        open_result(tmp_path / "junk.h5")
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["x"] = 1
    with pytest.raises(ResultsError, match="not a dr_masonry results file"):
        open_result(tmp_path / "other.h5")
    write_fake_result(tmp_path / "r.h5")
    with h5py.File(tmp_path / "r.h5", "a") as f:
        f["config"].attrs["schema_version"] = SCHEMA_VERSION + 1
    with pytest.raises(ResultsError, match=f"schema version {SCHEMA_VERSION + 1}"):
        open_result(tmp_path / "r.h5")
    with pytest.raises(ResultsError, match="mode must be"):
        ResultWriter(tmp_path / "x.h5", tiny_model(), {}, mode="r")


def test_append_restart(tmp_path):
    p = tmp_path / "r.h5"
    m, _ = write_fake_result(p)
    with ResultWriter(p, m, {"restart": True}, mode="a") as w:
        with pytest.raises(ResultsError, match="cannot keep 9"):
            w.truncate(2, 9)
        w.truncate(2, 3)   # restart after increment 2 (3 rows, increments 0-2): drop frame 4
        assert w.frame_ids == [0, 2] and w.n_history == 3
        w.append_history({"increment": 3, "disp": 7.0, "force": 8.0})
        w.write_frame(3, fake_fields(m, 3))
        # a newer version may add a column at a restart (NaN before), never drop one
        w.append_history({"increment": 4, "disp": 8.0, "force": 9.0, "new": 1.5})
        with pytest.raises(ResultsError, match=r"missing \['force'\]"):
            w.append_history({"increment": 5, "disp": 9.0, "new": 2.0})
    r = open_result(p)
    np.testing.assert_array_equal(r.history["disp"], [0.0, 1e-4, 2e-4, 7.0, 8.0])
    np.testing.assert_array_equal(r.history["new"], [np.nan] * 4 + [1.5])
    with ResultWriter(tmp_path / "fresh.h5", m, {}) as w:   # a new file's columns are fixed
        w.append_history({"a": 1.0})
        with pytest.raises(ResultsError, match=r"unknown \['b'\]"):
            w.append_history({"a": 2.0, "b": 1.0})
    assert r.frame_ids == [0, 2, 3]
    assert r.attrs["restarts"][0]["config"] == {"restart": True}
    other = Model()
    other.add_box((0, 0, 0), (1, 1, 1), StubMaterial())
    with pytest.raises(ResultsError, match="do not match"):
        ResultWriter(p, other, {}, mode="a")
    with pytest.raises(ResultsError, match="does not exist"):
        ResultWriter(tmp_path / "none.h5", None, {}, mode="a")


def test_killed_writer_leaves_readable_file(tmp_path):
    """A child writes 3 rows + 2 frames, flushes, then SIGKILLs itself: everything is readable."""
    p = tmp_path / "killed.h5"
    code = textwrap.dedent(f"""
        import os, signal, sys
        sys.path.insert(0, {os.path.dirname(__file__)!r})
        import numpy as np
        from conftest import tiny_model, fake_fields
        from dr_masonry.results import ResultWriter
        m = tiny_model()
        w = ResultWriter({str(p)!r}, m, {{"case": "killed"}})
        for i in range(3):
            w.append_history({{"i": i, "f": 10.0 * i}})
            if i < 2:
                w.write_frame(i, fake_fields(m, i + 1))
        os.kill(os.getpid(), signal.SIGKILL)
    """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    r = open_result(p)
    np.testing.assert_array_equal(r.history["f"], [0.0, 10.0, 20.0])
    assert r.frame_ids == [0, 1] and r.config == {"case": "killed"}
    np.testing.assert_array_equal(r.frame(1)["U"], fake_fields(tiny_model(), 2)["U"])
    with ResultWriter(p, None, {}, mode="a") as w:   # and a restart can continue it
        w.append_history({"i": 3, "f": 30.0})
    assert open_result(p).n_history == 4
    json.loads(h5py.File(p, "r")["config"].attrs["json"])


def test_writes_the_disk_could_not_hold_are_refused_before_they_start(tmp_path, monkeypatch):
    """A disk filled by the run: HDF5 cannot undo a write that fails midway (a full disk left a
    file that did not open, a flood of h5py errors and a segmentation fault); each write is
    refused before it starts, naming the file, the free space and what it needed."""
    import dr_masonry.results.writer as results
    p = tmp_path / "r.h5"
    write_fake_result(p)
    free = {"bytes": results.SPACE_RESERVE + 100}
    monkeypatch.setattr(results, "free_bytes", lambda path: free["bytes"])
    m = tiny_model()
    w = ResultWriter(p, None, {}, mode="a")
    with pytest.raises(ResultsError, match=r"r.h5: 16.0 MiB free on its disk; writing frame 9 "
                                           r"\(0.0 MiB\) would leave less than the 16 MiB kept"):
        w.write_frame(9, {"U": np.ones((m.n_nodes, 3)) * 1e-3})   # 576 bytes
    with pytest.raises(ResultsError, match=r"writing the checkpoint of increment 9 .*resume=true"):
        w.write_checkpoint(9, {"U": np.ones((m.n_nodes, 3))}, {"n": 9})
    free["bytes"] = results.SPACE_RESERVE + 800   # enough for the frame, not for a kept copy
    w.write_frame(9, {"U": np.ones((m.n_nodes, 3)) * 1e-3})
    w.write_checkpoint(9, {"U": np.ones((m.n_nodes, 3))}, {"n": 9})
    with pytest.raises(ResultsError, match=r"checkpoint of increment 10"):
        w.write_checkpoint(10, {"U": np.ones((m.n_nodes, 3))}, {"n": 10}, keep=True)
    w.close()
    r = open_result(p)
    assert r.frame_ids == [0, 2, 4, 9] and r.n_history == 5 and r.checkpoint()[0] == 9
    with pytest.raises(ResultsError, match=r"writing the model"):
        ResultWriter(tmp_path / "new.h5", m, {})
    assert not (tmp_path / "new.h5").exists()
    free["bytes"] = results.SPACE_RESERVE + 20_000   # the model, not 3 columns of 1,024 rows
    with ResultWriter(tmp_path / "new.h5", m, {}) as w:
        with pytest.raises(ResultsError, match=r"writing history row 1 \(0.0 MiB\)"):
            w.append_history({"increment": 0, "disp": 0.0, "force": 0.0})
    assert open_result(tmp_path / "new.h5").n_history == 0


def test_a_file_a_running_process_writes_is_read_with_a_warning(tmp_path):
    """`dr-masonry info` on a run still going: HDF5's lock refused the read ('unable to lock
    file'); the file is read as of its last row, with a warning naming it."""
    import dr_masonry.results.reader as results
    p = tmp_path / "r.h5"
    write_fake_result(p)
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import sys
        from dr_masonry.results import ResultWriter
        w = ResultWriter({str(p)!r}, None, {{}}, mode="a")
        w.append_history({{"increment": 5, "disp": 5e-4, "force": 0.0}})
        print("open", flush=True)
        sys.stdin.read()     # holds the file open for writing until stdin closes
        """)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "open"
        with pytest.raises(OSError, match="unable to lock file"):
            h5py.File(p, "r")
        results._UNLOCKED.discard(str(p))
        with pytest.warns(RuntimeWarning, match=r"r.h5' is open for writing in another process"):
            r = open_result(p)
        assert r.n_history == 6 and r.history["disp"][-1] == 5e-4 and r.frame_ids == [0, 2, 4]
        for mode, verb in (("a", "continue"), ("w", "create")):   # resume, or a run again
            with pytest.raises(ResultsError, match=rf"cannot {verb} results file .*r.h5': another "
                                                   r"process has it open \(a run still writing"):
                ResultWriter(p, tiny_model() if mode == "w" else None, {}, mode=mode)
    finally:
        holder.communicate(timeout=30)
    assert holder.returncode == 0


def test_an_existing_file_that_is_not_a_results_file_is_not_overwritten(tmp_path):
    """output="notes.txt" by mistake had replaced the notes by an HDF5 file."""
    p = tmp_path / "notes.txt"
    p.write_text("field notes")
    with pytest.raises(ResultsError, match=r"notes.txt' exists and is not an HDF5 file"):
        ResultWriter(p, tiny_model(), {})
    assert p.read_text() == "field notes"
    write_fake_result(tmp_path / "r.h5")
    write_fake_result(tmp_path / "r.h5", n_rows=2)     # a results file: a new run replaces it
    assert open_result(tmp_path / "r.h5").n_history == 2


def test_pack_keeps_history_checkpoint_and_chosen_frames(tmp_path, monkeypatch):
    """``pack``: a compressed copy with the history (still appendable), the last checkpoint and
    the chosen frames, equal to the file's; no checkpoint, a missing frame or the file itself as
    the copy are refused with the reason."""
    from dr_masonry.results import pack
    p, q = tmp_path / "r.h5", tmp_path / "copy.h5"
    m, cfg = write_fake_result(p)
    with pytest.raises(ResultsError, match="has no checkpoint"):
        pack(p, q)
    U = np.tile(np.linspace(0.0, 1e-3, 24)[:, None], (1, 3))   # compressible, not constant
    with ResultWriter(p, None, {}, mode="a") as w:
        w.write_checkpoint(4, {"U": U, "lam": np.array([0.5])}, {"stage": [0, 4]}, keep=True)
    with pytest.raises(ResultsError, match=r"no frame of increment\(s\) \[3\]; its frames are "
                       r"of increments \[0, 2, 4\]"):
        pack(p, q, frames=[2, 3])
    with pytest.raises(ResultsError, match="written over itself"):
        pack(p, str(p))
    assert not q.exists() and not os.path.exists(str(q) + ".part")
    pack(p, q, frames=[2])
    r, c = open_result(p), open_result(q)
    assert c.frame_ids == [2] and c.kept_checkpoints == [] and r.kept_checkpoints == [4]
    assert c.config == cfg and c.attrs == r.attrs
    for k in r.history:
        np.testing.assert_array_equal(c.history[k], r.history[k], err_msg=k)
    for k, v in r.model_arrays.items():
        if k != "contacts":
            np.testing.assert_array_equal(c.model_arrays[k], v, err_msg=k)
    for k, v in fake_fields(m, 2).items():
        np.testing.assert_array_equal(c.frame(0)[k], v, err_msg=k)
    (i, arrays, meta), (i0, arrays0, meta0) = c.checkpoint(), r.checkpoint()
    assert (i, meta) == (i0, meta0) == (4, {"stage": [0, 4]})
    assert set(arrays) == set(arrays0) and np.array_equal(arrays["U"], U)
    with h5py.File(q, "r") as f:
        assert f["checkpoint/U"].compression == "gzip"
        assert f["history/force"].maxshape == (None,)
    with ResultWriter(q, None, {}, mode="a") as w:   # a continued run appends its rows
        w.append_history({"increment": 5, "disp": 5e-4, "force": 1.0})
    assert open_result(q).n_history == 6
    pack(p, q, frames="all")
    assert open_result(q).frame_ids == [0, 2, 4]
    import dr_masonry.results.packing as results

    def full_disk(a, b):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(results, "_copy_packed", full_disk)
    with pytest.raises(OSError, match="No space left"):
        pack(p, tmp_path / "failed.h5")
    assert not list(tmp_path.glob("failed.h5*"))   # no copy, no partial file left


def test_git_revision_of_a_checkout(tmp_path):
    """The revision recorded with a run: a repository's short HEAD, ``.dirty`` with uncommitted
    changes to tracked files; nothing for a folder that is not the top of a work tree."""
    from dr_masonry.results.schema import _git_revision, code_version
    assert _git_revision(str(tmp_path)) == ""            # no repository
    git = ["git", "-C", str(tmp_path), "-c", "user.name=t", "-c", "user.email=t@example.org"]
    subprocess.run(git + ["init", "-q"], check=True)
    assert _git_revision(str(tmp_path)) == ""            # no commit yet
    (tmp_path / "a.txt").write_text("1")
    (tmp_path / "sub").mkdir()
    subprocess.run(git + ["add", "a.txt"], check=True)
    subprocess.run(git + ["commit", "-q", "-m", "one"], check=True)
    head = subprocess.run(git + ["rev-parse", "--short=7", "HEAD"], check=True,
                          capture_output=True, text=True).stdout.strip()
    assert _git_revision(str(tmp_path)) == head
    (tmp_path / "new.txt").write_text("untracked: not a change of the code run")
    assert _git_revision(str(tmp_path)) == head
    (tmp_path / "a.txt").write_text("2")
    assert _git_revision(str(tmp_path)) == head + ".dirty"
    assert _git_revision(str(tmp_path / "sub")) == ""    # inside a repository, not its top
    from importlib import metadata
    assert code_version().startswith(metadata.version("dr_masonry"))

"""Finite sliding of the joints (dr_masonry/sliding.py): a block pushed along two foundation blocks
and off their end (and back), checked against rigid-block statics (friction plateau, reactions,
friction work), the geometry of the re-paired points, the energy balance and a restart across a
re-pairing."""
import numpy as np
import pytest

from dr_masonry import BodyForce, Gravity, Indirect, JointLaw, Load, Model, PlasticDamage
from dr_masonry import Simulation, SolverOptions, Stage
from dr_masonry.contact_search import local_gaps, project_bilinear
from dr_masonry.kernels.joint_law import JS_D, JS_DP1, JS_DP2, JS_G1, JS_GU, P_KC
from dr_masonry.sliding import SWITCH
from dr_masonry.results import ResultsError, open_result

MU = 0.3
MAT = PlasticDamage.elastic(10e9, 0.2, 2000.0)


def build(output=None, redetect=True, **options):
    """Foundation blocks A = [0, 0.2] and B = [0.2, 0.4] m (fixed, two quads each along x) under a
    0.2 x 0.1 x 0.1 m block on [0.1, 0.3], across their joint (four elements along x: its base is
    the slave side)."""
    m = Model()
    m.set_joint_law(JointLaw.dry(MU))
    a = m.add_box((0.0, 0.0, -0.1), (0.2, 0.1, 0.1), MAT, (2, 1, 1), fixed=True)
    b = m.add_box((0.2, 0.0, -0.1), (0.2, 0.1, 0.1), MAT, (2, 1, 1), fixed=True)
    blk = m.add_box((0.1, 0.0, 0.0), (0.2, 0.1, 0.1), MAT, (4, 1, 1))
    sim = Simulation(m, SolverOptions(tol=1e-6, redetect=redetect, **options), output=output)
    nodes = m.block_nodes(blk)
    rp = sim.rigid_point("top", nodes=nodes[np.isclose(m.nodes[nodes, 2], 0.1)])
    sim.contact_reaction("base", [blk], [a, b])
    return sim, rp, blk


def stages(rp, blk, path, pattern=None):
    pattern = pattern or BodyForce(accel=(9.81, 0.0, 0.0), blocks=[blk])
    push = Indirect(pattern=pattern, target=rp, dof="x", path=path, name="push")
    return [Stage("gravity", 1, [Load(pattern=Gravity(), to=1.0)]), Stage("push", len(path), [push])]


PATH = np.linspace(0.016, 0.16, 10)   # the block ends on [0.26, 0.46]: 60 mm beyond B
WEIGHT = 2000.0 * 9.81 * 0.2 * 0.1 * 0.1


def test_block_slides_across_faces_and_off_the_end():
    sim, rp, blk = build()
    m = sim.model
    master0 = m.contacts.master.copy()
    with pytest.warns(RuntimeWarning, match="slid"):   # nodes beyond B's end, before they drop
        hist = sim.run(stages(rp, blk, PATH))
    c = sim.cont
    # rigid-block statics: the friction plateau and the base reactions, through every re-pairing
    np.testing.assert_allclose(hist["lambda"][1:], MU, rtol=1e-3)
    np.testing.assert_allclose(hist["base.fz"], WEIGHT, rtol=1e-6)
    np.testing.assert_allclose(hist["base.fx"][1:], -MU * WEIGHT, rtol=1e-3)
    assert np.all(np.abs(hist["balance_error"]) < 0.02)
    assert hist["contacts_moved"][1:].sum() > 0
    x = m.nodes + sim.dyn.U
    on = c.area > 0
    # the nodes beyond B's end by more than half the block's largest element edge (50 mm) are
    # off: the two at the leading end, x = 0.46
    xs = x[c.slave, 0]
    np.testing.assert_array_equal(~on, xs > 0.4 + 0.05)
    assert hist["contacts_off"][-1] == 2
    f = sim.fields()     # a point off the surface carries no traction, whatever its law says
    assert np.all(f["sigma"][~on] == 0.0) and np.all(f["tau"][~on] == 0.0)
    assert np.all(f["sigma"][on] < 0.0)
    # every point on a face is on the quad under its node (of B from x = 0.2) to within the
    # switching distance, and the gap its law sees is the block's whole slip: continuous through
    # every switch
    r, s = project_bilinear(x[c.master[on]], x[c.slave[on]])
    inside = xs[on] <= 0.4 + 1e-9
    assert np.abs(np.r_[r[inside], s[inside]]).max() <= 1 + SWITCH + 1e-6
    np.testing.assert_allclose(np.abs(c.gaps[on, 1]), PATH[-1], rtol=1e-4)
    assert np.all(sim.sliding.blocks[on, 1][xs[on] > 0.2 + 1e-9] == 1)
    # the model keeps the set as detected (reference pairing), the run its own
    np.testing.assert_array_equal(m.contacts.master, master0)


def test_points_taken_back_after_sliding_off_come_back_as_fresh_contacts():
    """Out to 60 mm beyond B's end (two points off) and back: the points a face takes back
    carry nothing from their time off into the friction. To make that state as bad as it gets
    (as on the S4 double-clamped cyclic run), the off points' nodes are put 2 mm below the plane
    of the quad they left (their gap offset) with a slider stuck 50 mm behind: the friction of
    every increment back is still the rigid block's, mu W |du|, and the balance holds."""
    sim, rp, blk = build()
    pattern = BodyForce(accel=(9.81, 0.0, 0.0), blocks=[blk])
    with pytest.warns(RuntimeWarning, match="slid"):
        out = sim.run(stages(rp, blk, PATH, pattern))
    c = sim.cont
    off = np.flatnonzero(c.area == 0.0)
    assert off.size == 2
    c.gap0[off, 0] += 0.002
    c.s_old[off, JS_DP1] -= 0.05 * np.sign(c.s_old[off, JS_G1])
    c.s_new[off] = c.s_old[off]
    back = np.linspace(0.144, 0.016, 9)
    push = Indirect(pattern=pattern, target=rp, dof="x", path=back, name="back")
    hist = sim.run([Stage("back", back.size, [push])])
    assert hist["contacts_off"][out["increment"].size] == 0      # taken back in the first row
    np.testing.assert_allclose(hist["lambda"][-back.size:], -MU, rtol=1e-3)
    # the first row back reverses the slip within one step (the midpoint rule's known limit);
    # every one after it dissipates the rigid block's friction work
    dw = np.diff(hist["D_joint_friction"][-back.size:])
    du = np.abs(np.diff(hist["top.ux"][-back.size:]))
    np.testing.assert_allclose(dw, MU * WEIGHT * du, rtol=2e-3)
    assert np.all(np.abs(hist["balance_error"]) < 0.01)
    # seated as fresh dry contacts when taken back (at the end of the first row back): plastic
    # slip measured from there
    np.testing.assert_allclose(c.s_old[off, JS_D], 1.0)
    np.testing.assert_allclose(np.linalg.norm(c.s_old[off, JS_DP1:JS_DP2 + 1], axis=1),
                               back[0] - back[-1], rtol=1e-3)


def _normal_traction(sim, pts):
    """sigma (Pa) of contact points ``pts`` at the current displacements (their committed
    histories unchanged)."""
    from dr_masonry.kernels.forces import contact_forces
    c, n = sim.cont, pts.size
    trac = np.zeros((n, 3))
    contact_forces(sim.model.nodes, sim.dyn.U, c.slave[pts], c.master[pts], c.xi[pts],
                   c.area[pts], c.law[pts], c.lparams, c.gap0[pts], c.s_old[pts],
                   c.s_new[pts].copy(), np.zeros((n, 3)), trac, np.zeros((5 * n, 3)), np.zeros(n))
    return trac[:, 0]


def test_a_node_behind_a_face_is_seated_where_it_is_and_the_seat_rises_with_it():
    """After the push, the block is moved back 20 mm by hand (the two nodes off the end come
    within reach of B's face again) with those nodes sagging 2 mm below the face's plane (a
    crushed corner hanging over the edge). Seated at the face, the penalty would throw them out;
    they are seated where they are, 2 mm sunk: no traction there, the penalty against a further
    sinking, none against lifting. Lifted by 1.5 mm the seat follows them to 0.5 mm below the
    face, and lifted above the face it is back at the face. A node on the far side of the brick
    (100 mm below, beyond ``SINK``) is not seated."""
    sim, rp, blk = build()
    with pytest.warns(RuntimeWarning, match="slid"):
        sim.run(stages(rp, blk, PATH))
    c, m, sl = sim.cont, sim.model, sim.sliding
    off = np.flatnonzero(c.area == 0.0)
    assert off.size == 2
    kc = c.lparams[c.law[off], P_KC]
    sim.dyn.U[m.block_nodes(blk), 0] -= 0.02
    sim.dyn.U[c.slave[off], 2] -= 0.1
    sl.update()                                           # far side of the brick: off
    assert np.all(c.area[off] == 0.0) and np.all(sl.sunk == 0.0)
    sim.dyn.U[c.slave[off], 2] += 0.098
    sl.update()
    np.testing.assert_allclose(c.area[off], sl.area0[off])
    np.testing.assert_allclose(sl.sunk[off], 0.002, atol=1e-8)
    np.testing.assert_allclose(c.s_old[off, JS_D], 1.0)
    np.testing.assert_allclose(c.s_old[off, JS_DP1:JS_DP2 + 1], 0.0)
    x = m.nodes + sim.dyn.U
    g = local_gaps(x, c.slave[off], c.master[off], c.xi[off]) - c.gap0[off]
    np.testing.assert_allclose(g, 0.0, atol=1e-12)        # seated where it is: no slip, no gap
    np.testing.assert_allclose(_normal_traction(sim, off), 0.0, atol=1e-3)
    sim.dyn.U[c.slave[off], 2] -= 1e-4                    # sinking further: the penalty
    np.testing.assert_allclose(_normal_traction(sim, off), -kc * 1e-4, rtol=1e-6)
    sim.dyn.U[c.slave[off], 2] += 1e-4 + 0.0015           # lifted 1.5 mm: free, seat follows
    assert np.all(_normal_traction(sim, off) == 0.0)
    gu = c.s_old[off, JS_GU].copy()
    sl.update()
    np.testing.assert_allclose(sl.sunk[off], 0.0005, atol=1e-8)
    x = m.nodes + sim.dyn.U
    g = local_gaps(x, c.slave[off], c.master[off], c.xi[off]) - c.gap0[off]
    np.testing.assert_allclose(g[:, 0], 0.0, atol=1e-12)
    np.testing.assert_allclose(c.s_old[off, JS_GU], gu - 0.0015, atol=1e-8)   # its gap as well
    sim.dyn.U[c.slave[off], 2] += 0.0015                  # 1 mm above the face: seat at it
    sl.update()
    assert np.all(sl.sunk[off] == 0.0)
    x = m.nodes + sim.dyn.U
    g = local_gaps(x, c.slave[off], c.master[off], c.xi[off]) - c.gap0[off]
    np.testing.assert_allclose(g[:, 0], 0.001, atol=1e-8)
    np.testing.assert_allclose(c.gap0[off, 0], sl.u_ref[off], atol=1e-12)   # the face's seat


def test_an_increment_that_moves_the_energy_balance_names_its_points():
    """A joint state corrupted by hand (the slider of one point 50 mm behind its slip) books
    friction from nowhere in the next increment: the warning names that point."""
    sim, rp, blk = build()
    pattern = BodyForce(accel=(9.81, 0.0, 0.0), blocks=[blk])
    with pytest.warns(RuntimeWarning, match="slid"):
        sim.run(stages(rp, blk, PATH[:3], pattern))
    c = sim.cont
    k = 3
    c.s_old[k, JS_DP1] -= 0.05 * np.sign(c.s_old[k, JS_G1])
    push = Indirect(pattern=pattern, target=rp, dof="x", path=PATH[3:4], name="push")
    with pytest.warns(RuntimeWarning, match=rf"moved by .* J .* in this one increment; most of "
                      rf"it booked at joint point {k} \(node {c.slave[k]}, blocks 2-\d\)"):
        sim.run([Stage("more", 1, [push])])


def test_small_sliding_keeps_the_reference_pairing():
    """``redetect=False``: no point moves; the node that started on the joint of A and B keeps
    its point on A, which it has left by the slip (the overhang)."""
    sim, rp, blk = build(redetect=False)
    with pytest.warns(RuntimeWarning, match="slid"):
        hist = sim.run(stages(rp, blk, PATH[:4]))
    assert np.all(hist["contacts_moved"] == 0)
    np.testing.assert_array_equal(sim.cont.master, sim.model.contacts.master)
    assert hist["max_overhang"][-1] == pytest.approx(PATH[3], rel=1e-3)


def test_restart_across_a_repairing(tmp_path):
    """A run stopped after its re-pairings and resumed from the file ends as an uninterrupted
    one; frames after the first change carry their contact set."""
    sim, rp, blk = build()
    with pytest.warns(RuntimeWarning):
        whole = sim.run(stages(rp, blk, PATH))
    path = str(tmp_path / "slide.h5")
    sim1, rp1, _ = build(output=path)
    with pytest.warns(RuntimeWarning):
        sim1.run(stages(rp1, blk, PATH[:7]))
    sim1.close()
    assert sum(sim1.history["contacts_moved"]) > 0
    sim2, rp2, _ = build()
    sim2.resume(path)
    push = Indirect(pattern=BodyForce(accel=(9.81, 0.0, 0.0), blocks=[blk]), target=rp2, dof="x",
                    path=PATH[7:], name="push")
    with pytest.warns(RuntimeWarning):
        hist = sim2.run([Stage("rest", 3, [push])])
    sim2.close()
    for key in ("lambda", "top.ux", "base.fz", "D_joints", "contacts_moved", "contacts_off"):
        np.testing.assert_allclose(hist[key], whole[key], rtol=1e-9, atol=1e-12, err_msg=key)
    np.testing.assert_array_equal(sim2.cont.master, sim.cont.master)
    r = open_result(path)
    assert r.contacts(-1)["area"].min() == 0.0               # the last frame's own set
    assert r.contacts(0)["area"].min() > 0.0                 # the first: the model's
    # the VTK series draws every frame with its own set
    from dr_masonry.viz.vtk_series import export_vtk
    export_vtk(path, str(tmp_path / "vtk"))
    assert (tmp_path / "vtk" / "contacts.pvd").exists()
    assert len(list((tmp_path / "vtk").glob("contacts_*.vtu"))) == len(r.frame_ids)


def test_resume_from_a_kept_checkpoint(tmp_path, capsys):
    """A run that keeps every checkpoint, continued from the one kept after increment 6 (before
    its block slid off the end), ends as an uninterrupted one; the kept checkpoints after 6 go
    with its rows, and asking for one it does not keep names those it keeps, file untouched."""
    sim, rp, blk = build()
    with pytest.warns(RuntimeWarning):
        whole = sim.run(stages(rp, blk, PATH))
    path = str(tmp_path / "keep.h5")
    sim1, rp1, _ = build(output=path, checkpoint_s=0.0, keep_checkpoint_s=1e-9)
    with pytest.warns(RuntimeWarning):
        sim1.run(stages(rp1, blk, PATH))
    sim1.close()
    assert open_result(path).kept_checkpoints == list(range(1, 12))
    restarts = len(open_result(path).attrs["restarts"])
    with pytest.raises(ResultsError, match=r"no checkpoint of increment 99; it keeps \[1, 2"):
        build()[0].resume(path, 99)
    assert len(open_result(path).attrs["restarts"]) == restarts
    sim2, rp2, _ = build()
    sim2.resume(path, 6)
    with pytest.warns(RuntimeWarning):
        hist = sim2.run(stages(rp2, blk, PATH))
    sim2.close()
    for key in ("lambda", "top.ux", "base.fz", "D_joints", "contacts_moved", "contacts_off"):
        np.testing.assert_allclose(hist[key], whole[key], rtol=1e-9, atol=1e-12, err_msg=key)
    r = open_result(path)
    assert r.kept_checkpoints == list(range(1, 7))
    assert r.n_history == whole["increment"].size
    from dr_masonry.cli import main
    assert main(["info", path]) == 0
    assert "kept checkpoints: increments 1, 2, 3, 4, 5, 6 (resume_from=INCREMENT)" in \
        capsys.readouterr().out


def _sagging(output=None):
    """The sliding block with its leading base corner (two nodes) as node set ``tip``: the
    simulation and the stages (push beyond B's end, pull the corner 2 mm down, slide back 20 mm
    over B, lift the corner back) as a dict of stage lists."""
    from dr_masonry import Displacement
    sim, rp, blk = build(output=output)
    nodes = sim.model.block_nodes(blk)
    x0 = sim.model.nodes[nodes]
    tip = sim.node_set("tip", nodes[np.isclose(x0[:, 0], 0.3) & np.isclose(x0[:, 2], 0.0)])
    pattern = BodyForce(accel=(9.81, 0.0, 0.0), blocks=[blk])

    def hold(path, z):
        return [Indirect(pattern=pattern, target=rp, dof="x", path=path, name="push"),
                Displacement(target=tip, dof="z", to=z)]
    return sim, nodes, {"out": stages(rp, blk, PATH, pattern) + [
        Stage("sag", 2, hold([PATH[-1]] * 2, -0.002)),
        Stage("back", 2, hold([0.15, 0.14], -0.002))],
        "lift": [Stage("lift", 2, hold([0.14, 0.14], 0.0))]}


def test_a_sagging_corner_slid_back_over_a_face_is_held_where_it_is():
    """The block's leading base corner (two nodes), pushed 60 mm beyond B's end, is pulled 2 mm
    down (a prescribed displacement: a crushed corner hanging over the edge) and the block slid
    back 20 mm, over B's face: the corner's points come back sunk 2 mm, the block slides back at
    the friction plateau with nothing thrown, and when the corner is lifted to the face the seats
    rise with it; the energy balance holds throughout. (Before the sunk seats, the two points
    stayed off and the corner could sink into B unresisted.)"""
    sim, nodes, run = _sagging()
    m = sim.model
    with pytest.warns(RuntimeWarning, match="slid"):
        hist = sim.run(run["out"] + run["lift"])
    n = PATH.size + 1
    off, sunk = hist["contacts_off"], hist["contacts_sunk"]
    assert np.all(off[n - 1:n + 2] == 2) and np.all(sunk[:n + 2] == 0)   # off while sagging
    assert off[n + 2] == 0 and sunk[n + 2] == 2          # taken back sunk at the first row back
    assert off[-1] == 0 and sunk[-1] == 0                # lifted to the face: seated there
    # sliding back at the friction plateau of the base's normal force: the weight and the pull
    # that holds the corner down
    back = slice(n + 2, n + 4)
    np.testing.assert_allclose(hist["base.fx"][back], MU * hist["base.fz"][back], rtol=1e-3)
    np.testing.assert_allclose(hist["base.fz"][back], WEIGHT - hist["tip.fz"][back], rtol=1e-3)
    z = (m.nodes + sim.dyn.U)[nodes, 2] - m.nodes[nodes, 2]
    assert np.abs(z).max() < 1e-4                        # nothing thrown
    assert np.all(np.abs(hist["balance_error"]) < 0.02)


def test_sunk_seats_survive_a_restart(tmp_path):
    """Stopped with two points sunk and resumed from the file, the run lifts them as the
    uninterrupted one does."""
    sim, _, run = _sagging()
    with pytest.warns(RuntimeWarning, match="slid"):
        whole = sim.run(run["out"] + run["lift"])
    path = str(tmp_path / "sag.h5")
    sim1, _, run1 = _sagging(output=path)
    with pytest.warns(RuntimeWarning, match="slid"):
        sim1.run(run1["out"])
    sim1.close()
    assert np.all(sim1.sliding.sunk[sim1.sliding.sunk > 0] > 0.0019)
    sim2, _, run2 = _sagging()
    sim2.resume(path)
    np.testing.assert_array_equal(sim2.sliding.sunk, sim1.sliding.sunk)
    np.testing.assert_array_equal(sim2.cont.gap0, sim1.cont.gap0)
    hist = sim2.run(run2["lift"])
    for key in ("contacts_sunk", "contacts_off"):
        np.testing.assert_array_equal(hist[key], whole[key], err_msg=key)
    # the same equilibria to the relaxation's tolerance (1e-6; the resumed iterates differ from
    # the uninterrupted ones by about 3e-9 once the corner is prescribed)
    for key, scale in (("lambda", 1.0), ("base.fz", WEIGHT), ("tip.fz", WEIGHT)):
        np.testing.assert_allclose(hist[key], whole[key], rtol=0, atol=1e-6 * scale, err_msg=key)

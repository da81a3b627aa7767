"""Finite sliding of the joints (dr_masonry/sliding.py): a block pushed along two foundation blocks
and off their end, checked against rigid-block statics (friction plateau, reactions), the
geometry of the re-paired points, the energy balance and a restart across a re-pairing."""
import numpy as np
import pytest

from dr_masonry import BodyForce, Gravity, Indirect, JointLaw, Load, Model, PlasticDamage
from dr_masonry import Simulation, SolverOptions, Stage
from dr_masonry.contact_search import project_bilinear
from dr_masonry.sliding import SWITCH
from dr_masonry.results import open_result

MU = 0.3
MAT = PlasticDamage.elastic(10e9, 0.2, 2000.0)


def build(output=None, redetect=True):
    """Foundation blocks A = [0, 0.2] and B = [0.2, 0.4] m (fixed, two quads each along x) under a
    0.2 x 0.1 x 0.1 m block on [0.1, 0.3], across their joint (four elements along x: its base is
    the slave side)."""
    m = Model()
    m.set_joint_law(JointLaw.dry(MU))
    a = m.add_box((0.0, 0.0, -0.1), (0.2, 0.1, 0.1), MAT, (2, 1, 1), fixed=True)
    b = m.add_box((0.2, 0.0, -0.1), (0.2, 0.1, 0.1), MAT, (2, 1, 1), fixed=True)
    blk = m.add_box((0.1, 0.0, 0.0), (0.2, 0.1, 0.1), MAT, (4, 1, 1))
    sim = Simulation(m, SolverOptions(tol=1e-6, redetect=redetect), output=output)
    nodes = m.block_nodes(blk)
    rp = sim.rigid_point("top", nodes=nodes[np.isclose(m.nodes[nodes, 2], 0.1)])
    sim.contact_reaction("base", [blk], [a, b])
    return sim, rp, blk


def stages(rp, blk, path):
    push = Indirect(pattern=BodyForce(accel=(9.81, 0.0, 0.0), blocks=[blk]), target=rp, dof="x",
                    path=path, name="push")
    return [Stage("gravity", 1, [Load(pattern=Gravity(), to=1.0)]), Stage("push", len(path), [push])]


PATH = np.linspace(0.016, 0.16, 10)   # the block ends on [0.26, 0.46]: 60 mm beyond B


def test_block_slides_across_faces_and_off_the_end():
    sim, rp, blk = build()
    m = sim.model
    master0 = m.contacts.master.copy()
    with pytest.warns(RuntimeWarning, match="slid"):   # nodes beyond B's end, before they drop
        hist = sim.run(stages(rp, blk, PATH))
    c = sim.cont
    weight = 2000.0 * 9.81 * 0.2 * 0.1 * 0.1
    # rigid-block statics: the friction plateau and the base reactions, through every re-pairing
    np.testing.assert_allclose(hist["lambda"][1:], MU, rtol=1e-3)
    np.testing.assert_allclose(hist["base.fz"], weight, rtol=1e-6)
    np.testing.assert_allclose(hist["base.fx"][1:], -MU * weight, rtol=1e-3)
    assert np.all(np.abs(hist["balance_error"]) < 0.02)
    assert hist["contacts_moved"][1:].sum() > 0
    x = m.nodes + sim.dyn.U
    on = c.area > 0
    # the nodes beyond B's end by more than half the block's largest element edge (50 mm) are
    # off: the two at the leading end, x = 0.46
    xs = x[c.slave, 0]
    np.testing.assert_array_equal(~on, xs > 0.4 + 0.05)
    assert hist["contacts_off"][-1] == 2
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

"""Run-time monitors (``Simulation.monitors``): called after every compiled relaxation call with
the iterations so far, and able to stop a run with the rows so far kept."""
import numpy as np
import pytest

from dr_masonry import Displacement, Gravity, JointLaw, Load, Model, PlasticDamage
from dr_masonry import Simulation, SolverOptions, Stage
from dr_masonry.kernels import relaxation as R
from dr_masonry.results import open_result
from dr_masonry.solver import relaxing as S

MAT = PlasticDamage.elastic(10e9, 0.2, 2000.0)


def setup(output=None):
    """A block on a fixed one, gravity then a lateral push of its top (cohesive joint)."""
    m = Model()
    m.set_joint_law(JointLaw.reference())
    m.add_box((0.0, 0.0, -0.1), (0.2, 0.1, 0.1), MAT, (2, 1, 1), fixed=True)
    blk = m.add_box((0.0, 0.0, 0.0), (0.2, 0.1, 0.1), MAT, (2, 1, 1))
    sim = Simulation(m, SolverOptions(tol=1e-6, coarse=False), output=output)
    nodes = m.block_nodes(blk)
    rp = sim.rigid_point("top", nodes=nodes[np.isclose(m.nodes[nodes, 2], 0.1)])
    stages = [Stage("gravity", 1, [Load(pattern=Gravity(), to=1.0)]),
              Stage("push", 4, [Displacement(target=rp, dof="x", to=2e-5)])]
    return sim, stages


def test_monitor_sees_every_call_of_every_row(monkeypatch):
    monkeypatch.setattr(S, "CALL_ITERATIONS", 20)   # rows of 40-90 iterations: several calls
    sim, stages = setup()
    calls = []
    sim.monitors.append(lambda s, out, done: calls.append(
        (s.increment + 1, done, out.status, out.residual)))
    hist = sim.run(stages)
    assert hist["cut_iterations"].sum() == 0
    for row, iters in zip(hist["increment"].astype(int), hist["iterations"].astype(int)):
        mine = [c for c in calls if c[0] == row]
        done = [c[1] for c in mine]
        assert done == sorted(done) and done[-1] == iters
        assert all(b - a <= 20 for a, b in zip([0] + done, done))
        assert mine[-1][2] == R.ST_CONVERGED and mine[-1][3] <= 1e-6
        assert all(c[2] == R.ST_MAXITER for c in mine[:-1])
    assert all(len([c for c in calls if c[0] == r]) > 1 for r in range(1, 6))


def test_a_monitor_stops_the_run_and_the_rows_so_far_stay(tmp_path):
    path = str(tmp_path / "stopped.h5")
    sim, stages = setup(path)

    class Enough(Exception):
        pass

    def stop_in_row_3(s, out, done):
        if s.increment + 1 == 3:
            raise Enough

    sim.monitors.append(stop_in_row_3)
    with pytest.raises(Enough):
        sim.run(stages)
    assert sim.increment == 2
    sim.close()
    assert np.asarray(open_result(path).history["increment"]).tolist() == [1.0, 2.0]

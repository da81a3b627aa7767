"""Opening control (``loading.Opening``): the closed-form snap-back of two elastic bars joined by
a softening joint, traced with the joint's opening held; the same specimen under end-displacement
control jumps instead. The analytical curve is that of bars and joint in series:

    u_end = 2 L sigma / E + w(sigma),   w(sigma) = u0 + (u_k - u0) x(sigma),
    1 - sigma / ft = (1 - exp(-zeta x)) / (1 - exp(-zeta))

(the monotonic tension envelope sigma = ft (1 - g) of the joint law, MODEL.md eq (7)); with
2 L / E above the softening compliance the end displacement decreases as the joint softens."""
import numpy as np
import pytest

from dr_masonry import (Displacement, JointLaw, Model, Opening, PlasticDamage, Simulation,
                        SolverOptions, Stage)
from dr_masonry.loading import LoadingError, PointLoad

L, A, E = 1.0, 0.01, 1e9            # m, m^2, Pa: each bar 1 m long, 0.1 x 0.1 m
FT, UK, ZETA, KNN = 1e5, 1e-4, 1.0, 75e9


def envelope(w):
    """The joint's monotonic tension envelope (Pa) at openings ``w`` (m)."""
    u0 = FT / KNN
    g = (1.0 - np.exp(-ZETA * (w - u0) / (UK - u0))) / (1.0 - np.exp(-ZETA))
    return np.where(w <= u0, KNN * w, FT * (1.0 - g))


def analytic_end(sigma):
    """End displacement (m) on the softening branch at stress ``sigma`` Pa (< FT)."""
    u0 = FT / KNN
    x = -np.log(1.0 - (1.0 - sigma / FT) * (1.0 - np.exp(-ZETA))) / ZETA
    return 2.0 * L * sigma / E + u0 + (UK - u0) * x


def specimen():
    """The two bars (4 hexahedra each, Poisson's ratio 0, every node held in y and z), the left
    end fixed in x; returns (simulation, end node set, the joint's two faces)."""
    m = Model()
    m.set_joint_law(JointLaw.reference(ft=FT, u_k=UK, zeta=ZETA, knn=KNN, c=1e6))
    bar = PlasticDamage.elastic(E, 0.0, 2000.0)
    m.add_box((0.0, 0.0, 0.0), (L, 0.1, 0.1), bar, (4, 1, 1))
    m.add_box((L, 0.0, 0.0), (L, 0.1, 0.1), bar, (4, 1, 1))
    sim = Simulation(m, SolverOptions(tol=1e-6, coarse=False, max_cuts=6))
    X = m.nodes
    sim.fix(np.arange(m.n_nodes), "yz")
    sim.fix(np.flatnonzero(np.isclose(X[:, 0], 0.0)), "x")
    end = sim.node_set("end", np.flatnonzero(np.isclose(X[:, 0], 2 * L)))
    faces = [sim.node_set(name, nodes[np.isclose(X[nodes, 0], L)])
             for name, nodes in (("face0", m.block_nodes([0])), ("face1", m.block_nodes([1])))]
    return sim, end, faces


@pytest.mark.parametrize("rate", [0.0, 1e-3, 1e-2])
def test_opening_control_traces_the_snap_back(rate):
    """40 increments of the opening up to 0.9 u_k, the factor by the secant (rate 0) or relaxed
    with the motion (rate 1e-3): every row is converged, the end displacement turns back after
    the peak (it falls by half), and every row lies on the analytical curve: its end displacement
    within 1 % of the curve's at its stress (measured: 1e-4)."""
    sim, end, (a, b) = specimen()
    pull = PointLoad(target=end, dof="x", value=A, name="pull")   # factor = stress, Pa
    ends = []

    class EndDisplacement:   # an observer of the committed rows
        def row(self, sim, row):
            ends.append(sim.dyn.U[end.nodes, 0].mean())
    sim.observers.append(EndDisplacement())
    hist = sim.run([Stage("open", 40, [Opening(pattern=pull, a=a, b=b, dof="x", to=0.9 * UK,
                                               rate=rate)])])
    sigma = hist["lambda"]
    u_end = np.array(ends)
    opening = hist["face1.ux"] - hist["face0.ux"]
    assert np.all(np.diff(opening) > 0) and opening[-1] == pytest.approx(0.9 * UK, rel=1e-6)
    assert np.all(hist["residual"] <= 1e-6)
    soft = sigma < 0.999 * FT
    assert soft.sum() >= 38 and sigma.max() == pytest.approx(FT, rel=0.02)
    assert np.all(np.diff(u_end[soft]) < 0) and u_end[-1] < 0.55 * u_end[soft][0]
    np.testing.assert_allclose(u_end[soft], analytic_end(sigma[soft]), rtol=0.01)
    # the joint's dissipation: the trapezoidal work of the analytical envelope over the rows'
    # openings (the rule the law integrates by, exact for a linear step) minus the energy that
    # secant unloading would give back, 1/2 sigma w
    w = np.concatenate([[0.0], opening])
    env = envelope(w)
    work = (0.5 * (env[1:] + env[:-1]) * np.diff(w)).sum()
    assert hist["D_joints"][-1] == pytest.approx((work - 0.5 * env[-1] * w[-1]) * A, rel=2e-3)
    assert np.abs(hist["balance_error"]).max() < 0.01


def test_end_displacement_control_jumps_where_the_curve_turns_back():
    """The same specimen with its end displacement prescribed: up to the peak the stress
    follows 2 L / E in series with the joint; past it no equilibrium is near on the softening
    branch (it turns back), and one increment drops the stress from near ft to almost nothing."""
    sim, end, _ = specimen()
    hist = sim.run([Stage("pull", 40, [Displacement(target=end, dof="x", to=2.5e-4)])])
    sigma = hist["end.fx"] / A
    drop = int(np.argmax(-np.diff(sigma)))
    assert sigma[drop] > 0.85 * FT and sigma[drop + 1] < 0.05 * FT
    before = slice(0, drop + 1)
    np.testing.assert_allclose(sigma[before],
                               hist["end.ux"][before] / (2 * L / E + 1 / KNN), rtol=0.01)


def test_opening_control_input_errors():
    sim, end, (a, b) = specimen()
    pull = PointLoad(target=end, dof="x", value=A, name="pull")
    with pytest.raises(LoadingError, match="b must be a NodeSet"):
        Opening(pattern=pull, a=a, b="face1", to=1e-5)
    with pytest.raises(LoadingError, match="share nodes"):
        Opening(pattern=pull, a=a, b=a, to=1e-5)
    for rate in (-1e-3, 0.5, float("nan"), "fast"):
        with pytest.raises(LoadingError, match=r"rate=.* must be a number in \[0, 0.01\]"):
            Opening(pattern=pull, a=a, b=b, to=1e-5, rate=rate)
    with pytest.raises(LoadingError, match="at most one Indirect or Opening"):
        Stage("s", 1, [Opening(pattern=pull, a=a, b=b, to=1e-5),
                       Opening(pattern=pull, a=a, b=b, to=2e-5)])
    fixed = sim.node_set("left", np.flatnonzero(np.isclose(sim.model.nodes[:, 0], 0.0)))
    with pytest.raises(LoadingError, match="fixed or tied"):
        sim.run([Stage("s", 1, [Opening(pattern=pull, a=fixed, b=b, to=1e-5)])])
    with pytest.raises(LoadingError, match="direction is the zero vector"):
        Opening(pattern=pull, a=a, b=b, direction=(0, 0, 0), to=1e-5)
    with pytest.raises(LoadingError, match="direction: .* must be 3 finite numbers"):
        Opening(pattern=pull, a=a, b=b, direction=(1, 0), to=1e-5)
    with pytest.raises(LoadingError, match="is fixed or tied to a rigid point in z"):
        sim.run([Stage("s", 1, [Opening(pattern=pull, a=a, b=b, direction=(1, 0, 1),
                                        to=1e-5)])])


def test_opening_along_a_direction_is_the_projection_of_the_mean_displacements():
    """The constraint of ``direction=(3, 0, 4)`` measures (mean U of b - mean U of a) . (0.6, 0,
    0.8) on any displacement field, and ``direction=(2, 0, 0)`` the same opening as dof x."""
    from dr_masonry.solver.controls import constraint
    sim, end, (a, b) = specimen()
    pull = PointLoad(target=end, dof="x", value=A, name="pull")
    U = np.random.default_rng(1).normal(size=(sim.model.n_nodes, 3))
    expect = (U[b.nodes].mean(0) - U[a.nodes].mean(0)) @ [0.6, 0.0, 0.8]
    for direction, value in (((3, 0, 4), expect),
                             ((2, 0, 0), U[b.nodes, 0].mean() - U[a.nodes, 0].mean())):
        con = constraint(sim, Opening(pattern=pull, a=a, b=b, direction=direction, to=1e-5), 0.0)
        assert (con.coef * U[con.node, con.dof]).sum() == pytest.approx(value, rel=1e-12)

"""Shared set-ups and plain numpy references of the relaxation tests (test_damping.py,
test_relaxation_kernels.py): a glued elastic column and its loaded variant, numpy FIRE and viscous
iterations, and :func:`relax_call`, one compiled call of the loop of any damping scheme."""
import numpy as np

from dr_masonry import JointLaw, Model, PlasticDamage, Simulation, SolverOptions
from dr_masonry.kernels import damping_schemes as D
from dr_masonry.kernels import relaxation as R

DOFS = ("x", "y", "z", "rx", "ry", "rz")



def column(n_blocks=3, H=0.081):
    """A column of ``n_blocks`` glued elastic bricks 0.22 x 0.102 x ``H`` m, 3 x 2 x 2
    hexahedra each."""
    m = Model()
    m.set_joint_law(JointLaw.tied(2e10, 8e9))
    mat = PlasticDamage.elastic(5e9, 0.2, 2000.0)
    for k in range(n_blocks):
        m.add_box((0.0, 0.0, k * H), (0.22, 0.102, H), mat, (3, 2, 2))
    return m


def loaded_column(n_blocks=3):
    """Glued column, base clamped, top face tied to a rigid point loaded on all 6 DOFs."""
    m = column(n_blocks)
    sim = Simulation(m, SolverOptions(damping="fire"))
    X = m.nodes
    sim.fix(np.nonzero(np.isclose(X[:, 2], 0.0))[0])
    rp = sim.rigid_point("tip", nodes=np.nonzero(np.isclose(X[:, 2], 3 * 0.081))[0])
    sim.build()
    sim.dyn.rpf[0] = 3e4 * np.array([3.0, 2.0, -5.0, 0.0, 0.0, 0.4])
    return sim, rp


def fire_reference(sim, n_iter, alpha):
    """Plain numpy FIRE (Bitzek et al. 2006, semi-implicit Euler, half step back on a stop) on the
    free node DOFs and rigid-point DOFs of ``sim``, forces from the kernels' internal forces."""
    d = sim.dyn
    free = d.free > 0
    rpfree = d.rpfree > 0
    minv = np.concatenate([np.broadcast_to(d.minv[:, None], d.U.shape)[free], d.rpminv[rpfree]])
    rpres = np.zeros((d.rpX.shape[0], 6))
    dt, a, n_pos = 0.5, alpha, 0
    R.place_rigid_nodes(d)
    for _ in range(n_iter):
        R.internal_forces(sim.mesh, sim.cont, d)
        R.residual(d, 0.0, rpres)
        f = np.concatenate([d.res[free], rpres[rpfree]])
        v = np.concatenate([d.V[free], d.rpV[rpfree]])
        x = np.concatenate([d.U[free], d.rpU[rpfree]])
        power = f @ v
        if power < 0:
            x -= 0.5 * dt * v
            v[:] = 0.0
            dt, a, n_pos = 0.5 * dt, alpha, 0
        else:
            n_pos += 1
            if n_pos > 5:
                dt, a = min(1.1 * dt, 1.0), 0.99 * a
            vnorm = np.sqrt(v @ (v / minv))          # |v|_M
            fnorm = np.sqrt(f @ (minv * f))          # |M^-1 f|_M
            v = (1 - a) * v + a * vnorm / fnorm * minv * f
        v += dt * minv * f
        x += dt * v
        nf = free.sum()
        d.V[free], d.rpV[rpfree] = v[:nf], v[nf:]
        d.U[free], d.rpU[rpfree] = x[:nf], x[nf:]
        R.place_rigid_nodes(d)


def viscous_reference(sim, n_iter, alpha, ring):
    """Plain numpy viscous damping (Underwood's coefficient from the Rayleigh quotient of the
    motion, capped at 1.9; none in the first iteration) with ring damping: a node DOF whose
    decaying count of velocity reversals exceeds ``R.RING_COUNT`` gets the coefficient ``ring``
    when that is larger. Returns how many DOF-iterations were ring-damped."""
    d = sim.dyn
    free = d.free > 0
    rpfree = d.rpfree > 0
    m = np.broadcast_to(1.0 / d.minv[:, None], d.U.shape)
    rpres = np.zeros((d.rpX.shape[0], 6))
    count = np.zeros(d.U.shape)
    fprev = d.fint.copy()
    rung = 0
    R.place_rigid_nodes(d)
    for it in range(n_iter):
        R.internal_forces(sim.mesh, sim.cont, d)
        R.residual(d, 0.0, rpres)
        num = (d.V * (d.fint - fprev))[free].sum() if it else 0.0
        den = (d.V ** 2 * m)[free].sum()
        c = min(alpha * 2.0 * np.sqrt(num / den), 1.9) if den > 0 and num > 0 else 0.0
        fprev = d.fint.copy()
        ci = np.where((count > R.RING_COUNT) & (ring > c), ring, c)
        rung += int(((ci > c) & free).sum())
        vn = ((2.0 - ci) * d.V + 2.0 * d.res / m) / (2.0 + ci)
        count = np.where(free, R.RING_MEMORY * count + (vn * d.V < 0), count)
        d.V[free] = vn[free]
        d.rpV[rpfree] = (((2.0 - c) * d.rpV + 2.0 * d.rpminv * rpres) / (2.0 + c))[rpfree]
        d.U[free] += d.V[free]
        d.rpU[rpfree] += d.rpV[rpfree]
        R.place_rigid_nodes(d)
    return rung


#: the kernel code of each non-default damping scheme
SCHEMES = {"kinetic": D.DAMP_KINETIC, "local": D.DAMP_LOCAL, "fire": D.DAMP_FIRE}


def relax_call(sim, scheme, alpha, tol, iters, stall, pr=None, state=None, check_every=10,
               ring=1.0, left=0.0):
    """One compiled call of the relaxation loop of ``scheme`` ("viscous", "kinetic", "local",
    "fire") on ``sim`` with no load factor or control, run-away limit 1 m, no block or
    resultant criterion; ``pr``, ``state``: the Progress and scheme state of an earlier call
    to continue (None: a new span). Returns (Exit, Progress, scheme state)."""
    crit = R.Criteria(float(tol), float(sim.ref_floor), 0.0, 0.0, int(check_every), int(stall),
                      1.0, float(left), int(iters))
    pr = R.start_progress() if pr is None else pr
    args = (sim.mesh, sim.cont, sim.dyn, np.zeros(1), np.zeros(3, np.int64), 1.0)
    if scheme == "viscous":
        return R.relax(*args, float(alpha), float(ring), crit, pr, R.no_constraint()) + (None,)
    code = SCHEMES[scheme]
    state = D.start_state(code, alpha) if state is None else state
    return D.relax_scheme(*args, code, float(alpha), crit, pr, state)

"""Peer comparison: the same hexahedral brick stepped explicitly by Akantu and by dr_masonry.

For each ``sizes`` entry ``nx x ny x nz`` a single block of nx x ny x nz cubic hexahedra of edge
``edge`` m (elastic ``E`` Pa, ``nu``, ``rho`` kg/m^3, no supports) is built twice:

* Akantu (EPFL, ``pip install akantu``; optional, benchmark only): the mesh is written by this
  script as a gmsh v2 ASCII file of ``_hexahedron_8`` elements (our node and element numbering, so
  node i is node i on both sides) with an ``elastic`` material file, both under
  ``benchmarks/out/``; ``SolidMechanicsModel.initFull(_analysis_method=_explicit_lumped_mass)``,
  and one explicit step is ``model.solveStep()`` (central differences, lumped mass, 2x2x2 Gauss
  points). Variants ``akantu``: ``small`` is Akantu's default small-strain elastic material,
  ``finite`` the same with ``finite_deformation = true`` (Green-Lagrange strain, total
  Lagrangian);
* dr_masonry: ``Model().add_box(origin, size, PlasticDamage.elastic(E, nu, rho), (nx, ny, nz))``
  and ``Simulation.build()``. One explicit step is one iteration of the production loop
  ``kernels.relaxation.relax`` (``internal_forces``: ``hex_forces`` + gather, residual, the
  viscous-damping Rayleigh-quotient pass, velocity and displacement updates, the run-away guard,
  norms every 10 iterations), run for ``relax_iters`` iterations per call with ``tol = 0``. The
  relax loop was chosen over a hand-written update because it is what the solver runs, so its
  cost is the one the target is about; with the viscous scheme at ``alpha = 0`` it is the
  undamped central-difference scheme, and with the fictitious masses replaced by the physical
  lumped masses (``minv = dt^2 / m``; V is then the displacement per step) it is the same
  time integrator as Akantu's, which the physics check below verifies. An elastic material's
  elements are corotational linear hexahedra in a run (``kernels/hex8.py``: exact under rigid
  motion, equal to either Akantu variant to first order in the strain). ``hex_forces`` alone is
  timed too, with the argument builder of ``benchmarks/kernels.py`` (its elastic material, the
  corotational tables of a run).

Physics check (per size and Akantu variant): both codes start from U = 0 and the same smooth
initial velocity field and take ``check_steps`` steps of dt = ``dt_factor`` x Akantu's stable
step; printed are the relative differences of the lumped masses, of the displacements after
those steps and of the internal forces at Akantu's final displacement (our corotational
kinematics differ from both variants by O(strain): 1e-7 to 6e-6 here).

Timings: one thread on each side (``numba.set_num_threads(1)``; the akantu 5.0.7 wheel is built
without MPI and links no OpenMP or TBB runtime). Per case: best and median wall time of
``repeats`` batches of >= ``min_time`` s after a warm-up call (``timed`` of
``benchmarks/kernels.py``), and the mean process CPU time per call over all batches (``cpu_ns``,
which a loaded machine inflates much less than the wall time; ``cpu_per_wall`` = 1.0 when one
thread ran undisturbed). ``malloc`` phases: ``default`` runs with glibc's allocator as it comes;
then ``tuned`` sets ``mallopt`` (no mmap, no heap trimming below 1 GiB) for the rest of the
process and times everything again. Akantu allocates and frees its quadrature-point temporaries
every step; with the default settings they come back from the kernel as fresh pages each time
(about 3,000 page faults per step for 4,000 elements, 36,000 for 32,000; about half of its CPU
time is then system time), which the tuned settings avoid (about 20 faults per step). Ratios
table: Akantu / dr_masonry ns per element-step, wall (best) and CPU, for the full step
(``step_ratio``; the project's target is >= 5 against ``akantu small``) and for ``hex_forces``
alone. Run:
``NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 python benchmarks/peer_akantu.py [key=value ...]``;
writes ``benchmarks/out/peer_akantu*.csv``.
"""
import os
import sys
import time

import numpy as np

from common import OUT, check_ran, divisions, machine, relax_args, report, timed  # noqa: I100  (script folder on sys.path)
from benchmarks import kernels as bench  # noqa: I100  (common puts the repository root on sys.path)

PARAMS = dict(
    sizes=("20x20x10", "40x40x20"),  # hexahedra along x, y, z
    edge=0.05,               # m, element edge
    E=4.8e9,                 # Pa
    nu=0.17,
    rho=1800.0,              # kg/m^3
    akantu=("small", "finite"),
    dt_factor=0.5,           # time step / Akantu's stable time step
    check_steps=50,
    velocity=1e-3,           # m/s, amplitude of the initial velocity field of the check
    relax_iters=100,         # iterations per timed relax call
    malloc=("default", "tuned"),  # glibc allocator settings, see tune_malloc
    repeats=3,
    min_time=1.0,            # s per timed batch
)
VARIANTS = {"small": False, "finite": True}
M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_MAX = -1, -2, -4  # glibc mallopt parameters


def write_gmsh(path, X, conn):
    """Gmsh v2.2 ASCII mesh of hexahedra (type 5, VTK = gmsh corner order), 1-based ids.

    ``X`` (n_nodes, 3) m, ``conn`` (ne, 8) int.
    """
    n, ne = X.shape[0], conn.shape[0]
    with open(path, "w") as f:
        f.write(f"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n{n}\n")
        np.savetxt(f, np.column_stack([np.arange(1, n + 1), X]), fmt=["%d"] + ["%.17g"] * 3)
        f.write(f"$EndNodes\n$Elements\n{ne}\n")
        # id, type 5 (8-node hexahedron), 2 tags (physical, elementary), nodes
        rows = np.column_stack([np.arange(1, ne + 1), np.full((ne, 3), [5, 2, 1]),
                                np.ones(ne, np.int64), conn + 1])
        np.savetxt(f, rows, fmt="%d")
        f.write("$EndElements\n")


def write_material(path, E, nu, rho, finite):
    """Akantu material file: one ``elastic`` material (E Pa, nu, rho kg/m^3)."""
    with open(path, "w") as f:
        f.write(f"material elastic [\n  name = brick\n  rho = {rho!r}\n  E = {E!r}\n"
                f"  nu = {nu!r}\n  finite_deformation = {'true' if finite else 'false'}\n]\n")


def build_ours(div, edge, E, nu, rho):
    """Built ``Simulation`` of one box block of ``div`` hexahedra of edge ``edge`` m."""
    from dr_masonry import Model, PlasticDamage, Simulation
    model = Model()
    size = edge * np.asarray(div, dtype=np.float64)
    model.add_box((0.0, 0.0, 0.0), size, PlasticDamage.elastic(E, nu, rho), div)
    sim = Simulation(model)
    sim.build()
    if sim.cont.slave.shape[0]:
        raise RuntimeError(f"one block should have no contacts, got {sim.cont.slave.shape[0]}")
    return sim


def build_akantu(aka, msh, mat):
    """Akantu explicit lumped-mass ``(Mesh, SolidMechanicsModel)`` of files ``msh`` and ``mat``."""
    aka.parseInput(mat)
    mesh = aka.Mesh(3)
    mesh.read(msh)
    model = aka.SolidMechanicsModel(mesh)
    model.initFull(_analysis_method=aka._explicit_lumped_mass)
    model.assembleMassLumped()
    return mesh, model


def initial_velocity(X, amp):
    """Smooth, non-rigid velocity field (n_nodes, 3) m/s of amplitude ``amp`` over the box ``X``."""
    s = (X - X.min(axis=0)) / np.ptp(X, axis=0) * np.pi
    return amp * np.column_stack([np.sin(s[:, 0]) * np.cos(s[:, 1]),
                                  np.sin(s[:, 1]) * np.cos(s[:, 2]),
                                  np.sin(s[:, 2]) * np.cos(s[:, 0])])


def rel(a, b):
    """||a - b|| / ||b||."""
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def tune_malloc():
    """glibc ``mallopt``: no mmap, no trimming below 1 GiB, so freed temporaries are reused."""
    import ctypes
    try:
        mallopt = ctypes.CDLL("libc.so.6").mallopt
    except (OSError, AttributeError) as err:
        raise RuntimeError(f"malloc: 'tuned' needs glibc's mallopt: {err}") from err
    for opt, value in ((M_MMAP_MAX, 0), (M_TRIM_THRESHOLD, 1 << 30), (M_TOP_PAD, 64 << 20)):
        if mallopt(opt, value) != 1:
            raise RuntimeError(f"malloc: mallopt({opt}, {value}) was refused")


def timed_cpu(fn, args, params):
    """(best s, median s per call, mean process CPU s per call, CPU / wall) of ``fn(*args)``."""
    calls = [0]

    def counted(*a):
        calls[0] += 1
        fn(*a)

    w0, c0 = time.perf_counter(), time.process_time()
    best, med = timed(counted, args, params["repeats"], params["min_time"])
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    return best, med, cpu / calls[0], cpu / wall


def check_physics(model, sim, v0, dt, steps):
    """Relative differences (masses, U after ``steps`` steps, internal forces) of a fresh pair.

    Both start from U = 0 and velocity ``v0`` (n_nodes, 3) m/s; time step ``dt`` s, set in
    ``model`` and, as ``minv`` = dt^2 / m, in ``sim.dyn``.
    """
    from dr_masonry.kernels.relaxation import internal_forces, relax
    d = sim.dyn
    model.getVelocity()[:] = v0
    for _ in range(steps):
        model.solveStep()
    u_aka = model.getDisplacement().copy()
    model.assembleInternalForces()
    f_aka = -model.getInternalForce()  # Akantu stores the internal force as -int B^T sigma
    d.U[:] = 0.0
    d.V[:] = dt * v0  # m per step
    args = relax_args(sim, steps, 0.0, 0.0)   # the same undamped dynamics as Akantu's
    check_ran(relax(*args))
    u_ours = d.U.copy()
    d.U[:] = u_aka
    internal_forces(sim.mesh, sim.cont, d)
    return dict(max_u_m=float(np.abs(u_aka).max()),
                rel_diff_mass=rel(sim.mass, model.getMass()[:, 0]),
                rel_diff_u=rel(u_ours, u_aka), rel_diff_fint=rel(d.fint, f_aka))


def run_size(aka, div, params, phase, rows, checks):
    """Time (and, if ``checks`` is a list, check) one mesh ``div`` (nx, ny, nz) in ``phase``."""
    from dr_masonry.kernels.relaxation import relax
    E, nu, rho = params["E"], params["nu"], params["rho"]
    sim = build_ours(div, params["edge"], E, nu, rho)
    X, conn = sim.model.nodes, sim.model.elements
    ne = conn.shape[0]
    tag = "x".join(str(v) for v in div)
    msh = os.path.join(OUT, f"peer_akantu_{tag}.msh")
    write_gmsh(msh, X, conn)
    v0 = initial_velocity(X, params["velocity"])
    d = sim.dyn

    def add(code, best, med, cpu, cpu_wall, units):
        rows.append(dict(mesh=tag, elements=ne, malloc=phase, code=code,
                         ns_best=1e9 * best / units, ns_median=1e9 * med / units,
                         cpu_ns=1e9 * cpu / units, cpu_per_wall=cpu_wall))
        print(f"  {tag} malloc {phase}, {code}: {rows[-1]['ns_best']:.0f} ns/element-step "
              f"(CPU {rows[-1]['cpu_ns']:.0f})", flush=True)

    for variant in params["akantu"]:
        mat = os.path.join(OUT, f"peer_akantu_material_{variant}.dat")
        write_material(mat, E, nu, rho, VARIANTS[variant])
        mesh, model = build_akantu(aka, msh, mat)
        same = np.array_equal(mesh.getNodes(), X)
        if mesh.getNbElement(type=aka._hexahedron_8) != ne or not same:
            raise RuntimeError(f"Akantu read a different mesh from {msh}")
        dt = params["dt_factor"] * model.getStableTimeStep()
        model.setTimeStep(dt)
        d.minv[:] = dt * dt / sim.mass  # physical masses: relax's unit step is dt
        if checks is not None:
            checks.append(dict(mesh=tag, akantu=variant, dt_s=dt, steps=params["check_steps"],
                               **check_physics(model, sim, v0, dt, params["check_steps"])))
            print(f"  {tag} check vs akantu {variant}: " + ", ".join(
                f"{k} {v:.2e}" for k, v in checks[-1].items() if k.startswith("rel")), flush=True)
        else:
            model.getVelocity()[:] = v0
        add(f"akantu {variant} solveStep", *timed_cpu(model.solveStep, (), params), ne)
        del model, mesh
    d.V[:] = dt * v0
    hargs = bench.hex_args(sim, d.U, True)
    add("dr_masonry hex_forces", *timed_cpu(*bench.hex_call(hargs, bench.corot(sim, hargs)),
                                            params), ne)
    args = relax_args(sim, params["relax_iters"], 0.0)   # the production step
    add("dr_masonry relax step", *timed_cpu(relax, args, params), ne * params["relax_iters"])
    check_ran(relax(*args))


def ratios(rows):
    """Akantu / dr_masonry ns per element-step, per mesh, malloc phase and Akantu variant."""
    out = []
    by = {(r["mesh"], r["malloc"], r["code"]): r for r in rows}
    for (mesh, phase, code), r in by.items():
        if not code.startswith("akantu"):
            continue
        step = by[(mesh, phase, "dr_masonry relax step")]
        hexf = by[(mesh, phase, "dr_masonry hex_forces")]
        out.append(dict(mesh=mesh, malloc=phase, peer=code,
                        step_ratio=r["ns_best"] / step["ns_best"],
                        step_ratio_cpu=r["cpu_ns"] / step["cpu_ns"],
                        hex_forces_ratio=r["ns_best"] / hexf["ns_best"],
                        hex_forces_ratio_cpu=r["cpu_ns"] / hexf["cpu_ns"]))
    return out


def main(argv=None):
    from dr_masonry.params import parse_overrides
    params = parse_overrides(PARAMS, sys.argv[1:] if argv is None else argv, __doc__)
    try:
        import akantu as aka
    except ImportError as err:
        raise SystemExit(f"peer_akantu.py needs the optional package akantu (pip install akantu), "
                         f"which dr_masonry itself never uses: {err}")
    sizes = [divisions(s, "sizes") for s in params["sizes"]]
    for variant in params["akantu"]:
        if variant not in VARIANTS:
            raise ValueError(f"akantu: {variant!r} is not one of {list(VARIANTS)}")
    phases = list(params["malloc"])
    if phases not in (["default"], ["tuned"], ["default", "tuned"]):
        raise ValueError(f"malloc must be default, tuned or default,tuned (mallopt cannot be "
                         f"undone), got {','.join(phases)}")
    for key in ("edge", "dt_factor", "velocity", "min_time"):
        if not (np.isfinite(params[key]) and params[key] > 0):
            raise ValueError(f"{key} must be positive and finite, got {params[key]}")
    if params["dt_factor"] > 1.0:
        raise ValueError(f"dt_factor must be <= 1 (stable step), got {params['dt_factor']}")
    for key in ("check_steps", "relax_iters", "repeats"):
        if params[key] < 1:
            raise ValueError(f"{key} must be >= 1, got {params[key]}")
    import numba
    numba.set_num_threads(1)
    os.makedirs(OUT, exist_ok=True)
    print(f"machine: {machine()}")
    print(f"akantu {aka.getVersion()}, MPI {aka.has_mpi()}; numba threads {numba.get_num_threads()}"
          f", OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}", flush=True)
    rows, checks = [], []
    for k, phase in enumerate(phases):
        if phase == "tuned":
            tune_malloc()
        for div in sizes:
            run_size(aka, div, params, phase, rows, checks if k == 0 else None)
    report(checks, "peer_akantu_check", "Same physics: relative differences dr_masonry vs "
           "Akantu (same mesh, dt, initial velocity)")
    report(rows, "peer_akantu", "ns per element-step, one thread each: wall (best, median of "
           "the batches) and process CPU (mean)")
    report(ratios(rows), "peer_akantu_ratios", "Akantu / dr_masonry time per element-step "
           "(target: step_ratio >= 5)")
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()

"""Kernel cost per unit of work: hexahedra, contact points and a whole DR iteration.

Measures, on in-plane running-bond walls of the reference brick (mesh 4 x 2 x 1 per brick:
along, thickness, height) built by ``dr_masonry.geometry.add_wall``:

* ``hex_forces`` (the force kernel with no contact points): ns per element-step, elastic material
  (``PlasticDamage.elastic``) and the reference plastic-damage material, with strains in the
  elastic range (virgin elements skipping the state, and through the full state update) and with
  strains that make every Gauss point plastic and damaged (the fraction of damaged Gauss points
  is printed); each as the corotational element of a run and, for comparison, as the
  total-Lagrangian element at its Gauss points (``hex_forces`` without tables). The plastic
  case repeats one strain, so each return starts from its own root (the lower bound); "strain
  moving" alternates two strains ``MOVE`` apart, as two relaxation iterations do;
* ``contact_forces`` (the force kernel with no elements): ns per contact-point-step, joints elastic and joints damaged (opened);
* ``relax``: a full dynamic-relaxation iteration (viscous damping, gravity load, ``tol=0`` so it
  runs ``relax_iters`` iterations), ns per element-iteration;
* on each thread count of ``threads`` and each wall size of ``sizes``;
* first-call compile time in a fresh subprocess with an empty ``NUMBA_CACHE_DIR``, then the cached
  warm start in a second subprocess on the same cache (``compile=0`` skips both, ``steady=0``
  runs only them), both started as a run starts (``dr_masonry.precompile``: on a cold cache the
  force kernel compiles in a second process; ``DR_MASONRY_COMPILE_WORKERS=0`` measures one
  process); for the cold start, the compile time of each function of a run's kernels in the
  run's own process (Numba's ``numba:compile`` events, exclusive of the functions it compiles
  in turn: the largest ``compile_top``), which says where a cold start goes.

Timings are best and median of ``repeats`` batches of at least ``min_time`` s each; the machine is
shared, so compare ratios within one run. Run: ``python benchmarks/kernels.py [key=value ...]``;
writes ``benchmarks/out/kernels*.csv``.
"""
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

from common import ROOT, check_ran, machine, relax_args, report, timed  # noqa: I100  (script folder on sys.path)

PARAMS = dict(
    sizes="1.1x0.81,4.0x2.75",  # wall length x height, m (comma separated)
    threads="1,2",
    repeats=5,
    min_time=0.2,               # s per timed batch
    relax_iters=100,
    steady=True,                # steady-state timings (steady=0: only the compile/cache starts)
    compile=True,
    mode="all",                 # "all" or "firstcall" (used by the compile subprocesses)
    compile_top=8,              # functions listed in the cold start's compile split
)
ELASTIC_STRAIN = 2e-5           # uniaxial strain well inside the elastic range (0.1 MPa)
PLASTIC_STRAIN = 1e-3           # uniaxial tension, trial stress 4.8 MPa >> ft = 1.5 MPa
MOVE = 1e-5                     # relative change of the displacements between two plastic calls
JUMP_ELASTIC = 2e-7             # m, block translations: joint gaps below u0 = ft / knn = 1.6 um
JUMP_DAMAGED = 2e-4             # m, joint gaps far beyond u0


def build(length, height):
    """Simulation of a wall clamped at its base with its arrays built (no run)."""
    from dr_masonry import JointLaw, Model, PlasticDamage, Simulation, SolverOptions
    from dr_masonry.geometry import BrickSpec, add_wall, plane_nodes
    import warnings
    model = Model()
    model.set_joint_law(JointLaw.reference())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # length snapped to half bricks
        add_wall(model, (0, 0, 0), length, height, PlasticDamage.reference(),
                 brick=BrickSpec(nx_along=4, ny_thick=2, nz_height=1))
    sim = Simulation(model, SolverOptions(damping="viscous"))
    sim.fix(plane_nodes(model, 2, 0.0), "xyz")
    sim.build()
    return sim


def displacement(sim, strain, jump, seed=0):
    """Uniaxial strain along x (lateral contraction nu) plus a random translation per block."""
    m = sim.model
    X = m.nodes
    U = np.zeros_like(X)
    U[:, 0] = strain * X[:, 0]
    U[:, 1] = -0.17 * strain * X[:, 1]
    U[:, 2] = -0.17 * strain * X[:, 2]
    t = np.random.default_rng(seed).uniform(-jump, jump, (m.n_blocks, 3))
    return U + t[m.node_block]


def hex_args(sim, U, elastic, virgin=True):
    """Arguments of ``hex_forces`` for every element with the given material (``virgin``: the
    elements marked pristine, so that in their elastic range they skip the state update)."""
    from dr_masonry import PlasticDamage
    me = sim.mesh
    mat = PlasticDamage.elastic(4800e6, 0.17, 1800.0) if elastic else PlasticDamage.reference()
    params = mat.params_array()[None, :]
    s0 = np.repeat(np.repeat(mat.initial_state()[None, None, :], me.conn.shape[0], 0), 8, 1)
    emat = np.zeros(me.conn.shape[0], dtype=np.int64)
    return (U, me.conn, np.arange(me.conn.shape[0], dtype=np.int64), me.dN, me.geo, me.wdet, me.h,
            emat, params, s0, s0.copy(), np.full(me.conn.shape[0], int(virgin), np.uint8),
            np.zeros(me.conn.shape[0], np.uint8), np.zeros((me.conn.shape[0], 8, 3)),
            np.zeros(me.conn.shape[0]))


def corot(sim, args):
    """The corotational tables that a run gives the elements of ``hex_args``."""
    from dr_masonry.kernels.hex8 import corot_tables
    conn, dN, geo, wdet, emat, params = (args[i] for i in (1, 3, 4, 5, 7, 8))
    return corot_tables(sim.model.nodes, conn, dN, geo, wdet, emat, params,
                        np.arange(conn.shape[0]))


def hex_call(args, tables=None):
    """(kernel, its arguments) for ``hex_forces(*args, corot=tables)``: the call that the wrapper
    :func:`dr_masonry.kernels.forces.hex_forces` makes (the force kernel of a run with tables,
    the total-Lagrangian reference ``gauss_forces`` without), its packing kept out of the
    timing."""
    from dr_masonry.kernels.forces import element_and_contact_forces, hex_only_args
    from dr_masonry.kernels.hex8 import gauss_forces
    if tables is None:
        return gauss_forces, args
    return element_and_contact_forces, hex_only_args(*args, corot=tables)


def alternating(fn, call_a, call_b):
    """(a function, its arguments ()) calling ``fn(*call_a)`` and ``fn(*call_b)`` in turn: with
    the same state arrays and displacements ``MOVE`` apart, each call's returns start from the
    other's multipliers, as between two relaxation iterations (the plastic cases' calls with one
    strain start from their own root: the lower bound)."""
    calls = (call_a, call_b)
    turn = [0]

    def step():
        turn[0] ^= 1
        fn(*calls[turn[0]])
    return step, ()


def contact_call(args):
    """(force kernel, its arguments) for ``contact_forces(*args)``, as :func:`hex_call`."""
    from dr_masonry.kernels.forces import contact_only_args, element_and_contact_forces
    return element_and_contact_forces, contact_only_args(*args)


def contact_args(sim, U):
    c = sim.cont
    return (sim.dyn.X, np.ascontiguousarray(U), c.slave, c.master, c.xi, c.area, c.law,
            c.lparams, c.gap0, c.s_old, c.s_new, c.gaps, c.trac, c.fbuf, c.psi)


def gravity(sim, iters=1):
    """Self-weight on the free DOFs; returns the arguments of ``relax`` for ``iters`` iterations."""
    d = sim.dyn
    d.U[:] = 0.0
    d.V[:] = 0.0
    d.fext[:] = 0.0
    d.fext[:, 2] = -9.81 * sim.mass * d.free[:, 2]
    return relax_args(sim, iters)


def steady(params):
    import numba
    from dr_masonry.kernels.plastic_damage import MS_DT, MS_DC
    from dr_masonry.kernels.relaxation import relax
    rows = []
    for size in params["sizes"].split(","):
        length, height = (float(v) for v in size.lower().split("x"))
        sim = build(length, height)
        ne, nc = sim.model.elements.shape[0], sim.cont.slave.shape[0]
        cases = []
        for label, elastic, strain, virgin in (
                ("hex elastic material (corotational)", True, ELASTIC_STRAIN, True),
                ("hex elastic material, Gauss points", True, ELASTIC_STRAIN, True),
                ("hex reference, elastic range (corotational)", False, ELASTIC_STRAIN, True),
                ("hex reference, elastic range, Gauss points", False, ELASTIC_STRAIN, True),
                ("hex reference, elastic range, full update (corotational)", False,
                 ELASTIC_STRAIN, False),
                ("hex reference, elastic range, full update, Gauss points", False,
                 ELASTIC_STRAIN, False),
                ("hex reference, plastic+damaged (corotational)", False, PLASTIC_STRAIN, True),
                ("hex reference, plastic+damaged, Gauss points", False, PLASTIC_STRAIN, True)):
            args = hex_args(sim, displacement(sim, strain, 0.0), elastic, virgin)
            fn, call = hex_call(args, corot(sim, args) if "corotational" in label else None)
            fn(*call)
            s_new = args[10]
            frac = float(np.mean((s_new[:, :, MS_DT] > 0) | (s_new[:, :, MS_DC] > 0))) if not elastic else 0.0
            cases.append((label, fn, call, ne, "element-step", frac))
            if label == "hex reference, plastic+damaged (corotational)":
                fn2, call2 = alternating(fn, call, hex_call((args[0] * (1.0 + MOVE),) + args[1:],
                                                            corot(sim, args))[1])
                cases.append(("hex reference, plastic+damaged, strain moving (corotational)", fn2,
                              call2, ne, "element-step", frac))
        for label, jump in (("contact, joints elastic", JUMP_ELASTIC),
                            ("contact, joints damaged", JUMP_DAMAGED)):
            from dr_masonry.kernels.joint_law import JS_D
            args = contact_args(sim, displacement(sim, 0.0, jump, seed=1))
            fn, call = contact_call(args)
            fn(*call)
            frac = float(np.mean(args[10][:, JS_D] > 0))
            cases.append((label, fn, call, nc, "contact-step", frac))
        rargs = gravity(sim, params["relax_iters"])
        check_ran(relax(*rargs))
        cases.append(("relax iteration (viscous)", relax, rargs, ne * params["relax_iters"],
                      "element-iteration", float("nan")))
        for nt in (int(t) for t in params["threads"].split(",")):
            numba.set_num_threads(nt)
            for label, fn, args, units, unit, frac in cases:
                best, med = timed(fn, args, params["repeats"], params["min_time"])
                rows.append(dict(wall=f"{length}x{height}", elements=ne, contacts=nc, threads=nt,
                                 kernel=label, unit=unit, ns_best=1e9 * best / units,
                                 ns_median=1e9 * med / units, damaged_fraction=frac))
                print(f"  {size} {nt}t {label}: {1e9 * best / units:.0f} ns/{unit}", flush=True)
    report(rows, "kernels_steady", "Steady state, ns per unit of work")
    # same-run ratios: 2 threads vs 1, plastic vs elastic
    ratios = []
    for size in sorted({r["wall"] for r in rows}):
        sel = {(r["threads"], r["kernel"]): r["ns_best"] for r in rows if r["wall"] == size}
        for k in {r["kernel"] for r in rows}:
            if (1, k) in sel and (2, k) in sel:
                ratios.append(dict(wall=size, kernel=k, speedup_2_threads=sel[(1, k)] / sel[(2, k)]))
    if ratios:
        report(ratios, "kernels_ratios", "Same-run speed-up of 2 threads over 1 (best times)")


def firstcall():
    """Time the first calls (compile or cache load) in this fresh process; prints JSON.

    ``relax`` first: it holds every kernel a run needs (the iteration's fused force kernel
    included), so build + relax is what a run's cold start compiles
    (``production_total_s``); ``hex_forces`` (with a run's tables) and ``contact_forces`` alone,
    called after it (tests and these benchmarks), run the same force kernel with the other set
    empty: nothing new to compile (the total-Lagrangian reference, ``hex_forces`` without tables,
    is compiled apart and not timed here)."""
    from numba.core import event
    from dr_masonry.kernels.forces import contact_forces, hex_forces
    from dr_masonry.kernels.relaxation import relax
    from dr_masonry.precompile import ensure_compiled
    t = {}
    t0 = t1 = time.perf_counter()
    with event.install_recorder("numba:compile") as rec:
        sim = build(0.44, 0.243)
        t["build_s (geometry kernels + set-up)"] = time.perf_counter() - t1
        t1 = time.perf_counter()
        t["compile_worker"] = ensure_compiled(sim.mesh, sim.cont, sim.dyn)   # as a run does
        relax(*gravity(sim))
        t["relax_s"] = time.perf_counter() - t1
    t["production_total_s"] = time.perf_counter() - t0
    hargs = hex_args(sim, displacement(sim, 1e-5, 0), False)
    for name, fn, args, kw in (
            ("hex_forces_s", hex_forces, hargs, dict(corot=corot(sim, hargs))),
            ("contact_forces_s", contact_forces, contact_args(sim, displacement(sim, 0, 1e-7)),
             {})):
        t1 = time.perf_counter()
        fn(*args, **kw)
        t[name] = time.perf_counter() - t1
    t["first_calls_total_s"] = time.perf_counter() - t0
    t["compile_split"] = compile_split(rec.buffer)
    print(json.dumps(t))


def compile_split(events):
    """{function: seconds} compiling each function, exclusive of the functions compiled inside
    it, from Numba's ``numba:compile`` start/end events (name -> s, largest first)."""
    stack, own = [], {}
    for ts, ev in events:
        name = ev.data["dispatcher"].py_func.__qualname__
        if ev.is_start:
            stack.append([name, ts, 0.0])
            continue
        name, start, inner = stack.pop()
        own[name] = own.get(name, 0.0) + (ts - start) - inner
        if stack:
            stack[-1][2] += ts - start
    return dict(sorted(own.items(), key=lambda kv: -kv[1]))


def compile_times(top_n):
    rows, cold_split = [], []
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        for label in ("cold (empty cache)", "warm (cached)"):
            t0 = time.perf_counter()
            out = subprocess.run([sys.executable, __file__, "mode=firstcall"], env=env, cwd=ROOT,
                                 capture_output=True, text=True, check=True).stdout
            wall = time.perf_counter() - t0
            res = json.loads(out.strip().splitlines()[-1])
            split = res.pop("compile_split")
            rows.append(dict(start=label, process_wall_s=wall, **res,
                             interpreter_and_imports_s=wall - res["first_calls_total_s"]))
            print(f"  {label}: {wall:.1f} s", flush=True)
            if label.startswith("cold"):
                top = list(split.items())[:top_n]
                cold_split = [dict(function=k, compile_s=v) for k, v in top]
    report(rows, "kernels_firstcall", "First call: compile vs cached start (fresh processes)")
    report(cold_split, "kernels_compile_split",
           f"Cold start of a run's kernels: compile time per function, exclusive (largest {top_n})")


def main(argv=None):
    from dr_masonry.params import parse_overrides
    params = parse_overrides(PARAMS, sys.argv[1:] if argv is None else argv, __doc__)
    if params["mode"] == "firstcall":
        firstcall()
        return
    import numba
    print(f"machine: {machine()}")
    if params["steady"]:
        steady(params)
        print(f"numba threading layer used: {numba.threading_layer()}, "
              f"OMP_WAIT_POLICY={os.environ.get('OMP_WAIT_POLICY')}")
    if params["compile"]:
        compile_times(params["compile_top"])


if __name__ == "__main__":
    main()

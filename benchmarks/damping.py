"""Iterations per load increment and wall time of each damping scheme, and growth with size.

Part 1 runs every scheme of ``schemes`` on
* S2: ``cases/triplet.py`` at one pre-compression ``sigma`` (MPa), ``s2_increments`` shear steps;
* S3: ``cases/wallet.py`` shortened to ``s3_shortening`` m in ``s3_increments`` steps;
* a rocking block: an elastic 0.2 x 0.1 x 0.4 m block on a dry joint (mu 0.6) over a fixed
  foundation, gravity, then a horizontal body force whose factor is found by indirect control of
  the x displacement of a rigid cap over its top face (rigid-block overturning factor b / h = 0.5).
Part 2 pushes in-plane walls of ``lengths`` (m, ``height`` m, coarse mesh 2 x 1 x 1 per brick)
clamped at the base and carrying an elastic top beam: gravity, then ``push_increments`` steps
of an elastic-range horizontal displacement ``push`` (m) of the beam; the fitted exponent b of
iterations ~ n^b (n = elements along the wall) is printed per scheme; the same for ``heights``
at the first length (n = courses).

The iteration cap per increment is lowered to ``max_iter`` with ``max_cuts`` halvings so a stalling
scheme fails in bounded time; a failure is recorded with its message. Run:
``python benchmarks/damping.py [key=value ...]``; writes ``benchmarks/out/damping*.csv``.
"""
import sys
import time
import warnings

import numpy as np

from common import machine, report  # noqa: I100

PARAMS = dict(
    schemes="viscous,fire,kinetic,local",
    parts="scenes,size",
    sigma=0.6,               # S2 pre-compression, MPa
    s2_increments=30,
    s3_shortening=0.003,     # m
    s3_increments=30,
    rock_increments=20,
    rock_top=0.01,           # m, final horizontal displacement of the block's top corner
    lengths="1.1,2.2,4.0",
    height=0.81,             # m, height of the length scan
    heights="0.81,1.62,2.75",  # m, heights scanned at the first length
    push=2e-5,               # m, horizontal displacement of the top beam (elastic range)
    push_increments=4,
    max_iter=30000,
    max_cuts=2,
    tol=1e-4,
    tag="",                  # suffix of the CSV names (keeps partial runs apart)
)



def run_stages(sim, stages, params):
    """Run stage by stage; returns (per-stage list of (name, iterations array), wall s, error)."""
    sim.options.increments.max_iter = params["max_iter"]
    sim.options.increments.max_cuts = params["max_cuts"]
    out, err = [], ""
    t0 = time.perf_counter()
    for st in stages:
        n0 = len(sim.history.get("iterations", []))
        try:
            sim.run([st])
        except Exception as e:  # a failing scheme is a result, recorded with its message
            err = f"{type(e).__name__}: {e}"
        out.append((st.name, np.asarray(sim.history.get("iterations", []))[n0:]))
        if err:
            break
    return out, time.perf_counter() - t0, err


def rocking(params, damping):
    from dr_masonry import (Gravity, BodyForce, Indirect, JointLaw, Load, Model, PlasticDamage,
                            Simulation, SolverOptions, Stage)
    model = Model()
    model.set_joint_law(JointLaw.dry(0.6))
    mat = PlasticDamage.elastic(4800e6, 0.17, 1800.0)
    model.add_box((-0.1, 0, -0.1), (0.4, 0.1, 0.1), mat, (4, 1, 1), fixed=True)
    b = model.add_box((0, 0, 0), (0.2, 0.1, 0.4), mat, (2, 1, 4))
    sim = Simulation(model, SolverOptions(tol=params["tol"], damping=damping))
    nodes = model.block_nodes([b])
    x = model.nodes[nodes]
    # indirect control on a rigid cap over the top face (a single-node target fails without any
    # rigid point in the model: see BENCHMARKS.md, solver bug)
    top = sim.rigid_point("cap", nodes=nodes[np.isclose(x[:, 2], 0.4)])
    n = params["rock_increments"]
    path = params["rock_top"] * np.arange(1, n + 1) / n
    stages = [Stage("gravity", 5, [Load(pattern=Gravity(), to=1.0)]),
              Stage("push", n, [Indirect(pattern=BodyForce(accel=(9.81, 0, 0), blocks=[b]),
                                         target=top, dof="x", path=path)])]
    return sim, stages


def wall_push(params, length, height, damping):
    from dr_masonry import (Displacement, Gravity, JointLaw, Load, Model, PlasticDamage,
                            Simulation, SolverOptions, Stage)
    from dr_masonry.geometry import BrickSpec, add_beam, add_wall, plane_nodes
    model = Model()
    model.set_joint_law(JointLaw.reference())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        w = add_wall(model, (0, 0, 0), length, height, PlasticDamage.reference(),
                     brick=BrickSpec(nx_along=2, ny_thick=1, nz_height=1))
    beam = add_beam(model, (0, 0, w.height), (w.length, w.thickness, 0.1),
                    PlasticDamage.elastic(30e9, 0.2, 2500.0),
                    element_size=(0.11, w.thickness, 0.1))
    sim = Simulation(model, SolverOptions(tol=params["tol"], damping=damping))
    sim.fix(plane_nodes(model, 2, 0.0), "xyz")
    rp = sim.rigid_point("beam", blocks=[beam])
    holds = [Displacement(target=rp, dof=d, to=0.0) for d in ("y", "rx", "ry", "rz")]
    stages = [Stage("gravity", 3, [Load(pattern=Gravity(), to=1.0)]),
              Stage("push", params["push_increments"],
                    holds + [Displacement(target=rp, dof="x", to=params["push"])])]
    return sim, stages, int(round(w.length / 0.11)), len(w.courses)


def scenes(params, schemes):
    rows = []
    from dr_masonry.cases import triplet, wallet
    sim, stages = triplet.build(dict(triplet.PARAMS, increments=1, h5=None), 0.2e6)
    t0 = time.perf_counter()
    sim.run(stages[:1])  # compile or load the kernels before any timing
    print(f"  warm-up (compile or cache load): {time.perf_counter() - t0:.1f} s", flush=True)
    for damping in schemes:
        builds = {
            "S2 triplet": lambda: triplet.build(dict(triplet.PARAMS, increments=params["s2_increments"],
                                                     damping=damping, h5=None), params["sigma"] * 1e6),
            "S3 wallet": lambda: wallet.build(dict(wallet.PARAMS, shortening=params["s3_shortening"],
                                                   increments=params["s3_increments"],
                                                   damping=damping, h5=None)),
            "rocking block": lambda: rocking(params, damping),
        }
        for scene, make in builds.items():
            built = make()            # (sim, stages), the wallet's with its Wallet third
            sim, stages = built[:2]
            per_stage, wall, err = run_stages(sim, stages, params)
            for name, its in per_stage:
                rows.append(dict(scene=scene, stage=name, damping=damping, increments=len(its),
                                 it_mean=float(its.mean()) if its.size else float("nan"),
                                 it_max=int(its.max()) if its.size else 0,
                                 status="ok" if not err or name != per_stage[-1][0] else "FAILED"))
            h = {k: np.asarray(v) for k, v in sim.history.items()}
            rows[-1]["wall_s_scene"] = wall
            rows[-1]["relax_s_scene"] = float(np.sum(sim.history.get("time_s", [0.0])))
            n_it = float(np.sum(sim.history.get("iterations", [0.0])))
            rows[-1]["us_per_iter"] = 1e6 * rows[-1]["relax_s_scene"] / n_it if n_it else float("nan")
            extra = ""
            if "lambda" in h and scene == "rocking block":
                extra = f"max lambda {np.max(h['lambda']):.3f} (rigid 0.5)"
            elif scene == "S2 triplet" and "push.fx" in h:
                extra = f"max tau {np.max(h['push.fx']) / (2 * triplet.AREA) / 1e6:.3f} MPa"
            elif scene == "S3 wallet" and "platen.fz" in h:
                extra = f"max stress {np.max(-h['platen.fz']) / built[2].area / 1e6:.2f} MPa"
            for r in rows:
                r.setdefault("wall_s_scene", float("nan"))
                r.setdefault("relax_s_scene", float("nan"))
                r.setdefault("us_per_iter", float("nan"))
            rows[-1]["note"] = (err[:160] + " | " if err else "") + extra
            print(f"  {scene} {damping}: {wall:.1f} s {'FAILED ' + err[:120] if err else 'ok'}",
                  flush=True)
    for r in rows:
        r.setdefault("note", "")
    report(rows, "damping_scenes" + params["tag"], "Iterations per increment by damping scheme")


def _mean(a):
    """Mean of an iteration array, NaN when the stage produced no increment."""
    return float(np.mean(a)) if a is not None and len(a) else float("nan")


def size_growth(params, schemes):
    rows, fits = [], []
    lengths = [float(v) for v in params["lengths"].split(",")]
    heights = [float(v) for v in params["heights"].split(",")]
    scans = [("length", [(v, params["height"]) for v in lengths]),
             ("height", [(lengths[0], v) for v in heights])]
    for damping in schemes:
        for scan, sizes in scans:
            ns, its = [], []
            for length, height in sizes:
                sim, stages, n_along, n_up = wall_push(params, length, height, damping)
                per_stage, wall, err = run_stages(sim, stages, params)
                push = dict(per_stage).get("push", np.zeros(0))
                dmax = float(np.max(sim.history.get("max_joint_damage", [np.nan])))
                rows.append(dict(damping=damping, scan=scan, length_m=length, height_m=height,
                                 n_along=n_along, n_up=n_up, elements=sim.model.elements.shape[0],
                                 it_gravity=_mean(dict(per_stage).get("gravity")),
                                 it_push_mean=_mean(push),
                                 wall_s=wall, max_joint_damage=dmax,
                                 status="FAILED: " + err[:120] if err else "ok"))
                print(f"  wall {length} x {height} m {damping}: {rows[-1]['it_push_mean']:.0f} "
                      f"it/incr, {wall:.1f} s {err[:100]}", flush=True)
                if push.size and not err:
                    ns.append(n_along if scan == "length" else n_up)
                    its.append(push.mean())
            if len(ns) >= 2:
                b = np.polyfit(np.log(ns), np.log(its), 1)[0]
                fits.append(dict(damping=damping, scan=scan, n="elements along" if scan == "length"
                                 else "courses", exponent_b=b,
                                 iters_per_n=float(np.mean(np.array(its) / ns))))
    report(rows, "damping_size" + params["tag"], "Wall push: iterations per increment vs size")
    if fits:
        report(fits, "damping_size_fit" + params["tag"], "Fit iterations ~ n^b")


def main(argv=None):
    from dr_masonry.params import parse_overrides
    params = parse_overrides(PARAMS, sys.argv[1:] if argv is None else argv, __doc__)
    schemes = params["schemes"].split(",")
    print(f"machine: {machine()}")
    parts = params["parts"].split(",")
    if "scenes" in parts:
        scenes(params, schemes)
    if "size" in parts:
        size_growth(params, schemes)


if __name__ == "__main__":
    main()

"""Run time against error: solver tolerance, mass-scaling safety and mesh density.

Problems (``problem``, comma separated):

* ``linear``: a column of ``col_blocks`` reference bricks (``BrickSpec`` size, elastic E 4.8 GPa,
  nu 0.17; tied joints knn 75 GPa/m, kss 7.5 GPa/m) clamped at its base, the load ``LOAD`` on a
  rigid point over its top face, one increment. ``err``: relative displacement error
  ||U - U_ref|| / ||U_ref|| over all nodes against the direct sparse solve of the same mesh
  (``tests/linear_reference.py``); ``err_tip_mesh``: tip translation against the direct solve
  on ``linear_ref_mesh`` (adds the discretisation error). The load is small enough that the
  geometric terms of the corotational elements stay near 1e-5 of the solution.
* ``s2``: S2 triplet (``dr_masonry.cases.triplet``) at ``sigma`` MPa, ``s2_increments`` shear
  increments; reference: tol ``ref_tol`` on ``s2_ref_mesh``.
* ``s5``: S5 squat wall (``dr_masonry.cases.squat_wall``), monotonic to ``drift`` % in
  ``s5_increments`` graded increments (0.15 % = 4.1 mm, past the peak at ~2 mm); reference: tol
  ``ref_tol`` on ``s5_ref_mesh`` (coarse by default; ``s5_meshes=coarse,fine s5_ref_mesh=fine``
  adds the mesh axis at the price of a fine reference run). Coarse runs take minutes each;
  ``quick=true`` runs the ``fast=true`` 0.88 x 0.81 m wall (``squat_wall.FAST``: 0.2 % drift in
  20 increments) with two tolerances (smoke check).

For ``s2`` and ``s5`` (curve y(x): shear stress against slip, base shear against top
displacement): ``err_peak`` = |max|y| - max|y_ref|| / max|y_ref|; ``err_curve`` = RMS of
y - y_ref over the common x range (y interpolated at the reference's x) / max|y_ref|;
``err`` = the larger of the two; ``err_peak_same_mesh`` against tol ``ref_tol`` on the row's own
mesh (solver error alone). The references run with the same ``coarse`` setting; they are cached
in ``benchmarks/out/front_ref_*.npz`` under a hash of their settings (``refresh=true`` recomputes
them, e.g. after a solver change).

Settings: tolerances ``tols``, safety factors ``safeties`` (fictitious masses = safety x
Gershgorin row sum / 4), out-of-balance resultant bounds ``gap_tols`` (``SolverOptions.gap_tol``;
0: off, the default), meshes (hexahedra per brick, along x thickness x height, or the squat
wall's ``coarse``/``fine``). ``grid=axes`` varies one at a time from the defaults
(``SolverOptions`` tol and safety, the scene's default mesh), ``grid=full`` runs every combination.
``coarse`` sets ``SolverOptions.coarse`` (two-level relaxation, the default) for every run.
Recorded: wall time of ``Simulation.run`` (s), total iterations, errors. The recommended setting
is the cheapest (wall time) one whose ``err`` is at most ``threshold``.

Run: ``python benchmarks/front.py [key=value ...]``; writes
``benchmarks/out/front_<problem><tag>.csv`` and ``.png`` (wall time against error, log-log; the
default setting circled in red).
"""
import hashlib
import itertools
import json
import os
import sys
import time
import warnings

import numpy as np

from common import OUT, ROOT, divisions, machine, report  # noqa: I100  (script folder on sys.path)

PARAMS = dict(
    problem="linear,s2",
    grid="axes",             # axes (one setting at a time from the defaults) | full
    tols="1e-2,3e-3,1e-3,3e-4,1e-4,3e-5",
    safeties="1.0,1.1,1.5,2.0",
    gap_tols="0",            # SolverOptions.gap_tol values (0: off)
    threshold=0.01,          # largest acceptable err of the recommended setting
    ref_tol=1e-6,
    refresh=False,           # recompute the cached reference runs
    coarse=True,             # SolverOptions.coarse of every run (false: plain relaxation)
    tag="",                  # suffix of the output names (keeps runs apart)
    quick=False,             # preset QUICK: smoke check in about a minute
    col_blocks=10,           # linear: bricks in the column
    linear_meshes="1x1x1,2x1x1,4x2x1,8x4x2",
    linear_ref_mesh="16x8x4",
    sigma=0.6,               # S2 pre-compression, MPa
    s2_increments=150,
    s2_meshes="1x1x1,2x1x1,4x2x1,8x4x2",
    s2_ref_mesh="16x8x4",
    drift=0.15,              # S5 monotonic target, % of the height
    s5_increments=12,
    s5_meshes="coarse",      # coarse,fine with s5_ref_mesh=fine: the mesh axis (long runs)
    s5_ref_mesh="coarse",
)
#: overrides of ``quick=true`` (explicit arguments still win): two tolerances, default mesh and
#: safety only, the references on the default meshes, the ``fast=true`` squat wall
QUICK = dict(tols="1e-2,1e-3", safeties="1.1", linear_meshes="4x2x1", linear_ref_mesh="4x2x1",
             s2_meshes="4x2x1", s2_ref_mesh="4x2x1", s5_meshes="coarse", s5_ref_mesh="coarse")
#: tip load of the linear column: force (N) along x, y, z and moment (N m) about x, y, z
LOAD = (3.0, 2.0, -5.0, 0.0, 0.0, 0.4)
DOFS = ("x", "y", "z", "rx", "ry", "rz")
TESTS = os.path.join(ROOT, "tests")  # linear_reference.py: the independent direct solve


# ------------------------------------------------------------------ shared helpers
def floats(text):
    """``"1e-2,1e-3"`` -> [0.01, 0.001]."""
    return [float(v) for v in text.split(",")]


def timed_run(sim, stages, safety, coarse, gap_tol=0.0):
    """Run ``stages`` with the mass-scaling ``safety``, ``SolverOptions.coarse`` and
    ``SolverOptions.gap_tol`` (validated by ``SolverOptions``).

    Returns (history dict of arrays, wall time s, "" or the SolverError message).
    """
    from dr_masonry import SolverError
    sim.options = sim.options.replace(safety=safety, coarse=coarse, gap_tol=gap_tol)
    t0 = time.perf_counter()
    err = ""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # energy balance at loose tolerances
        try:
            sim.run(stages)
        except SolverError as e:
            err = str(e)
    wall = time.perf_counter() - t0
    sim.close()
    return {k: np.asarray(v) for k, v in sim.history.items()}, wall, err


_LOADED = {}  # path -> arrays, so that a reference is read (or recomputed) once per run


def cached(name, key, params, compute):
    """Arrays of ``compute()`` (dict of arrays), stored in ``out/front_ref_<name>_<hash>.npz``."""
    tag = hashlib.sha1(json.dumps(key, sort_keys=True, default=str).encode()).hexdigest()[:10]
    path = os.path.join(OUT, f"front_ref_{name}_{tag}.npz")
    if path in _LOADED:
        return _LOADED[path]
    if os.path.exists(path) and not params["refresh"]:
        _LOADED[path] = dict(np.load(path))
        return _LOADED[path]
    t0 = time.perf_counter()
    arrays = _LOADED[path] = compute()
    os.makedirs(OUT, exist_ok=True)
    np.savez(path, **arrays)
    print(f"  reference {name} {key.get('mesh', '')}: {time.perf_counter() - t0:.1f} s, written "
          f"{os.path.relpath(path, ROOT)}", flush=True)
    return arrays


def curve_errors(x, y, xr, yr):
    """(peak error, curve error) of y(x) against y_ref(x_ref), both relative to max|y_ref|."""
    peak = np.max(np.abs(yr))
    lo, hi = max(x.min(), xr.min()), min(x.max(), xr.max())
    sel = (xr >= lo) & (xr <= hi)
    diff = np.interp(xr[sel], x, y) - yr[sel]
    return abs(np.max(np.abs(y)) - peak) / peak, float(np.sqrt(np.mean(diff ** 2))) / peak


def warm_up():
    """Load (or compile) the kernels once so that no timed run pays for it."""
    from dr_masonry.cases import triplet
    t0 = time.perf_counter()
    sim, stages = triplet.build(dict(triplet.PARAMS, increments=1, h5=None), 0.2e6)
    sim.run(stages[:1])
    print(f"  warm-up (compile or cache load): {time.perf_counter() - t0:.1f} s", flush=True)


# ------------------------------------------------------------------ (a) linear column
def column(params, mesh, tol):
    """(simulation, stages, base nodes, tip rigid point) of the glued column."""
    from dr_masonry import Force, JointLaw, Model, PlasticDamage, Simulation, SolverOptions, Stage
    from dr_masonry.geometry import BrickSpec
    b = BrickSpec()
    model = Model()
    model.set_joint_law(JointLaw.tied(75e9, 7.5e9))
    mat = PlasticDamage.elastic(4.8e9, 0.17, 1800.0)
    n = params["col_blocks"]
    for k in range(n):
        model.add_box((0.0, 0.0, k * b.height), (b.length, b.thickness, b.height), mat,
                      divisions(mesh, "mesh"))
    sim = Simulation(model, SolverOptions(tol=tol))
    z = model.nodes[:, 2]
    base = np.nonzero(np.isclose(z, 0.0))[0]
    sim.fix(base)
    tip = sim.rigid_point("tip", nodes=np.nonzero(np.isclose(z, n * b.height))[0])
    stage = Stage("load", 1, [Force(target=tip, dof=d, to=v) for d, v in zip(DOFS, LOAD)])
    return sim, [stage], base, tip


def direct_solve(params, mesh):
    """Cached direct sparse solve of the column: {"U": (n, 3) m, "tip": (6,) m / rad}."""
    if TESTS not in sys.path:
        sys.path.insert(0, TESTS)
    import linear_reference

    def compute():
        sim, _, base, tip = column(params, mesh, 1e-4)
        m = sim.model
        fixed = np.zeros((m.n_nodes, 3), dtype=bool)
        fixed[base] = True
        U, Q = linear_reference.solve(m, fixed, np.zeros((m.n_nodes, 3)),
                                      [(tip.nodes, tip.position, np.array(LOAD))])
        return {"U": U, "tip": Q[0]}
    return cached("linear", dict(mesh=mesh, blocks=params["col_blocks"], load=LOAD), params, compute)


def run_linear(params, mesh, tol, safety, gap_tol):
    """Table row of one column run: wall_s, iterations, err, err_tip_mesh, status."""
    sim, stages, _, _ = column(params, mesh, tol)
    hist, wall, err = timed_run(sim, stages, safety, params["coarse"], gap_tol)
    row = dict(wall_s=wall, iterations=int(hist["iterations"].sum()) if "iterations" in hist else 0,
               err=np.nan, err_tip_mesh=np.nan, status="FAILED: " + err[:120] if err else "ok")
    if not err:
        U = direct_solve(params, mesh)["U"]
        row["err"] = float(np.linalg.norm(sim.dyn.U - U) / np.linalg.norm(U))
        ref = direct_solve(params, params["linear_ref_mesh"])["tip"][:3]
        tip = np.array([hist[f"tip.u{d}"][-1] for d in "xyz"])
        row["err_tip_mesh"] = float(np.linalg.norm(tip - ref) / np.linalg.norm(ref))
    return row


# ------------------------------------------------------------------ (b), (c) curves
def scene(problem, params, mesh, tol):
    """(simulation, stages, x key, y key, y scale) of an S2 or S5 run; h5 output off."""
    if problem == "s2":
        from dr_masonry.cases import triplet
        nx, ny, nz = divisions(mesh, "mesh")
        p = dict(triplet.PARAMS, nx=nx, ny=ny, nz=nz, tol=tol, increments=params["s2_increments"],
                 h5=None)
        sim, stages = triplet.build(p, params["sigma"] * 1e6)
        return sim, stages, "push.ux", "push.fx", 1.0 / (2 * triplet.AREA)
    from dr_masonry.cases import squat_wall
    p = dict(squat_wall.PARAMS, drift=params["drift"], increments=params["s5_increments"])
    if params["quick"]:
        p.update(squat_wall.FAST)
    p.update(mesh=mesh, tol=tol, h5=None)
    sim, stages, _ = squat_wall.build(p)
    return sim, stages, "beam.ux", "beam.fx", 1.0


def curve(problem, params, mesh, tol, safety, gap_tol=0.0):
    """(x, y, wall s, iterations, error text) of one S2/S5 run (x, y over the loading stage)."""
    sim, stages, xk, yk, scale = scene(problem, params, mesh, tol)
    hist, wall, err = timed_run(sim, stages, safety, params["coarse"], gap_tol)
    its = int(hist["iterations"].sum()) if "iterations" in hist else 0
    if err:
        return None, None, wall, its, err
    load = hist["increment"] > stages[0].increments
    return hist[xk][load], hist[yk][load] * scale, wall, its, err


def reference_curve(problem, params, mesh):
    """Cached reference curve at tol ``ref_tol``: {"x", "y", "wall_s", "iterations"}."""
    from dr_masonry import SolverOptions

    def compute():
        x, y, wall, its, err = curve(problem, params, mesh, params["ref_tol"],
                                     SolverOptions().safety)
        if err:
            raise RuntimeError(f"reference run {problem} mesh {mesh} tol {params['ref_tol']} "
                               f"failed: {err}")
        return {"x": x, "y": y, "wall_s": np.array(wall), "iterations": np.array(its)}
    keys = {"s2": ("sigma", "s2_increments"), "s5": ("drift", "s5_increments", "quick")}[problem]
    key = dict({k: params[k] for k in keys}, mesh=mesh, tol=params["ref_tol"],
               coarse=params["coarse"])
    return cached(problem, key, params, compute)


def run_curve(problem, params, mesh, tol, safety, gap_tol):
    """Table row of one S2/S5 run: wall_s, iterations, err, err_peak, err_curve,
    err_peak_same_mesh, status."""
    x, y, wall, its, err = curve(problem, params, mesh, tol, safety, gap_tol)
    row = dict(wall_s=wall, iterations=its, err=np.nan, err_peak=np.nan, err_curve=np.nan,
               err_peak_same_mesh=np.nan, status="FAILED: " + err[:120] if err else "ok")
    if not err:
        ref = reference_curve(problem, params, params[f"{problem}_ref_mesh"])
        row["err_peak"], row["err_curve"] = curve_errors(x, y, ref["x"], ref["y"])
        row["err"] = max(row["err_peak"], row["err_curve"])
        own = reference_curve(problem, params, mesh)
        row["err_peak_same_mesh"] = curve_errors(x, y, own["x"], own["y"])[0]
    return row


# ------------------------------------------------------------------ sweep, table, plot
def settings(params, meshes, default_mesh):
    """(tol, safety, mesh, gap_tol) of each run of the sweep."""
    from dr_masonry import SolverOptions
    d = SolverOptions()
    tols, safeties, gaps = (floats(params[k]) for k in ("tols", "safeties", "gap_tols"))
    if params["grid"] == "full":
        return list(itertools.product(tols, safeties, meshes, gaps))
    if params["grid"] != "axes":
        from dr_masonry.params import ParameterError
        raise ParameterError(f"parameter grid={params['grid']!r}: valid values are ['axes', 'full']")
    out = [(t, d.safety, default_mesh, d.gap_tol) for t in tols]
    out += [(d.tol, s, default_mesh, d.gap_tol) for s in safeties if s != d.safety]
    out += [(d.tol, d.safety, m, d.gap_tol) for m in meshes if m != default_mesh]
    out += [(d.tol, d.safety, default_mesh, g) for g in gaps if g != d.gap_tol]
    return out


def default_mesh(problem):
    """The mesh a problem uses by default (the scene's PARAMS; ``BrickSpec`` for the column)."""
    from dr_masonry.cases import squat_wall, triplet
    from dr_masonry.geometry import BrickSpec
    if problem == "s5":
        return squat_wall.PARAMS["mesh"]
    if problem == "s2":
        return "x".join(str(triplet.PARAMS[k]) for k in ("nx", "ny", "nz"))
    b = BrickSpec()
    return f"{b.nx_along}x{b.ny_thick}x{b.nz_height}"


def sweep(problem, params):
    from dr_masonry import SolverOptions
    d = SolverOptions()
    dmesh = default_mesh(problem)
    meshes = params[f"{problem}_meshes"].split(",")
    rows = []
    for tol, safety, mesh, gap in settings(params, meshes, dmesh):
        res = (run_linear(params, mesh, tol, safety, gap) if problem == "linear"
               else run_curve(problem, params, mesh, tol, safety, gap))
        is_default = ((tol, safety, mesh, params["coarse"], gap)
                      == (d.tol, d.safety, dmesh, d.coarse, d.gap_tol))
        rows.append(dict(problem=problem, coarse=params["coarse"], mesh=mesh, tol=tol,
                         safety=safety, gap_tol=gap, default="yes" if is_default else "", **res))
        print(f"  {problem} tol {tol:g} safety {safety:g} mesh {mesh} gap_tol {gap:g}: "
              f"{res['wall_s']:.2f} s, "
              f"{res['iterations']} it, err {res['err']:.3g} {res['status'][:80]}", flush=True)
    report(rows, f"front_{problem}{params['tag']}", f"{problem}: wall time against error "
           f"(err threshold {params['threshold']:g})")
    ok = [r for r in rows if r["status"] == "ok" and r["err"] <= params["threshold"]]
    best = min(ok, key=lambda r: r["wall_s"]) if ok else None
    for r in rows:
        if r["default"]:
            print(f"{problem} default: {describe(r)}")
    print(f"{problem} recommended (cheapest with err <= {params['threshold']:g}): "
          + (describe(best) if best else "none"))
    for mesh in dict.fromkeys(r["mesh"] for r in rows):
        sel = [r for r in ok if r["mesh"] == mesh]
        print(f"  on mesh {mesh}: " + (describe(min(sel, key=lambda r: r["wall_s"])) if sel
                                        else "none"))
    if problem == "linear":
        print("  (linear err is the solver error on each mesh; err_tip_mesh adds the "
              "discretisation error)")
    plot(rows, problem + params["tag"], params["threshold"], best)


def describe(r):
    """One line: setting, error, cost of a table row."""
    return (f"tol {r['tol']:g}, safety {r['safety']:g}, mesh {r['mesh']}, gap_tol "
            f"{r['gap_tol']:g}: err {r['err']:.3g}, "
            f"{r['wall_s']:.2f} s, {r['iterations']} iterations")


def plot(rows, problem, threshold, best):
    """out/front_<problem>.png: wall time against err, log-log, one colour per mesh and one
    marker per safety factor, each point labelled with its tolerance (and gap_tol if set)."""
    from matplotlib.figure import Figure
    fig = Figure(figsize=(8.5, 5))
    ax = fig.add_subplot()
    meshes = list(dict.fromkeys(r["mesh"] for r in rows))
    safeties = sorted({r["safety"] for r in rows})
    markers = "osD^v<>p"
    for r in rows:
        if r["status"] != "ok":
            continue
        c = f"C{meshes.index(r['mesh']) % 10}"
        m = markers[safeties.index(r["safety"]) % len(markers)]
        x = max(r["err"], 1e-12)
        ax.loglog(x, r["wall_s"], m, color=c, ms=5)
        label = f"{r['tol']:g}" + (f" gap {r['gap_tol']:g}" if r["gap_tol"] else "")
        ax.annotate(label, (x, r["wall_s"]), fontsize=6, xytext=(3, 2),
                    textcoords="offset points")
        if r["default"]:
            ax.loglog(x, r["wall_s"], "o", mfc="none", mec="red", ms=14, mew=1.5)
    for i, mesh in enumerate(meshes):
        ax.plot([], [], "s", color=f"C{i % 10}", label=f"mesh {mesh}")
    for i, s in enumerate(safeties):
        ax.plot([], [], markers[i % len(markers)], color="gray", label=f"safety {s:g}")
    if any(r["default"] and r["status"] == "ok" for r in rows):
        ax.plot([], [], "o", mfc="none", mec="red", ms=10, label="default setting")
    if best:
        ax.loglog(max(best["err"], 1e-12), best["wall_s"], "*", color="gold", mec="k", ms=14,
                  label="recommended")
    ax.axvline(threshold, color="k", ls="--", lw=0.8, label=f"threshold {threshold:g}")
    ax.set(xlabel="error (relative)", ylabel="wall time (s)",
           title=f"{problem}: wall time against error (labels: tolerance)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    path = os.path.join(OUT, f"front_{problem}.png")
    fig.savefig(path, dpi=120)
    print(f"(written {os.path.relpath(path, ROOT)})", flush=True)


def main(argv=None):
    from dr_masonry.params import parse_overrides
    argv = sys.argv[1:] if argv is None else argv
    params = parse_overrides(PARAMS, argv, __doc__)
    if params["quick"]:                 # the preset first, explicit overrides on top
        params = parse_overrides(dict(PARAMS, **QUICK), argv, __doc__)
    problems = params["problem"].split(",")
    for p in problems:
        if p not in ("linear", "s2", "s5"):
            from dr_masonry.params import ParameterError
            raise ParameterError(f"parameter problem={p!r}: valid values are linear, s2, s5")
    print(f"machine: {machine()}")
    warm_up()
    for p in problems:
        sweep(p, params)


if __name__ == "__main__":
    main()

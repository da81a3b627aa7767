"""One dynamic-relaxation iteration of the main job's wall, by thread count and OpenMP wait policy.

Builds the S5 wall of ``dr-masonry run squat_wall`` (``mesh=fine``: CASES.md's mesh), runs ``rows``
push rows to reach a state with damaged joints (or, with ``file=<run>.h5 scene=<name>``, takes the
state of a stored run's checkpoint, e.g. the half house of ``terraced_house`` on its rocking
plateau), then times ``relax`` for ``iters`` iterations with tol 0 (``repeats`` batches; best and
median per iteration, and the best per node) and its parallel pieces: ``element_and_contact_forces``
(hexahedra and contact points, one region), ``gather_pair`` (node forces, one region) and
``internal_forces`` (both, plus the energy sums); ``rest`` = iteration - internal forces (the
residual, damping and update passes over the nodes and the serial remainder);
``forces_full_update``: the forces again with every element through the full state update (the
pristine elements' skip switched off); ``hexahedra`` and ``contacts``: the two halves of the force
kernel alone (the other set empty), also per hexahedron and per contact point. Every (threads,
policy) setting runs in a process of its own, since OpenMP reads ``OMP_WAIT_POLICY`` when it starts.
docs/internals.md, "Decisions".

Run: ``python benchmarks/iteration.py [threads=1,2 policies=PASSIVE,ACTIVE rows=8 mesh=coarse
iters=400 repeats=15 file= scene= tag=]`` (about 1 min per setting); writes
``benchmarks/out/iteration<tag>.csv``.
"""
import json
import os

import numpy as np

from common import ROOT, child_row, report, start, stored_run, timed  # noqa: I100  (script folder on sys.path)

PARAMS = dict(
    threads="1,2",
    policies="PASSIVE,ACTIVE",
    rows=8,          # push rows before the timing (the main job peaks at row 16)
    mesh="coarse",   # the S5 wall's mesh: coarse (the main job's) or fine (CASES.md's 4 x 1 x 2)
    iters=400,       # iterations per timed batch
    repeats=15,
    mode="all",      # "all", or "child" (one setting, used by the subprocesses)
    file="",         # a stored run (.h5) whose checkpoint state is timed instead of the S5 wall
    scene="",        # the scene of ``file`` (e.g. terraced_house)
    tag="",          # suffix of the CSV name
)


def child(params):
    """Time one setting (this process's threads and wait policy); prints one JSON line."""
    import numba
    from dr_masonry.kernels import relaxation as R
    from dr_masonry.kernels.assembly import gather_pair
    from dr_masonry.kernels.forces import NO_CONTACTS, NO_ELEMENTS
    if params["file"]:
        sim, _, copy = stored_run(params["scene"], params["file"], "iteration_state")
        sim.resume(copy)
    else:
        sim = wall_state(params["rows"], params["mesh"])
    m, c, d, o = sim.mesh, sim.cont, sim.dyn, sim.options
    n = params["iters"]
    crit = R.Criteria(0.0, float(sim.ref_floor), 0.0, 0.0, o.convergence.check_every, 0,
                      0.5 * sim.size, 0.0, n)

    def iterations():
        R.relax(m, c, d, sim.lam, np.zeros(3, np.int64), 1.0, o.damping.alpha, o.damping.ring,
                crit, R.start_progress(), R.no_constraint())

    def pieces(f):
        return lambda: [f() for _ in range(n)]

    us = 1e6 / n
    out = dict(threads=numba.get_num_threads(), policy=os.environ.get("OMP_WAIT_POLICY"),
               nodes=d.U.shape[0], hexahedra=m.active.shape[0], contacts=c.slave.shape[0])
    pristine = m.pristine.copy()

    def full_update():
        """The forces with every element through the full state update (no pristine ones)."""
        m.pristine[:] = 0
        R.element_and_contact_forces(d.X, d.U, m, c)
        m.pristine[:] = pristine

    out["pristine_elements"] = int(pristine[m.active].sum())
    for name, f in (("iteration", iterations),
                    ("forces", pieces(lambda: R.element_and_contact_forces(d.X, d.U, m, c))),
                    ("forces_full_update", pieces(full_update)),
                    ("hexahedra", pieces(lambda: R.element_and_contact_forces(
                        d.X, d.U, m, NO_CONTACTS))),
                    ("contacts", pieces(lambda: R.element_and_contact_forces(
                        d.X, d.U, NO_ELEMENTS, c))),
                    ("gather", pieces(lambda: gather_pair(m.fbuf.reshape((-1, 3)), m.ptr, m.rows,
                                                          c.fbuf, c.ptr, c.rows, d.fint))),
                    ("internal_forces", pieces(lambda: R.internal_forces(m, c, d)))):
        b, med = timed(f, (), params["repeats"], 0.0)
        out[f"{name}_us_best"] = b * us
        out[f"{name}_us_median"] = med * us
    out["rest_us_best"] = out["iteration_us_best"] - out["internal_forces_us_best"]
    out["ns_per_node_iteration"] = out["iteration_us_best"] * 1e3 / out["nodes"]
    out["ns_per_hexahedron"] = out["hexahedra_us_best"] * 1e3 / max(out["hexahedra"], 1)
    out["ns_per_contact_point"] = out["contacts_us_best"] * 1e3 / max(out["contacts"], 1)
    print(json.dumps(out), flush=True)


def wall_state(rows, mesh):
    """The main job's S5 wall with ``mesh`` after ``rows`` push rows (a state with damaged
    joints)."""
    from cases import squat_wall
    from dr_masonry import Stage
    p = dict(squat_wall.PARAMS, mesh=mesh, h5=None, progress=False,
             out=os.path.join(ROOT, "benchmarks", "out", "iteration"))
    sim, stages, _ = squat_wall.build(p)
    push = stages[1].controls[0]
    push.path = push.path[:rows]
    sim.run([stages[0], Stage("push", rows, [push], frames=1000)])
    return sim


def main(argv=None):
    params = start(PARAMS, __doc__, argv, "child", child)
    if params is None:
        return
    rows = []
    for policy in params["policies"].split(","):
        for threads in params["threads"].split(","):
            env = dict(os.environ, OMP_WAIT_POLICY=policy, NUMBA_NUM_THREADS=threads)
            rows.append(child_row(__file__, ["mode=child"] + [
                f"{k}={params[k]}"
                for k in ("rows", "mesh", "iters", "repeats", "file", "scene")], env))
            print(f"  {policy} x {threads}: {rows[-1]['iteration_us_median']:.0f} us per "
                  f"iteration (median)", flush=True)
    what = f"{params['scene']} ({params['file']})" if params["file"] else "S5"
    report(rows, "iteration" + params["tag"],
           f"One {what} iteration in place by threads and wait policy, us")


if __name__ == "__main__":
    main()

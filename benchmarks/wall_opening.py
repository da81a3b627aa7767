"""The opening control on a wall: the S5 main job pushed by a held diagonal elongation.

The coarse S5 squat wall (the main job's model and pre-compression) is pushed by the beam's
horizontal force, its factor found so that the mean displacement of the top-right corner brick
minus that of the bottom-left one, along the line joining them, follows ``to`` m in ``n`` equal
increments from its value after the pre-compression (a diagonal transducer's control,
``loading.Opening(direction=...)``). Each relaxation of the secant on the factor is traced: the
factor (kN), the constraint's reaction (N) against its tolerance tol x the reference force, the
iterations. It shows where the secant meets its tolerance and where it cannot (docs/internals.md,
"Decisions"): once joints crack, the reaction at a fixed factor scatters by more than the
tolerance, so that no factor brings it within tolerance.

``rate`` > 0 (``Opening.rate``) lets the factor relax with the motion instead, one relaxation per
increment.

Run: ``python benchmarks/wall_opening.py [n=30 to=0.003 rate=0]``; prints the rows (iterations,
relaxations, beam displacement, base shear) and the trace of the increment that stopped the run.
"""
import sys
import time

import numpy as np

from dr_masonry import Force, Opening, Stage
from dr_masonry.cases import squat_wall as S
from dr_masonry.loading import PointLoad
from dr_masonry.solver import SolverError
from dr_masonry.solver import controls, relaxing

KN = 1e3


def main(argv):
    args = dict(a.split("=", 1) for a in argv)
    n, to = int(args.get("n", 30)), float(args.get("to", 3e-3))
    rate = float(args.get("rate", 0.0))
    sim, stages, rig = S.build(dict(S.PARAMS, h5=None, progress=False))
    a, b, e = S.corner_bricks(sim, rig.wall)
    sim.run([stages[0]])
    diagonal = Opening(pattern=PointLoad(target=rig.beam, dof="x", value=KN, name="shear"), a=a,
                       b=b, direction=e, dof="x", to=0.0, name="diagonal", rate=rate)
    diagonal.to = controls.opening(sim, diagonal) + to   # ramped from its value now
    trace = []
    plain = relaxing.relax_increment

    def traced(sim_, ctrl, pc, tol, max_iter, stall, con=None):   # one secant step
        lam = float(sim_.lam[0])
        out = plain(sim_, ctrl, pc, tol, max_iter, stall, con)
        trace.append((sim_.increment + 1, lam, out.reaction, tol * out.ref, out.iterations))
        return out
    relaxing.relax_increment = traced
    push = Stage("push", n, [diagonal, Force(target=rig.beam, dof="x", to=0.0,
                                             name="beam_x_free")], frames=n)
    t = time.perf_counter()
    stopped = None
    try:
        sim.run([push])
    except SolverError as err:
        stopped = str(err)
    wall_s = time.perf_counter() - t
    h = {k: np.asarray(v) for k, v in sim.history.items()}
    rows = h["increment"] > stages[0].increments
    steps = {}
    for inc, *_ in trace:
        steps[inc] = steps.get(inc, 0) + 1
    print(f"S5 coarse, diagonal {np.degrees(np.arctan2(e[2], e[0])):.1f} deg, {n} increments "
          f"of {to / n * 1e3:.3f} mm, rate {rate:g}; {wall_s:.0f} s")
    print("| row | iterations | relaxations | beam ux (mm) | base shear (kN) |")
    print("|---|---|---|---|---|")
    for inc, it, ux, fx in zip(h["increment"][rows], h["iterations"][rows],
                               h["beam.ux"][rows], h["beam.fx"][rows]):
        print(f"| {inc:.0f} | {it:,.0f} | {steps.get(int(inc), 0)} | {ux * 1e3:.3f} | "
              f"{fx / KN:.2f} |")
    if stopped:
        print("stopped:", stopped)
        last = trace[-1][0]
        print("| factor (kN) | reaction (N) | tolerance (N) | iterations |")
        print("|---|---|---|---|")
        for inc, lam, mu, tol, it in trace:
            if inc == last:
                print(f"| {lam:.3f} | {mu:.1f} | {tol:.1f} | {it:,} |")


if __name__ == "__main__":
    main(sys.argv[1:])

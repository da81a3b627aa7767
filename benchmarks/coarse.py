"""Two-level relaxation: iterations and run time with and without the coarse correction.

Runs scenes with ``SolverOptions(coarse=False)`` (plain dynamic relaxation, viscous damping) and
``coarse=True`` (the default: a coarse correction on the blocks' affine motions every
``coarse_every`` iterations) and reports total iterations, wall time and the peak of the scene's
response, which must agree.

Usage::

    python benchmarks/coarse.py [scenes=s6_fast,s7_fast,s5_short] [every=50]

``s5_short`` is the coarse-mesh 4.0 m S5 wall to 0.1 % drift (2.75 mm) in 4 + 4 increments, the
``*_fast`` scenes are the test-suite presets. Writes ``benchmarks/out/coarse.csv``.
"""
import sys
import time

import numpy as np

from common import machine, report

from dr_masonry.cases import out_of_plane_wall, squat_wall, terraced_house
from dr_masonry.params import parse_overrides

SCENES = {
    "s5_fast": (squat_wall, dict(fast=True), "beam.fx"),
    "s5_short": (squat_wall, dict(drift=0.1, increments=4), "beam.fx"),
    "s6_fast": (out_of_plane_wall, dict(fast=True), "lambda"),
    "s7_fast": (terraced_house, dict(fast=True), "lambda"),
}


def run(name, coarse, every):
    module, over, ykey = SCENES[name]
    params = dict(module.PARAMS, **(module.FAST if over.get("fast") else {}), **over, h5=None)
    import dr_masonry.solver as S
    init = S.SolverOptions.__init__

    def patched(self, *a, **k):  # the scenes build their own SolverOptions
        init(self, *a, **k)
        self.coarse, self.coarse_every = coarse, every
    S.SolverOptions.__init__ = patched
    try:
        t0 = time.perf_counter()
        sim, hist, push, _ = module.run(params)
        wall = time.perf_counter() - t0
    finally:
        S.SolverOptions.__init__ = init
    y = hist[ykey][push]
    row = dict(scene=name, coarse=coarse, every=every if coarse else 0,
               increments=int(hist["increment"].size),
               iterations=int(hist["iterations"].sum()),
               max_per_increment=int(hist["iterations"].max()), wall_s=wall,
               peak=float(y[np.argmax(np.abs(y))]))
    if sim.coarse is not None:
        row.update(corrections=sim.coarse.n_corrections, rejected=sim.coarse.n_rejected)
    else:
        row.update(corrections=0, rejected=0)
    return row


def main(argv=None):
    opts = parse_overrides(dict(scenes="s6_fast,s7_fast,s5_short", every=50),
                           sys.argv[1:] if argv is None else argv, __doc__)
    print(machine())
    rows = []
    for name in opts["scenes"].split(","):
        if name not in SCENES:
            raise SystemExit(f"unknown scene {name!r}; valid: {list(SCENES)}")
        plain = run(name, False, opts["every"])
        fast = run(name, True, opts["every"])
        fast["iteration_ratio"] = plain["iterations"] / fast["iterations"]
        fast["time_ratio"] = plain["wall_s"] / fast["wall_s"]
        fast["peak_difference"] = fast["peak"] / plain["peak"] - 1.0
        plain.update(iteration_ratio=1.0, time_ratio=1.0, peak_difference=0.0)
        rows += [plain, fast]
    report(rows, "coarse", "Plain and two-level dynamic relaxation")


if __name__ == "__main__":
    main()

"""Cost of the finite-sliding check (``dr_masonry/sliding.py``) per committed increment.

After every increment the solver projects each slave node on its master quad and re-pairs the
points that left it (``Sliding.update``); this script times that check on the built models of
the scenes, with random nodal displacements of ``noise`` m (small enough that no point switches,
the case of almost every increment), best and mean of ``repeat`` calls, and reports it with the
model size. Compare with the seconds an increment of the same scene takes (BENCHMARKS.md).

Run: ``python benchmarks/sliding.py [scenes=s5,s5fine,s7 repeat=5 noise=1e-4]`` (about 1 min);
writes ``benchmarks/out/sliding.csv``. BENCHMARKS.md, "Finite-sliding check per increment".
"""
import time

import numpy as np

import common

DEFAULTS = dict(scenes="s5,s5fine,s7", repeat=5, noise=1e-4)
SCENES = {"s5": ("squat_wall", {}), "s5fine": ("squat_wall", {"mesh": "fine"}),
          "s7": ("terraced_house", {})}


def row(name, repeat, noise):
    """Time ``Sliding.update`` on scene ``name``'s model; a dict of the table."""
    from dr_masonry.cli import import_case
    from dr_masonry.params import ParameterError
    if name not in SCENES:
        raise ParameterError(f"parameter scenes: {name!r} is not one of {sorted(SCENES)}")
    case, extra = SCENES[name]
    mod = import_case(case)
    sim = mod.build(dict(mod.PARAMS, h5=None, **extra))[0]
    sim.build()
    sim.dyn.U[:] = noise * np.random.default_rng(0).standard_normal(sim.dyn.U.shape)
    moved = sim.sliding.update()
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        moved += sim.sliding.update()
        times.append(time.perf_counter() - t)
    return dict(scene=name, nodes=sim.model.n_nodes, contacts=int(sim.cont.slave.size),
                switched=moved, best_ms=1e3 * min(times), mean_ms=1e3 * float(np.mean(times)))


def main(argv=None):
    params = common.start(DEFAULTS, __doc__, argv)
    rows = [row(s, params["repeat"], params["noise"]) for s in params["scenes"].split(",")]
    common.report(rows, "sliding", "finite-sliding check per increment")


if __name__ == "__main__":
    main()

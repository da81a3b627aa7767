"""How the rows of stored runs converged: iterations per row before and after the peak, rows at
the residual floor, and the out-of-balance between driving force and support reaction.

For each result file of ``files`` (comma-separated) the driven rows (those whose history has a
finite driving force ``drive.f*``: the push of a scene, not its gravity or pre-compression
stage) are split at the peak (the row of the largest |driving force| along the driven axis; it
counts as before the peak). Reported per run: the scene and its non-default solver settings, the
driven rows and how many were accepted above ``tol`` (at the residual floor), the median and
largest iterations per row before and after the peak and the ratio of the post-peak median to
the pre-peak one (issue target: at most 3), the iterations spent in attempts that were cut, the
largest out-of-balance resultant along the driven axis in % of the peak (target: at most 0.5 %),
and the relaxation time. It reads the files only; the commands that made them are in
BENCHMARKS.md. Run: ``python benchmarks/rows.py files=a.h5,b.h5``; writes
``benchmarks/out/rows.csv``.
"""
import numpy as np

import common

DEFAULTS = dict(files="")
#: the scene and solver settings reported (from the file's configuration)
SETTINGS = ("mesh", "direction", "protocol", "bc", "tol", "alpha", "gap_tol", "floor_tol",
            "max_iter", "stall_iter", "max_cuts")


def summary(path):
    """The table row (dict) of result file ``path``."""
    from dr_masonry.params import ParameterError
    from dr_masonry.results import open_result
    from dr_masonry.results.reader import above_tol
    r = open_result(path)
    h, cfg = r.history, r.config
    driven, axis = common.driven(h)
    if axis < 0:
        raise ParameterError(f"{path}: no row of its history is driven (no finite drive.f*)")
    f = np.abs(h[f"drive.f{'xyz'[axis]}"][driven])
    peak = int(np.argmax(f))
    it = h["iterations"][driven]
    pre, post = it[:peak + 1], it[peak + 1:]
    solver = cfg["solver"]
    floor = above_tol(h["residual"][driven], solver["tol"])
    gap = np.abs(h[f"gap.f{'xyz'[axis]}"][driven])
    given = {k: cfg[k] if cfg.get(k) is not None else solver.get(k) for k in SETTINGS}
    settings = " ".join(f"{k}={v}" for k, v in given.items() if v not in ("", None))
    med_pre = float(np.median(pre))
    med_post = float(np.median(post)) if post.size else float("nan")
    return dict(scene=cfg.get("scene", "?"), settings=settings, rows=int(driven.sum()),
                at_floor=int(floor.sum()), peak_kN=f[peak] / 1e3,
                pre_median=med_pre, pre_max=int(pre.max()), post_median=med_post,
                post_max=int(post.max()) if post.size else 0,
                post_over_pre=med_post / med_pre,
                iterations=int(it.sum()), cut_iterations=int(np.nansum(
                    h.get("cut_iterations", np.zeros(1))[driven])),
                max_gap_pct_peak=100.0 * float(np.nanmax(gap)) / f[peak],
                relax_min=float(np.nansum(h["time_s"])) / 60.0)


def main(argv=None):
    params = common.start(DEFAULTS, __doc__, argv)
    from dr_masonry.params import ParameterError
    files = [p for p in params["files"].split(",") if p]
    if not files:
        raise ParameterError("parameter files: give one or more result files, "
                             "files=a.h5,b.h5")
    common.report([summary(p) for p in files], "rows",
                  "iterations per row before and after the peak")


if __name__ == "__main__":
    main()

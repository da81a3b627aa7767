"""Render the 3-D damage views of results files to docs/ at their curves' peaks and end.

Run: ``python docs/make_views.py FILE NAME [FILE NAME ...]``: for each results file, its scene's
``VIEWS`` (:mod:`dr_masonry.viz.views`) at the frames nearest the peaks and the end, written as
``docs/NAME_<view>_<peak|peak+|peak-|end>.png``. The figures of docs/validation.md and README.md:

    dr-masonry run squat_wall out=results/squat_wall
    dr-masonry run terraced_house fast=true out=results/terraced_house_fast
    python docs/make_views.py results/squat_wall.h5 s5 results/terraced_house_fast.h5 s7_fast
    dr-masonry run out_of_plane_wall floor_tol=1e-3 frames=1 out=results/out_of_plane_wall
    python docs/make_views.py results/out_of_plane_wall.h5 s6

and the full S7 runs' (README, "Full protocols", with ``frames=1``) as ``s7_plus`` and ``s7_minus``.
"""
import os
import sys
import time

from dr_masonry.results import open_result
from dr_masonry.viz.report import DEFAULT_VIEWS, curve_rows, peak_frames, scene_of
from dr_masonry.viz.views import write_views

HERE = os.path.dirname(os.path.abspath(__file__))


def main(argv):
    if not argv or len(argv) % 2:
        sys.exit(__doc__)
    for path, name in zip(argv[::2], argv[1::2]):
        t = time.perf_counter()
        r = open_result(path)
        scene, mod = scene_of(r)
        frames = peak_frames(r, mod.CURVE, curve_rows(r, mod.CURVE))
        paths = write_views(r, os.path.join(HERE, name), frames,
                            getattr(mod, "VIEWS", DEFAULT_VIEWS), curve=mod.CURVE,
                            size=(1000, 750))
        print(f"{path} ({scene}): {len(paths)} views in {time.perf_counter() - t:.1f} s")
        for p in paths:
            print("  " + os.path.relpath(p))


if __name__ == "__main__":
    main(sys.argv[1:])

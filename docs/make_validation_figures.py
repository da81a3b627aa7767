"""Figures of docs/validation.md from the result files of the validation runs (S4-S7).

Usage: ``python docs/make_validation_figures.py RESULT.h5 [RESULT.h5 ...]``: for each file, the
scene is read from the file's stored configuration; writes into docs/ the response curve, the
crack map (joint damage and block tensile damage) at the frame nearest the peak and at the last
state (the last frame, or the checkpoint of a run stopped after it), the crushing map (block
compressive damage) at the last state and, for the house, the
vertical reactions of each wall and pier (paper Fig. 26).
``RESULT.h5@ROW`` draws a run as if it had stopped after history row ``ROW`` (a copy of the
file cut there, in a temporary folder: the rows after a defect left out, as for the S4
double-clamped cyclic run), in overlays too.
``python docs/make_validation_figures.py overlay NAME RESULT.h5=LABEL ...`` draws the response
curves of runs of one scene on one plot, ``docs/NAME.png`` (and for the house their reactions,
``docs/NAME_reactions.png``); rows accepted above tol are marked with open circles. Commands that made the result files
are listed in docs/validation.md.
"""
import os
import shutil
import sys
import tempfile

import h5py
import numpy as np

from dr_masonry.results import ResultsError, open_result, truncate_file
from dr_masonry.viz.plots import crack_map, plot_history

HERE = os.path.dirname(os.path.abspath(__file__))

#: scene -> (x column, y column, y scale, elevations: (plane, block groups or None, label))
SCENES = {
    "squat_wall": ("beam.ux", "beam.fx", 1e-3, [("xz", None, "")]),
    "slender_wall": ("beam.ux", "beam.fx", 1e-3, [("xz", None, "")]),
    "out_of_plane_wall": ("centre.uy", "lambda", 1e-3, [("xz", None, "")]),
    "terraced_house": ("floor2.ux", "lambda", 4e-3,
                       [("xz", ("pier_wide", "pier_narrow", "spandrel", "lintel"), "_facade"),
                        ("yz", ("transversal_wall_1",), "_W1"),
                        ("yz", ("transversal_wall_2",), "_W2")]),
}


def cut(spec):
    """``path`` for ``path``; for ``path@ROW`` a copy of the file with its first ``ROW`` history
    rows, the frames up to that row's increment and no checkpoints (so that its last frame is
    its last state), in a temporary folder under the same name."""
    path, sep, row = spec.partition("@")
    if not sep:
        return path
    rows = int(row)
    out = os.path.join(tempfile.mkdtemp(prefix="figures_"), os.path.basename(path))
    shutil.copyfile(path, out)
    with h5py.File(out, "a") as f:
        h = f["history"]
        if not 0 < rows <= h["increment"].shape[0]:
            raise SystemExit(f"{spec}: {path} has {h['increment'].shape[0]} history rows")
        truncate_file(f, int(h["increment"][rows - 1]), rows)
        for k in ("checkpoint", "checkpoint_new", "checkpoints"):
            if k in f:
                del f[k]
    return out


def scene_of(r):
    out = r.config.get("out", "")
    for name in SCENES:
        if name in r.path or name in out:
            return name
    if "direction" in r.config:
        return "terraced_house"
    if "target" in r.config:
        return "out_of_plane_wall"
    if r.config.get("height", 0.0) > 2.0 * r.config.get("length", np.inf):
        return "slender_wall"   # the slender wall runs the squat wall's builder and parameters
    return "squat_wall"


def last_state(r):
    """The last frame, or the last checkpoint when the run stopped after it (between frames)."""
    try:
        if r.frame_increment("checkpoint") > r.frame_ids[-1]:
            return "checkpoint"
    except ResultsError:
        pass
    return -1


def nearest_frame(r, increment, end):
    """Frame (or checkpoint, when ``end`` = :func:`last_state` is it) nearest to ``increment``."""
    ids = np.asarray(r.frame_ids + ([r.frame_increment(end)] if end == "checkpoint" else []))
    i = int(np.argmin(np.abs(ids - increment)))
    return end if i == len(r.frame_ids) else i


def figures(path):
    r = open_result(path)
    scene = scene_of(r)
    xk, yk, ys, views = SCENES[scene]
    stem = os.path.join(HERE, os.path.splitext(os.path.basename(path))[0])
    h = r.history
    made = [plot_history(r, xk, yk, stem + "_curve.png", yscale=ys, label=scene)]
    if scene == "terraced_house":
        made.append(reactions(r, xk, stem + "_reactions.png"))
    peak = int(h["increment"][int(np.argmax(np.abs(h[yk])))])
    end = last_state(r)
    for plane, names, tag in views:
        group = None if names is None else np.concatenate([r.groups[n] for n in names])
        for which, frame in (("peak", nearest_frame(r, peak, end)), ("end", end)):
            made.append(crack_map(r, frame, f"{stem}{tag}_cracks_{which}.png", plane=plane,
                                  blocks=group, warp=0.0))
        made.append(crack_map(r, end, f"{stem}{tag}_crushing_end.png", plane=plane,
                              blocks=group, element_field="dc", threshold=0.99))
    return made


def reactions(runs, xk, png, labels=None):
    """The house's vertical reactions of each pier and transversal wall (paper Fig. 26) against
    ``xk`` for one run or several (``labels``) on one plot."""
    return plot_history(runs, xk, [f"{n}.fz" for n in ("base_P1", "base_P2", "base_W1", "base_W2")],
                        png, label=labels, ylabel="vertical reaction, half model [kN]",
                        title="reactions of the piers (P1 wide, P2 narrow) and walls")


def overlay(name, specs):
    """Response curves of the runs ``specs`` (``path=label``) on one plot ``docs/name.png``; for
    the house also their reactions, ``docs/name_reactions.png``."""
    from dr_masonry.cli import import_case
    paths, labels = zip(*(spec.split("=", 1) for spec in specs))
    paths = [cut(p) for p in paths]
    scene = scene_of(open_result(paths[0]))
    xk, yk, ys, _ = SCENES[scene]
    curve = import_case(scene).CURVE
    made = [plot_history(list(paths), xk, yk, os.path.join(HERE, name + ".png"), yscale=ys,
                         label=list(labels), xlabel=curve["xlabel"], ylabel=curve["ylabel"])]
    if scene == "terraced_house":
        made.append(reactions(list(paths), xk, os.path.join(HERE, name + "_reactions.png"),
                              list(labels)))
    return made


if __name__ == "__main__":
    if sys.argv[1:2] == ["overlay"]:
        for f in overlay(sys.argv[2], sys.argv[3:]):
            print(f)
    else:
        for p in sys.argv[1:]:
            for f in figures(cut(p)):
                print(f)

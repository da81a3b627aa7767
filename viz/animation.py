"""Animation of a run (``dr-masonry animate FILE``): at each stored frame, the deformed, damaged
structure (:func:`dr_masonry.viz.views.damage_view`) beside the response curve with a marker at the
frame's row.

Written through matplotlib's movie writers: GIF with Pillow (a dependency of matplotlib, nothing
to install), MP4 with ffmpeg where it is on ``PATH``.
"""
from __future__ import annotations

import os
import tempfile

import numpy as np
from matplotlib.figure import Figure
from matplotlib.image import imread

from dr_masonry.results import CHECKPOINT, Result, ResultsError, open_result

from .render import RenderError, output_file
from .report import curve_rows, scene_of
from .views import auto_warp, damage_view

#: output formats and the matplotlib writer of each
WRITERS = {"gif": "pillow", "mp4": "ffmpeg"}


def animate(h5_path, out_path=None, case=None, curve=None, field="dt", camera=None, cut=None,
            warp="auto", fps=2.0, size=(800, 600), dpi=100):
    """Write the animation of a run's frames.

    Parameters
    ----------
    h5_path : str or Result
        the results file (its frames, and the last checkpoint where the run stopped after its
        last frame).
    out_path : str, optional
        ``.gif`` or ``.mp4`` (default ``<file stem>.gif`` next to the file).
    case : str, optional
        the scene, for its ``CURVE`` and the camera of its first ``VIEWS`` entry (default
        :func:`dr_masonry.viz.report.scene_of`).
    curve : dict, optional
        the curve (history columns ``x``, ``y``, optional ``stage``, ``xscale``, ``yscale``,
        ``xlabel``, ``ylabel``); default the scene's ``CURVE``.
    field : {"dt", "dc"}
        brick colouring.
    camera : str, optional
        a :data:`dr_masonry.viz.views.CAMERAS` preset (default: the scene's first view's, else
        "iso").
    cut : (axis, value), optional
        blocks left out (:func:`damage_view`); default the scene's first view's.
    warp : float or "auto"
        displacement magnification, one for all frames ("auto": :func:`auto_warp` of the frame
        of the largest displacement).
    fps : float
        frames per second.
    size : (width, height)
        pixels of the 3-D view; the curve beside it is as high and 0.8 as wide.
    dpi : int

    Returns
    -------
    str
        the written path.
    """
    r = h5_path if isinstance(h5_path, Result) else open_result(h5_path)
    out_path = out_path or os.path.splitext(r.path)[0] + ".gif"
    out_path = output_file("animate", out_path, list(WRITERS))
    if not (isinstance(fps, (int, float)) and np.isfinite(fps) and fps > 0):
        raise RenderError(f"animate: fps={fps!r} must be a number > 0")
    from matplotlib import animation
    kind = WRITERS[out_path.rsplit(".", 1)[1].lower()]
    if not animation.writers.is_available(kind):
        raise RenderError(f"animate: {out_path!r}: matplotlib's {kind} movie writer is not "
                          f"available here (MP4 needs ffmpeg on PATH); write a .gif")
    writer_cls = animation.writers[kind]
    name, mod = scene_of(r, case)
    curve = curve or getattr(mod, "CURVE", None)
    first = next(iter((getattr(mod, "VIEWS", None) or {}).values()), {})
    camera = camera or first.get("camera", "iso")
    cut = cut if cut is not None else first.get("cut")
    frames = list(range(r.n_frames))
    ids = r.frame_ids
    try:                        # a run stopped after its last frame: its checkpoint too
        if not ids or r.frame_increment(CHECKPOINT) > ids[-1]:
            frames.append(CHECKPOINT)
    except ResultsError:        # no checkpoint: the frames alone
        pass
    if not frames:
        raise RenderError(f"animate: {r.path} has no frames to animate")
    if warp == "auto":
        warp = min(auto_warp(r, f) for f in frames)
    h = r.history
    if curve is not None:
        rows = curve_rows(r, curve)
        x = np.asarray(h[curve["x"]], dtype=float) * curve.get("xscale", 1.0)
        y = np.asarray(h[curve["y"]], dtype=float) * curve.get("yscale", 1.0)
    w_in, h_in = size[0] / dpi, size[1] / dpi
    fig = Figure(figsize=(w_in * (1.8 if curve is not None else 1.0), h_in), dpi=dpi)
    ax_view = fig.add_axes([0.0, 0.0, 1 / 1.8 if curve is not None else 1.0, 1.0])
    ax_view.set_axis_off()
    marker = None
    if curve is not None:
        ax = fig.add_axes([1 / 1.8 + 0.07, 0.12, 0.8 / 1.8 - 0.1, 0.78])
        ax.plot(x[rows], y[rows], "-", color="0.3", lw=1)
        marker, = ax.plot([], [], "o", color="red", ms=8)
        ax.set(xlabel=curve.get("xlabel", curve["x"]), ylabel=curve.get("ylabel", curve["y"]))
        ax.grid(alpha=0.3)
    increments = np.asarray(h["increment"]) if "increment" in h else np.empty(0)
    writer = writer_cls(fps=fps)
    with tempfile.TemporaryDirectory() as tmp, writer.saving(fig, out_path, dpi):
        image = None
        for i, frame in enumerate(frames):
            png = damage_view(r, os.path.join(tmp, f"{i}.png"), frame=frame, field=field,
                              camera=camera, cut=cut, warp=warp, curve=curve, size=size).path
            pixels = imread(png)
            if image is None:
                image = ax_view.imshow(pixels)
            else:
                image.set_data(pixels)
            if marker is not None:
                k = np.flatnonzero(increments == r.frame_increment(frame))
                marker.set_data(x[k[-1:]], y[k[-1:]])
            writer.grab_frame()
    return out_path

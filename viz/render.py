"""Offscreen PNG pictures of a model or a results frame.

Two back ends draw the same picture (block surfaces coloured by group or by a field, block outlines):

* ``"vtk"``: a ``vtkRenderWindow`` with offscreen rendering (EGL/OSMesa/GLX, whatever the VTK wheel
  finds). Whether it works is probed once per process in a child process (a missing OpenGL context
  can abort the process instead of raising).
* ``"matplotlib"``: the fallback when the probe fails: the exterior faces of the hexahedra as a
  ``Poly3DCollection`` on a bare ``Figure`` (Agg canvas). Slower for large models, no lighting.

The environment variable ``DR_MASONRY_RENDER`` (``vtk`` or ``matplotlib``) forces a back end.
:func:`render_model` returns which one ran.
"""
from __future__ import annotations

import functools
import os
import subprocess
import sys
from typing import NamedTuple

import numpy as np

from dr_masonry.model import HEX_FACE_CORNERS, Model
from dr_masonry.results import Result, ResultsError, make_folder, model_arrays, open_result

from .vtk_series import block_corner_nodes, positions

#: camera directions (from the focal point towards the camera) and view-up vectors
VIEWS = {
    "iso": ((1.0, -1.6, 1.0), (0.0, 0.0, 1.0)),
    "front": ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)),
    "back": ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
    "side": ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    "top": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
}
#: matplotlib (elev, azim) of the same views
_MPL_VIEWS = {"iso": (25.0, -58.0), "front": (0.0, -90.0), "back": (0.0, 90.0),
              "side": (0.0, 0.0), "top": (90.0, -90.0)}
#: fields whose colour range is fixed to [0, 1]
DAMAGE_FIELDS = ("dt", "dc", "D")
#: the 12 edges of a hexahedron (corner indices)
HEX_EDGES = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4],
                      [0, 4], [1, 5], [2, 6], [3, 7]])
#: largest picture width or height, pixels
MAX_PIXELS = 10000

_PROBE = """
import vtk
from vtk.util.numpy_support import vtk_to_numpy
w = vtk.vtkRenderWindow(); w.SetOffScreenRendering(1); w.SetSize(64, 64)
r = vtk.vtkRenderer(); w.AddRenderer(r)
s = vtk.vtkSphereSource(); m = vtk.vtkPolyDataMapper(); m.SetInputConnection(s.GetOutputPort())
a = vtk.vtkActor(); a.SetMapper(m); r.AddActor(a); w.Render()
f = vtk.vtkWindowToImageFilter(); f.SetInput(w); f.Update()
img = vtk_to_numpy(f.GetOutput().GetPointData().GetScalars())
print("ok" if img.max() > img.min() else "blank")
"""


class Rendered(NamedTuple):
    """What :func:`render_model` produced: the PNG path and the back end that drew it."""
    path: str
    backend: str


class RenderError(ValueError):
    """Bad arguments to a rendering function."""


def output_file(what, png, formats=None, error=RenderError):
    """``png`` as a str path, its folder created; ``error`` naming ``what`` and the value unless
    it is a file path whose extension is one of ``formats`` (default: those matplotlib writes)."""
    if formats is None:
        from matplotlib.backend_bases import FigureCanvasBase
        formats = sorted(FigureCanvasBase.get_supported_filetypes())
    path = os.fspath(png) if isinstance(png, (str, os.PathLike)) else None
    if not isinstance(path, str) or not path:
        raise error(f"{what}: png must be a file path, got {png!r}")
    if os.path.splitext(path)[1][1:].lower() not in formats:
        raise error(f"{what}: png={path!r} must end in one of "
                    f"{', '.join('.' + f for f in formats)}")
    if os.path.isdir(path):
        raise error(f"{what}: png={path!r} is a folder, not a file")
    try:
        make_folder(os.path.dirname(path) or ".")
    except ResultsError as e:
        raise error(f"{what}: png={path!r}: {e}") from None
    return path


@functools.lru_cache(maxsize=1)
def vtk_offscreen_available():
    """True if VTK can render offscreen on this machine (probed once, in a child process)."""
    try:
        p = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True,
                           timeout=120)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return p.returncode == 0 and p.stdout.strip().endswith("ok")


def choose_backend(backend=None):
    """``backend`` or ``$DR_MASONRY_RENDER`` if given, else "vtk" when it works, else "matplotlib"."""
    backend = backend or os.environ.get("DR_MASONRY_RENDER") or (
        "vtk" if vtk_offscreen_available() else "matplotlib")
    if backend not in ("vtk", "matplotlib"):
        raise RenderError(f"render back end must be 'vtk' or 'matplotlib', got {backend!r}")
    return backend


def _scene(model_or_h5, field, frame, warp):
    """Arrays, node positions, per-cell or per-point values and contact points to draw."""
    if isinstance(model_or_h5, Model):
        if field is not None or frame is not None:
            raise RenderError("render_model: a Model has no fields; give a results file for "
                              f"field={field!r} / frame={frame!r}")
        if not model_or_h5.n_blocks:
            raise RenderError("render_model: the model has no blocks to draw")
        arrays, names = model_arrays(model_or_h5)
        fields, where, contacts = {}, {}, None
    else:
        r = model_or_h5 if isinstance(model_or_h5, Result) else open_result(model_or_h5)
        arrays, names = r.model_arrays, r.group_names
        if not len(arrays["block_divisions"]):
            raise RenderError(f"render_model: the model of {r.path} has no blocks to draw")
        if frame is None and field is not None:
            frame = -1
        fields = r.frame(frame) if frame is not None else {}
        where = r.locations(frame) if frame is not None else {}
        contacts = r.contacts(frame) if frame is not None else None
    x = positions(arrays["nodes"], fields, warp)
    scene = {"arrays": arrays, "x": x, "names": names, "cell": None, "point": None,
             "contact": None, "label": "group"}
    if field is None:
        scene["cell"] = arrays["block_group"][arrays["element_block"]].astype(float)
        return scene
    if field not in fields:
        raise RenderError(f"render_model: frame {frame} has no field {field!r}; it has "
                          f"{sorted(fields)}")
    v = np.asarray(fields[field], dtype=float)
    v = np.linalg.norm(v, axis=1) if v.ndim == 2 else v
    if v.ndim != 1:
        raise RenderError(f"render_model: field {field!r} of shape {fields[field].shape} "
                          "cannot be drawn")
    if where[field] == "node":
        scene["point"] = v
    elif where[field] == "element":
        scene["cell"] = v
    else:
        scene["contact"] = (x[contacts["slave"]], v)
    scene["label"] = field if fields[field].ndim == 1 else f"|{field}|"
    return scene


def _range(scene, field):
    if field in DAMAGE_FIELDS:
        return 0.0, 1.0
    v = next(s for s in (scene["cell"], scene["point"]) if s is not None) \
        if scene["contact"] is None else scene["contact"][1]
    lo, hi = float(np.min(v)), float(np.max(v))
    return (lo, hi) if hi > lo else (lo - 0.5, lo + 0.5)


def render_model(model_or_h5, png, field=None, frame=None, warp=1.0, view="iso",
                 size=(1200, 900), backend=None):
    """Render blocks to a PNG, coloured by block group or by a field.

    Parameters
    ----------
    model_or_h5 : Model, Result or str
        a Model (reference configuration) or a results file.
    png : str
        output file.
    field : str, optional
        a frame field: node fields ("U": |U|, m) colour points, element fields ("dt", "dc")
        colour hexahedra, contact fields ("D", ...) colour the contact points over grey blocks.
        None colours blocks by group.
    frame : int or "checkpoint", optional
        frame position (negative from the end) or the last checkpoint; default the last frame
        when ``field`` is given, else the reference configuration.
    warp : float
        displacement magnification of the drawn positions.
    view : {"iso", "front", "back", "side", "top"}
    size : (width, height) pixels
        two integers in [1, :data:`MAX_PIXELS`].
    backend : {"vtk", "matplotlib"}, optional
        default: see :func:`choose_backend`.

    Returns
    -------
    Rendered
        ``(path, backend)``.
    """
    if view not in VIEWS:
        raise RenderError(f"render_model: view must be one of {sorted(VIEWS)}, got {view!r}")
    if (not isinstance(size, (tuple, list, np.ndarray)) or len(size) != 2
            or not all(isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))
                       and 1 <= v <= MAX_PIXELS for v in size)):
        raise RenderError(f"render_model: size must be (width, height), two integers in "
                          f"[1, {MAX_PIXELS}] pixels, got {size!r}")
    size = (int(size[0]), int(size[1]))
    backend = choose_backend(backend)
    png = output_file("render_model", png, ["png"] if backend == "vtk" else None)
    scene = _scene(model_or_h5, field, frame, warp)
    crange = (0.0, max(len(scene["names"]) - 1, 1)) if field is None else _range(scene, field)
    (_render_vtk if backend == "vtk" else _render_mpl)(scene, png, crange, view, size, field)
    return Rendered(png, backend)


def _outline_segments(scene):
    """Block outline segments (n_blocks * 12, 2, 3) at the drawn positions."""
    c = block_corner_nodes(scene["arrays"])
    return scene["x"][c[:, HEX_EDGES]].reshape(-1, 2, 3)


# ---------------------------------------------------------------------- VTK back end
def _render_vtk(scene, png, crange, view, size, field):
    import vtk
    from vtk.util.numpy_support import numpy_to_vtk

    from .vtk_series import block_grid

    cell = {} if scene["cell"] is None else {"value": scene["cell"]}
    point = {} if scene["point"] is None else {"value": scene["point"]}
    grid = block_grid(scene["arrays"], scene["x"], cell, point)
    surf = vtk.vtkDataSetSurfaceFilter()
    surf.SetInputData(grid)
    lut = vtk.vtkLookupTable()
    if field is None:
        n = len(scene["names"])
        lut.SetNumberOfTableValues(max(n, 2))
        lut.Build()
        for i in range(max(n, 2)):
            lut.SetTableValue(i, *_GROUP_COLOURS[i % len(_GROUP_COLOURS)], 1.0)
    else:
        lut.SetHueRange(0.667, 0.0)
        lut.Build()
    mapper = vtk.vtkDataSetMapper()
    mapper.SetInputConnection(surf.GetOutputPort())
    mapper.SetResolveCoincidentTopologyToPolygonOffset()  # outlines drawn over the faces
    ren = vtk.vtkRenderer()
    ren.SetBackground(1.0, 1.0, 1.0)
    actor = vtk.vtkActor()
    actor.SetMapper(mapper)
    if scene["contact"] is None:
        mapper.SetLookupTable(lut)
        mapper.SetScalarRange(*crange)
        mapper.SetScalarModeToUseCellFieldData() if cell else mapper.SetScalarModeToUsePointFieldData()
        mapper.SelectColorArray("value")
        mapper.ScalarVisibilityOn()
    else:
        mapper.ScalarVisibilityOff()
        actor.GetProperty().SetColor(0.8, 0.8, 0.8)
        actor.GetProperty().SetOpacity(0.35)
        xp, v = scene["contact"]
        pts = vtk.vtkPoints()
        pts.SetData(numpy_to_vtk(np.ascontiguousarray(xp), deep=True))
        poly = vtk.vtkPolyData()
        poly.SetPoints(pts)
        arr = numpy_to_vtk(np.ascontiguousarray(v), deep=True)
        arr.SetName("value")
        poly.GetPointData().SetScalars(arr)
        verts = vtk.vtkVertexGlyphFilter()
        verts.SetInputData(poly)
        pm = vtk.vtkPolyDataMapper()
        pm.SetInputConnection(verts.GetOutputPort())
        pm.SetLookupTable(lut)
        pm.SetScalarRange(*crange)
        pa = vtk.vtkActor()
        pa.SetMapper(pm)
        pa.GetProperty().SetPointSize(10)
        pa.GetProperty().SetRenderPointsAsSpheres(True)
        ren.AddActor(pa)
    ren.AddActor(actor)
    seg = _outline_segments(scene).reshape(-1, 3)
    lines = vtk.vtkPolyData()
    lp = vtk.vtkPoints()
    lp.SetData(numpy_to_vtk(np.ascontiguousarray(seg), deep=True))
    lines.SetPoints(lp)
    ca = vtk.vtkCellArray()
    ns = seg.shape[0] // 2
    ca.SetData(numpy_to_vtk(np.arange(0, 2 * ns + 1, 2, dtype=np.int64), deep=True),
               numpy_to_vtk(np.arange(2 * ns, dtype=np.int64), deep=True))
    lines.SetLines(ca)
    lm = vtk.vtkPolyDataMapper()
    lm.SetInputData(lines)
    la = vtk.vtkActor()
    la.SetMapper(lm)
    la.GetProperty().SetColor(0.1, 0.1, 0.1)
    la.GetProperty().SetLineWidth(2.0)
    ren.AddActor(la)
    if field is not None:
        bar = vtk.vtkScalarBarActor()
        bar.SetLookupTable(lut)
        bar.SetTitle(scene["label"])
        for tp in (bar.GetTitleTextProperty(), bar.GetLabelTextProperty()):
            tp.SetColor(0.0, 0.0, 0.0)
            tp.ShadowOff()
        bar.SetWidth(0.08)
        ren.AddViewProp(bar)
    d, up = VIEWS[view]
    cam = ren.GetActiveCamera()
    cam.SetFocalPoint(0.0, 0.0, 0.0)
    cam.SetPosition(*d)
    cam.SetViewUp(*up)
    ren.ResetCamera()
    win = vtk.vtkRenderWindow()
    win.SetOffScreenRendering(1)
    win.SetSize(*size)
    win.AddRenderer(ren)
    win.Render()
    grab = vtk.vtkWindowToImageFilter()
    grab.SetInput(win)
    grab.Update()
    writer = vtk.vtkPNGWriter()
    writer.SetFileName(png)
    writer.SetInputConnection(grab.GetOutputPort())
    writer.Write()
    win.Finalize()


# ---------------------------------------------------------------------- matplotlib back end
_GROUP_COLOURS = [(0.80, 0.40, 0.30), (0.55, 0.55, 0.60), (0.35, 0.55, 0.80), (0.85, 0.70, 0.30),
                  (0.45, 0.70, 0.45), (0.65, 0.45, 0.70), (0.95, 0.60, 0.60), (0.50, 0.35, 0.25)]


def exterior_faces(elements):
    """Element faces that belong to one hexahedron only: (element ids (m,), quads (m, 4))."""
    quads = elements[:, HEX_FACE_CORNERS].reshape(-1, 4)
    key = np.sort(quads, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    once = cnt[inv.ravel()] == 1
    return np.repeat(np.arange(len(elements)), 6)[once], quads[once]


def _render_mpl(scene, png, crange, view, size, field):
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import ListedColormap, Normalize
    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    x = scene["x"]
    elem, quads = exterior_faces(scene["arrays"]["elements"])
    norm = Normalize(*crange)
    cmap = ListedColormap(_GROUP_COLOURS) if field is None else colormaps["jet"]
    fig = Figure(figsize=(size[0] / 100, size[1] / 100), dpi=100)
    ax = fig.add_subplot(projection="3d")
    if scene["contact"] is not None:
        colours = (0.8, 0.8, 0.8, 0.35)
    elif scene["cell"] is not None:
        v = scene["cell"][elem]
        colours = cmap(v.astype(int) % len(_GROUP_COLOURS)) if field is None else cmap(norm(v))
    else:
        colours = cmap(norm(scene["point"][quads].mean(axis=1)))
    ax.add_collection3d(Poly3DCollection(x[quads], facecolors=colours, edgecolors="none"))
    ax.add_collection3d(Line3DCollection(_outline_segments(scene), colors="k", linewidths=0.4))
    if scene["contact"] is not None:
        xp, v = scene["contact"]
        ax.scatter(xp[:, 0], xp[:, 1], xp[:, 2], c=v, cmap=cmap, norm=norm, s=20)
    lo, hi = x.min(axis=0), x.max(axis=0)
    span = np.maximum(hi - lo, 1e-3 * np.max(hi - lo))
    ax.set_xlim(lo[0], lo[0] + span[0])
    ax.set_ylim(lo[1], lo[1] + span[1])
    ax.set_zlim(lo[2], lo[2] + span[2])
    ax.set_box_aspect(span)
    ax.view_init(*_MPL_VIEWS[view])
    ax.set_axis_off()
    if field is not None:
        sm = ScalarMappable(norm=norm, cmap=cmap)
        fig.colorbar(sm, ax=ax, shrink=0.6, label=scene["label"])
    fig.savefig(png)

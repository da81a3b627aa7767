"""3-D damage views of a results frame, offscreen (VTK): the deformed bricks coloured by tensile or
compressive damage, the open or slipped joints as coloured joint faces, one colour bar for both.

* Each block is drawn shrunk towards its centre so that its faces stand :func:`default_gap` off
  the joints (:func:`shrunk_positions`); a damaged joint fills that gap with the joint faces of
  its contact points (:func:`joint_patches`): around each slave node, the quarter of each slave
  element face at that node (the node's share of the face), as a slab across the gap, coloured by
  the point's joint field (``D``: damage of the cohesive-frictional law).
* The bricks' colour is smooth: each node gets the mean of the element values of the block's
  hexahedra at it, and the faces interpolate the nodes' values (no smoothing across a joint).
* Parallel projection with the camera presets :data:`CAMERAS` (a wall's elevation from the front or
  the back, a house's facade, the isometric view), fitted to the whole deformed structure, so a
  ``cut`` (the blocks in front of a plane left out, e.g. a house's front facade, to show its
  transversal walls) keeps the uncut picture's frame.

Without a working VTK offscreen context (:func:`dr_masonry.viz.render.choose_backend`) the
picture falls back to :func:`dr_masonry.viz.render.render_model`'s matplotlib drawing of the
bricks alone.
"""
from __future__ import annotations

import os

import numpy as np

from dr_masonry.model import quad_normal
from dr_masonry.results import Result, open_result

from . import render
from .render import RenderError, exterior_faces

#: camera presets: direction from the focal point to the camera, view-up, the matplotlib view
CAMERAS = {
    "elevation": ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0), "front"),    # a wall along x, from -y
    "back": ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0), "back"),           # the same wall from +y
    "facade": ((0.35, -1.0, 0.35), (0.0, 0.0, 1.0), "front"),     # a house's front (y min)
    "iso": ((1.0, -1.6, 1.0), (0.0, 0.0, 1.0), "iso"),
}
#: the part of the picture (x0, y0, x1, y1, fractions of width and height) the structure is
#: drawn in; the title is above it, the colour bar right of it
MODEL_VIEWPORT = (0.0, 0.0, 0.86, 0.93)
#: the structure's projection fills this fraction of the model viewport's height or width
FILL = 0.92
#: gap between a block and its joints as a fraction of the structure's largest extent
JOINT_GAP = 0.002
#: share of ambient light: a face turned away from the camera keeps this fraction of its colour
AMBIENT = 0.45
#: element fields a view can colour the bricks by
BRICK_FIELDS = ("dt", "dc")
#: largest displacement as a fraction of the structure's largest extent for ``warp="auto"``
AUTO_WARP = 0.03


def default_gap(x):
    """Gap (m) between the blocks and their joints in a picture of nodes ``x`` (nn, 3) m."""
    return JOINT_GAP * float(np.max(np.ptp(x, axis=0)))


def auto_warp(result, frame=-1):
    """Displacement magnification for ``warp="auto"``: 1, 2 or 5 times a power of ten, the
    largest at most that makes the largest |U| of ``frame`` :data:`AUTO_WARP` of the structure's
    largest extent, and at least 1 (1 for a frame without displacements)."""
    r = result if isinstance(result, Result) else open_result(result)
    fields = r.frame(frame)
    u = float(np.max(np.linalg.norm(fields["U"], axis=1))) if "U" in fields else 0.0
    if u <= 0.0:
        return 1.0
    want = AUTO_WARP * float(np.max(np.ptp(r.model_arrays["nodes"], axis=0))) / u
    if want <= 1.0:
        return 1.0
    p = 10.0 ** np.floor(np.log10(want))
    return float(max(m * p for m in (1.0, 2.0, 5.0) if m * p <= want * (1 + 1e-12)))


def block_of_nodes(arrays):
    """Block id of each node (nn,), from the results file's model ``arrays``."""
    count = np.diff(arrays["block_node_start"])
    return np.repeat(np.arange(len(count)), count)


def shrunk_positions(arrays, x, gap):
    """Node positions ``x`` (nn, 3) m with every block scaled about its centre (the mean of its
    nodes) along x, y and z so that its faces move in by ``gap`` (m; at most a quarter of the
    block's reference extent along that axis, from ``arrays["block_corners"]``)."""
    block = block_of_nodes(arrays)
    n = len(arrays["block_divisions"])
    centre = np.zeros((n, 3))
    np.add.at(centre, block, x)
    centre /= np.maximum(np.bincount(block, minlength=n), 1)[:, None]
    extent = np.ptp(arrays["block_corners"], axis=1)                    # (n_blocks, 3)
    factor = 1.0 - 2.0 * np.minimum(gap, 0.25 * extent) / np.maximum(extent, 1e-300)
    return centre[block] + factor[block] * (x - centre[block])


def node_values(elements, values, n_nodes):
    """Element values (ne,) averaged at the nodes (n_nodes,): each node the mean over the
    hexahedra ``elements`` (ne, 8) at it (the nodes of one block are its own: no averaging across
    a joint)."""
    total = np.bincount(elements.ravel(), np.repeat(values, 8), minlength=n_nodes)
    count = np.bincount(elements.ravel(), minlength=n_nodes)
    return total / np.maximum(count, 1)


def joint_patches(quads, nodes, con, value, threshold, parallel=0.9):
    """The joint faces of the contact points whose ``value`` (nc,) is above ``threshold``.

    A contact point's face is its slave node's share of the slave block's exterior faces that
    lie on the joint (normal within ``parallel`` of the master face's): the quarter of each such
    face at the node.

    Parameters
    ----------
    quads : (m, 4) int
        exterior element faces (:func:`dr_masonry.viz.render.exterior_faces`).
    nodes : (nn, 3) float
        reference node positions, m (the faces' normals).
    con : dict of arrays
        contact arrays ``slave`` (nc,) and ``master`` (nc, 4).
    value, threshold : (nc,) float, float

    Returns
    -------
    face, corner : (k,) int
        the face (row of ``quads``) and the corner (0-3) at the slave node of each patch.
    patch_value : (k,) float
        the largest ``value`` of the points at that corner.
    """
    on = np.flatnonzero(value > threshold)
    slave = np.asarray(con["slave"])[on]
    fn = quads.ravel()
    order = np.argsort(fn, kind="stable")
    lo = np.searchsorted(fn[order], slave, "left")
    cnt = np.searchsorted(fn[order], slave, "right") - lo
    point = np.repeat(np.arange(on.size), cnt)
    entry = order[np.repeat(lo, cnt) + np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)]
    face = entry // 4
    n_face = quad_normal(nodes[quads[face]])
    n_master = quad_normal(nodes[np.asarray(con["master"])[on[point]]])
    ok = np.abs(np.einsum("ij,ij->i", n_face, n_master)) > parallel
    key, inv = np.unique(entry[ok], return_inverse=True)
    patch_value = np.full(key.size, -np.inf)
    np.maximum.at(patch_value, inv.ravel(), np.asarray(value, dtype=float)[on[point[ok]]])
    return key // 4, key % 4, patch_value


def patch_slabs(quads, face, corner, x, xs):
    """Hexahedra (k, 8, 3) across the joint gap of the patches ``face``, ``corner``
    (:func:`joint_patches`): the patch (the corner node, the middle of its edge to the next
    corner, the face's centre, the middle of its edge to the previous corner) at the shrunk
    positions ``xs`` and its mirror through the joint along the face's normal, node positions
    ``x`` (nn, 3) m unshrunk."""
    q = quads[face]
    nxt, prv = q[np.arange(len(q)), (corner + 1) % 4], q[np.arange(len(q)), (corner + 3) % 4]
    here = q[np.arange(len(q)), corner]

    def patch(p):
        return np.stack([p[here], 0.5 * (p[here] + p[nxt]), p[q].mean(axis=1),
                         0.5 * (p[here] + p[prv])], axis=1)
    inner = patch(xs)
    n = quad_normal(x[q])[:, None, :]
    across = 2.0 * np.sum((patch(x) - inner) * n, axis=2, keepdims=True) * n
    return np.concatenate([inner, inner + across], axis=1)


def fit_camera(x, camera, aspect):
    """(focal point (3,), camera position (3,), view-up (3,), parallel scale (m)) of preset
    ``camera`` for points ``x`` (n, 3) m in a viewport of width / height ``aspect``: the focal
    point at the centre of their bounding box, whose projection fills :data:`FILL` of the
    viewport's height or width."""
    d, up = (np.asarray(v, dtype=float) for v in CAMERAS[camera][:2])
    d /= np.linalg.norm(d)
    right = np.cross(-d, up)
    right /= np.linalg.norm(right)
    up = np.cross(right, -d)
    lo, hi = x.min(axis=0), x.max(axis=0)
    centre = 0.5 * (lo + hi)
    box = np.array([[a, b, c] for a in (lo[0], hi[0]) for b in (lo[1], hi[1])
                    for c in (lo[2], hi[2])]) - centre
    half_w, half_h = np.abs(box @ right).max(), np.abs(box @ up).max()
    scale = max(half_h, half_w / aspect, 1e-9) / FILL
    return centre, centre + d * 4.0 * max(np.linalg.norm(hi - lo), 1e-9), up, scale


def _row_text(r, inc, curve):
    """``", top displacement (mm) 1.23, base shear (kN) 45.6"`` of the history row of increment
    ``inc`` (``curve``: a case's CURVE, its columns scaled to the plotted units) or "" when the
    file has no such row or columns."""
    h = r.history
    if curve is None or not all(curve[k] in h for k in ("x", "y")):
        return ""
    rows = np.flatnonzero(np.asarray(h["increment"]) == inc)
    if not rows.size:
        return ""
    k = rows[-1]
    return "".join(f", {curve.get(a + 'label', curve[a])} "
                   f"{h[curve[a]][k] * curve.get(a + 'scale', 1.0):.3g}" for a in ("x", "y"))


def damage_view(result, png, frame=-1, field="dt", camera="iso", warp="auto", joint_field="D",
                threshold=0.5, cut=None, curve=None, title=None, size=(1200, 900), gap=None,
                backend=None):
    """Render the deformed structure of one frame, bricks coloured by ``field``, joints with
    ``joint_field`` above ``threshold`` as coloured joint faces (colour range [0, 1] for both).

    Parameters
    ----------
    result : str or Result
    png : str
        output file (.png).
    frame : int or "checkpoint"
        frame position (negative from the end).
    field : {"dt", "dc"}
        element damage colouring the bricks (smoothed within each block).
    camera : {"elevation", "back", "facade", "iso"}
    warp : float or "auto"
        displacement magnification ("auto": :func:`auto_warp` of this frame).
    joint_field : str or None
        contact field drawn as joint faces (None: no joints).
    threshold : float
        joints with ``joint_field`` above it are drawn.
    cut : (axis, value), optional
        leave out the blocks whose centre has coordinate ``axis`` (0, 1, 2) below ``value`` (m),
        e.g. ``(1, 0.11)`` removes the house's front facade.
    curve : dict, optional
        a case's ``CURVE`` (history columns ``x``, ``y``, their ``xscale``, ``yscale``,
        ``xlabel``, ``ylabel``): the row's values in the title.
    title : str, optional
        default: file name, increment, magnification and the row's curve values.
    size : (width, height) pixels
    gap : float, optional
        gap between the blocks and their joints, m (default :func:`default_gap`).
    backend : {"vtk", "matplotlib"}, optional

    Returns
    -------
    render.Rendered
    """
    if field not in BRICK_FIELDS:
        raise RenderError(f"damage_view: field must be one of {BRICK_FIELDS}, got {field!r}")
    if camera not in CAMERAS:
        raise RenderError(f"damage_view: camera must be one of {sorted(CAMERAS)}, got {camera!r}")
    if not (isinstance(threshold, (int, float)) and np.isfinite(threshold) and threshold >= 0):
        raise RenderError(f"damage_view: threshold={threshold!r} must be a finite number >= 0")
    if cut is not None and not (len(cut) == 2 and cut[0] in (0, 1, 2)
                                and np.isfinite(float(cut[1]))):
        raise RenderError(f"damage_view: cut must be (axis 0/1/2, coordinate m), got {cut!r}")
    if gap is not None and not (isinstance(gap, (int, float)) and np.isfinite(gap) and gap >= 0):
        raise RenderError(f"damage_view: gap={gap!r} must be a finite length >= 0 (m)")
    r = result if isinstance(result, Result) else open_result(result)
    if warp == "auto":
        warp = auto_warp(r, frame)
    backend = render.choose_backend(backend)
    inc = r.frame_increment(frame)
    title = title or (f"{os.path.basename(r.path)}: increment {inc}{_row_text(r, inc, curve)}"
                      f"; displacements x{warp:g}")
    if backend == "matplotlib":
        return render.render_model(r, png, field=field, frame=frame, warp=warp,
                                   view=CAMERAS[camera][2], size=size, backend=backend)
    png = render.output_file("damage_view", png, ["png"])
    scene = render._scene(r, field, frame, warp)
    arrays, x = scene["arrays"], scene["x"]
    keep = np.ones(len(arrays["block_divisions"]), bool)
    if cut is not None:
        c = render.block_corner_nodes(arrays)
        keep = x[c].mean(axis=1)[:, cut[0]] >= float(cut[1])
    xs = shrunk_positions(arrays, x, default_gap(x) if gap is None else gap)
    slabs = None
    con = r.contacts(frame)
    if joint_field is not None and con is not None:
        fields = r.frame(frame)
        if joint_field not in fields or r.locations(frame)[joint_field] != "contact":
            raise RenderError(f"damage_view: frame {frame!r} has no contact field "
                              f"{joint_field!r}")
        both = keep[np.asarray(con["blocks"])].all(axis=1)
        d = np.where(both, np.asarray(fields[joint_field], dtype=float), -np.inf)
        _, quads = exterior_faces(arrays["elements"])
        face, corner, value = joint_patches(quads, arrays["nodes"], con, d, threshold)
        slabs = (patch_slabs(quads, face, corner, x, xs), value)
    values = node_values(arrays["elements"], scene["cell"], len(x))
    _draw_vtk(arrays, x, xs, values, keep, slabs, png, camera, size, field, joint_field, title)
    return render.Rendered(png, backend)


def _hexahedra(points, cell_value):
    """vtkUnstructuredGrid of hexahedra ``points`` (k, 8, 3) with cell data "value" (k,)."""
    import vtk
    from vtk.util.numpy_support import numpy_to_vtk

    grid = vtk.vtkUnstructuredGrid()
    pts = vtk.vtkPoints()
    pts.SetData(numpy_to_vtk(np.ascontiguousarray(points.reshape(-1, 3)), deep=True))
    grid.SetPoints(pts)
    k = len(points)
    cells = vtk.vtkCellArray()
    cells.SetData(numpy_to_vtk(np.arange(0, 8 * k + 1, 8, dtype=np.int64), deep=True),
                  numpy_to_vtk(np.arange(8 * k, dtype=np.int64), deep=True))
    grid.SetCells(vtk.VTK_HEXAHEDRON, cells)
    arr = numpy_to_vtk(np.ascontiguousarray(cell_value, dtype=float), deep=True)
    arr.SetName("value")
    grid.GetCellData().AddArray(arr)
    return grid


def _draw_vtk(arrays, x, xs, values, keep, slabs, png, camera, size, field, joint_field, title):
    import vtk

    from .vtk_series import block_grid

    lut = vtk.vtkLookupTable()
    lut.SetHueRange(0.667, 0.0)
    lut.SetRampToLinear()                            # colour linear in the value (not an S)
    lut.Build()
    ren = vtk.vtkRenderer()
    ren.SetBackground(1.0, 1.0, 1.0)
    ren.SetViewport(*MODEL_VIEWPORT)
    grid = block_grid(arrays, xs, {"keep": keep[arrays["element_block"]].astype(float)},
                      {"value": values})
    kept = vtk.vtkThreshold()
    kept.SetInputData(grid)
    kept.SetInputArrayToProcess(0, 0, 0, vtk.vtkDataObject.FIELD_ASSOCIATION_CELLS, "keep")
    kept.SetUpperThreshold(0.5)                      # keep >= 0.5
    kept.SetThresholdFunction(vtk.vtkThreshold.THRESHOLD_UPPER)
    parts = [(kept.GetOutputPort(), vtk.vtkDataObject.FIELD_ASSOCIATION_POINTS)]
    if slabs is not None and len(slabs[1]):
        joints = vtk.vtkPassThrough()
        joints.SetInputData(_hexahedra(*slabs))
        parts.append((joints.GetOutputPort(), vtk.vtkDataObject.FIELD_ASSOCIATION_CELLS))
    for port, where in parts:
        surf = vtk.vtkDataSetSurfaceFilter()
        surf.SetInputConnection(port)
        mapper = vtk.vtkPolyDataMapper()
        mapper.SetInputConnection(surf.GetOutputPort())
        mapper.SetLookupTable(lut)
        mapper.SetScalarRange(0.0, 1.0)
        if where == vtk.vtkDataObject.FIELD_ASSOCIATION_POINTS:
            mapper.SetScalarModeToUsePointFieldData()
            mapper.InterpolateScalarsBeforeMappingOn()    # the colour of the interpolated value
        else:
            mapper.SetScalarModeToUseCellFieldData()
        mapper.SelectColorArray("value")
        actor = vtk.vtkActor()
        actor.SetMapper(mapper)
        actor.GetProperty().SetAmbient(AMBIENT)       # faces away from the light stay legible
        actor.GetProperty().SetDiffuse(1.0 - AMBIENT)
        ren.AddActor(actor)
    focal, position, up, scale = fit_camera(
        x, camera, size[0] * (MODEL_VIEWPORT[2] - MODEL_VIEWPORT[0])
        / (size[1] * (MODEL_VIEWPORT[3] - MODEL_VIEWPORT[1])))
    cam = ren.GetActiveCamera()
    cam.ParallelProjectionOn()
    cam.SetFocalPoint(*focal)
    cam.SetPosition(*position)
    cam.SetViewUp(*up)
    cam.SetParallelScale(scale)
    ren.ResetCameraClippingRange()
    back = vtk.vtkRenderer()                         # the white of the whole picture
    back.SetBackground(1.0, 1.0, 1.0)
    back.InteractiveOff()
    overlay = vtk.vtkRenderer()                      # title and colour bar over the whole picture
    overlay.SetLayer(1)
    overlay.InteractiveOff()
    bar = vtk.vtkScalarBarActor()
    bar.SetLookupTable(lut)
    bar.SetTitle(field if joint_field is None else f"{field}\njoints {joint_field}")
    bar.SetPosition(MODEL_VIEWPORT[2] + 0.01, 0.08)
    bar.SetWidth(0.11)
    bar.SetHeight(0.8)
    text = vtk.vtkTextActor()
    text.SetInput(title)
    text.SetPosition(10, size[1] - 28)
    for tp in (bar.GetTitleTextProperty(), bar.GetLabelTextProperty(), text.GetTextProperty()):
        tp.SetColor(0.0, 0.0, 0.0)
        tp.ShadowOff()
        tp.ItalicOff()
    text.GetTextProperty().SetFontSize(max(10, min(18, size[0] // 70)))
    overlay.AddViewProp(bar)
    overlay.AddViewProp(text)
    win = vtk.vtkRenderWindow()
    win.SetOffScreenRendering(1)
    win.SetNumberOfLayers(2)
    win.SetSize(*size)
    for layer in (back, ren, overlay):
        win.AddRenderer(layer)
    win.Render()
    grab = vtk.vtkWindowToImageFilter()
    grab.SetInput(win)
    grab.Update()
    writer = vtk.vtkPNGWriter()
    writer.SetFileName(png)
    writer.SetInputConnection(grab.GetOutputPort())
    writer.Write()
    win.Finalize()


def write_views(result, out, frames, views, curve=None, **common):
    """Damage views ``{out}_{name}_{tag}.png`` of each ``(tag, frame)`` of ``frames`` (e.g.
    :func:`dr_masonry.scene.map_frames`) and each ``{name: keyword arguments of
    damage_view}`` of ``views``, all with the displacement magnification of :func:`auto_warp` at
    the frame of the largest displacement unless a view gives its own ``warp``; ``curve`` (a
    case's CURVE) puts the row's values in the titles; ``common``: keyword arguments of every
    view (a view's own win). Returns the written paths."""
    r = result if isinstance(result, Result) else open_result(result)
    if not frames:
        return []
    warp = min(auto_warp(r, frame) for _, frame in frames)   # one magnification for all
    return [damage_view(r, f"{out}_{name}_{tag}.png", frame=frame, curve=curve,
                        **dict({"warp": warp}, **common, **kw)).path
            for tag, frame in frames for name, kw in views.items()]

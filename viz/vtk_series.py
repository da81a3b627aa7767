"""VTK time series of a results file: one ``.vtu`` per frame, tied by ``.pvd`` collections.

``blocks.pvd`` -> ``blocks_NNNNNN.vtu``: the hexahedra (VTK_HEXAHEDRON) with point data "U" (m) and
every other node field, cell data "dt", "dc", "block_id", "group" and every other element field.
``contacts.pvd`` -> ``contacts_NNNNNN.vtu``: one VTK_VERTEX per contact point at its slave node,
point data "D", "opening", "slip" (and every other contact field) plus "law", "slave_block",
"master_block". Points are in the deformed configuration ``X + warp * U`` (``warp=0``: reference).
Fields with more than two dimensions (Gauss-point states) are left out.
"""
from __future__ import annotations

import os
from xml.sax.saxutils import quoteattr

import numpy as np
import vtk
from vtk.util.numpy_support import numpy_to_vtk

from dr_masonry.loading import is_number
from dr_masonry.model import block_corner_nodes as corner_nodes
from dr_masonry.postprocess import PostprocessError
from dr_masonry.results import Result, ResultsError, make_folder, open_result, require_space


def as_result(obj):
    """A :class:`Result` from a Result or a path."""
    return obj if isinstance(obj, Result) else open_result(obj)


def positions(nodes, fields, warp=1.0):
    """Node positions (nn, 3), m: ``nodes + warp * fields["U"]`` (``nodes`` without "U")."""
    if not is_number(warp):
        raise PostprocessError(f"warp={warp!r}: the displacement scale must be a finite number")
    if warp and "U" in fields:
        return nodes + warp * fields["U"]
    return nodes.copy()


def _add(data, name, arr):
    a = numpy_to_vtk(np.ascontiguousarray(arr), deep=True)
    a.SetName(name)
    data.AddArray(a)


def block_grid(arrays, x, cell_fields=None, point_fields=None):
    """vtkUnstructuredGrid of the hexahedra at node positions ``x`` (nn, 3).

    ``arrays`` are :attr:`Result.model_arrays` (or :func:`dr_masonry.results.model_arrays`);
    cell data "block_id" and "group" are always added.
    """
    grid = vtk.vtkUnstructuredGrid()
    pts = vtk.vtkPoints()
    pts.SetData(numpy_to_vtk(np.ascontiguousarray(x, dtype=np.float64), deep=True))
    grid.SetPoints(pts)
    conn = np.ascontiguousarray(arrays["elements"], dtype=np.int64)
    ne = conn.shape[0]
    cells = vtk.vtkCellArray()
    cells.SetData(numpy_to_vtk(np.arange(0, 8 * ne + 1, 8, dtype=np.int64), deep=True),
                  numpy_to_vtk(conn.ravel(), deep=True))
    grid.SetCells(vtk.VTK_HEXAHEDRON, cells)
    eb = arrays["element_block"]
    _add(grid.GetCellData(), "block_id", eb.astype(np.int64))
    _add(grid.GetCellData(), "group", arrays["block_group"][eb].astype(np.int64))
    for k, v in (cell_fields or {}).items():
        _add(grid.GetCellData(), k, v)
    for k, v in (point_fields or {}).items():
        _add(grid.GetPointData(), k, v)
    return grid


def contact_grid(contacts, x, point_fields=None):
    """vtkUnstructuredGrid of VTK_VERTEX cells at the slave nodes of ``contacts`` (dict of arrays)."""
    slave = contacts["slave"]
    nc = slave.shape[0]
    grid = vtk.vtkUnstructuredGrid()
    pts = vtk.vtkPoints()
    pts.SetData(numpy_to_vtk(np.ascontiguousarray(x[slave], dtype=np.float64), deep=True))
    grid.SetPoints(pts)
    cells = vtk.vtkCellArray()
    cells.SetData(numpy_to_vtk(np.arange(nc + 1, dtype=np.int64), deep=True),
                  numpy_to_vtk(np.arange(nc, dtype=np.int64), deep=True))
    grid.SetCells(vtk.VTK_VERTEX, cells)
    pd = grid.GetPointData()
    _add(pd, "law", contacts["law"].astype(np.int64))
    _add(pd, "slave_block", contacts["blocks"][:, 0].astype(np.int64))
    _add(pd, "master_block", contacts["blocks"][:, 1].astype(np.int64))
    for k, v in (point_fields or {}).items():
        _add(pd, k, v)
    return grid


def block_corner_nodes(arrays):
    """Node ids (n_blocks, 8) of the block corners in VTK hexahedron order, from the model
    ``arrays`` of a results file (:func:`dr_masonry.model.block_corner_nodes`)."""
    return corner_nodes(arrays["block_node_start"][:-1], arrays["block_divisions"])


def split_fields(fields, locations):
    """Split frame fields by location into dicts (node, element, contact) of VTK-ready arrays
    (one or two dimensions)."""
    out = {"node": {}, "element": {}, "contact": {}}
    for k, v in fields.items():
        if v.ndim in (1, 2):
            out[locations[k]][k] = v
    return out["node"], out["element"], out["contact"]


def _write_vtu(grid, path):
    require_space(path, 1024 * grid.GetActualMemorySize(), "a VTK file",
                  "the results file is complete: free disk space, then `dr-masonry vtk` writes "
                  "the series from it")
    w = vtk.vtkXMLUnstructuredGridWriter()
    w.SetFileName(path)
    w.SetInputData(grid)
    w.SetDataModeToAppended()
    w.EncodeAppendedDataOff()
    if w.Write() != 1:
        raise ResultsError(f"VTK could not write {path}")


def write_pvd(path, entries):
    """Write a ParaView collection ``path`` of (time, file name relative to it) entries."""
    with open(path, "w") as f:
        f.write('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1" '
                'byte_order="LittleEndian">\n  <Collection>\n')
        for t, name in entries:
            f.write(f'    <DataSet timestep="{t:.12g}" group="" part="0" file={quoteattr(name)}/>\n')
        f.write("  </Collection>\n</VTKFile>\n")


def frame_times(result):
    """Time of each frame for the collections: attr "time" if every frame has one, else "control"
    if every frame has one and it increases strictly, else the increment index."""
    attrs = [result.frame_attrs(i) for i in range(result.n_frames)]
    for key in ("time", "control"):
        if attrs and all(key in a for a in attrs):
            t = np.array([float(a[key]) for a in attrs])
            if key == "time" or np.all(np.diff(t) > 0):
                return t
    return np.array(result.frame_ids, dtype=np.float64)


def export_vtk(h5_path, out_dir=None, warp=1.0):
    """Write the VTK time series of a results file.

    Parameters
    ----------
    h5_path : str or Result
        the results file.
    out_dir : str, optional
        output folder (created); default ``<file stem>_vtk`` next to the file.
    warp : float
        displacement scale of the point positions (0: reference configuration).

    Returns
    -------
    str
        path of ``blocks.pvd`` (``contacts.pvd`` is written next to it when the model has
        contacts).
    """
    r = as_result(h5_path)
    if not r.n_frames:
        raise ResultsError(f"results file {r.path!r} has no frames to write as VTK (the run "
                           f"stopped before its first frame; {r.n_history} history rows)")
    if out_dir is None:
        out_dir = os.path.splitext(r.path)[0] + "_vtk"
    make_folder(out_dir)
    arrays = r.model_arrays
    times = frame_times(r)
    blocks, contacts = [], []
    for i, (inc, t) in enumerate(zip(r.frame_ids, times)):
        fields = r.frame(i)
        con = r.contacts(i)
        nodal, elem, cont = split_fields(fields, r.locations(i))
        x = positions(arrays["nodes"], fields, warp)
        name = f"blocks_{inc:06d}.vtu"
        _write_vtu(block_grid(arrays, x, elem, nodal), os.path.join(out_dir, name))
        blocks.append((t, name))
        if con is not None and len(con["slave"]):
            name = f"contacts_{inc:06d}.vtu"
            _write_vtu(contact_grid(con, x, cont), os.path.join(out_dir, name))
            contacts.append((t, name))
    pvd = os.path.join(out_dir, "blocks.pvd")
    write_pvd(pvd, blocks)
    if contacts:
        write_pvd(os.path.join(out_dir, "contacts.pvd"), contacts)
    return pvd

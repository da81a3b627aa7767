"""What a results file holds: its format name and version, the tables of its fields and arrays,
the groups every file has (:data:`REQUIRED`), and the checks of values read back from it.

The layout is documented in ``docs/file_format.md``; :data:`SCHEMA_VERSION` is stored in the file
and checked on reading. Units are SI: displacements and gaps in m, tractions in Pa, forces in N.
"""
from __future__ import annotations

import dataclasses
import json
import os
import subprocess
from importlib import metadata

import numpy as np


#: version of the layout described in docs/file_format.md; bump on any incompatible change
SCHEMA_VERSION = 1

#: value of the root attribute ``format``
FORMAT_NAME = "dr_masonry-result"

LIBVER = ("v108", "v108")

#: standard frame fields: name -> (location, trailing shape, units, description)
STANDARD_FIELDS = {
    "U": ("node", (3,), "m", "nodal displacement"),
    "dt": ("element", (), "1", "maximum block tensile damage over the Gauss points"),
    "dc": ("element", (), "1", "maximum block compressive damage over the Gauss points"),
    "D": ("contact", (), "1", "joint damage"),
    "opening": ("contact", (), "m", "normal gap u (positive opening)"),
    "slip": ("contact", (), "m", "tangential gap magnitude sqrt(d1^2 + d2^2)"),
    "sigma": ("contact", (), "Pa", "normal traction (positive tension)"),
    "tau": ("contact", (), "Pa", "tangential traction magnitude"),
}

#: model arrays written to /model: attribute name on Model -> dtype
MODEL_ARRAYS = {
    "nodes": np.float64, "elements": np.int64, "element_block": np.int64,
    "block_node_start": np.int64, "block_element_start": np.int64,
    "block_divisions": np.int64, "block_corners": np.float64, "block_material": np.int64,
    "block_fixed": np.bool_, "block_joint": np.int64,
}

#: contact-set arrays written to /model/contacts and a frame's contacts: the fields of ContactSet
CONTACT_ARRAYS = {
    "slave": np.int64, "master": np.int64, "xi": np.float64, "area": np.float64,
    "law": np.int64, "blocks": np.int64, "gap0": np.float64,
}

#: groups and datasets every results file has from its creation on (:func:`check_file`)
REQUIRED = ("config", "history", "frames", "model/block_group",
            *(f"model/{name}" for name in MODEL_ARRAYS))

#: rows of one chunk of a history column (the unit in which the file grows as rows are added)
HISTORY_CHUNK = 1024

#: free disk space (bytes) that a write must leave: HDF5's metadata, the space that replaced
#: checkpoints leave in the file, the scene's CSV, plot and VTK written after the run
SPACE_RESERVE = 16 * 2**20

#: frame "position" of the last checkpoint (:meth:`Result.frame`)
CHECKPOINT = "checkpoint"

#: the next checkpoint while it is written; it replaces ``/checkpoint`` once complete
CHECKPOINT_NEW = "checkpoint_new"

#: copies of earlier checkpoints kept for a restart further back, ``/checkpoints/NNNNNN``
KEPT = "checkpoints"


class ResultsError(ValueError):
    """A results file that cannot be written or read as asked; the message says why."""


def code_version():
    """Installed version of dr_masonry ("unknown" when it is not installed), with the git
    revision of the source tree when it runs from a checkout of its own repository (an editable
    install): "0.1.0+g5e9e6a8", "+g5e9e6a8.dirty" with uncommitted changes. A run continued over
    several restarts records each restart's code this way (``/config`` attribute ``restarts``)."""
    try:
        version = metadata.version("dr_masonry")
    except metadata.PackageNotFoundError:
        version = "unknown"
    package = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))   # dr_masonry/
    rev = _git_revision(os.path.dirname(package))
    return f"{version}+g{rev}" if rev else version


def _git_revision(root):
    """Short revision (".dirty" appended with uncommitted changes) of the git work tree whose top
    folder is ``root``; "" when ``root`` is not one (an installed copy, no git)."""
    def git(*args):
        return subprocess.run(["git", "-C", root, *args], capture_output=True, text=True,
                              timeout=10, check=True).stdout.strip()
    try:
        if os.path.realpath(git("rev-parse", "--show-toplevel")) != os.path.realpath(root):
            return ""   # installed inside some other repository
        rev = git("rev-parse", "--short=7", "HEAD")
        return rev + (".dirty" if git("status", "--porcelain", "--untracked-files=no") else "")
    except (OSError, subprocess.SubprocessError):
        return ""


def _describe(obj):
    """JSON-ready description of a material / joint law: type name and its fields."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {"type": type(obj).__name__, "params": dataclasses.asdict(obj)}
    return {"type": type(obj).__name__, "repr": repr(obj)}


def _json(obj):
    return json.dumps(obj, default=lambda o: o.tolist() if hasattr(o, "tolist") else repr(o))


def _frame_name(increment):
    return f"{int(increment):06d}"


def _kept(f):
    """Increments of the checkpoints kept in the open file ``f``, ascending."""
    return sorted(int(k) for k in f[KEPT]) if KEPT in f else []


def require_kept(path, kept, increment):
    """ResultsError unless ``increment`` is among ``kept`` (the kept checkpoints of ``path``)."""
    if increment not in kept:
        raise ResultsError(f"{path} keeps no checkpoint of increment {increment}; it keeps "
                           f"{kept or 'none'} (and the last one, /checkpoint)")


def _last_checkpoint(f):
    """The open file's ``/checkpoint`` group, or a complete ``/checkpoint_new`` (a process killed
    between removing the old one and renaming the new one), or None."""
    if CHECKPOINT in f:
        return f[CHECKPOINT]
    if CHECKPOINT_NEW in f and f[CHECKPOINT_NEW].attrs.get("complete", False):
        return f[CHECKPOINT_NEW]
    return None


def model_arrays(model):
    """The ``/model`` arrays of a Model as a dict, and the block group names.

    Returns
    -------
    arrays : dict of str -> ndarray
        :data:`MODEL_ARRAYS` plus ``block_group`` (n_blocks,) int64 indexing ``names``.
    names : list of str
        block group names in order of first use.
    """
    arrays = {k: np.asarray(getattr(model, k), dtype=t) for k, t in MODEL_ARRAYS.items()}
    names = list(dict.fromkeys(model.block_group))
    arrays["block_group"] = np.array([names.index(g) for g in model.block_group], dtype=np.int64)
    return arrays, names


def _n_rows(history_group):
    """Number of rows of the open file's ``/history`` group."""
    cols = _columns(history_group)
    return int(history_group[cols[0]].shape[0]) if cols else 0


def _columns(history_group):
    """History column names in the order of the first row ([] before the first row)."""
    return json.loads(history_group.attrs.get("columns", "[]"))


def _model_difference(stored, model):
    """What differs between the open file's ``/model`` group ``stored`` and ``model`` of the same
    sizes: node coordinates (beyond 1 nm), connectivity, or a parameter of a material or joint
    law that both versions describe ("" when nothing does)."""
    dx = np.abs(stored["nodes"][()] - model.nodes)
    if dx.size and dx.max() > 1e-9:
        i = int(np.argmax(dx.max(axis=1)))
        return f"node {i} lies {dx.max():.3g} m from where it was"
    if not np.array_equal(stored["elements"][()], model.elements):
        return "the hexahedra's connectivity differs"
    for key, objs in (("materials", model.materials), ("joint_laws", model.joint_laws)):
        old = json.loads(stored.attrs[key])
        new = json.loads(_json([_describe(x) for x in objs]))
        if len(old) != len(new):
            return f"{len(new)} {key} instead of {len(old)}"
        for i, (a, b) in enumerate(zip(old, new)):
            pa, pb = a.get("params", {}), b.get("params", {})
            keys = sorted(k for k in set(pa) & set(pb) if not k.startswith("_") and pa[k] != pb[k])
            if a["type"] != b["type"] or keys:
                return (f"{key[:-1].replace('_', ' ')} {i} differs"
                        + (f" in {', '.join(f'{k} {pa[k]!r} -> {pb[k]!r}' for k in keys)}"
                           if keys else f": {a['type']} -> {b['type']}"))
    return ""


def _model_sizes(model):
    nc = 0 if model.contacts is None else int(np.asarray(model.contacts.slave).shape[0])
    return {"node": int(model.n_nodes), "element": int(model.n_elements), "contact": nc}


def _check_field(name, value, sizes):
    """Validate a frame field; returns (array, location)."""
    arr = np.asarray(value)
    if arr.ndim == 0:
        raise ResultsError(f"write_frame: field {name!r} is a scalar; store scalars in attrs")
    if name in STANDARD_FIELDS:
        loc, trail, _, _ = STANDARD_FIELDS[name]
        want = (sizes[loc],) + trail
        if arr.shape != want:
            raise ResultsError(f"write_frame: field {name!r} must have shape {want} "
                               f"(n_{loc}s = {sizes[loc]}), got {arr.shape}")
        return arr.astype(np.float64, copy=False), loc
    for loc in ("node", "element", "contact"):
        if arr.shape[0] == sizes[loc]:
            return arr, loc
    raise ResultsError(f"write_frame: field {name!r} has leading dimension {arr.shape[0]}, not "
                       f"n_nodes={sizes['node']}, n_elements={sizes['element']} or "
                       f"n_contacts={sizes['contact']}")


def state_fields(U, s_blocks, s_joints):
    """Frame fields of a committed state: ``U`` (n_nodes, 3) m, the largest block damage over
    the Gauss points ``dt``, ``dc`` (n_elements,) of ``s_blocks`` (n_elements, 8, NMS) and, with
    contacts, the joint damage ``D`` and largest slip ``slip_max`` (n_contacts,) m of ``s_joints``
    (n_contacts, NJS). The solver's frames add the gaps and tractions of the current trial."""
    from ..kernels.joint_law import JS_D, JS_DMAX
    from ..kernels.plastic_damage import MS_DC, MS_DT
    f = {"U": U.copy(), "dt": s_blocks[:, :, MS_DT].max(axis=1),
         "dc": s_blocks[:, :, MS_DC].max(axis=1)}
    if s_joints.shape[0]:
        f.update(D=s_joints[:, JS_D].copy(), slip_max=s_joints[:, JS_DMAX].copy())
    return f


def check_stored(path, name, value, shape=None, bound=None):
    """Raise :class:`ResultsError` naming the checkpoint of ``path`` and the array ``name``
    unless ``value`` is there, has ``shape`` (when given), finite values and, with ``bound``,
    ids in [0, bound)."""
    damaged = f"checkpoint of {path} is damaged"
    if value is None:
        raise ResultsError(f"{damaged}: it lacks {name}")
    v = np.asarray(value)
    if shape is not None and v.shape != shape:
        raise ResultsError(f"{damaged}: {name} has shape {v.shape}, not {shape}")
    if v.dtype.kind == "f" and not np.isfinite(v).all():
        raise ResultsError(f"{damaged}: {name} holds {np.count_nonzero(~np.isfinite(v))} "
                           "non-finite values")
    if bound is not None and v.size and (v.min() < 0 or v.max() >= bound):
        raise ResultsError(f"{damaged}: {name}: indices outside [0, {bound})")


def ends_run(position):
    """Whether a checkpoint's stage position ``(stage, increments done, start values, stages,
    increments of the stage)`` (None in older files) is the end of its run."""
    return bool(position) and position[0] == position[3] - 1 and position[1] == position[4]

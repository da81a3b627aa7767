"""The HDF5 results file: write (append + flush), read, restart.

The schema is documented in ``docs/file_format.md``; :data:`SCHEMA_VERSION` is stored in the file
and checked on reading. Every write is followed by a flush, so a run that is killed leaves a file
that opens and holds every row and frame written before the kill; a Ctrl-C or SIGTERM waits
until the write under way is complete (:func:`dr_masonry.interrupts.uninterrupted`), and a new
checkpoint replaces the old one only once it is complete. A write that the disk could not hold
is refused before it starts (:func:`free_bytes`, :data:`SPACE_RESERVE`): HDF5 cannot undo a
write that fails midway, and the file might not open again. The file is written with the
HDF5 1.8 format (``libver=("v108", "v108")``): the 1.10+ format marks a file "open for write" in its
superblock and refuses to open it after a crash without ``h5clear``.

Units are SI: displacements and gaps in m, tractions in Pa, forces in N.
"""
from __future__ import annotations

import dataclasses
import json
import os
import shutil
import subprocess
import time
import warnings
from importlib import metadata

import h5py
import numpy as np

from .interrupts import uninterrupted
from .model import size_summary

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


def free_bytes(path):
    """Free bytes on the file system of file ``path`` (its folder's)."""
    return shutil.disk_usage(os.path.dirname(os.path.abspath(path))).free


def require_space(path, nbytes, what, then):
    """Raise :class:`ResultsError` before writing ``what`` (about ``nbytes`` bytes) to file
    ``path`` when its disk would keep less than :data:`SPACE_RESERVE` free; ``then`` says what
    the user can do."""
    free = free_bytes(path)
    if free < nbytes + SPACE_RESERVE:
        raise ResultsError(f"{path}: {free / 2**20:.1f} MiB free on its disk; writing {what} "
                           f"({nbytes / 2**20:.1f} MiB) would leave less than the "
                           f"{SPACE_RESERVE / 2**20:.0f} MiB kept free, so it was not started (a "
                           f"write that fails midway can leave a file that does not open); {then}")


def code_version():
    """Installed version of dr_masonry ("unknown" when it is not installed), with the git
    revision of the source tree when it runs from a checkout of its own repository (an editable
    install): "0.1.0+g5e9e6a8", "+g5e9e6a8.dirty" with uncommitted changes. A run continued over
    several sessions records each restart's code this way (``/config`` attribute ``restarts``)."""
    try:
        version = metadata.version("dr_masonry")
    except metadata.PackageNotFoundError:
        version = "unknown"
    rev = _git_revision(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
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


class ResultWriter:
    """Writer of one results file.

    Parameters
    ----------
    path : str or os.PathLike
        the ``.h5`` file.
    model : Model or None
        the model; written to ``/model`` in mode ``"w"``. In mode ``"a"`` it may be None, else its
        sizes must match the file's.
    config : dict
        the full input configuration (JSON-serialisable; other values are stored as ``repr``).
        In mode ``"a"`` it is appended to ``/config`` attribute ``restarts``.
    mode : {"w", "a"}
        ``"w"`` creates (truncates) the file; ``"a"`` opens an existing one to continue its history
        and frames (restart).
    """

    def __init__(self, path, model, config, mode="w"):
        self.path = os.fspath(path)
        self._restart = mode == "a"
        if mode == "w":
            if model is None:
                raise ResultsError("ResultWriter: mode 'w' needs a model, got None")
            if os.path.isfile(self.path) and not h5py.is_hdf5(self.path):
                raise ResultsError(f"results file {self.path!r} exists and is not an HDF5 file: "
                                   f"not overwritten (give another output path, or remove it)")
            arrays = model_arrays(model)
            self._require_space(_nbytes(arrays[0].values()), "the model")
            try:
                self._f = h5py.File(self.path, "w", libver=LIBVER)
            except OSError as e:
                raise ResultsError(f"cannot create results file {self.path!r}: "
                                   f"{_open_error(e)}") from None
            try:
                self._create(model, config, arrays)
            except BaseException:
                self._f.close()
                raise
        elif mode == "a":
            check_file(self.path)
            try:
                self._f = h5py.File(self.path, "a", libver=LIBVER)
            except OSError as e:
                raise ResultsError(f"cannot continue results file {self.path!r}: "
                                   f"{_open_error(e)}") from None
            if (CHECKPOINT not in self._f and CHECKPOINT_NEW in self._f
                    and self._f[CHECKPOINT_NEW].attrs.get("complete", False)):
                self._f.move(CHECKPOINT_NEW, CHECKPOINT)   # killed between removal and rename
            self._sizes = json.loads(self._f["model"].attrs["sizes"])
            if model is not None:
                got = _model_sizes(model)
                differs = (f"model sizes {got} do not match file {self.path} sizes {self._sizes}"
                           if got != self._sizes else _model_difference(self._f["model"], model))
                if differs:
                    self._f.close()
                    raise ResultsError(f"ResultWriter: {differs} (not the model the file was run "
                                       f"with)")
            cfg = self._f["config"]
            restarts = json.loads(cfg.attrs.get("restarts", "[]"))
            restarts.append({"time": time.strftime("%Y-%m-%dT%H:%M:%S"), "code_version": code_version(),
                             "config": json.loads(_json(config))})
            cfg.attrs["restarts"] = _json(restarts)
        else:
            raise ResultsError(f"ResultWriter: mode must be 'w' or 'a', got {mode!r}")
        self.flush()

    # ------------------------------------------------------------------ creation
    def _create(self, model, config, model_data):
        f = self._f
        f.attrs["format"] = FORMAT_NAME
        f.attrs["created"] = time.strftime("%Y-%m-%dT%H:%M:%S")
        cfg = f.create_group("config")
        cfg.attrs["json"] = _json(config)
        cfg.attrs["code_version"] = code_version()
        cfg.attrs["schema_version"] = SCHEMA_VERSION
        m = f.create_group("model")
        arrays, names = model_data
        for name, arr in arrays.items():
            m.create_dataset(name, data=arr)
        m.attrs["group_names"] = _json(names)
        m.attrs["materials"] = _json([_describe(x) for x in model.materials])
        m.attrs["joint_laws"] = _json([_describe(x) for x in model.joint_laws])
        m.attrs["default_joint"] = int(model.default_joint)
        if model.contacts is not None:
            _write_contacts(m.create_group("contacts"), model.contacts)
        self._sizes = _model_sizes(model)
        m.attrs["sizes"] = _json(self._sizes)
        f.create_group("history")
        f.create_group("frames")

    # ------------------------------------------------------------------ writing
    @uninterrupted()
    def append_history(self, row):
        """Append one row ``{key: float}`` to ``/history`` (keys fixed by the first row; a
        restart (mode ``"a"``) may add columns, NaN in the rows before it)."""
        h = self._f["history"]
        cols = _columns(h)
        if not cols:
            if not row:
                raise ResultsError("append_history: the first row is empty")
            bad = [k for k in row if not isinstance(k, str) or not k or "/" in k or k == "."]
            if bad:
                raise ResultsError(f"append_history: invalid column names {bad}")
            for k in row:
                h.create_dataset(k, shape=(0,), maxshape=(None,), dtype=np.float64,
                                 chunks=(HISTORY_CHUNK,))
            cols = list(row)
            h.attrs["columns"] = _json(cols)
        elif set(row) != set(cols):
            missing = sorted(set(cols) - set(row))
            extra = sorted(set(row) - set(cols))
            if missing or not self._restart:
                raise ResultsError(f"append_history: row keys differ from the file's columns "
                                   f"(missing {missing}, unknown {extra}); columns are {cols}")
            # a restart by a newer version may add columns: NaN in the rows written before
            n = h[cols[0]].shape[0]
            for k in extra:
                h.create_dataset(k, data=np.full(n, np.nan), maxshape=(None,),
                                 chunks=(HISTORY_CHUNK,))
            cols = cols + extra
            h.attrs["columns"] = _json(cols)
        values = {}
        for k in cols:
            try:
                values[k] = float(row[k])
            except (TypeError, ValueError):
                raise ResultsError(f"append_history: column {k!r} value {row[k]!r} is not a number") \
                    from None
        n = h[cols[0]].shape[0]
        if n % HISTORY_CHUNK == 0:   # a new chunk for every column
            self._require_space(8 * HISTORY_CHUNK * len(cols), f"history row {n + 1}")
        for k, v in values.items():
            h[k].resize((n + 1,))
            h[k][n] = v
        self.flush()

    @property
    def n_history(self):
        """Number of history rows written."""
        return _n_rows(self._f["history"])

    @property
    def frame_ids(self):
        """Increments of the frames written, ascending."""
        return sorted(int(k) for k in self._f["frames"])

    @uninterrupted()
    def write_frame(self, increment, fields, attrs=None, contacts=None):
        """Write the frame of load increment ``increment`` (int >= 0).

        Parameters
        ----------
        fields : dict of str -> ndarray
            standard names (:data:`STANDARD_FIELDS`) must have their standard shape; other names
            need a leading dimension of n_nodes, n_elements or n_contacts.
        attrs : dict, optional
            scalar attributes of the frame, e.g. ``time``, ``control`` (the load factor or
            controlled displacement).
        contacts : ContactSet, optional
            the contact set of this frame when it differs from ``/model/contacts`` (re-detection);
            contact fields are then sized by it.
        """
        inc = int(increment)
        if inc < 0:
            raise ResultsError(f"write_frame: increment must be >= 0, got {increment}")
        frames = self._f["frames"]
        name = _frame_name(inc)
        if name in frames:
            raise ResultsError(f"write_frame: frame {inc} already exists in {self.path}")
        sizes = dict(self._sizes)
        if contacts is not None:
            missing = [k for k in CONTACT_ARRAYS if not hasattr(contacts, k)]
            if missing:
                raise ResultsError(f"write_frame: contacts of frame {inc} lack {', '.join(missing)}"
                                   " (pass a ContactSet)")
            sizes["contact"] = int(np.asarray(contacts.slave).shape[0])
        checked = {k: _check_field(k, v, sizes) for k, v in fields.items()}
        self._require_space(_nbytes(a for a, _ in checked.values()) + (
            0 if contacts is None else _nbytes(getattr(contacts, k) for k in CONTACT_ARRAYS)),
            f"frame {inc}")
        g = frames.create_group(name)
        g.attrs["increment"] = inc
        g.attrs["history_rows"] = self.n_history
        for k, v in (attrs or {}).items():
            g.attrs[k] = v
        if contacts is not None:
            _write_contacts(g.create_group("contacts"), contacts)
        for k, (arr, loc) in checked.items():
            d = g.create_dataset(k, data=arr)
            d.attrs["location"] = loc
            if k in STANDARD_FIELDS:
                d.attrs["units"] = STANDARD_FIELDS[k][2]
        self.flush()

    @uninterrupted()
    def truncate(self, increment, rows):
        """Drop the frames after ``increment`` and the history rows after the first ``rows``.

        Used on restart from the checkpoint written after ``increment`` (``rows``: the history
        length then; the checkpoint need not coincide with a frame) so that the continued run
        does not duplicate rows.
        """
        truncate_file(self._f, increment, rows)
        self.flush()

    @uninterrupted()
    def write_checkpoint(self, increment, arrays, meta, keep=False):
        """Replace ``/checkpoint`` by the solver state after ``increment`` (restart data).

        ``arrays``: name -> ndarray (any shape); ``meta``: JSON-serialisable dict; ``keep``: also
        keep a copy as ``/checkpoints/NNNNNN`` (a restart from there: :meth:`rewind`).
        """
        f = self._f
        meta_json = _json(meta)
        self._require_space((2 if keep else 1) * (_nbytes(arrays.values()) + len(meta_json)),
                            f"the checkpoint of increment {increment}")
        if CHECKPOINT_NEW in f:   # left by a process killed while writing it
            del f[CHECKPOINT_NEW]
        g = f.create_group(CHECKPOINT_NEW)
        g.attrs["increment"] = int(increment)
        g.attrs["history_rows"] = self.n_history
        g.attrs["meta"] = meta_json
        for name, arr in arrays.items():
            g.create_dataset(name, data=np.asarray(arr))
        g.attrs["complete"] = True
        self._install_new()
        if keep:
            name = f"{KEPT}/{_frame_name(increment)}"
            if name in f:
                del f[name]
            f.copy(f[CHECKPOINT], name)
        self.flush()

    @uninterrupted()
    def rewind(self, increment):
        """Make the kept checkpoint of ``increment`` the file's checkpoint and drop the kept ones
        after it (a restart from there: :meth:`Simulation.resume` with ``increment``; the rows
        and frames after it go with :meth:`truncate`)."""
        f = self._f
        kept = _kept(f)
        require_kept(self.path, kept, increment)
        for k in kept:
            if k > increment:
                del f[f"{KEPT}/{_frame_name(k)}"]
        if CHECKPOINT_NEW in f:
            del f[CHECKPOINT_NEW]
        f.copy(f[f"{KEPT}/{_frame_name(increment)}"], CHECKPOINT_NEW)
        self._install_new()
        self.flush()

    def _require_space(self, nbytes, what):
        require_space(self.path, nbytes, what,
                      "the file holds every row and frame written before it: free disk space, "
                      "then resume=true continues it")

    def _install_new(self):
        """Replace ``/checkpoint`` by the complete ``/checkpoint_new`` (flushed first, so that a
        kill in between leaves one of them complete on disk)."""
        f = self._f
        self.flush()
        if CHECKPOINT in f:
            del f[CHECKPOINT]
        f.move(CHECKPOINT_NEW, CHECKPOINT)

    def flush(self):
        """Write everything to disk."""
        self._f.flush()

    def close(self):
        """Close the file (everything written is flushed); closing twice does nothing."""
        if self._f.id.valid:
            self._f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def pack(src, dst, frames=()):
    """Write a compressed copy of results file ``src`` to ``dst`` that a run can continue from.

    The copy holds ``/config``, ``/model``, ``/history`` and the last checkpoint, every dataset
    compressed (gzip with byte shuffling; the history columns stay resizable), and of the frames
    only those of the increments in ``frames`` (``"all"``: every one); the checkpoints kept for a
    restart further back are left out. ``resume=true`` with ``out`` naming the copy continues the
    run from it as from ``src``: the way a run longer than one machine's session is carried to
    the next machine (``docs/file_format.md``, "Packed copies"). ``dst`` is written to
    ``dst + ".part"`` and renamed when complete. Returns (bytes of ``src``, bytes of ``dst``).
    """
    src, dst = os.fspath(src), os.fspath(dst)
    check_file(src)
    if os.path.abspath(src) == os.path.abspath(dst):
        raise ResultsError(f"pack: {src} would be written over itself; give another output file")
    part = dst + ".part"
    with _reading(src) as f:
        ck = _last_checkpoint(f)
        if ck is None:
            raise ResultsError(f"pack: {src} has no checkpoint, so no run could continue from a "
                               f"copy (a frame or a checkpoint_s interval writes one)")
        ids = sorted(int(k) for k in f["frames"])
        keep = ids if frames == "all" else sorted({int(i) for i in frames})
        missing = sorted(set(keep) - set(ids))
        if missing:
            raise ResultsError(f"pack: {src} has no frame of increment(s) {missing}; its frames "
                               f"are of increments {ids or 'none'}")
        require_space(part, os.path.getsize(src), "the packed copy", "free disk space")
        try:
            with h5py.File(part, "w", libver=LIBVER) as g:
                _copy_attrs(f, g)
                for name in ("config", "model", "history"):
                    _copy_packed(f[name], g.create_group(name))
                frames_out = g.create_group("frames")
                _copy_attrs(f["frames"], frames_out)
                for i in keep:
                    _copy_packed(f["frames"][_frame_name(i)],
                                 frames_out.create_group(_frame_name(i)))
                _copy_packed(ck, g.create_group(CHECKPOINT))
        except BaseException:
            if os.path.exists(part):
                os.remove(part)
            raise
    os.replace(part, dst)
    return os.path.getsize(src), os.path.getsize(dst)


def _last_checkpoint(f):
    """The open file's ``/checkpoint`` group, or a complete ``/checkpoint_new`` (a process killed
    between removing the old one and renaming the new one), or None."""
    if CHECKPOINT in f:
        return f[CHECKPOINT]
    if CHECKPOINT_NEW in f and f[CHECKPOINT_NEW].attrs.get("complete", False):
        return f[CHECKPOINT_NEW]
    return None


def _copy_attrs(a, b):
    for k, v in a.attrs.items():
        b.attrs[k] = v


def _copy_packed(a, b):
    """Copy the open group ``a`` into the empty group ``b``: attributes, subgroups, and datasets
    gzip-compressed with shuffling (a resizable dataset keeps its chunks and maximum shape)."""
    _copy_attrs(a, b)
    for k, item in a.items():
        if isinstance(item, h5py.Group):
            _copy_packed(item, b.create_group(k))
            continue
        opts = {}
        if item.maxshape != item.shape:
            opts = dict(chunks=item.chunks, maxshape=item.maxshape)
        if item.size:
            opts.update(compression="gzip", compression_opts=4, shuffle=True)
        d = b.create_dataset(k, data=item[()], dtype=item.dtype, **opts)
        _copy_attrs(item, d)


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


def truncate_file(f, increment, rows):
    """Drop, in the open result file ``f`` (h5py, writable), the frames after ``increment`` and
    the history rows after the first ``rows``."""
    h = f["history"]
    n = _n_rows(h)
    if not 0 <= rows <= n:
        raise ResultsError(f"truncate: {f.filename} has {n} history rows, cannot keep {rows}")
    frames = f["frames"]
    for k in list(frames):
        if int(k) > int(increment):
            del frames[k]
    for k in _columns(h):
        h[k].resize((rows,))


def _nbytes(arrays):
    """Bytes of the arrays (or array-likes) of iterable ``arrays``."""
    return sum(np.asarray(a).nbytes for a in arrays)


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


def _write_contacts(g, contacts):
    for name, dtype in CONTACT_ARRAYS.items():
        g.create_dataset(name, data=np.asarray(getattr(contacts, name), dtype=dtype))


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
    from .kernels.joint_law import JS_D, JS_DMAX
    from .kernels.plastic_damage import MS_DC, MS_DT
    f = {"U": U.copy(), "dt": s_blocks[:, :, MS_DT].max(axis=1),
         "dc": s_blocks[:, :, MS_DC].max(axis=1)}
    if s_joints.shape[0]:
        f.update(D=s_joints[:, JS_D].copy(), slip_max=s_joints[:, JS_DMAX].copy())
    return f


# ---------------------------------------------------------------------- reading
def make_folder(path):
    """Create the output folder ``path`` (and its parents) unless it exists; returns ``path``.
    Raises :class:`ResultsError` naming the folder when it cannot be made (a file of that name,
    no permission)."""
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as e:
        raise ResultsError(f"cannot create the output folder {path!r}: {e.strerror or e}") from None
    return path


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


def _locked(e):
    """Whether an OSError of ``h5py.File`` is HDF5's refusal of a file another process holds."""
    return "unable to lock file" in str(e)


def _open_error(e):
    """What an OSError of ``h5py.File`` means for the user."""
    if _locked(e):
        return "another process has it open (a run still writing it?)"
    return e.strerror or str(e)


#: files read without HDF5's lock in this process (warned once each)
_UNLOCKED = set()


def _reading(path):
    """``h5py.File`` of ``path`` for reading. A file that a running process holds open for
    writing (HDF5's lock: a run still going) is read without the lock, with a warning once: the
    writer flushes after every row, frame and checkpoint, so its file reads as of its last write,
    but a read during a write may miss it or fail."""
    try:
        return h5py.File(path, "r")
    except OSError as e:
        if not _locked(e):
            raise
    if path not in _UNLOCKED:
        _UNLOCKED.add(path)
        warnings.warn(f"results file {path!r} is open for writing in another process (a run "
                      f"still going?): read without HDF5's lock, as of the last row written",
                      RuntimeWarning, stacklevel=3)
    return h5py.File(path, "r", locking=False)


def check_file(path):
    """Raise :class:`ResultsError` unless ``path`` is a dr_masonry results file of this schema."""
    if not isinstance(path, (str, os.PathLike)):
        raise ResultsError(f"a results file must be given as a path, got {path!r}")
    path = os.fspath(path)
    if os.path.isdir(path):
        raise ResultsError(f"results file {path!r} is a directory")
    if not os.path.isfile(path):
        raise ResultsError(f"results file {path!r} does not exist")
    try:
        with _reading(path) as f:
            fmt = f.attrs.get("format")
            ver = f["config"].attrs.get("schema_version") if "config" in f else None
            missing = [name for name in REQUIRED if name not in f]
    except OSError as e:
        raise ResultsError(f"results file {path!r} cannot be opened as HDF5: {e}") from None
    if fmt != FORMAT_NAME or ver is None:
        raise ResultsError(f"{path!r} is not a dr_masonry results file (format attribute {fmt!r})")
    if int(ver) != SCHEMA_VERSION:
        raise ResultsError(f"{path!r} has schema version {int(ver)}, this code reads version "
                           f"{SCHEMA_VERSION}")
    if missing:
        raise ResultsError(f"results file {path!r} is damaged: it lacks {', '.join(missing)}")


class Result:
    """A results file opened for reading (see :func:`open_result`).

    Attributes
    ----------
    path : str
    model_arrays : dict of str -> ndarray
        the ``/model`` datasets (and ``contacts`` -> dict of contact arrays, or None).
    group_names : list of str
        block group names; ``model_arrays["block_group"]`` indexes them.
    materials, joint_laws : list of dict
        descriptions of the block materials and joint laws.
    config : dict
        the input configuration of the run.
    attrs : dict
        ``code_version``, ``schema_version``, ``created``, ``restarts``.
    history : dict of str -> (n_rows,) float64
    frame_ids : list of int
        the increments of the frames, ascending.
    """

    def __init__(self, path):
        check_file(path)
        self.path = os.fspath(path)
        with _reading(self.path) as f:
            m = f["model"]
            self.model_arrays = {k: m[k][()] for k in m if isinstance(m[k], h5py.Dataset)}
            self.model_arrays["contacts"] = (
                {k: v[()] for k, v in m["contacts"].items()} if "contacts" in m else None)
            a = self.model_arrays
            nn = a["nodes"].shape[0]
            if not np.all(np.isfinite(a["nodes"])) or a["elements"].size and (
                    a["elements"].min() < 0 or a["elements"].max() >= nn):
                raise ResultsError(f"results file {self.path!r} is damaged: model/nodes not "
                                   f"finite or model/elements outside [0, {nn})")
            self.group_names = json.loads(m.attrs["group_names"])
            self.materials = json.loads(m.attrs["materials"])
            self.joint_laws = json.loads(m.attrs["joint_laws"])
            self.sizes = json.loads(m.attrs["sizes"])
            c = f["config"]
            self.config = json.loads(c.attrs["json"])
            self.attrs = {"code_version": str(c.attrs["code_version"]),
                          "schema_version": int(c.attrs["schema_version"]),
                          "created": str(f.attrs.get("created", "")),
                          "restarts": json.loads(c.attrs.get("restarts", "[]"))}
            h = f["history"]
            self.history = {k: h[k][()] for k in _columns(h)}
            self.frame_ids = sorted(int(k) for k in f["frames"])

    @property
    def n_frames(self):
        """Number of frames (saved states) in the file."""
        return len(self.frame_ids)

    @property
    def kept_checkpoints(self):
        """Increments of the checkpoints kept for a restart further back (``/checkpoints``)."""
        with _reading(self.path) as f:
            return _kept(f)

    @property
    def n_history(self):
        """Number of history rows (0 for a file without history)."""
        return len(next(iter(self.history.values()))) if self.history else 0

    @property
    def groups(self):
        """Block group name -> block ids."""
        bg = self.model_arrays["block_group"]
        return {n: np.flatnonzero(bg == i) for i, n in enumerate(self.group_names)}

    def _frame_group(self, f, i):
        try:
            inc = self.frame_ids[i]
        except (IndexError, TypeError):
            raise ResultsError(f"frame index {i!r} out of range: {self.path} has "
                               f"{self.n_frames} frames") from None
        return f["frames"][_frame_name(inc)]

    def _checkpoint_group(self, f):
        """The open file's ``/checkpoint`` group (or a complete ``/checkpoint_new``: a process
        killed between removing the old one and renaming the new one); ResultsError if none."""
        ck = _last_checkpoint(f)
        if ck is not None:
            return ck
        raise ResultsError(f"{self.path} has no checkpoint (written with every frame)")

    @property
    def complete(self):
        """Whether the stored run ended its last stage: its last checkpoint's stage position
        (:func:`ends_run`) is the last increment of the last stage."""
        with _reading(self.path) as f:
            if CHECKPOINT not in f and CHECKPOINT_NEW not in f:
                return False
            return ends_run(self._meta(self._checkpoint_group(f)).get("stage"))

    def checkpoint(self):
        """(increment, arrays dict, meta dict) of the last checkpoint; ResultsError if none."""
        with _reading(self.path) as f:
            g = self._checkpoint_group(f)
            arrays = {}
            g.visititems(lambda k, v: arrays.__setitem__(k, v[()])
                         if isinstance(v, h5py.Dataset) else None)
            return int(g.attrs["increment"]), arrays, self._meta(g)

    def _meta(self, g):
        """The JSON attribute ``meta`` of checkpoint group ``g``; ResultsError if damaged."""
        try:
            meta = json.loads(g.attrs["meta"])
            if isinstance(meta, dict):
                return meta
        except (KeyError, ValueError):
            pass
        raise ResultsError(f"checkpoint of {self.path} is damaged: its attribute meta is missing "
                           "or not a JSON object")

    def frame(self, i):
        """Fields of frame ``i`` (position in :attr:`frame_ids`, negative counts from the end), or
        of the last checkpoint (``i = "checkpoint"``: a run stopped between frames; the fields
        the checkpoint holds, ``U``, ``dt``, ``dc``, ``D``, ``slip_max``)."""
        if i == CHECKPOINT:
            return self._checkpoint_fields()
        with _reading(self.path) as f:
            g = self._frame_group(f, i)
            fields = {k: v[()] for k, v in g.items() if isinstance(v, h5py.Dataset)}
        bad = [k for k, v in fields.items() if v.dtype.kind == "f" and not np.all(np.isfinite(v))]
        if bad:
            raise ResultsError(f"results file {self.path!r} is damaged: frame {i} field "
                               f"{bad[0]} holds non-finite values")
        return fields

    def frame_increment(self, i):
        """Increment of frame ``i`` (or of the last checkpoint: ``i = "checkpoint"``)."""
        with _reading(self.path) as f:
            g = self._checkpoint_group(f) if i == CHECKPOINT else self._frame_group(f, i)
            return int(g.attrs["increment"])

    def _checkpoint_fields(self):
        with _reading(self.path) as f:
            g = self._checkpoint_group(f)
            return state_fields(g["U"][()], g["s_blocks"][()], g["s_joints"][()])

    def locations(self, i):
        """Location ("node", "element" or "contact") of each field of frame ``i``."""
        if i == CHECKPOINT:
            return {"U": "node", "dt": "element", "dc": "element", "D": "contact",
                    "slip_max": "contact"}
        with _reading(self.path) as f:
            g = self._frame_group(f, i)
            return {k: str(v.attrs["location"]) for k, v in g.items()
                    if isinstance(v, h5py.Dataset)}

    def frame_attrs(self, i):
        """Attributes of frame ``i`` (``increment``, ``history_rows``, ``time``, ...)."""
        with _reading(self.path) as f:
            return {k: (v.item() if hasattr(v, "item") else v)
                    for k, v in self._frame_group(f, i).attrs.items()}

    def contacts(self, i=None):
        """Contact arrays valid at frame ``i`` (the frame's own set if it has one; ``i =
        "checkpoint"``: the checkpoint's), or None."""
        if i == CHECKPOINT:
            with _reading(self.path) as f:
                g = self._checkpoint_group(f)
                a = {k: v[()] for k, v in g["contacts"].items()} if "contacts" in g else {}
            base = self.model_arrays["contacts"]
            if base is None or "master" not in a or not np.asarray(a["master"]).size:
                return base
            return dict(base, **{k: a[k] for k in CONTACT_ARRAYS if k in a})
        if i is not None:
            with _reading(self.path) as f:
                g = self._frame_group(f, i)
                if "contacts" in g:
                    return {k: v[()] for k, v in g["contacts"].items()}
        return self.model_arrays["contacts"]

    def rows_above_tol(self):
        """(tol, rows): the run's solver tolerance and the (k,) history rows whose residual
        ratio is above it, i.e. accepted at a residual floor (``SolverOptions.floor_tol``);
        (None, None) where the file records no tolerance or no residual column."""
        tol = (self.config.get("solver") or {}).get("tol", self.config.get("tol"))
        res = self.history.get("residual")
        if tol is None or res is None:
            return None, None
        return tol, np.flatnonzero(above_tol(res, tol))

    def summary(self):
        """One-line description of the model size."""
        c = self.model_arrays["contacts"]
        nc = 0 if c is None else len(c["slave"])
        nb = len(self.model_arrays["block_divisions"])
        return size_summary(nb, self.sizes["element"], self.sizes["node"], nc)


def above_tol(residual, tol):
    """Bool mask of the history rows whose residual ratio ``residual`` (k,) is above the solver
    tolerance ``tol`` (beyond round-off): the rows accepted at a residual floor."""
    return np.asarray(residual) > tol * (1.0 + 1e-9)


def open_result(path):
    """Open a results file for reading; raises :class:`ResultsError` if it is missing or foreign."""
    return Result(path)

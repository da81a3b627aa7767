"""Writing a results file: :class:`ResultWriter` (history rows, frames, checkpoints, restart),
and the free-space check made before every write.

Every write is followed by a flush, so a run that is killed leaves a file that opens and holds
every row and frame written before the kill; a Ctrl-C or SIGTERM waits until the write under way
is complete (:func:`dr_masonry.interrupts.uninterrupted`), and a new checkpoint replaces the old
one only once it is complete. A write that the disk could not hold is refused before it starts
(:func:`free_bytes`, :data:`~dr_masonry.results.schema.SPACE_RESERVE`): HDF5 cannot undo a write
that fails midway, and the file might not open again. The file is written with the HDF5 1.8
format (``libver=("v108", "v108")``): the 1.10+ format marks a file "open for write" in its
superblock and refuses to open it after a crash without ``h5clear``.
"""
from __future__ import annotations

import json
import os
import shutil
import time

import h5py
import numpy as np

from ..interrupts import uninterrupted
from .reader import _open_error, check_file
from .schema import (CHECKPOINT, CHECKPOINT_NEW, CONTACT_ARRAYS, FORMAT_NAME, HISTORY_CHUNK, KEPT,
                     LIBVER, SCHEMA_VERSION, SPACE_RESERVE, STANDARD_FIELDS, ResultsError,
                     _check_field, _columns, _describe, _frame_name, _json, _kept,
                     _model_difference, _model_sizes, _n_rows, code_version, model_arrays,
                     require_kept)


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


def _write_contacts(g, contacts):
    for name, dtype in CONTACT_ARRAYS.items():
        g.create_dataset(name, data=np.asarray(getattr(contacts, name), dtype=dtype))


def make_folder(path):
    """Create the output folder ``path`` (and its parents) unless it exists; returns ``path``.
    Raises :class:`ResultsError` naming the folder when it cannot be made (a file of that name,
    no permission)."""
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as e:
        raise ResultsError(f"cannot create the output folder {path!r}: {e.strerror or e}") from None
    return path

"""Reading a results file: :func:`open_result` and its :class:`Result`, :func:`check_file`, and
:func:`above_tol` (the history rows accepted at a residual floor).

A file that a running process holds open for writing is read without HDF5's lock, with a warning
(:func:`_reading`).
"""
from __future__ import annotations

import json
import os
import warnings

import h5py
import numpy as np

from ..model import size_summary
from .schema import (CHECKPOINT, CHECKPOINT_NEW, CONTACT_ARRAYS, FORMAT_NAME, REQUIRED,
                     SCHEMA_VERSION, ResultsError, _columns, _frame_name, _kept, _last_checkpoint,
                     ends_run, state_fields)


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

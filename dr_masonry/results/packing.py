"""Packed copies of a results file (:func:`pack`): compressed, with the last checkpoint, so that
a run can continue from them.

The module is named ``packing`` rather than ``pack`` so that ``dr_masonry.results.pack`` stays the
function, not this module.
"""
from __future__ import annotations

import os

import h5py

from .reader import _reading, check_file
from .schema import CHECKPOINT, LIBVER, ResultsError, _frame_name, _last_checkpoint
from .writer import require_space


def pack(src, dst, frames=()):
    """Write a compressed copy of results file ``src`` to ``dst`` that a run can continue from.

    The copy holds ``/config``, ``/model``, ``/history`` and the last checkpoint, every dataset
    compressed (gzip with byte shuffling; the history columns stay resizable), and of the frames
    only those of the increments in ``frames`` (``"all"``: every one); the checkpoints kept for a
    restart further back are left out. ``resume=true`` with ``out`` naming the copy continues the
    run from it as from ``src``: the way a run longer than one machine allows is carried to
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

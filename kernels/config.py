"""Numba flags in one place: every kernel is compiled with ``jit`` or ``pjit`` from here.

Caching: a kernel that calls kernels of other files carries their compiled code in its own cache
entry, and Numba checks only the caller's file. The kernels' entries are therefore stamped with a
hash of every file of this package (:class:`_Stamped`): editing any kernel recompiles all
of them instead of running stale code.
"""
import glob
import hashlib
import os

# Threads spin-wait with the OpenMP layer on a loaded machine (PERFORMANCE_NOTES.md): be passive.
# The only place that sets it: every entry point imports this module (through dr_masonry) before
# Numba starts its thread pool, and the environment still wins (docs/internals.md, "Decisions").
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numba  # noqa: E402
from numba.core import caching  # noqa: E402

FASTMATH = False  # keep IEEE semantics: NaN detection by the guards must work

_HERE = os.path.dirname(os.path.abspath(__file__))


def _sources_stamp():
    """sha1 of the concatenated sources of this package's ``*.py`` files (hex string)."""
    sha = hashlib.sha1()
    for path in sorted(glob.glob(os.path.join(_HERE, "*.py"))):
        with open(path, "rb") as f:
            sha.update(f.read())
    return sha.hexdigest()


class _Stamped:
    """Cache locator mixin: this package's files only, stamped with all their sources."""

    _stamp = _sources_stamp()

    def get_source_stamp(self):
        return self._stamp

    @classmethod
    def from_function(cls, py_func, py_file):
        if os.path.dirname(os.path.abspath(py_file)) != _HERE:
            return None
        return super().from_function(py_func, py_file)


class _KernelsUserDirLocator(_Stamped, caching.UserProvidedCacheLocator):
    """``NUMBA_CACHE_DIR`` when it is set."""


class _KernelsLocator(_Stamped, caching.InTreeCacheLocator):
    """Otherwise Numba's in-tree cache (``__pycache__`` next to the kernels)."""


for _loc in (_KernelsLocator, _KernelsUserDirLocator):
    if _loc not in caching.CacheImpl._locator_classes:
        caching.CacheImpl._locator_classes.insert(0, _loc)

jit = numba.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
pjit = numba.njit(cache=True, fastmath=FASTMATH, error_model="numpy", parallel=True)
#: small per-point helpers: inlined in Numba IR, so callers loaded from the cache inline them too
ijit = numba.njit(cache=True, fastmath=FASTMATH, error_model="numpy", inline="always")
prange = numba.prange


def plain(kernel):
    """The Python body of compiled ``kernel``, to run it on numpy arrays (``kernel`` itself when
    ``NUMBA_DISABLE_JIT=1`` left it a plain function)."""
    return getattr(kernel, "py_func", kernel)

"""Numba flags in one place: every kernel is compiled with ``jit`` or ``pjit`` from here."""
import os

# Threads spin-wait with the OpenMP layer on a loaded machine (PERFORMANCE_NOTES.md): be passive.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numba  # noqa: E402

FASTMATH = False  # keep IEEE semantics: NaN detection by the guards must work

jit = numba.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
pjit = numba.njit(cache=True, fastmath=FASTMATH, error_model="numpy", parallel=True)
#: small per-point helpers: inlined in Numba IR, so callers loaded from the cache inline them too
ijit = numba.njit(cache=True, fastmath=FASTMATH, error_model="numpy", inline="always")
prange = numba.prange

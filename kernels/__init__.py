"""Numba kernels: pure functions over arrays and scalars, no I/O, no Python objects."""

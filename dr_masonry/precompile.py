"""Cold start: the kernels of a run compiled in two processes at once.

Numba compiles a function and everything it calls in one thread, so the first run after an
install or an edit of ``kernels/`` spends about a minute compiling ``relax`` and its callees
(BENCHMARKS.md, "Cold and warm start"), one core busy and the other idle. The callees of ``relax`` fall
into two groups of similar cost, compiled side by side when their cache entries are missing:

* the fused force kernel (``element_and_contact_forces``, with the return mapping and the joint
  law; ``internal_forces``), in a worker process (``python -m dr_masonry.precompile FILE``:
  FILE holds the pickled argument types), which saves them in Numba's cache;
* the node passes and the small helpers, in this process meanwhile.

``relax`` itself then compiles here with every callee in memory or loaded from the cache
(BENCHMARKS.md, "Cold and warm start"). Nothing changes when the cache is warm, when caching is unavailable
(the worker's work could not be shared) or with ``DR_MASONRY_COMPILE_WORKERS=0``; a worker that
fails only costs the time it ran: what it did not compile compiles here as before.
"""
import os
import pickle
import subprocess
import sys
import tempfile
import warnings

import numpy as np
from numba import typeof

from .kernels import relaxation as R

#: environment switch: 0 compiles everything in this process as Numba does by default
ENV_SWITCH = "DR_MASONRY_COMPILE_WORKERS"


def callee_signatures(mesh, cont, dyn):
    """{group: [(kernel name in ``kernels.relaxation``'s namespace, argument types)]} of the
    functions that ``relax``, ``internal_forces`` and the solver call, typed as they type them
    (``mesh``, ``cont``, ``dyn``: the solver's named tuples of arrays)."""
    nr = dyn.rpX.shape[0]
    rpres = np.zeros((nr, 6))
    parts = np.zeros((1, 4))
    lam, flag = 0.0, True
    hbuf = mesh.fbuf.reshape((-1, 3))
    sigs = {
        "forces": [("element_and_contact_forces", (dyn.X, dyn.U, mesh, cont)),
                   ("internal_forces", (mesh, cont, dyn))],
        "nodes": [("place_rigid_nodes", (dyn,)),
                  ("gather_residual", (hbuf, mesh.ptr, mesh.rows, cont, dyn, lam, dyn.fint, flag,
                                       parts)),   # (relax passes a copy of fint: same type)
                  ("rp_residual", (dyn, lam, rpres)),
                  ("residual", (dyn, lam, rpres)),
                  ("norms", (dyn, lam, rpres)),
                  ("update_nodes", (dyn, lam, flag, lam, lam, parts)),
                  ("worst_place", (dyn, lam)),
                  ("stored_energy", (mesh, cont)),     # also callees of ``internal_forces``,
                  ("gather_pair", (hbuf, mesh.ptr, mesh.rows, cont.fbuf, cont.ptr, cont.rows,
                                   dyn.fint))],        # cached before the worker reaches it
    }
    return {g: [(name, tuple(typeof(a) for a in args)) for name, args in items]
            for g, items in sigs.items()}


def _cached(name, sig):
    """True if kernel ``name`` is compiled for ``sig`` in this process or in the cache; None if
    it has no usable cache (nothing a worker compiled could reach this process) or is not
    compiled at all (``NUMBA_DISABLE_JIT=1``)."""
    disp = getattr(R, name)
    if not hasattr(disp, "overloads"):   # a plain Python function
        return None
    if tuple(sig) in disp.overloads:
        return True
    cache_file = getattr(disp._cache, "_cache_file", None)   # NullCache: caching unavailable
    if cache_file is None:
        return None
    key = disp._cache._index_key(tuple(sig), disp.targetctx.codegen())
    return key in cache_file._load_index()


def compile_group(items):
    """Compile (and with ``cache=True`` save) each ``(name, argument types)`` of ``items``."""
    for name, sig in items:
        getattr(R, name).compile(tuple(sig))


def ensure_compiled(mesh, cont, dyn):
    """Compile the callees of ``relax`` for these arrays, the force kernel in a worker process
    when it is in no cache (module docstring). Returns True if a worker was used."""
    if os.environ.get(ENV_SWITCH, "1").strip() == "0" or (os.cpu_count() or 1) < 2:
        return False
    groups = callee_signatures(mesh, cont, dyn)
    name, sig = groups["forces"][0]
    if _cached(name, sig) is not False:   # warm, or no cache to share through
        return False
    with tempfile.TemporaryDirectory(prefix="dr_masonry_compile_") as tmp:
        path = os.path.join(tmp, "forces.pkl")
        with open(path, "wb") as f:
            pickle.dump(groups["forces"], f)
        # the worker imports this package from where this process found it
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
        with open(os.path.join(tmp, "stderr"), "w+") as err:
            worker = subprocess.Popen([sys.executable, "-m", __name__, path], env=env,
                                      stdout=subprocess.DEVNULL, stderr=err)
            try:
                compile_group(groups["nodes"])
                rc = worker.wait()
            except BaseException:   # Ctrl-C, or a compile error that the run will report
                worker.kill()
                raise
            if rc != 0:
                err.seek(0)
                warnings.warn(f"kernel compile worker failed (exit {rc}), compiling here instead: "
                              f"{err.read()[-500:]}", RuntimeWarning, stacklevel=2)
    return True


def main(argv):
    """Worker: compile the pickled group of file ``argv[0]``."""
    with open(argv[0], "rb") as f:
        compile_group(pickle.load(f))


if __name__ == "__main__":
    main(sys.argv[1:])

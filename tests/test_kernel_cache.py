"""The kernels' Numba cache follows edits to any kernel file (``kernels/config.py``).

Numba stamps a cached function with its own file only, while the compiled code of the kernels it
calls from other files is part of its cache entry: without the package-wide stamp an edit of a
callee leaves the caller running the old code.
"""
import os
import shutil
import subprocess
import sys
import textwrap

from dr_masonry.kernels import config

CALL = "import pkgx.caller as c; print(c.g())"


def _run(root):
    env = dict(os.environ, PYTHONPATH=str(root))
    out = subprocess.run([sys.executable, "-c", CALL], env=env, capture_output=True, text=True,
                         check=True)
    return out.stdout.strip()


def test_editing_a_callee_recompiles_its_cached_caller(tmp_path):
    pkg = tmp_path / "pkgx"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    shutil.copy(config.__file__, pkg / "config.py")
    callee = pkg / "callee.py"
    callee.write_text("from .config import jit\n\n\n@jit\ndef f():\n    return 1\n")
    (pkg / "caller.py").write_text(textwrap.dedent("""\
        from .callee import f
        from .config import jit


        @jit
        def g():
            return f()
        """))
    assert _run(tmp_path) == "1"
    assert any(name.endswith(".nbi") for name in os.listdir(pkg / "__pycache__"))
    callee.write_text("from .config import jit\n\n\n@jit\ndef f():\n    return 2\n")
    assert _run(tmp_path) == "2"


#: compiles one kernel under NUMBA_CACHE_DIR and prints how many functions Numba compiled (0:
#: every one came from the cache); with argv[1] "edited" the kernel's module is loaded again under
#: another package stamp, as after an edit of any kernel file
STAMPED = textwrap.dedent("""\
    import importlib, sys
    import numpy as np
    from numba.core import event
    from dr_masonry.kernels import config, contact_frame as module
    if sys.argv[1] == "edited":
        config._Stamped._stamp = "the stamp of an edited package"
        module = importlib.reload(module)
    xq = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    with event.install_recorder("numba:compile") as rec:
        assert module.contact_frame(xq, 0.0, 0.0, np.empty(3), np.empty((3, 3))) == 0.25
    print(sum(ev.is_start for _, ev in rec.buffer))
    """)


def test_kernels_use_the_package_stamp(tmp_path):
    """A kernel compiled once is loaded from the cache the next time; once the package's stamp
    differs (any kernel file edited) it is compiled again."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))

    def compiled(stamp):
        out = subprocess.run([sys.executable, "-c", STAMPED, stamp], env=env, capture_output=True,
                             text=True, check=True)
        return int(out.stdout.strip().splitlines()[-1])
    assert compiled("as is") >= 1
    assert compiled("as is") == 0
    assert compiled("edited") >= 1

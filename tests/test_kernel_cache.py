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


def test_kernels_use_the_package_stamp():
    from dr_masonry.kernels import relaxation
    locator = relaxation.relax._cache._impl.locator
    assert isinstance(locator, config._Stamped)
    assert locator.get_source_stamp() == config._sources_stamp()

"""``python -m dr_masonry``: the command line of :mod:`dr_masonry.cli`."""
import os
import sys

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # before Numba loads (see kernels/config.py)

from dr_masonry.cli import main  # noqa: E402

sys.exit(main())

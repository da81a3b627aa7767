"""``python -m dr_masonry``: the command line of :mod:`dr_masonry.cli`."""
import sys

from dr_masonry.cli import main

sys.exit(main())

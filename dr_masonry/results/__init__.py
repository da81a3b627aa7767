"""The HDF5 results file: write (append + flush), read, restart, pack.

The layout is documented in ``docs/file_format.md``. The package holds:

- :mod:`.schema`: the format name and version, the field and array tables, :data:`REQUIRED`, and
  the checks of stored values;
- :mod:`.writer`: :class:`ResultWriter` (rows, frames, checkpoints) and the free-space checks;
- :mod:`.reader`: :func:`open_result`, :class:`Result`, :func:`check_file`, :func:`above_tol`;
- :mod:`.packing`: :func:`pack`, the compressed copy a run can continue from.
"""
from .packing import pack
from .reader import Result, above_tol, check_file, open_result
from .schema import (CHECKPOINT, CHECKPOINT_NEW, CONTACT_ARRAYS, FORMAT_NAME, KEPT, MODEL_ARRAYS,
                     REQUIRED, SCHEMA_VERSION, SPACE_RESERVE, STANDARD_FIELDS, ResultsError,
                     check_stored, code_version, ends_run, model_arrays, require_kept,
                     state_fields)
from .writer import ResultWriter, free_bytes, make_folder, require_space, truncate_file

__all__ = ["CHECKPOINT", "CHECKPOINT_NEW", "CONTACT_ARRAYS", "FORMAT_NAME", "KEPT", "MODEL_ARRAYS",
           "REQUIRED", "SCHEMA_VERSION", "SPACE_RESERVE", "STANDARD_FIELDS", "Result",
           "ResultWriter", "ResultsError", "above_tol", "check_file", "check_stored",
           "code_version", "ends_run", "free_bytes", "make_folder", "model_arrays", "open_result",
           "pack", "require_kept", "require_space", "state_fields", "truncate_file"]

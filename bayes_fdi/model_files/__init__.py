"""Model files: fitted objects saved without pickle, and read back only as registered classes.

- `bayes_fdi.model_files.format`: `save` and `load` (a versioned ``.npz`` of JSON and arrays,
  written atomically; the file format is its module docstring).
- `bayes_fdi.model_files.codec`: the object tree of a file as JSON values and arrays.
- `bayes_fdi.model_files.registry`: the classes a file may hold, each under a stable name.

May import the foundation (`bayes_fdi.atomic`) only; the classes it saves are looked up in the
registry's table, never by a name read from a file.
"""

from bayes_fdi.model_files.format import (
    DEFAULT_MAX_BYTES,
    FORMAT_NAME,
    FORMAT_VERSION,
    MAX_METADATA_BYTES,
    load,
    read_metadata,
    save,
)
from bayes_fdi.model_files.registry import register_persistable

__all__ = [
    "DEFAULT_MAX_BYTES",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "MAX_METADATA_BYTES",
    "load",
    "read_metadata",
    "register_persistable",
    "save",
]

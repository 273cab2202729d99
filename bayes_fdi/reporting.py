"""``results.json`` of the reproduction: plain JSON values only (no NaN, no numpy types)."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from bayes_fdi.atomic import write_text

__all__ = [
    "to_jsonable",
    "write_json",
]


def to_jsonable(obj: Any) -> Any:
    """Convert results to JSON-ready values: plain ``dict``/``list``/``int``/``float``/``str``.

    numpy scalars and arrays, tuples and paths are converted; non-finite floats become ``None``
    (JSON has no NaN). Anything else raises ``ValueError`` naming its type.
    """
    if obj is None or isinstance(obj, bool | str):
        return obj
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, int | np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        value = float(obj)
        return value if math.isfinite(value) else None
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if isinstance(obj, Mapping):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [to_jsonable(v) for v in obj]
    raise ValueError(f"cannot write a {type(obj).__name__} to JSON")


def write_json(results: Mapping[str, Any], path: str | os.PathLike) -> Path:
    """Write ``results`` as indented JSON (see :func:`to_jsonable`) and return the path."""
    return write_text(path, json.dumps(to_jsonable(results), indent=2, sort_keys=False) + "\n")

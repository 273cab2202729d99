"""Report helpers shared by every report of the package: Markdown tables, numbers, JSON.

- `markdown_table`, `format_percent`, `format_number`: the text of a report's tables;
- `to_jsonable`, `write_json`: results as plain JSON values (no NaN, no numpy types), written
  atomically.

Figures are written with `bayes_fdi.atomic.save_figure`. Foundation code: imports nothing of the
package but `bayes_fdi.atomic`.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bayes_fdi.atomic import write_text

__all__ = [
    "format_number",
    "format_percent",
    "markdown_table",
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


def format_percent(value: float, digits: int = 2) -> str:
    """Format a ratio in ``[0, 1]`` as a percentage (``0.9824 -> '98.24%'``); NaN as ``'–'``."""
    if value is None or not math.isfinite(float(value)):
        return "–"
    return f"{100.0 * float(value):.{digits}f}%"


def format_number(value: Any, fmt: str = ".4f") -> str:
    """``value`` formatted with ``fmt``; None, NaN and infinities as ``'–'``."""
    if value is None or (isinstance(value, float | np.floating) and not math.isfinite(value)):
        return "–"
    return format(value, fmt)


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """Render a GitHub-flavoured Markdown table.

    Parameters
    ----------
    header
        Column titles.
    rows
        One sequence per row, each as long as ``header``; cells are converted with ``str``.

    Returns
    -------
    str
        The table, one line per row, ending with a newline.
    """
    header = [str(h) for h in header]
    if not header:
        raise ValueError("a table needs at least one column")
    for i, row in enumerate(rows):
        if len(row) != len(header):
            raise ValueError(f"row {i} has {len(row)} cells, the header has {len(header)}")

    def line(cells: Sequence[Any]) -> str:
        return "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |"

    out = [line(header), "|" + "|".join("---" for _ in header) + "|"]
    out.extend(line(row) for row in rows)
    return "\n".join(out) + "\n"

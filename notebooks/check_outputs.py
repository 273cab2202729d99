"""Refuse executed notebooks whose outputs show machine paths or numpy reprs.

The docs show the notebooks as `make notebooks` executed them, so their outputs must read as
they would on any reader's machine: no absolute path of this checkout, its Python environment,
the home or the temporary folder, and no ``np.str_('f1')`` or ``np.float64(0.5)`` where a plain
value was meant (print ``str(x)``, ``float(x)`` or a formatted number instead). Only the
outputs are read (stream text, plain text, Markdown and HTML), never the code or the images.

Usage: ``python notebooks/check_outputs.py build/notebooks/*.ipynb`` (run by
``make notebooks``); exits 1 and names each notebook, cell and offending text otherwise.
"""

from __future__ import annotations

import json
import re
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

#: numpy scalar and array reprs (numpy 2 prints scalars in containers as ``np.float64(0.5)``).
NUMPY_REPR = re.compile(
    r"\b(?:np|numpy)\.(?:str_|bytes_|bool_?|u?int\d*|float\d*|complex\d*|longdouble|"
    r"datetime64|timedelta64)\(|\barray\(\["
)
#: Output types whose text is read.
TEXT_TYPES = ("text/plain", "text/markdown", "text/html")


def machine_paths() -> list[str]:
    """Absolute folders that are this machine's own (checkout, environment, home, temp)."""
    here = Path(__file__).resolve().parent.parent
    folders = {here, Path(sys.prefix).resolve(), Path.home().resolve()}
    folders.add(Path(tempfile.gettempdir()).resolve())
    return sorted({str(f) for f in folders if str(f) != "/"}, key=len, reverse=True)


def output_texts(notebook: dict) -> Iterator[tuple[int, str]]:
    """(cell index, text) of every text output of a notebook."""
    for index, cell in enumerate(notebook.get("cells", [])):
        for output in cell.get("outputs", []):
            if output.get("output_type") == "stream":
                yield index, "".join(output.get("text", ""))
            elif output.get("output_type") == "error":
                yield index, "\n".join(output.get("traceback", []))
            for kind in TEXT_TYPES:
                if kind in output.get("data", {}):
                    yield index, "".join(output["data"][kind])


def problems(path: Path, paths: list[str]) -> list[str]:
    """One line per machine path or numpy repr in the outputs of the notebook at ``path``."""
    found = []
    for index, text in output_texts(json.loads(path.read_text(encoding="utf-8"))):
        hits = [m.start() for p in paths for m in re.finditer(re.escape(p), text)]
        hits += [m.start() for m in NUMPY_REPR.finditer(text)]
        for start in sorted(set(hits)):  # nested folders (a venv in the checkout) once
            excerpt = text[max(0, start - 40) : start + 60].replace("\n", " ")
            found.append(f"{path.name}, cell {index}: ...{excerpt}...")
    return found


def main(argv: list[str]) -> int:
    """Check the notebooks named in ``argv``; 0 when every output is clean."""
    if not argv:
        print("usage: check_outputs.py NOTEBOOK.ipynb ...", file=sys.stderr)
        return 2
    paths = machine_paths()
    found = [line for name in argv for line in problems(Path(name), paths)]
    for line in found:
        print(line, file=sys.stderr)
    if found:
        print(
            f"{len(found)} machine path(s) or numpy repr(s) in notebook outputs: print plain "
            "values (str, float, formatted numbers) and names without their folders",
            file=sys.stderr,
        )
        return 1
    print(f"notebook outputs clean: {len(argv)} notebook(s)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

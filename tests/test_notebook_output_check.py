"""``notebooks/check_outputs.py``, run by ``make notebooks``: executed notebooks whose outputs show
a machine path or a numpy repr are refused, naming the cell; code and clean outputs pass."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "notebooks" / "check_outputs.py"


def _notebook(path: Path, code: str, *outputs: dict) -> Path:
    cell = {"cell_type": "code", "metadata": {}, "source": code, "outputs": list(outputs)}
    path.write_text(json.dumps({"cells": [cell], "metadata": {}, "nbformat": 4}))
    return path


def _stream(text: str) -> dict:
    return {"output_type": "stream", "name": "stdout", "text": text}


def _check(*paths: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(SCRIPT), *map(str, paths)], capture_output=True, text=True
    )


def test_plain_outputs_pass_and_code_is_not_read(tmp_path):
    # the code mentions np.float64( and the checkout's folder; only outputs are read
    code = f"x = np.float64(0.5)\nprint({str(ROOT)!r})"
    clean = _notebook(tmp_path / "clean.ipynb", code, _stream("classes: f1, f2\nwidth 0.5\n"))
    done = _check(clean)
    assert done.returncode == 0, done.stderr
    assert "clean: 1 notebook" in done.stdout


def test_numpy_reprs_in_outputs_are_refused_with_their_cell(tmp_path):
    # what print() of a list of numpy strings and a dict of numpy floats writes under numpy 2
    text = str([np.str_("f1")]) + " " + str({"w": np.float64(0.5)})
    assert "np.str_('f1')" in text and "np.float64(0.5)" in text
    bad = _notebook(tmp_path / "bad.ipynb", "print(classes)", _stream(text))
    done = _check(bad)
    assert done.returncode == 1
    assert done.stderr.count("bad.ipynb, cell 0") == 2


def test_machine_paths_in_outputs_are_refused(tmp_path):
    warning = f"{sys.prefix}/lib/site.py:1: Warning: something\n"
    display = {"output_type": "execute_result", "data": {"text/plain": str(ROOT / "sim")}}
    bad = _notebook(tmp_path / "paths.ipynb", "", _stream(warning), display)
    done = _check(bad)
    assert done.returncode == 1
    assert done.stderr.count("paths.ipynb, cell 0") == 2

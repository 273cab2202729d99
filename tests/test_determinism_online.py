"""Same seed, same figures on any BLAS code path and thread count: the online diagnoser.

``bayes-fdi benchmark --small`` fits the small default diagnoser (simulating its campaigns) and
scores it, once on the reference code path (default MKL and OpenBLAS paths, one thread) and once
with everything else changed at once (MKL's AVX2 path, OpenBLAS's Haswell kernels, two
threads), each in a fresh interpreter with its own cache folder, so each fits its own model.
Every figure the report prints must be identical; only the lines that report wall-clock or CPU
times may differ. The fitted numbers themselves differ in their last bits between the code paths
(a matrix product's rounding), which no printed figure shows: this fails whenever a discrete
decision of the fit or of the stream (a relevance vector, a threshold, an alarm, a diagnosed
group) amplifies that rounding.
"""

from __future__ import annotations

import difflib
import re
import subprocess
import sys
from pathlib import Path

import pytest
from blas_paths import EVERYTHING_ELSE, REFERENCE, blas_env

#: Lines of benchmark.md that hold times (the only figures that may differ between two runs).
TIMED = re.compile(r"Wall time|per CPU s|training took|CPU s\b|wall\b", re.IGNORECASE)


def run_small_benchmark(out: Path, cache: Path, env: dict[str, str]) -> list[str]:
    """The printed lines of ``benchmark --small --seeds 1`` run under ``env``, timed ones out."""
    cmd = [sys.executable, "-m", "bayes_fdi", "benchmark", "--small", "--seeds", "1"]
    full = blas_env(env) | {"BAYES_FDI_CACHE": str(cache)}
    proc = subprocess.run(
        [*cmd, "--out", str(out), "--quiet"],
        env=full, capture_output=True, text=True, timeout=1800, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = (out / "benchmark.md").read_text().splitlines()
    return [line for line in lines if not TIMED.search(line)]


@pytest.mark.slow
def test_small_benchmark_prints_the_same_figures_on_another_code_path(tmp_path):
    reference = run_small_benchmark(tmp_path / "ref", tmp_path / "cache-ref", REFERENCE)
    other = run_small_benchmark(tmp_path / "other", tmp_path / "cache-other", EVERYTHING_ELSE)
    assert len(reference) > 100  # the whole report, not an error page
    diff = list(difflib.unified_diff(reference, other, "reference", "everything-else", n=0))
    assert not diff, "printed figures differ:\n" + "\n".join(line[:300] for line in diff[:40])


def test_only_timed_lines_are_left_out():
    assert TIMED.search("Wall time 39 s: simulation 2 CPU s, diagnosis 1 CPU s")
    assert TIMED.search("| `run` replays >= 20 000 samples/s | 233,378 samples per CPU s | yes |")
    assert not TIMED.search("| f1 abrupt big | 0.000 | 1 | 0.98 |")
    assert not TIMED.search("Top-label ECE of the group probabilities: **0.118**")

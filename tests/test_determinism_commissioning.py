"""Same seed, same figures on any BLAS code path and thread count: commissioning.

A quick commissioning (the test suite's small settings, tree and forest isolation) of a simulated
level-loop valve runs in a fresh interpreter on the reference code path (default MKL and
OpenBLAS paths, one thread) and with everything else changed at once (MKL's AVX2 path,
OpenBLAS's Haswell kernels, two threads). What a user reads must be identical: the
commissioning report (its times zeroed) and the diagnosis of a run with a bypass flow added:
DD, the diagnosed state and the SEVA status every second, and the probability of the state to
four decimals, as ``alarms.csv`` gives it. The fitted numbers themselves differ in their last
bits between code paths (the calibration temperature in its 8th significant digit on this
case); this fails when a discrete step of the commissioning (a relevance vector, a group, a
tree split, the detector's threshold crossing) amplifies that rounding into a printed figure.
"""

from __future__ import annotations

import difflib
from pathlib import Path

import pytest
from blas_paths import EVERYTHING_ELSE, REFERENCE, run_python

pytestmark = pytest.mark.slow
REFERENCE_AND_OTHER = (REFERENCE, EVERYTHING_ELSE)

_SCRIPT = """
import sys
sys.path.insert(0, {tests!r})
import numpy as np
from bayes_fdi.actuator import simulate
from bayes_fdi.actuator.excitation import level_loop_inputs
from bayes_fdi.commissioning import commission
from bayes_fdi.commissioning.report import render_report
from test_commissioning import _small_commissioning

healthy = simulate(level_loop_inputs(1, 1500, seed=4), seed=4)
bypass = healthy.copy()
bypass["F"] = bypass["F"] + 0.1 * (bypass["time"] >= 900)
for isolation in ("tree", "forest"):
    diagnoser, _, report = commission(healthy, isolation=isolation, **_small_commissioning())
    report = dict(report)
    report["seconds"] = {{k: 0.0 for k in report["seconds"]}}
    report["twin"] = {{**report["twin"], "fit_seconds": 0.0}}
    print(render_report(report))
    stream = diagnoser.run(bypass[["CV", "P1", "P2", "T1", "X", "F"]]).isel(run=0)
    for name in ("DD", "state", "status"):
        print(name, " ".join(map(str, np.asarray(stream[name].values).tolist())))
    print("probability", " ".join(f"{{p:.4f}}" for p in stream["probability"].values))
"""


def test_a_commissioning_prints_the_same_on_another_code_path():
    script = _SCRIPT.format(tests=str(Path(__file__).parent))
    reference, other = (run_python(script, env).splitlines() for env in REFERENCE_AND_OTHER)
    assert sum(line == "# Commissioning report" for line in reference) == 2  # tree and forest
    assert any(line.startswith("state ") and "f18" in line for line in reference)  # named
    diff = list(difflib.unified_diff(reference, other, "reference", "everything-else", n=0))
    assert not diff, "printed figures differ:\n" + "\n".join(line[:300] for line in diff[:40])

"""``benchmarks/naming_threshold.py``: the seconds named right and wrong at a probability
threshold, against counts made by hand."""

from __future__ import annotations

import numpy as np
from benchmark_scripts import load_benchmark

tool = load_benchmark("naming_threshold")


def test_seconds_are_counted_right_or_wrong_only_when_named_at_the_threshold():
    rows = [
        # f1 big, true group f1: right at 0.9 and 0.45, wrong (f11|f15) at 0.6, one second
        # unknown, one not detected (fn, probability NaN)
        ("f1 big", "f1", np.array(["f1", "f1", "f11|f15", "unknown", "fn"]),
         np.array([0.9, 0.45, 0.6, np.nan, np.nan])),
        # a second run of the same scenario: wrong at 0.3, mismatch
        ("f1 big", "f1", np.array(["f6|f18", "mismatch"]), np.array([0.3, np.nan])),
        # a fault in DGN0: any named group is wrong
        ("f12 big", "DGN0", np.array(["f11|f15", "f11|f15"]), np.array([0.55, 0.4])),
    ]  # fmt: skip
    assert tool.tally(rows, 0.0) == {"f1 big": [2, 2, 7], "f12 big": [0, 2, 2]}
    assert tool.tally(rows, 0.5) == {"f1 big": [1, 1, 7], "f12 big": [0, 1, 2]}
    assert tool.tally(rows, 0.95) == {"f1 big": [0, 0, 7], "f12 big": [0, 0, 2]}

"""``benchmarks/fault_free_draws.py``: its seeds and its summary, by hand."""

from __future__ import annotations

import pytest
from benchmark_scripts import load_benchmark

tool = load_benchmark("fault_free_draws")


def test_seeds_as_a_range_or_a_list():
    assert tool.parse_seeds("5002-5005") == [5002, 5003, 5004, 5005]
    assert tool.parse_seeds("5002,5007") == [5002, 5007]
    assert tool.parse_seeds("5003") == [5003]
    with pytest.raises(ValueError, match="empty range"):
        tool.parse_seeds("5005-5002")


def test_summary_scales_the_alarms_to_8_hours():
    draws = [
        {"alarms": 0, "dd_on": 0.0},
        {"alarms": 1, "dd_on": 0.01},  # 2 in 8 h: over the target
        {"alarms": 3, "dd_on": 0.05},  # 6 in 8 h
        {"alarms": 1, "dd_on": 0.5},  # 2 in 8 h, and on half the time
    ]
    s = tool.summary(draws, hours=4.0)
    assert s["n_draws"] == 4
    assert s["within_target"] == 1
    assert s["mean_alarms_per_8h"] == pytest.approx((0 + 2 + 6 + 2) / 4)
    assert s["mean_dd_on"] == pytest.approx(0.56 / 4)
    assert s["blurred_seconds"] == 0  # no draw says how long it was BLURRED
    # over 8 hours: one alarm is within the target unless DD stays on for more than 1 %
    eight = tool.summary([{"alarms": 1, "dd_on": 0.01}, {"alarms": 1, "dd_on": 0.02}], hours=8.0)
    assert eight["within_target"] == 1

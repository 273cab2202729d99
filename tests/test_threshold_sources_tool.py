"""``benchmarks/threshold_sources.py``: the CUSUM peak and the valve's regimes against values
worked out by hand."""

from __future__ import annotations

import numpy as np
import pytest
from benchmark_scripts import load_benchmark

tool = load_benchmark("threshold_sources")


def test_the_cusum_peak_by_hand():
    e = np.zeros((12, 2))
    e[2:6, 0] = 2.0  # S+ on X: 1.5, 3.0, 4.5, 6.0 at seconds 2..5, then falls by 0.5 a second
    e[8:11, 1] = -3.0  # S- on F: 2.5, 5.0, 7.5 at seconds 8..10
    e[7, 1] = np.nan  # a gap: skipped
    peak, at, channel = tool.cusum_peak(e)
    assert (peak, at, channel) == (pytest.approx(7.5), 10, 1)
    e[8:11, 1] = 0.0
    assert tool.cusum_peak(e) == (pytest.approx(6.0), 5, 0)
    assert tool.cusum_peak(np.zeros((5, 2))) == (0.0, -1, -1)


def test_the_cusum_is_not_capped():
    e = np.full((200, 1), 3.0)  # grows by 2.5 a second, far past twice any threshold
    assert tool.cusum_peak(e)[0] == pytest.approx(500.0)


def test_valve_regimes_by_hand():
    x = np.array([0.5, 0.98, 0.99, 0.2, 0.3])
    f = np.array([0.4, 0.01, 0.0, 1.0, 0.995])
    z = np.array([1.0, -8.0, 6.0, 0.5, -1.5])
    got = tool.valve_regimes(x, f, z)
    assert got["shut_seconds"] == 2 and got["rail_seconds"] == 2
    assert got["z_F_shut"] == pytest.approx(7.0)
    assert got["z_F_rail"] == pytest.approx(1.0)
    assert got["z_F_other"] == pytest.approx(1.0)
    assert np.isnan(tool.valve_regimes(x[:1], f[:1], z[:1])["z_F_shut"])

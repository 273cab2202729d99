"""``benchmarks/excitation_misfit.py``: its per-case figures against values computed by hand, and
its cases' inputs changing only what each case names."""

from __future__ import annotations

import numpy as np
import pytest
from benchmark_scripts import load_benchmark

tool = load_benchmark("excitation_misfit")


def test_figures_are_the_median_rms_the_dd_share_and_the_rising_edges():
    r_x = np.array([[3.0, 4.0, np.nan], [1.0, 1.0, 1.0]])  # RMS 3.536 (NaN left out) and 1
    r_f = np.array([[0.0, 0.0, 0.0], [2.0, 2.0, 2.0]])  # RMS 0 and 2
    dd = np.array([[True, False, True], [False, True, True]])  # 2 alarms, then 1
    f = tool.stream_figures(r_x, r_f, dd)
    assert f["rms_X"] == pytest.approx((np.sqrt(12.5) + 1.0) / 2)
    assert f["rms_F"] == pytest.approx(1.0)
    assert f["dd_share"] == pytest.approx(4 / 6) and f["alarms"] == 3
    # a second without a decision (NaN, e.g. BLIND) counts as off, as PICalc reads it
    g = tool.stream_figures(r_x[:1], r_f[:1], np.array([[np.nan, 1.0, 1.0]]))
    assert g["dd_share"] == pytest.approx(2 / 3) and g["alarms"] == 1


def test_each_case_changes_only_the_input_it_names():
    made = {name: make() for name, make in tool.cases(2, 600, seed=905).items()}
    shipped, still = made["chirp"], made["chirp, P1 still"]
    for ch in ("CV", "P2", "T1"):
        np.testing.assert_array_equal(shipped[ch].values, still[ch].values)
    assert np.ptp(shipped["P1"].values - still["P1"].values, axis=1).min() > 0.04  # >= 100 kPa
    low = made["sums of sines, P1 0-200 kPa, drop 0.3-0.5 MPa"]
    drop = (low["P1"].values - low["P2"].values) * 4e6
    assert drop.mean(axis=1).max() < 0.5e6 + 0.1e6  # around its drawn level, within the drift
    np.testing.assert_array_equal(
        made["sums of sines, P1 still"]["CV"].values,
        made["sums of sines, P1 0-200 kPa"]["CV"].values,
    )


def test_the_sums_of_sines_are_the_training_files():
    """The sums-of-sines cases take the training campaign's own settings; "P1 still" only
    switches its P1 oscillation off."""
    settings = tool.training_sine_sum()
    assert settings["p1_amplitude"] == (0.0, 200e3)  # as sim/online-normal-sine-sum.toml says
    assert settings["frequencies"] == (0.002, 0.1) and settings["n_sines"] == 3

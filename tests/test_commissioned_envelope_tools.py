"""``benchmarks/commissioned_envelope.py`` and ``benchmarks/twin_flow_given_stem.py``: how far
the inputs lie beyond a range, and the least-squares gain of one residual on another, against
hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from benchmark_scripts import load_benchmark

from bayes_fdi.diagnosis.online import InputEnvelope

envelope_tool = load_benchmark("commissioned_envelope")
stem_tool = load_benchmark("twin_flow_given_stem")


def test_the_distance_is_the_largest_share_of_a_span_beyond_the_range():
    low = {"CV": 0.2, "P1": 0.5, "P2": 0.4, "T1": 0.1}
    high = {"CV": 0.6, "P1": 0.7, "P2": 0.5, "T1": 0.3}
    values = {
        "CV": [0.4, 0.7, 0.1, 0.4],  # inside; 0.1 above (a quarter of 0.4); 0.1 below
        "P1": [0.6, 0.6, 0.6, 0.8],  # inside, inside, inside, 0.1 above (half of 0.2)
        "P2": [0.45, 0.45, 0.45, 0.45],
        "T1": [0.2, 0.2, 0.2, 0.2],
    }
    run = xr.Dataset(
        {c: (("run", "time"), np.array(v)[None]) for c, v in values.items()},
        coords={"run": [0], "time": np.arange(4.0)},
    )
    got = envelope_tool.distance_beyond_range(run, low, high)
    np.testing.assert_allclose(got, [0, 0.25, 0.25, 0.5])


def test_the_gain_is_the_least_squares_slope_through_the_origin_on_the_masked_samples():
    rng = np.random.default_rng(0)
    e_x = rng.standard_normal((2, 50))
    slope = rng.uniform(-3, -1, (2, 50))
    r = np.stack([e_x, 1.5 * slope * e_x + 0.01 * rng.standard_normal((2, 50))], axis=-1)
    mask = np.ones((2, 50), dtype=bool)
    mask[1, 40:] = False
    r[1, 40:, 1] = 1e6  # masked samples do not count
    g = (slope * e_x)[mask]
    want = np.linalg.lstsq(g[:, None], r[..., 1][mask], rcond=None)[0][0]  # a second solver
    # both solve the same 1-parameter least squares: they agree to rounding (~1e-15 relative)
    assert stem_tool.stem_gain(r, slope, mask) == pytest.approx(want, rel=1e-12)
    assert abs(want - 1.5) < 0.01  # the noise is 1 % of the signal


def _run_of(values: dict) -> xr.Dataset:
    return xr.Dataset(
        {c: (("run", "time"), np.asarray(v, dtype=np.float64)[None]) for c, v in values.items()},
        coords={"run": [0], "time": np.arange(float(len(values["CV"])))},
    )


def test_a_run_leaves_the_range_at_its_onset_by_the_command_after_it_or_the_inputs_before():
    # the range CV 0.2-0.6, P1 0.5-0.7, P2 0.4-0.5, T1 0.1-0.3 widened by the 0.02 floor
    envelope = InputEnvelope.from_bounds([0.18, 0.48, 0.38, 0.08], [0.62, 0.72, 0.52, 0.32])
    inside = {"CV": np.full(200, 0.4), "P1": np.full(200, 0.6), "P2": np.full(200, 0.45),
              "T1": np.full(200, 0.2)}  # fmt: skip
    args = (envelope, 100, 10)  # onset at 100 s, 10 s looked at
    assert envelope_tool.onset_outside(_run_of(inside), *args) == (False, 0.0)
    late = {**inside, "CV": inside["CV"].copy()}
    late["CV"][111:131] = 0.65  # outside the widened range (0.62), but 11 s after the onset
    flag, share = envelope_tool.onset_outside(_run_of(late), *args)
    assert not flag and share == pytest.approx(20 / 100)
    near = {**inside, "CV": inside["CV"].copy()}
    near["CV"][110] = 0.65  # 10 s after the onset: within the lookback
    assert envelope_tool.onset_outside(_run_of(near), *args) == (True, pytest.approx(0.01))
    within_floor = {**inside, "CV": inside["CV"].copy()}
    within_floor["CV"][100:] = 0.61  # beyond the range but inside its 0.02 floor
    assert envelope_tool.onset_outside(_run_of(within_floor), *args) == (False, 0.0)
    before = {**inside, "T1": inside["T1"].copy()}
    before["T1"][40:100] = 0.35  # the minute before the onset outside, back inside at it
    assert envelope_tool.onset_outside(_run_of(before), *args) == (True, 0.0)


def test_the_healthy_range_is_each_inputs_lowest_and_highest_value():
    run = _run_of({"CV": [0.3, 0.1, 0.5], "P1": [0.6, 0.7, 0.65], "P2": [0.4, 0.4, 0.4],
                   "T1": [0.2, 0.25, 0.1]})  # fmt: skip
    low, high = envelope_tool.healthy_range(run)
    assert low == {"CV": 0.1, "P1": 0.6, "P2": 0.4, "T1": 0.1}
    assert high == {"CV": 0.5, "P1": 0.7, "P2": 0.4, "T1": 0.25}

"""The two-speed CUSUM (bayes_fdi.diagnosis.detection.two_speed): a fast and a slow branch."""

from __future__ import annotations

import math

import numpy as np
import pytest
from cusum_reference import hand_two_sided_sums

from bayes_fdi import model_files
from bayes_fdi.diagnosis.component_state import stack_states
from bayes_fdi.diagnosis.detection import (
    CUSUM,
    ARWhitener,
    TwoSpeedCUSUM,
    TwoSpeedCUSUMState,
)
from bayes_fdi.diagnosis.detection.thresholds import cusum_threshold, empirical_arl
from bayes_fdi.diagnosis.detection.two_speed import REFERENCE_ARL


@pytest.fixture
def rng():
    return np.random.default_rng(20261127)


def test_statistic_is_the_larger_of_the_fast_sums_and_the_scaled_slow_ones(rng):
    test = TwoSpeedCUSUM(k=0.5, k_slow=0.1, threshold=12.0)
    e = rng.standard_normal(3000) + np.where(np.arange(3000) > 1500, 0.3, 0.0)
    e[[10, 11, 700]] = np.nan
    scale, band = test.slow_scale_, test.slow_band_
    fast = hand_two_sided_sums(e, 0.5, 24.0).max(axis=1)
    slow = hand_two_sided_sums(e, 0.1, 24.0 / scale + band).max(axis=1)
    expected = np.maximum(fast, scale * np.maximum(slow - band, 0.0))
    expected[np.isnan(e)] = np.nan
    out, _ = test.run(e)
    np.testing.assert_allclose(out.statistic, expected, rtol=1e-12, atol=1e-12)
    # the scale: Siegmund's thresholds of the two branches at the reference budget
    fast_h = cusum_threshold(REFERENCE_ARL, 0.5, n_sides=2)
    slow_h = cusum_threshold(REFERENCE_ARL, 0.1, n_sides=2)
    assert scale == pytest.approx(fast_h / (slow_h - 10.0))


def test_run_equals_update_and_stacked_runs_equal_single_runs(rng):
    test = TwoSpeedCUSUM(k_slow=0.15, threshold=8.0)
    e = rng.standard_normal((3, 400)) + 0.2
    e[1, 50] = np.nan
    whole = [test.run(row)[0].statistic for row in e]
    stacked, _ = test.run_stacked(e, stack_states([test.init_state()] * 3))
    np.testing.assert_array_equal(stacked.statistic, np.stack(whole))
    state = None
    one_by_one = []
    for v in e[0]:
        out, state = test.update(float(v), state)
        one_by_one.append(out.statistic)
    np.testing.assert_array_equal(np.array(one_by_one), whole[0])
    assert isinstance(state, TwoSpeedCUSUMState)


def test_a_lasting_small_shift_is_found_by_the_slow_branch_only(rng):
    """A shift of 0.2 innovation standard deviations: well below the fast CUSUM's reference
    0.5, so at the same false-alarm budget the fast CUSUM finds it only by chance (Siegmund:
    a mean run length of about 4000 s), the slow branch in about
    (h / scale + band) / (0.2 - k_slow) samples."""
    target = 8 * 3600.0
    two = TwoSpeedCUSUM(k_slow=0.1)
    h_two = two.gaussian_threshold(target, n_channels=1)
    h_fast = CUSUM(k=0.5).gaussian_threshold(target, n_channels=1)
    two, fast = two.with_threshold(h_two), CUSUM(k=0.5, threshold=h_fast)
    expected = (h_two / two.slow_scale_ + two.slow_band_) / (0.2 - 0.1)
    delays_two, found_fast = [], 0
    for _ in range(20):
        e = rng.standard_normal(1500) + 0.2
        delays_two.append(int(np.argmax(two.run(e)[0].statistic > h_two)))
        found_fast += bool(np.any(fast.run(e)[0].statistic > h_fast))
    assert all(d > 0 for d in delays_two)
    assert 0.6 * expected < np.median(delays_two) < 1.4 * expected < 1500
    assert found_fast <= 10


def test_the_gaussian_threshold_keeps_the_budget_on_white_noise(rng):
    target = 1500.0
    test = TwoSpeedCUSUM(k_slow=0.1)
    h = test.gaussian_threshold(target, n_channels=2)
    e = rng.standard_normal((600_000, 2))
    arl, alarms, _ = empirical_arl(test, [e], h, clear=0.0)
    assert alarms > 50
    # the branches share the budget (a union bound): at or above the target, not far above
    assert target * 0.9 < arl < target * 3.0


def test_a_persistent_residual_shift_survives_whitening_through_the_slow_branch(rng):
    """An AR(1) residual with phi = 0.95 shifted by 1.5 standard deviations: after the
    onset's spike the whitened innovations shift by only 1.5 (1 - phi) / sqrt(1 - phi^2) =
    0.24, below the fast branch's reference 0.5; the slow branch finds it within minutes, the
    fast CUSUM (same threshold) much later or never."""
    from scipy.signal import lfilter

    phi, onset, n = 0.95, 1000, 3500
    noise = rng.standard_normal(30_000) * math.sqrt(1 - phi**2)
    whitener = ARWhitener(max_order=3).fit(lfilter([1.0], [1.0, -phi], noise))
    two = TwoSpeedCUSUM(k_slow=0.1)
    h = two.gaussian_threshold(8 * 3600.0, n_channels=1)
    two, fast = two.with_threshold(h), CUSUM(k=0.5, threshold=h)
    delays = {"two": [], "fast": []}
    for _ in range(10):
        z = lfilter([1.0], [1.0, -phi], rng.standard_normal(n) * math.sqrt(1 - phi**2))
        e = whitener.run(z + np.where(np.arange(n) >= onset, 1.5, 0.0))[0]
        for name, test in (("two", two), ("fast", fast)):
            above = np.flatnonzero(test.run(e)[0].statistic > h)
            delays[name].append(above[0] - onset if above.size else n)
    assert min(delays["two"]) > 0  # no alarm before the onset
    assert max(delays["two"]) < 1000
    assert np.median(delays["two"]) < 0.5 * np.median(delays["fast"])


def test_bad_parameters_are_named_and_the_model_file_round_trips(tmp_path, rng):
    with pytest.raises(ValueError, match="k_slow must be a number in"):
        TwoSpeedCUSUM(k=0.5, k_slow=0.5).run(np.zeros(3))
    test = TwoSpeedCUSUM(k_slow=0.12, threshold=9.0)
    e = rng.standard_normal(300) + 0.25
    _, state = test.run(e[:100])
    model_files.save(test, tmp_path / "t.npz")
    model_files.save(state, tmp_path / "s.npz")
    back, back_state = model_files.load(tmp_path / "t.npz"), model_files.load(tmp_path / "s.npz")
    assert repr(back) == repr(test) == "TwoSpeedCUSUM(k=0.5, k_slow=0.12, threshold=9.0)"
    assert model_files.read_metadata(tmp_path / "t.npz")["format_version"] >= 7
    np.testing.assert_array_equal(
        back.run(e[100:], back_state)[0].statistic,
        test.run(e[100:], state)[0].statistic,
    )


def test_short_data_calibrate_on_thresholds_with_a_few_alarms(rng):
    """Where fewer than two thresholds give ``min_alarms`` alarms (short data, or the slow
    branch's merged alarms), the log-ARL line is fitted on those with at least FEW_ALARMS."""
    from bayes_fdi.diagnosis.detection.thresholds import FEW_ALARMS, calibrate_threshold

    e = rng.standard_normal((700, 2))
    got = calibrate_threshold(TwoSpeedCUSUM(), [e], 8 * 3600.0, min_alarms=10)
    counts, arl = np.array(got["alarms"]), np.array(got["arl"])
    assert (counts >= 10).sum() < 2 <= (counts >= FEW_ALARMS).sum()
    used = counts >= FEW_ALARMS
    slope, intercept = np.polyfit(np.array(got["grid"])[used], np.log(arl[used]), 1)
    assert got["fit"] == pytest.approx((intercept, slope))
    assert got["threshold"] == pytest.approx((math.log(8 * 3600.0) - intercept) / slope)

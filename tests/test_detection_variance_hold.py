"""The CUSUM whose alarm holds while the innovations' variance stays high
(bayes_fdi.diagnosis.detection.variance_hold)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from cusum_reference import hand_two_sided_sums
from scipy import stats

from bayes_fdi import model_files
from bayes_fdi.diagnosis.component_state import stack_states
from bayes_fdi.diagnosis.detection import (
    CUSUM,
    DetectionDecision,
    VarianceHoldCUSUM,
    VarianceHoldCUSUMState,
    variance_reference,
)
from bayes_fdi.diagnosis.detection.detectors import sequential_test


@pytest.fixture
def rng():
    return np.random.default_rng(20261128)


def hand_variance_sum(e, k_var, clip, cap):
    """``V`` per sample, written out: the clipped squares less ``k_var``, a NaN counting as its
    in-control expectation 1."""
    v, out = 0.0, []
    for x in e:
        square = 1.0 if math.isnan(x) else min(x * x, clip * clip)
        v = min(cap, max(0.0, v + square - k_var))
        out.append(v)
    return np.array(out)


def test_the_reference_is_where_the_variance_likelihood_ratio_changes_sign():
    """At ``e^2 = k_var`` N(0, hold_sigma^2) and N(0, 1) are equally likely (closed form)."""
    for sigma in (1.2, 1.5, 2.0, 3.0):
        k_var = variance_reference(sigma)
        e = math.sqrt(k_var)
        llr = stats.norm.logpdf(e, scale=sigma) - stats.norm.logpdf(e)
        assert llr == pytest.approx(0.0, abs=1e-12)
        assert 1.0 < k_var < sigma**2
    assert variance_reference(1.5) == pytest.approx(1.4597, abs=1e-4)


def test_statistic_is_the_mean_sums_or_the_variance_sum_up_to_half_the_threshold(rng):
    test = VarianceHoldCUSUM(k=0.5, hold_sigma=1.5, clip=3.0, threshold=12.0)
    e = rng.standard_normal(3000) * np.where(np.arange(3000) > 1500, 1.8, 1.0)
    e[[10, 11, 700, 2000]] = np.nan
    mean = hand_two_sided_sums(e, 0.5, 24.0).max(axis=1)
    variance = hand_variance_sum(e, test.k_var_, 3.0, 24.0)
    expected = np.maximum(mean, np.minimum(variance, 6.0))
    expected[np.isnan(e)] = np.nan
    out, state = test.run(e)
    np.testing.assert_allclose(out.statistic, expected, rtol=1e-12, atol=1e-12)
    assert test.hold_level_ == 6.0 and state.sums[2] == pytest.approx(variance[-1])
    # in control the clipped square's mean, 0.995, is below k_var = 1.46: V drifts down by
    # 0.465 a sample, a reflected walk whose mean is about var / (2 drift) = 2.0 (diffusion
    # approximation, variance of the clipped square 1.9); with a std of 1.8 the mean is
    # 2.72 and V drifts up by 1.26 a sample, to its cap within about 20 samples, and stays near it
    assert np.mean(variance[100:1500]) < 4.0
    assert np.mean(variance[1550:]) > 18.0 and np.mean(variance[1550:] > 6.0) > 0.95


def test_the_variance_sum_never_raises_a_detection_by_itself():
    """Innovations alternating +-2.5: zero mean, so the mean sums return to 0 every other
    sample, while each square adds min(6.25, 9) - k_var; the statistic stops at half the
    threshold and the decision never switches on."""
    test = VarianceHoldCUSUM(threshold=10.0)
    e = np.tile([2.5, -2.5], 200)
    stat = test.run(e)[0].statistic
    assert stat.max() == pytest.approx(5.0)
    dd = DetectionDecision(10.0, 0.0, n_channels=1, hold=0).run(stat[:, None])[0]
    assert not dd.any()


def test_a_detection_holds_while_the_variance_stays_high_and_clears_once_it_is_back(rng):
    """A mean shift raises the alarm; then the mean goes back to 0 with a std of 2 (the fault
    now only widens the residuals): with plain hysteresis the CUSUM's alarm clears within
    seconds, the variance hold keeps it on; once the std is back to 1 it clears."""
    n = 1200
    e = rng.standard_normal(n)
    e[300:330] += 3.0  # the fault's onset
    e[330:800] *= 2.0  # then only wider
    threshold = 15.0
    decision = DetectionDecision(threshold, 0.0, n_channels=1, hold=0)
    plain = decision.run(CUSUM(threshold=threshold).run(e)[0].statistic[:, None])[0]
    held = decision.run(VarianceHoldCUSUM(threshold=threshold).run(e)[0].statistic[:, None])[0]
    assert plain[:300].sum() == held[:300].sum() == 0
    assert plain[310] and held[310]
    assert held[310:800].all()
    assert not plain[310:800].all()
    assert not held[900:].any()


def test_a_gap_counts_as_in_control_for_the_variance_sum():
    test = VarianceHoldCUSUM(threshold=10.0)
    state = test.run(np.tile([2.5, -2.5], 20))[1]
    assert state.sums[2] == pytest.approx(20.0)  # the cap, twice the threshold
    out, state = test.run(np.full(3, np.nan), state)
    assert np.isnan(out.statistic).all()
    assert state.sums[2] == pytest.approx(20.0 - 3 * (test.k_var_ - 1.0))


def test_run_equals_update_and_stacked_runs_equal_single_runs(rng):
    test = VarianceHoldCUSUM(hold_sigma=1.3, clip=4.0, threshold=8.0)
    e = rng.standard_normal((3, 400)) * 1.4
    e[1, 50] = np.nan
    whole = [test.run(row)[0] for row in e]
    stacked, _ = test.run_stacked(e, stack_states([test.init_state()] * 3))
    np.testing.assert_array_equal(stacked.statistic, np.stack([w.statistic for w in whole]))
    np.testing.assert_array_equal(stacked.since, np.stack([w.since for w in whole]))
    state = None
    one_by_one = []
    for v in e[0]:
        out, state = test.update(float(v), state)
        one_by_one.append(out.statistic)
    np.testing.assert_array_equal(np.array(one_by_one), whole[0].statistic)
    assert isinstance(state, VarianceHoldCUSUMState)


def test_parameters_threshold_and_the_named_detector():
    test = sequential_test("variance-hold", cusum_k=0.4, glr_window=60)
    assert isinstance(test, VarianceHoldCUSUM) and test.k == 0.4 and test.threshold == 1.0
    other = VarianceHoldCUSUM(k=0.3, hold_sigma=2.0, clip=5.0).with_threshold(7.0)
    assert (other.k, other.hold_sigma, other.clip, other.threshold) == (0.3, 2.0, 5.0, 7.0)
    assert other.hold_level_ == 3.5 and "hold_sigma=2.0" in repr(other)
    mean = other.mean_test()
    assert type(mean) is CUSUM and (mean.k, mean.threshold, mean.cap) == (0.3, 7.0, None)
    # the Gaussian threshold is the mean CUSUM's: the variance sum raises no alarm
    assert other.gaussian_threshold(28800.0) == CUSUM(k=0.3).gaussian_threshold(28800.0)
    for bad in ({"hold_sigma": 1.0}, {"clip": 0.5}, {"hold_sigma": "2"}, {"clip": True}):
        with pytest.raises(ValueError, match="above 1"):
            VarianceHoldCUSUM(**bad).run(np.zeros(3))
    with pytest.raises(ValueError, match="variance-hold"):
        sequential_test("variance", cusum_k=0.5, glr_window=60)
    with pytest.raises(ValueError, match="detector state"):
        VarianceHoldCUSUM().run(np.zeros(3), CUSUM().init_state())


def test_the_detector_and_its_state_round_trip_a_model_file(tmp_path, rng):
    test = VarianceHoldCUSUM(hold_sigma=1.4, threshold=9.0)
    e = rng.standard_normal(200) * 1.6
    state = test.run(e)[1]
    detector = model_files.load(model_files.save(test, tmp_path / "detector.npz"))
    saved = model_files.load(model_files.save(state, tmp_path / "state.npz"))
    assert repr(detector) == repr(test) and isinstance(saved, VarianceHoldCUSUMState)
    more = rng.standard_normal(50)
    np.testing.assert_array_equal(
        detector.run(more, saved)[0].statistic, test.run(more, state)[0].statistic
    )


def test_the_variance_hold_adds_no_alarm_and_only_lengthens_them(rng):
    """Same innovations, same threshold: the exceedances are the mean sums' in both, so DD with
    the variance hold is on wherever the plain CUSUM's is, and each of its rising edges is one
    of the plain CUSUM's (the false-alarm budget calibrated on rising edges holds a fortiori)."""
    threshold = 8.0
    longer = 0
    for _ in range(20):
        scale = np.exp(rng.normal(0.0, 0.4, size=(2000, 2)).cumsum(axis=0) * 0.02)
        e = rng.standard_normal((2000, 2)) * scale + rng.normal(0.0, 0.3)
        e[rng.random((2000, 2)) < 0.01] = np.nan
        plain = np.stack([CUSUM(threshold=threshold).run(c)[0].statistic for c in e.T], -1)
        hold = VarianceHoldCUSUM(threshold=threshold)
        held = np.stack([hold.run(c)[0].statistic for c in e.T], -1)
        np.testing.assert_array_equal(plain > threshold, held > threshold)
        decision = DetectionDecision(threshold, 0.0, n_channels=2, hold=5)
        dd_plain, dd_held = decision.run(plain)[0], decision.run(held)[0]
        assert np.all(dd_held[dd_plain])
        rising = lambda dd: np.flatnonzero(dd & ~np.concatenate([[False], dd[:-1]]))  # noqa: E731
        assert set(rising(dd_held)) <= set(rising(dd_plain))
        longer += int(dd_held.sum() > dd_plain.sum())
    assert longer >= 5  # the widening stretches do hold alarms on: the check is not vacuous

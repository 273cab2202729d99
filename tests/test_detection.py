"""Sequential detectors, whitening and thresholds (bayes_fdi.diagnosis: detection, whitening,
thresholds)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from cusum_reference import hand_two_sided_sums
from scipy.linalg import solve_toeplitz

from bayes_fdi.diagnosis.detection.decision import DetectionDecision, detection_decision
from bayes_fdi.diagnosis.detection.detectors import CUSUM, GLR, CUSUMState, GLRState
from bayes_fdi.diagnosis.detection.thresholds import (
    calibrate_threshold,
    cusum_arl,
    cusum_threshold,
    empirical_arl,
)
from bayes_fdi.diagnosis.detection.whitening import ARWhitener, levinson_durbin


def _hand_cusum(e, k, cap):
    """Page's two-sided statistic, NaN where the sample is missing."""
    stat = hand_two_sided_sums(e, k, cap).max(axis=1)
    return np.where(np.isnan(np.asarray(e, dtype=float)), np.nan, stat)


def _hand_glr(e, window):
    """max over the last L <= window samples of (sum)^2 / (2 L), by brute force."""
    seen, out = [], []
    for v in e:
        seen.append(0.0 if math.isnan(v) else v)  # a missing sample: an innovation of 0
        last = seen[-window:]
        best = max(sum(last[-n:]) ** 2 / (2 * n) for n in range(1, len(last) + 1))
        out.append(math.nan if math.isnan(v) else best)
    return np.array(out)


def test_cusum_equals_the_hand_recursion_with_cap_and_gaps(rng):
    e = rng.normal(0.3, 1.0, 3000)
    e[1000:1020] = np.nan
    e[2000:2300] += 3.0  # a shift that reaches the cap
    det = CUSUM(k=0.5, threshold=8.0, cap=20.0)
    out, state = det.run(e)
    want = _hand_cusum(e, 0.5, 20.0)
    # same additions and comparisons in the same order: identical by construction
    np.testing.assert_array_equal(out.statistic, want)
    assert np.nanmax(out.statistic) == 20.0
    assert max(state.sums) == want[-1]  # the state holds the last sums


def test_glr_equals_brute_force(rng):
    e = rng.normal(size=700)
    e[300:320] = np.nan
    e[400:] += 1.0
    got = GLR(window=25, threshold=10.0).run(e)[0].statistic
    want = _hand_glr(e, 25)
    # the kernel sums the same samples in the same (newest-first) order, but the brute force
    # sums oldest-first: agreement to rounding of a 25-term sum of O(1) numbers
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("make", [lambda: CUSUM(k=0.25, threshold=5.0), lambda: GLR(window=30)])
def test_run_equals_update(rng, make):
    e = rng.normal(size=500)
    e[100:105] = np.nan
    det = make()
    whole, end = det.run(e)
    state, stepwise = det.init_state(), []
    for v in e:
        out, state = det.update(v, state)
        stepwise.append(out.statistic)
    # the same compiled kernel on the same state, one sample at a time: identical
    np.testing.assert_array_equal(whole.statistic, stepwise)
    for a, b in zip(end, state, strict=True):
        np.testing.assert_array_equal(a, b)
    # a state continues exactly where it stopped, and the state passed in is not changed
    first, middle = det.run(e[:250])
    kept = [a.copy() for a in middle]
    second, _ = det.run(e[250:], middle)
    joined = np.concatenate([first.statistic, second.statistic])
    np.testing.assert_array_equal(joined, whole.statistic)
    for a, b in zip(middle, kept, strict=True):
        np.testing.assert_array_equal(a, b)


def test_detector_states_are_checked_by_field():
    cusum, glr = CUSUM(), GLR(window=10)
    with pytest.raises(ValueError, match="CUSUMState"):
        cusum.run([0.0], glr.init_state())
    with pytest.raises(ValueError, match=r"buffer must be a float64 array of shape \(10,\)"):
        glr.run([0.0], GLR(window=12).init_state())
    with pytest.raises(ValueError, match="lengths"):
        cusum.run([0.0], CUSUMState(np.zeros(2), np.zeros(3)))
    with pytest.raises(ValueError, match="stored must be a int64"):
        glr.run([0.0], GLRState(np.zeros(10), np.zeros(1), np.zeros(1, dtype=np.int64)))


def test_cusum_onset_estimate_counts_from_the_last_zero(rng):
    e = np.concatenate([np.zeros(50), np.full(10, 3.0)])
    stat, since = CUSUM(k=0.5, threshold=20.0).run(e)[0]
    assert since[49] == 0 and since[-1] == 10  # S+ left 0 at sample 50
    assert stat[-1] == pytest.approx(10 * 2.5)


def test_siegmund_arl_matches_a_one_sided_monte_carlo(rng):
    # one-sided CUSUM by the textbook recursion on white N(0, 1): mean first-passage time
    k, h = 0.5, 3.0
    runs, n = [], 0
    s, t = 0.0, 0
    for v in rng.standard_normal(600_000):
        t += 1
        s = max(0.0, s + v - k)
        if s > h:
            runs.append(t)
            s, t = 0.0, 0
    arl = float(np.mean(runs))
    n = len(runs)
    # Siegmund's correction (b = h + 1.166) is accurate to a few per cent at h = 3 (Siegmund
    # 1985, Table 2.1); the Monte Carlo mean of ~5000 exponential-like run lengths has a
    # relative standard error of 1/sqrt(n) ~ 1.4 %: 8 % covers both with margin
    assert n > 3000
    assert arl == pytest.approx(float(cusum_arl(h, k)), rel=0.08)


def test_two_sided_threshold_meets_its_arl_on_white_noise(rng):
    k, target = 0.5, 400.0
    h = cusum_threshold(target, k, n_sides=2)
    e = rng.standard_normal(1_500_000)
    arl, alarms, samples = empirical_arl(CUSUM(k=k), [e], h, clear=0.0)
    assert samples == e.size and alarms > 2000
    # two one-sided CUSUMs alarm together about twice as often as one (1/ARL2 = 2/ARL1,
    # Lucas & Crosier 1982); with the hysteresis (off only when both sums are 0) an alarm
    # lasts a little longer, so the measured ARL sits slightly above the target: within 15 %
    # (Siegmund's few per cent, the Monte Carlo's 2 %, and the clearing time)
    assert target * 0.95 < arl < target * 1.15


def test_calibrated_threshold_recovers_the_gaussian_one(rng):
    e = [rng.standard_normal((400_000, 2))]
    target = 20_000.0
    got = calibrate_threshold(CUSUM(k=0.5), e, target, grid=np.arange(1.0, 12.01, 0.5))
    want = cusum_threshold(target, 0.5, n_sides=4)
    # extrapolating log ARL linearly from thresholds with >= 10 alarms: within one unit of h
    # (one unit multiplies the ARL by about e^(2k) = 2.7 at k = 0.5)
    assert abs(got["threshold"] - want) < 1.0
    # Siegmund's local slope d log(ARL)/dh is about 2k = 1 here; the fit over low thresholds
    # (where the alarms of the four one-sided sums and the hysteresis interact) is flatter,
    # which extrapolates to a larger, safe threshold
    assert 0 < got["fit"][1] <= 1.2
    floored = calibrate_threshold(CUSUM(k=0.5), e, target, floor=want + 3.0)
    assert floored["threshold"] == want + 3.0


def test_levinson_durbin_matches_the_toeplitz_solve(rng):
    acov = np.array([2.0, 1.2, 0.5, 0.1, -0.05])
    table, var = levinson_durbin(acov, 4)
    for p in range(1, 5):
        want = solve_toeplitz(acov[:p], acov[1 : p + 1])
        np.testing.assert_allclose(table[p, :p], want, rtol=1e-12)
        assert var[p] == pytest.approx(acov[0] - np.dot(want, acov[1 : p + 1]), rel=1e-12)


def test_whitener_recovers_a_known_ar2_process(rng):
    phi = np.array([0.6, -0.3])
    n, runs = 20_000, 4
    z = np.zeros((runs, n))
    eps = rng.standard_normal((runs, n)) * 0.7
    for t in range(2, n):
        z[:, t] = phi[0] * z[:, t - 1] + phi[1] * z[:, t - 2] + eps[:, t]
    w = ARWhitener(max_order=6).fit(z)
    assert w.order_ == 2
    # Yule-Walker estimates have standard error ~ 1/sqrt(80 000) = 0.0035: 5 SE
    np.testing.assert_allclose(w.coef_, phi, atol=0.02)
    assert w.innovation_std_[-1] == pytest.approx(0.7, rel=0.02)
    e = w.run(z[0])[0]
    assert np.std(e[10:]) == pytest.approx(1.0, rel=0.02)
    r1 = np.corrcoef(e[10:-1], e[11:])[0, 1]
    assert abs(r1) < 0.03  # white: lag-1 correlation within ~4 SE of 0
    # innovations are exactly the prediction errors of the fitted predictor
    m = w.mean_
    want = ((z[0, 5] - m) - w.coef_[0] * (z[0, 4] - m) - w.coef_[1] * (z[0, 3] - m)) / (
        w.innovation_std_[2]
    )
    assert e[5] == pytest.approx(want, rel=1e-12)


def test_whitener_restarts_after_a_gap_and_update_equals_run(rng):
    z = rng.normal(size=300)
    w = ARWhitener(order=3).fit(rng.normal(size=(2, 2000)))
    z[100] = np.nan
    whole, end = w.run(z)
    state, stepwise = w.init_state(), []
    for v in z:
        e, state = w.update(v, state)
        stepwise.append(e)
    np.testing.assert_array_equal(whole, stepwise)
    np.testing.assert_array_equal(end.history, state.history)
    assert end.valid[0] == state.valid[0] == 3  # 199 samples since the gap: full order
    with pytest.raises(ValueError, match=r"history must be a float64 array of shape \(3,\)"):
        w.run(z, ARWhitener(order=2).fit(rng.normal(size=(2, 2000))).init_state())
    assert np.isnan(whole[100])
    # the first sample after the gap is predicted at order 0: its own scaled deviation
    assert whole[101] == pytest.approx((z[101] - w.mean_) / w.innovation_std_[0], rel=1e-12)


def test_detection_decision_hysteresis():
    stats = np.array(
        [[0, 0], [5, 1], [11, 0], [6, 2], [0, 3], [0, 0], [np.nan, 12], [np.nan, 0], [0, 0]],
        dtype=float,
    )
    dd = detection_decision(stats, threshold=10.0, clear=0.0)
    # on above 10, off only when both channels are back at 0; a NaN keeps the last value
    assert dd.tolist() == [False, False, True, True, True, False, True, False, False]
    with pytest.raises(ValueError, match="clear"):
        detection_decision(stats, threshold=1.0, clear=2.0)
    # second by second from a carried state: the same
    rule = DetectionDecision(10.0, 0.0)
    state, stepwise = rule.init_state(), []
    for row in stats:
        on, state = rule.update(row, state)
        stepwise.append(on)
    assert stepwise == dd.tolist()
    np.testing.assert_array_equal(state.held, [0.0, 0.0])
    with pytest.raises(ValueError, match="held"):
        DetectionDecision(10.0, 0.0, n_channels=3).run(np.zeros((2, 3)), state)


def test_bad_parameters_are_named():
    with pytest.raises(ValueError, match="threshold"):
        CUSUM(threshold=-1.0).run([0.0])
    with pytest.raises(ValueError, match="window"):
        GLR(window=0).run([0.0])
    with pytest.raises(ValueError, match="not fitted"):
        ARWhitener().run([0.0])


def test_a_gap_decays_the_cusum_as_in_control_seconds_do():
    """Through a gap the sums fall by k a second (no evidence of a fault comes in), so a
    statistic high before a long outage does not carry an alarm across it."""
    det = CUSUM(k=0.5, threshold=20.0)
    e = np.r_[np.full(10, 2.0), np.full(30, np.nan), np.zeros(3)]
    out, state = det.run(e)
    assert tuple(state.sums) == (0.0, 0.0)  # the state carries the decayed sums
    assert out.statistic[9] == 15.0  # ten seconds of 2 - 0.5
    assert np.isnan(out.statistic[10:40]).all()
    # 30 missing seconds take 15 down to 0; the next zeros keep it there
    np.testing.assert_array_equal(out.statistic[40:], [0.0, 0.0, 0.0])
    short = det.run(np.r_[np.full(10, 2.0), np.full(4, np.nan), [0.0]])[0].statistic
    assert short[-1] == 15.0 - 5 * 0.5  # four missing seconds and one zero

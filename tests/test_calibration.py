"""Tests of bayes_fdi.calibration against closed forms, simulation truths and scikit-learn."""

from __future__ import annotations

from types import SimpleNamespace

import matplotlib
import numpy as np
import pytest
from scipy import stats

from bayes_fdi.calibration import (
    StdScaler,
    TemperatureScaler,
    brier,
    crps_gaussian,
    expected_calibration_error,
    interval_coverage,
    log_loss,
    node_calibration,
    pit_histogram,
    pit_values,
    plot_pit_histogram,
    probability_rows,
    reliability_diagram,
)

matplotlib.use("Agg")


def _calibrated_sample(rng, n, k, concentration=1.0):
    """Dirichlet class distributions and labels drawn from them: calibrated by construction."""
    p = rng.dirichlet(np.full(k, concentration), size=n)
    u = rng.random(n)[:, None]
    y = (u > np.cumsum(p, axis=1)).sum(axis=1)
    return np.minimum(y, k - 1), p


def _top_label_sample(rng, n, k, conf, acc):
    """Top class prob ``conf`` (rest spread evenly); the top class is right with prob ``acc``."""
    top = rng.integers(0, k, size=n)
    p = np.repeat(((1 - conf) / (k - 1))[:, None], k, axis=1)
    p[np.arange(n), top] = conf
    correct = rng.random(n) < acc
    other = (top + rng.integers(1, k, size=n)) % k
    return np.where(correct, top, other), p


def _expected_ece_calibrated(res):
    """E|acc - conf| per bin for a calibrated model: sqrt(2/pi) sqrt(c(1-c)/n_b), count-weighted."""
    n_b = res.bin_counts
    c = np.nan_to_num(res.bin_confidence)
    ok = n_b > 0
    return float(np.sum(n_b[ok] / n_b.sum() * np.sqrt(2 / np.pi * c[ok] * (1 - c[ok]) / n_b[ok])))


# ------------------------------------------------------------------------------ ECE
@pytest.mark.parametrize("strategy", ["uniform", "quantile"])
def test_ece_of_calibrated_sampler_is_sampling_noise_only(rng, strategy):
    y, p = _calibrated_sample(rng, 20_000, 4)
    res = expected_calibration_error(
        y, p, n_bins=15, strategy=strategy, n_bootstrap=200, random_state=1
    )
    noise = _expected_ece_calibrated(res)
    # the binned ECE of a calibrated model is its sampling noise, ~ sqrt(2/pi) sigma per bin
    assert res.value < 3 * noise
    # and below twice its worst case: sqrt(2/pi) sqrt(15 bins * 1/4 / 20 000) = 0.011
    assert res.value < 0.02
    # the basic interval reaches down to (about) zero, the true ECE
    assert res.ci_low <= noise
    assert res.ci_low <= res.ci_high
    assert res.debiased < res.value
    assert res.bin_counts.sum() == 20_000
    # noise floor uses sum c(1-c) per bin, <= the c_bar(1-c_bar) version (Jensen), close to it
    assert 0.8 * noise < res.noise_floor <= noise * (1 + 1e-12)


def test_noise_floor_is_the_mean_ece_of_calibrated_models(rng):
    eces, floors = [], []
    for _ in range(40):
        y, p = _calibrated_sample(rng, 2000, 3)
        r = expected_calibration_error(y, p, n_bins=10)
        eces.append(r.value)
        floors.append(r.noise_floor)
    # one calibrated ECE (10 bins of ~200 runs) is a sum of half-normal bin gaps: relative sd
    # about sqrt(pi/2 - 1) / sqrt(10) = 0.24; the mean of 40 has 0.038, so 0.12 is 3 sd
    assert np.mean(eces) == pytest.approx(np.mean(floors), rel=0.12)


def test_basic_bootstrap_interval_covers_the_true_ece(rng):
    hits_basic = hits_pct = 0
    reps = 40
    for i in range(reps):
        conf = rng.uniform(0.6, 1.0, size=1500)
        y, p = _top_label_sample(rng, conf.size, 3, conf, conf - 0.1)
        kw = {"n_bins": 10, "n_bootstrap": 150, "random_state": i}
        basic = expected_calibration_error(y, p, **kw)
        pct = expected_calibration_error(y, p, ci_method="percentile", **kw)
        hits_basic += basic.ci_low <= 0.1 <= basic.ci_high
        hits_pct += pct.ci_low <= 0.1 <= pct.ci_high
        assert pct.value == basic.value
    # nominal 95 %: the hit rate of 40 replicates has sd sqrt(0.95 * 0.05 / 40) = 0.034, so
    # 0.85 is 2.9 sd below nominal
    assert hits_basic / reps >= 0.85
    assert hits_basic >= hits_pct


def test_ece_of_constant_overconfidence_is_the_shift(rng):
    conf = rng.uniform(0.6, 1.0, size=100_000)
    y, p = _top_label_sample(rng, conf.size, 3, conf, conf - 0.1)
    res = expected_calibration_error(y, p, n_bins=10, n_bootstrap=100, random_state=0)
    # conf ~ U(0.6, 1) fills 4 bins of 25 000 runs; each bin's gap has sd
    # sqrt(0.8 * 0.2 / 25 000) = 0.0025, their weighted mean 0.0013: 0.006 is 4.6 sd
    assert res.value == pytest.approx(0.1, abs=0.006)
    assert res.ci_low < 0.1 < res.ci_high or abs(res.value - 0.1) < 0.004
    # every non-empty bin is over-confident by ~0.1, so MCE ~ 0.1 too (the largest of 4 bin
    # gaps of sd 0.0025: 0.03 is 12 sd, it only has to tell 0.1 from other gaps)
    assert res.mce == pytest.approx(0.1, abs=0.03)


@pytest.mark.parametrize("strategy,n_bins", [("uniform", 7), ("quantile", 12)])
def test_ece_of_one_signed_miscalibration_is_mean_gap(rng, strategy, n_bins):
    # accuracy = conf**2 <= conf: every bin has the same sign of gap, so the binned ECE equals
    # E[conf] - E[conf**2] for any binning. conf ~ U(0.6, 1): 0.8 - 0.784/1.2.
    conf = rng.uniform(0.6, 1.0, size=200_000)
    y, p = _top_label_sample(rng, conf.size, 5, conf, conf**2)
    res = expected_calibration_error(y, p, n_bins=n_bins, strategy=strategy)
    # sampling sd of the binned gap sum: sqrt(E[c^2 (1 - c^2)] / 200 000) = 0.001; 0.004 = 4 sd
    assert res.value == pytest.approx(0.8 - 0.784 / 1.2, abs=0.004)


def test_equal_mass_bins_have_equal_counts(rng):
    y, p = _calibrated_sample(rng, 1003, 3)
    # ties: round probabilities coarsely and renormalise
    p = np.round(p, 1)
    p[:, -1] = 1 - p[:, :-1].sum(axis=1)
    p = np.clip(p, 0, 1)
    p /= p.sum(axis=1, keepdims=True)
    res = expected_calibration_error(y, p, n_bins=10, strategy="quantile")
    assert res.bin_counts.max() - res.bin_counts.min() <= 1
    assert res.bin_counts.sum() == 1003
    assert np.all(np.diff(res.bin_edges) >= 0)
    # bins ordered by confidence
    assert np.all(np.diff(res.bin_confidence) >= 0)


def test_uniform_bins_match_sklearn_calibration_curve(rng):
    from sklearn.calibration import calibration_curve

    y, p = _calibrated_sample(rng, 3000, 2, concentration=0.7)
    # bias it so that the ECE is not tiny
    p1 = p[:, 1] ** 0.7
    p2 = np.column_stack([1 - p1, p1])
    res = expected_calibration_error(y, p2, classes=[0, 1], n_bins=10, classwise=True)
    prob_true, prob_pred = calibration_curve(y, p1, n_bins=10, strategy="uniform")
    counts = res.bin_counts[1]
    ok = counts > 0
    # the same bin means (scikit-learn's own, see metrics._sklearn_reliability): rounding only
    np.testing.assert_allclose(res.bin_accuracy[1][ok], prob_true, rtol=1e-12)
    np.testing.assert_allclose(res.bin_confidence[1][ok], prob_pred, rtol=1e-12)
    ece_sklearn = np.sum(counts[ok] / counts.sum() * np.abs(prob_true - prob_pred))
    # for two classes the classwise ECE of class 0 equals that of class 1 (bins mirror); the
    # mirrored bins of class 0 are summed in another order, hence rounding, far inside 1e-9
    assert res.value == pytest.approx(ece_sklearn, rel=1e-9)


def test_classwise_vs_top_label_on_two_classes(rng):
    n = 40_000
    # class 1 always on top (p >= 0.5): top-label and classwise ECE coincide exactly
    p1 = rng.uniform(0.55, 0.95, size=n)
    y = (rng.random(n) < p1 - 0.05).astype(int)
    p = np.column_stack([1 - p1, p1])
    top = expected_calibration_error(y, p, n_bins=10)
    cw = expected_calibration_error(y, p, n_bins=10, classwise=True)
    assert cw.value == pytest.approx(top.value, rel=1e-12)  # same sums, another order
    # gaps that cancel in the top-label view but not per class:
    # p1 = 0.7 with P(y=1) = 0.8 (top-label gap +0.1), p1 = 0.3 with P(y=1) = 0.4 (gap -0.1)
    high = rng.random(n) < 0.5
    p1 = np.where(high, 0.7, 0.3)
    y = (rng.random(n) < np.where(high, 0.8, 0.4)).astype(int)
    p = np.column_stack([1 - p1, p1])
    top = expected_calibration_error(y, p, n_bins=10)
    cw = expected_calibration_error(y, p, n_bins=10, classwise=True)
    # both kinds of run fall in the 0.7 bin, whose top-label gap is 0 in expectation with sd
    # sqrt(0.24 / 40 000) = 0.0024 (0.01 = 4 sd); each class's gaps are 0.1 with the same sd
    assert top.value < 0.01
    assert cw.value == pytest.approx(0.1, abs=0.01)
    assert cw.bin_counts.shape == (2, 10)


def test_ece_bootstrap_is_seeded(rng):
    y, p = _calibrated_sample(rng, 500, 3)
    a = expected_calibration_error(y, p, n_bootstrap=50, random_state=7)
    b = expected_calibration_error(y, p, n_bootstrap=50, random_state=7)
    assert (a.ci_low, a.ci_high) == (b.ci_low, b.ci_high)
    assert np.isnan(expected_calibration_error(y, p).ci_low)


def test_ece_string_labels_and_class_order(rng):
    y, p = _calibrated_sample(rng, 2000, 3)
    names = np.array(["fn", "f1", "f2"])
    res_a = expected_calibration_error(names[y], p, classes=names, classwise=True)
    res_b = expected_calibration_error(y, p, classes=[0, 1, 2], classwise=True)
    assert res_a.value == pytest.approx(res_b.value)  # the same numbers, labels renamed
    # default classes are the sorted labels, which would misalign these columns
    res_c = expected_calibration_error(names[y], p, classwise=True)
    assert res_c.value > res_a.value + 0.05


@pytest.mark.parametrize(
    "kwargs,msg",
    [
        ({"proba": np.array([[0.5, 0.6]])}, "sum to 1"),
        ({"proba": np.array([[np.nan, 1.0]])}, "NaN"),
        ({"proba": np.array([[0.5, 0.5, 0.0]])}, "columns"),
        ({"strategy": "kmeans"}, "strategy"),
        ({"n_bins": 0}, "n_bins"),
    ],
)
def test_ece_rejects_bad_input(kwargs, msg):
    args = {"y_true": np.array([0]), "proba": np.array([[0.3, 0.7]])}
    args.update(kwargs)
    y = args.pop("y_true")
    p = args.pop("proba")
    with pytest.raises(ValueError, match=msg):
        expected_calibration_error(y, p, classes=[0, 1], **args)


def test_probabilities_off_the_unit_interval_by_rounding_are_held_there():
    # as a forest's leaf shares averaged over its trees and summed over a group can be
    over = np.array([[np.nextafter(1.0, 2.0), 0.0]])
    held = probability_rows(over)
    np.testing.assert_array_equal(held, [[1.0, 0.0]])
    assert over[0, 0] > 1.0  # the caller's array is left as it was
    ece = expected_calibration_error([0, 1], np.vstack([over, [0.3, 0.7]]), classes=[0, 1])
    same = expected_calibration_error([0, 1], np.vstack([held, [0.3, 0.7]]), classes=[0, 1])
    assert ece.value == same.value == pytest.approx(0.15)  # |1 - 1| and |1 - 0.7|, halved
    ts = TemperatureScaler().fit(np.array([[0.7, 0.3], [0.2, 0.8]]), [0, 1])
    np.testing.assert_array_equal(ts.transform(over), ts.transform(held))
    # more than rounding is an error naming how far
    for bad in ([[1.0 + 1e-6, -1e-6]], [[-1e-6, 1.0 + 1e-6]]):
        with pytest.raises(ValueError, match=r"must lie in \[0, 1\] \(an entry lies 1e-06 outside"):
            probability_rows(np.array(bad))
        with pytest.raises(ValueError, match=r"must lie in \[0, 1\]"):
            ts.transform(np.array(bad))


# ------------------------------------------------------------------------------ scores
def test_brier_and_log_loss_closed_forms():
    y = np.array(["f2", "fn", "f1"])
    classes = ["fn", "f1", "f2"]  # tree order, not sorted
    p = np.array([[0.1, 0.2, 0.7], [0.6, 0.3, 0.1], [0.25, 0.5, 0.25]])
    want_brier = np.mean([0.01 + 0.04 + 0.09, 0.16 + 0.09 + 0.01, 0.0625 + 0.25 + 0.0625])
    assert brier(y, p, classes=classes) == pytest.approx(want_brier)
    assert brier(y, p, classes=classes, scale_by_half=True) == pytest.approx(want_brier / 2)
    assert log_loss(y, p, classes=classes) == pytest.approx(-np.mean(np.log([0.7, 0.6, 0.5])))


# ------------------------------------------------------------------------------ temperature
def _tempered(logits: np.ndarray, temperature: float) -> np.ndarray:
    """``softmax(logits / temperature)`` row by row."""
    p = np.exp((logits - logits.max(axis=1, keepdims=True)) / temperature)
    return p / p.sum(axis=1, keepdims=True)


def _softmax_labels(rng, n: int, k: int):
    """Logits ``(n, k)``, their softmax and labels drawn from it: a calibrated model's data."""
    logits = rng.normal(scale=2.0, size=(n, k))
    p_true = _tempered(logits, 1.0)
    y = (rng.random(n)[:, None] > np.cumsum(p_true, axis=1)).sum(axis=1).clip(max=k - 1)
    return logits, p_true, y


def test_temperature_scaling_recovers_known_temperature(rng):
    logits, p_true, y = _softmax_labels(rng, 20_000, 5)
    # an over-confident model reports softmax(logits / 0.5); the right fix is T = 0.5 back... i.e. 2
    hot = _tempered(logits, 0.5)
    ts = TemperatureScaler().fit(hot, y)
    # maximum likelihood on 20 000 runs: the inverse temperature's standard error is about
    # 1 / sqrt(n * Fisher information) ~ 0.5 %; 5 % is 10 se and still tells 2 from 1.5 or 2.5
    assert ts.temperature_ == pytest.approx(2.0, rel=0.05)
    assert ts.nll_after_ < ts.nll_before_
    q = ts.transform(hot)
    np.testing.assert_allclose(q.sum(axis=1), 1.0, atol=1e-12)
    np.testing.assert_array_equal(q.argmax(axis=1), hot.argmax(axis=1))
    # T within 5 % of 2 moves a probability by at most ~0.25 * |log-odds| * 5 % < 0.02
    np.testing.assert_allclose(q, p_true, atol=0.02)
    before = expected_calibration_error(y, hot).value
    after = expected_calibration_error(y, q).value
    # recalibrated: sampling noise only (worst case 0.011, as above); the hot model's ECE is
    # an order of magnitude above it
    assert after < 0.02 < before
    # logits input gives the same temperature
    ts2 = TemperatureScaler(input="logits").fit(logits / 0.5, y)
    # the same likelihood, minimised to Brent's tolerance 1e-8 in 1/T from another start
    assert ts2.temperature_ == pytest.approx(ts.temperature_, rel=1e-3)


def test_a_lower_bound_of_one_softens_but_never_sharpens(rng):
    logits, _, y = _softmax_labels(rng, 20_000, 5)
    # an under-confident model reports softmax(logits / 2): its maximum-likelihood fix is
    # T = 0.5 (within 5 %, ten standard errors on 20 000 runs, as above)
    cold = _tempered(logits, 2.0)
    free = TemperatureScaler().fit(cold, y)
    assert free.temperature_ == pytest.approx(0.5, rel=0.05) and not free.at_bound_
    # bounded below by 1: the NLL is convex in 1/T with its minimum outside the interval, so
    # the bounded optimum is the bound (Brent's tolerance 1e-8 on 1/T) and flagged
    floor = TemperatureScaler(bounds=(1.0, 50.0)).fit(cold, y)
    assert floor.temperature_ == pytest.approx(1.0, abs=1e-6) and floor.at_bound_
    np.testing.assert_allclose(floor.transform(cold), cold, atol=1e-6)
    # an over-confident model is still softened as without the bound
    hot = _tempered(logits, 0.5)
    bounded, unbounded = TemperatureScaler(bounds=(1.0, 50.0)).fit(hot, y), TemperatureScaler()
    assert bounded.temperature_ == pytest.approx(unbounded.fit(hot, y).temperature_, rel=1e-6)
    assert not bounded.at_bound_


def test_temperature_of_calibrated_model_is_one(rng):
    y, p = _calibrated_sample(rng, 20_000, 4, concentration=0.5)
    ts = TemperatureScaler().fit(p, y)
    # calibrated by construction: the MLE of T is 1 up to its standard error (~1 % on 20 000
    # runs); 0.05 is 5 se
    assert ts.temperature_ == pytest.approx(1.0, abs=0.05)


def test_temperature_scaler_handles_zero_probabilities(rng):
    p = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.5, 0.5, 0.0], [0.0, 0.0, 1.0]])
    y = np.array([0, 0, 1, 2])  # second row: an impossible class happened
    ts = TemperatureScaler(floor=1e-6).fit(p, y)
    q = ts.transform(p)
    assert np.all(np.isfinite(q)) and np.all(q > 0)
    np.testing.assert_allclose(q.sum(axis=1), 1.0)
    np.testing.assert_array_equal(q.argmax(axis=1), p.argmax(axis=1))
    # hand check of the floor: logit of 0 is log(1e-6)
    z = np.log(np.maximum(p[0], 1e-6)) / ts.temperature_
    np.testing.assert_allclose(q[0], np.exp(z) / np.exp(z).sum())
    assert ts.temperature_ > 1  # it must soften to make the impossible possible


def test_temperature_scaler_rejects_bad_input():
    with pytest.raises(ValueError, match="not fitted"):
        TemperatureScaler().transform(np.array([[0.5, 0.5]]))
    with pytest.raises(ValueError, match="sum to 1"):
        TemperatureScaler().fit(np.array([[0.5, 0.6]]), [0])
    with pytest.raises(ValueError, match="classes"):
        TemperatureScaler(classes=[0, 1, 2]).fit(np.array([[0.5, 0.5]]), [0])
    assert TemperatureScaler(floor=1e-9).get_params()["floor"] == 1e-9
    p, y = np.array([[0.7, 0.3], [0.2, 0.8]]), [0, 1]
    for bounds in [(2.0, 1.0), (0.0, 50.0), (1.0, np.inf), (np.nan, 2.0)]:
        with pytest.raises(ValueError, match=r"bounds must satisfy 0 < low < high < inf"):
            TemperatureScaler(bounds=bounds).fit(p, y)


# ------------------------------------------------------------------------------ nodes
class _LogisticNode:
    """A binary 'estimator' with a known P(right | x) = sigmoid(a x)."""

    def __init__(self, a, classes=(0, 1)):
        self.a = a
        self.classes_ = np.array(classes)

    def predict_proba(self, X):
        p1 = 1 / (1 + np.exp(-self.a * X[:, 0]))
        cols = {1: p1, 0: 1 - p1}
        return np.column_stack([cols[int(c)] for c in self.classes_])


def test_node_calibration_on_known_nodes(rng):
    n = 30_000
    x = rng.normal(size=(n, 1))
    # true P(right)=sigmoid(x). Node 0 (fn | f1,f2) is calibrated; node 1 (f1 | f2) is
    # over-confident (slope 3 instead of 1). Labels drawn from the true model.
    right0 = rng.random(n) < 1 / (1 + np.exp(-x[:, 0]))
    right1 = rng.random(n) < 1 / (1 + np.exp(-x[:, 0]))
    y = np.where(~right0, "fn", np.where(right1, "f2", "f1"))
    nodes = [
        SimpleNamespace(left=("fn",), right=("f1", "f2"), estimator=_LogisticNode(1.0)),
        SimpleNamespace(left=("f1",), right=("f2",), estimator=_LogisticNode(3.0, (1, 0))),
        SimpleNamespace(left=("f7",), right=("f8",), estimator=_LogisticNode(1.0)),
    ]
    res = node_calibration(nodes, x, y, n_bins=10)
    assert res[0].n_samples == n
    assert res[1].n_samples == int(right0.sum())
    # calibrated node: sampling noise, at most sqrt(2/pi) sqrt(10 * 1/4 / 30 000) = 0.007;
    # the slope-3 node is off by ~0.1 in its outer bins
    assert res[0].ece.value < 0.02
    assert res[1].ece.value > 0.05
    # log loss of the calibrated node ~ the conditional entropy E[H(sigmoid(x))]
    s = 1 / (1 + np.exp(-x[:, 0]))
    ent = -np.mean(s * np.log(s) + (1 - s) * np.log(1 - s))
    # the mean of 30 000 log losses of sd ~0.4 has sd 0.0023: 0.01 is 4 sd
    assert res[0].log_loss == pytest.approx(ent, abs=0.01)
    assert res[2].n_samples == 0 and res[2].ece is None and np.isnan(res[2].brier)


# ------------------------------------------------------------------------------ regression
def test_interval_coverage_of_exact_gaussian_draws(rng):
    n = 50_000
    mean = rng.normal(size=n)
    std = rng.uniform(0.1, 2.0, size=n)
    y = mean + std * rng.normal(size=n)
    res = interval_coverage(y, mean, std)
    se = np.sqrt(res.levels * (1 - res.levels) / n)
    assert np.all(np.abs(res.coverage - res.levels) < 4 * se)
    z = stats.norm.ppf(0.5 + res.levels / 2)
    np.testing.assert_allclose(res.mean_width, 2 * z * std.mean())
    assert res.n == n
    assert set(res.as_dict()) == {"50%", "80%", "90%", "95%"}
    # a model with half the right std under-covers: P(|Z| <= z/2)
    half = interval_coverage(y, mean, std / 2)
    want = 2 * stats.norm.cdf(z / 2) - 1
    assert np.all(np.abs(half.coverage - want) < 5 * se)


def test_pit_of_correct_model_is_uniform_and_of_wrong_model_is_not(rng):
    n = 5000
    mean = rng.normal(size=n)
    y = mean + rng.normal(size=n)
    u = pit_values(y, mean, 1.0)
    assert stats.kstest(u, "uniform").pvalue > 0.01
    density, edges = pit_histogram(u, 10)
    assert np.allclose(np.sum(density * np.diff(edges)), 1.0)
    assert stats.kstest(pit_values(y, mean, 0.5), "uniform").pvalue < 1e-6
    ax = plot_pit_histogram(u)
    bars = ax.containers[0]
    np.testing.assert_allclose([b.get_height() for b in bars], density)


def test_crps_closed_form_matches_monte_carlo(rng):
    # CRPS(F, y) = E|X - y| - 0.5 E|X - X'| for X, X' ~ F
    for mu, sigma, y in [(0.0, 1.0, 0.3), (2.0, 0.5, -1.0), (-1.0, 3.0, 4.0)]:
        x = mu + sigma * rng.normal(size=400_000)
        xp = mu + sigma * rng.normal(size=400_000)
        mc = np.mean(np.abs(x - y)) - 0.5 * np.mean(np.abs(x - xp))
        # Monte Carlo with 400 000 draws: sd of the estimate about 1.2 sigma / sqrt(4e5)
        # = 0.002 sigma; 0.01 sigma is 5 sd
        assert crps_gaussian(y, mu, sigma) == pytest.approx(mc, abs=0.01 * sigma)
    # std -> 0: absolute error
    assert crps_gaussian(1.0, 0.2, 1e-9) == pytest.approx(0.8, abs=1e-6)


def test_regression_metrics_reject_nan_and_bad_std():
    with pytest.raises(ValueError, match="NaN"):
        interval_coverage([1.0, np.nan], [0.0, 0.0], [1.0, 1.0])
    with pytest.raises(ValueError, match="positive"):
        crps_gaussian([1.0], [0.0], [0.0])
    with pytest.raises(ValueError, match="levels"):
        interval_coverage([1.0], [0.0], [1.0], levels=(0.5, 1.0))


# ------------------------------------------------------------------------------ plotting
def test_reliability_diagram_draws_bins_with_counts(rng):
    y, p = _calibrated_sample(rng, 2000, 3)
    res = expected_calibration_error(y, p, n_bins=10, n_bootstrap=20, random_state=0)
    ax = reliability_diagram(res)
    n_nonempty = int(np.sum(res.bin_counts > 0))
    count_texts = [t.get_text() for t in ax.texts]
    assert sorted(int(t) for t in count_texts) == sorted(res.bin_counts[res.bin_counts > 0])
    assert len(count_texts) == n_nonempty
    assert "ECE" in ax.get_title()
    ax2 = reliability_diagram(y, p, n_bins=5, classwise=True)
    assert "classwise" in ax2.get_title()
    with pytest.raises(ValueError, match="proba"):
        reliability_diagram(y)


def test_reliability_diagram_classwise_quantile_needs_a_class(rng):
    y, p = _calibrated_sample(rng, 600, 3)
    res = expected_calibration_error(y, p, n_bins=5, strategy="quantile", classwise=True)
    with pytest.raises(ValueError, match="class_index"):
        reliability_diagram(res)
    ax = reliability_diagram(res, class_index=2)
    assert sorted(int(t.get_text()) for t in ax.texts) == sorted(res.bin_counts[2])


@pytest.mark.parametrize("method", ["mle", "coverage"])
def test_std_scaler_recovers_a_known_factor(rng, method):
    n = 40_000
    mean = rng.normal(size=n)
    true_std = rng.uniform(0.5, 2.0, size=n)
    y = mean + true_std * rng.normal(size=n)
    stated = true_std / 1.6  # an over-confident model: every std 1.6 times too small
    sc = StdScaler(method=method).fit(y[: n // 2], mean[: n // 2], stated[: n // 2])
    # a scale fitted on 20 000 standardised residuals: relative se 1/sqrt(2n) = 0.5 % (MLE),
    # a few times that for the 95 % coverage quantile; 3 % covers both
    assert sc.scale_ == pytest.approx(1.6, rel=0.03)
    cov = interval_coverage(y[n // 2 :], mean[n // 2 :], sc.transform(stated[n // 2 :]))
    se = np.sqrt(cov.levels * (1 - cov.levels) / (n // 2))
    assert np.all(np.abs(cov.coverage - cov.levels) < 5 * se + 0.005)
    with pytest.raises(ValueError, match="not fitted"):
        StdScaler().transform([1.0])


def test_node_calibration_uses_the_nodes_own_scaling(rng):
    """On a tree whose nodes standardise their inputs, the per-node scores must be those of
    the probabilities the tree itself computes (`node_probabilities`)."""
    from sklearn.linear_model import LogisticRegression

    from bayes_fdi.calibration import node_calibration
    from bayes_fdi.diagnosis.isolation.tree import HierarchicalClassifier

    centres = {"a": (0.0, 0.0), "b": (0.03, 0.0), "c": (0.0, 0.03)}
    y = np.repeat(list(centres), 60)
    X = np.array([centres[k] for k in y]) + 0.004 * rng.standard_normal((y.size, 2))
    tree = HierarchicalClassifier(LogisticRegression(), random_state=0).fit(X, y)
    assert all(n.scaler is not None for n in tree.nodes_)
    default = node_calibration(tree.nodes_, X, y)
    own = tree.node_probabilities(X)
    exact = node_calibration(tree.nodes_, X, y, p_right=lambda n, Z: own[:, n.index][_rows(n, y)])
    for a, b in zip(default, exact, strict=True):
        # the same probabilities computed along two paths: equal up to rounding
        assert a.accuracy == pytest.approx(b.accuracy)
        assert a.log_loss == pytest.approx(b.log_loss)
    assert min(r.accuracy for r in default) > 0.95


def _rows(node, y):
    return np.isin(y, [*node.left, *node.right])

"""Tools of benchmarks/calibration_families.py, checked against independent computations."""

from __future__ import annotations

import numpy as np
from benchmark_scripts import load_benchmark

from bayes_fdi.calibration import TemperatureScaler

bench = load_benchmark("calibration_families")


def test_trailing_std_is_the_population_std_of_the_trailing_window():
    rng = np.random.default_rng(0)
    values = rng.normal(size=(3, 40))
    got = bench.trailing_std(values, 7)
    for r in range(3):
        for t in range(40):
            window = values[r, max(0, t - 6) : t + 1]
            assert abs(got[r, t] - np.std(window)) < 1e-12  # rounding of a 7-term sum


def test_variance_since_detection_restarts_at_each_rising_edge():
    values = np.arange(12, dtype=float)[None, :] ** 1.5
    detected = np.array([[0, 1, 1, 1, 0, 0, 1, 1, 1, 1, 0, 1]], dtype=bool)
    values[0, 8] = np.nan  # skipped, as the signature window skips a NaN second
    got = bench.variance_since_detection(values, detected)[0]
    want = np.full(12, np.nan)
    for start, end in ((1, 4), (6, 10), (11, 12)):
        for t in range(start, end):
            seen = values[0, start : t + 1]
            want[t] = np.var(seen[np.isfinite(seen)])
    assert np.array_equal(np.isnan(got), np.isnan(want))
    ok = np.isfinite(want)
    assert np.allclose(got[ok], want[ok], rtol=0, atol=1e-9)  # sums of squares up to 1331


def test_mean_since_detection_restarts_at_each_rising_edge():
    values = np.array([[3.0, -1.0, 2.0, 4.0, 7.0, 5.0, np.nan, 1.0, -3.0]])
    detected = np.array([[0, 1, 1, 1, 0, 1, 1, 1, 1]], dtype=bool)
    got = bench.mean_since_detection(values, detected)[0]
    # off at 0 and 4; from 1: -1, (-1+2)/2, (-1+2+4)/3; from 5: 5, 5 (NaN skipped), 3, 1
    want = np.array([np.nan, -1.0, 0.5, 5 / 3, np.nan, 5.0, 5.0, 3.0, 1.0])
    assert np.array_equal(np.isnan(got), np.isnan(want))
    ok = np.isfinite(want)
    assert np.allclose(got[ok], want[ok], rtol=0, atol=1e-15)  # sums of a few small numbers


def test_strength_covariates_are_the_standardised_residual_means_since_detection():
    import xarray as xr

    dd = np.array([[0, 1, 1, 0, 1]], dtype=bool)
    x = np.array([[0.6, 0.7, -0.1, 0.5, 0.8]])
    x_hat = np.full((1, 5), 0.5)  # residuals 0.1, 0.2, -0.6, 0, 0.3
    f = np.array([[2.0, -1.0, -3.0, 1.0, 2.0]])
    f_hat = np.full((1, 5), 1.0)  # residuals 1, -2, -4, 0, 1
    std_x, std_f = np.full((1, 5), 0.1), np.full((1, 5), 2.0)
    dims = ("run", "time")
    runs = xr.Dataset({"X": (dims, x), "F": (dims, f)})
    stream = xr.Dataset(
        {
            k: (dims, v)
            for k, v in {"DD": dd, "X_hat": x_hat, "F_hat": f_hat, "X_hat_std": std_x,
                         "F_hat_std": std_f}.items()
        }
    )  # fmt: skip
    got = bench.covariates_of(runs, stream, 120, "strength")[0]
    # X: 2, then |(2 - 6) / 2|, off, 3; F: 1, |(-1 - 2) / 2|, off, 0.5
    want = np.array([[np.nan, np.nan], [2.0, 1.0], [2.0, 1.5], [np.nan, np.nan], [3.0, 0.5]])
    assert np.array_equal(np.isnan(got), np.isnan(want))
    assert np.allclose(got[np.isfinite(want)], want[np.isfinite(want)], rtol=1e-12)


def test_scaled_is_a_temperature_scaling_row_by_row():
    rng = np.random.default_rng(1)
    proba = rng.dirichlet(np.ones(4), size=50)
    log_t = np.full(50, np.log(2.0))
    want = proba**0.5 / (proba**0.5).sum(axis=1, keepdims=True)
    assert np.allclose(bench.scaled(np.log(proba), log_t), want, rtol=0, atol=1e-12)


def test_input_temperature_recovers_a_temperature_that_follows_a_covariate():
    # labels drawn from softmax(z / T) with log T = 0.5 - 0.8 c: the maximum-likelihood fit of
    # log T = [1, c] @ w recovers w within its sampling error (40 000 rows: about 0.02)
    rng = np.random.default_rng(2)
    n, k = 40_000, 5
    z = rng.normal(scale=2.0, size=(n, k))
    c = rng.uniform(-1.0, 1.0, size=n)
    w_true = np.array([0.5, -0.8])
    design = np.column_stack([np.ones(n), c])
    p = bench.scaled(z, design @ w_true)
    true = (p.cumsum(axis=1) > rng.uniform(size=(n, 1))).argmax(axis=1)
    w = bench.fit_input_temperature(z, true, design)
    assert np.allclose(w, w_true, atol=0.06)


def test_input_temperature_without_covariates_is_the_temperature_scaler():
    rng = np.random.default_rng(3)
    n, k = 5000, 4
    logits = rng.normal(scale=3.0, size=(n, k))
    proba = np.exp(logits) / np.exp(logits).sum(axis=1, keepdims=True)
    true = (bench.scaled(np.log(proba), np.full(n, np.log(1.7))).cumsum(axis=1)
            > rng.uniform(size=(n, 1))).argmax(axis=1)  # fmt: skip
    w = bench.fit_input_temperature(np.log(proba), true, np.ones((n, 1)))
    scaler = TemperatureScaler(classes=list(range(k))).fit(proba, true)
    # two optimisers of the same one-parameter likelihood
    assert abs(np.exp(w[0]) - scaler.temperature_) < 1e-3 * scaler.temperature_


def test_scores_on_a_hand_computed_case():
    proba = np.array([[0.9, 0.1], [0.8, 0.2], [0.3, 0.7], [0.4, 0.6]])
    true = np.array([0, 1, 1, 1])
    got = bench.scores(proba, true, [0, 1])
    assert got["accuracy"] == 0.75
    assert abs(got["confidence"] - 0.75) < 1e-12
    # 15 equal bins: {0.9}: 1 right; {0.8}: wrong; {0.7}: right; {0.6}: right
    want = (abs(0.9 - 1) + abs(0.8 - 0) + abs(0.7 - 1) + abs(0.6 - 1)) / 4
    assert abs(got["ece"] - want) < 1e-12

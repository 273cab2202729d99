"""Tests of DirichletScaler / cross_val_log_loss against known distortions and closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from bayes_fdi.calibration import (
    DirichletScaler,
    TemperatureScaler,
    cross_val_log_loss,
    expected_calibration_error,
    log_loss,
)
from bayes_fdi.calibration.recalibration import LOG_LOSS_RTOL


@pytest.fixture
def rng():
    return np.random.default_rng(20261122)


def _calibrated(rng, n, k, concentration=1.0):
    """Class distributions and labels drawn from them: calibrated by construction."""
    p = rng.dirichlet(np.full(k, concentration), size=n)
    y = (rng.random(n)[:, None] > np.cumsum(p, axis=1)).sum(axis=1)
    return np.minimum(y, k - 1), p


def _softmax(z):
    e = np.exp(z - z.max(axis=1, keepdims=True))
    return e / e.sum(axis=1, keepdims=True)


def _centred(w):
    """W up to its gauge: a constant added to a column does not change the map."""
    return w - w.mean(axis=0, keepdims=True)


K = 4
# A known Dirichlet distortion log p_obs = A log p_true + c (+ normaliser). The rows of A sum
# to the same constant, so A^{-1} maps the normaliser to a shift of all logits and the exact
# inverse is the Dirichlet map W = A^{-1}, b = -A^{-1} c.
A = 1.8 * np.eye(K) + 0.4 * (np.roll(np.eye(K), 1, axis=1) - np.eye(K))
C = np.array([0.5, -0.3, 0.0, -0.2])


def test_dirichlet_scaler_inverts_a_known_dirichlet_distortion(rng):
    y, p_true = _calibrated(rng, 30_000, K)
    p_obs = _softmax(np.log(p_true) @ A.T + C)
    ds = DirichletScaler(random_state=0).fit(p_obs[:20_000], y[:20_000])
    q = ds.transform(p_obs[20_000:])
    y_te = y[20_000:]
    # the recalibrated probabilities are the true ones (up to the estimation error of W, b:
    # 20 parameters from 20 000 runs, standard errors about 0.01-0.02 in the log-odds, which
    # move a probability by at most a quarter of that on average; the max is over 10 000 runs)
    err = np.abs(q - p_true[20_000:])
    assert err.mean() < 0.01 and err.max() < 0.1
    np.testing.assert_allclose(q.sum(axis=1), 1.0, atol=1e-12)
    before = expected_calibration_error(y_te, p_obs[20_000:], classes=range(K))
    after = expected_calibration_error(y_te, q, classes=range(K))
    # the noise floor is the expected ECE of a calibrated model with these bins; a calibrated
    # ECE exceeds twice its expectation rarely (sd of one ECE about 0.3 of its mean)
    assert before.value > 5 * before.noise_floor
    assert after.value < 2 * after.noise_floor
    # and the map is the inverse of the distortion (up to the gauge)
    w_true = np.linalg.inv(A)
    # entries of W estimated from 20 000 runs with standard errors ~0.015 (and a mild ODIR
    # shrinkage): 0.06 is about 4 se
    np.testing.assert_allclose(_centred(ds.coef_), _centred(w_true), atol=0.06)
    b_true = -w_true @ C
    np.testing.assert_allclose(
        ds.intercept_ - ds.intercept_.mean(), b_true - b_true.mean(), atol=0.06
    )
    assert ds.converged_ and ds.fallback_ is None
    assert set(ds.cv_results_) == set(ds.reg_grid)
    # the chosen penalty scores the lowest (ties within LOG_LOSS_RTOL go to the larger one)
    best = min(ds.cv_results_.values())
    assert ds.cv_results_[ds.reg_lambda_] <= best * (1 + LOG_LOSS_RTOL)
    assert ds.nll_after_ < ds.nll_before_


def test_dirichlet_scaler_is_the_identity_on_calibrated_input(rng):
    y, p = _calibrated(rng, 20_000, K)
    ds = DirichletScaler(random_state=0).fit(p[:10_000], y[:10_000])
    q = ds.transform(p[10_000:])
    # the identity is the truth; what is left is the estimation error of W and b from 10 000
    # runs (se ~0.02 per entry: atol 0.05 is 2.5 se for the largest of 16 entries) and its
    # effect on the probabilities (at most a quarter of the log-odds error: 0.03)
    np.testing.assert_allclose(q, p[10_000:], atol=0.03)
    np.testing.assert_allclose(_centred(ds.coef_), _centred(np.eye(K)), atol=0.05)
    # in-sample gain of fitting 20 free parameters to a calibrated model: chi2(20) / (2 n)
    # = 1e-3 on average; 2e-3 is its mean plus about 3 sd
    assert ds.nll_after_ == pytest.approx(ds.nll_before_, abs=2e-3)
    after = expected_calibration_error(y[10_000:], q, classes=range(K))
    assert after.value < 2 * after.noise_floor


def test_scalar_parametrization_is_temperature_scaling(rng):
    y, p_true = _calibrated(rng, 5_000, K)
    hot = _softmax(np.log(p_true) / 0.5)  # over-confident by T = 2
    ts = TemperatureScaler().fit(hot, y)
    ds = DirichletScaler(parametrization="scalar").fit(hot, y)
    # the same one-parameter likelihood minimised by Newton (gradient < 1e-9) and by Brent
    # (1/T within 1e-8): parameters agree to ~1e-8 relative, the minimum NLL to its square
    np.testing.assert_allclose(ds.coef_, np.eye(K) / ts.temperature_, rtol=1e-5)
    np.testing.assert_array_equal(ds.intercept_, np.zeros(K))
    np.testing.assert_allclose(ds.transform(hot), ts.transform(hot), atol=1e-6)
    assert ds.nll_after_ == pytest.approx(ts.nll_after_, abs=1e-9)
    assert ds.cv_results_ == {}
    # vector scaling of a pure temperature distortion finds the same power for every class
    vs = DirichletScaler(parametrization="diagonal").fit(hot, y)
    # four powers estimated from 5 000 runs: se ~0.01-0.015 each, 0.05 is over 3 se
    np.testing.assert_allclose(np.diag(vs.coef_), 0.5, atol=0.05)
    np.testing.assert_allclose(vs.coef_ - np.diag(np.diag(vs.coef_)), 0.0)


def test_strong_odir_penalty_leaves_only_the_diagonal(rng):
    y, p_true = _calibrated(rng, 3_000, K)
    p_obs = _softmax(np.log(p_true) @ A.T + C)
    ds = DirichletScaler(reg_lambda=1e7, reg_mu=1e7).fit(p_obs, y)
    off = ds.coef_ - np.diag(np.diag(ds.coef_))
    # a penalty of 1e7 against gradients of order 1: the penalised entries are ~1e-7 each
    assert np.max(np.abs(off)) < 1e-3 and np.max(np.abs(ds.intercept_)) < 1e-3
    assert ds.reg_lambda_ == 1e7 and ds.cv_results_ == {}
    # with no penalty on the diagonal the fit still sharpens/softens per class
    assert not np.allclose(np.diag(ds.coef_), 1.0, atol=0.05)


def test_dirichlet_can_change_the_argmax_and_fixes_it(rng):
    # the distortion swaps the evidence of classes 0 and 1: argmax is wrong, W undoes it
    y, p_true = _calibrated(rng, 8_000, 3, concentration=0.5)
    swap = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    p_obs = _softmax(np.log(p_true) @ swap.T)
    ds = DirichletScaler(random_state=1).fit(p_obs[:4_000], y[:4_000])
    q = ds.transform(p_obs[4_000:])
    acc_before = np.mean(p_obs[4_000:].argmax(1) == y[4_000:])
    acc_after = np.mean(q.argmax(1) == y[4_000:])
    acc_true = np.mean(p_true[4_000:].argmax(1) == y[4_000:])
    # the fitted map differs from the exact inverse by its estimation error, which moves the
    # argmax of only the runs near a class boundary: well under 1 % of 4 000 runs
    assert acc_after == pytest.approx(acc_true, abs=0.01) and acc_after > acc_before + 0.2


def test_tiny_calibration_set_falls_back_to_one_temperature(rng):
    y, p_true = _calibrated(rng, 12, 3)
    hot = _softmax(np.log(p_true) / 0.5)
    ds = DirichletScaler(classes=[0, 1, 2]).fit(hot, y)
    assert ds.parametrization_ == "scalar" and "temperature" in ds.fallback_
    ts = TemperatureScaler(classes=[0, 1, 2]).fit(hot, y)
    # the same temperature by two optimisers (see test_scalar_parametrization_...)
    np.testing.assert_allclose(ds.transform(hot), ts.transform(hot), atol=1e-6)
    assert ds.get_params()["parametrization"] == "full"  # the user's parameter is kept


def test_zero_probabilities_are_floored(rng):
    p = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.5, 0.5, 0.0], [0.0, 0.0, 1.0]] * 10)
    y = np.array([0, 0, 1, 2] * 10)
    ds = DirichletScaler(parametrization="diagonal", floor=1e-6, min_samples=1, cv=2).fit(p, y)
    q = ds.transform(p)
    assert np.all(np.isfinite(q)) and np.all(q > 0)
    np.testing.assert_allclose(q.sum(axis=1), 1.0)
    # hand check: logits W log(max(p, floor)) + b
    z = np.log(np.maximum(p[2], 1e-6)) @ ds.coef_.T + ds.intercept_
    np.testing.assert_allclose(q[2], np.exp(z) / np.exp(z).sum())


def test_dirichlet_scaler_rejects_bad_input():
    p = np.full((40, 2), 0.5)
    y = np.arange(40) % 2
    with pytest.raises(ValueError, match="not fitted"):
        DirichletScaler().transform(p)
    with pytest.raises(ValueError, match="parametrization"):
        DirichletScaler(parametrization="matrix").fit(p, y)
    with pytest.raises(ValueError, match="cv"):
        DirichletScaler(cv=1).fit(p, y)
    with pytest.raises(ValueError, match="reg_grid"):
        DirichletScaler(reg_grid=(-1.0,)).fit(p, y)
    with pytest.raises(ValueError, match="reg_lambda"):
        DirichletScaler(reg_lambda=-1.0).fit(p, y)
    with pytest.raises(ValueError, match="sum to 1"):
        DirichletScaler().fit(np.full((40, 2), 0.6), y)
    with pytest.raises(ValueError, match="classes"):
        DirichletScaler(classes=[0, 1, 2]).fit(p, y)
    with pytest.raises(ValueError, match="not among the classes"):
        DirichletScaler(classes=[0, 5]).fit(p, y)
    with pytest.raises(ValueError, match="labels"):
        DirichletScaler().fit(p, y[:-1])
    with pytest.raises(ValueError, match="Invalid parameter"):
        DirichletScaler().set_params(temperature=2.0)
    fitted = DirichletScaler(parametrization="diagonal").fit(p, y)
    with pytest.raises(ValueError, match="columns"):
        fitted.transform(np.full((3, 3), 1 / 3))


def test_cross_val_log_loss_scores_held_out_folds(rng):
    y, p_true = _calibrated(rng, 6_000, K)
    hot = _softmax(np.log(p_true) / 0.5)
    cv_t = cross_val_log_loss(TemperatureScaler(), hot, y, cv=3, random_state=0)
    # a one-parameter fit on 4,000 runs scores about the true model's NLL on the rest
    assert cv_t == pytest.approx(log_loss(y, p_true), abs=0.01)
    assert cv_t < log_loss(y, hot) - 0.05
    with pytest.raises(ValueError, match="cv"):
        cross_val_log_loss(TemperatureScaler(), hot, y, cv=1)

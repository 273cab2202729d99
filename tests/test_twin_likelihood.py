"""The twin's residual model and priors against closed forms."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.stats import multivariate_normal

from bayes_fdi.actuator import NOMINAL
from bayes_fdi.twin import DEFAULT_PRIORS, ParameterPrior
from bayes_fdi.twin.likelihood import StationaryAR1, ar1_paths
from bayes_fdi.twin.model import noise_estimate
from bayes_fdi.twin.priors import check_priors


def _ar1_covariance(n: int, sigma: float, phi: float) -> np.ndarray:
    lags = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    return sigma**2 / (1.0 - phi**2) * phi**lags


@pytest.mark.parametrize("phi", [-0.6, 0.0, 0.45, 0.9])
def test_the_ar1_density_is_the_gaussian_with_the_ar1_covariance(rng, phi):
    n, sigma = 40, 0.03
    loc = rng.normal(size=n)
    x = loc + rng.normal(scale=0.05, size=n)
    expected = multivariate_normal(loc, _ar1_covariance(n, sigma, phi)).logpdf(x)
    got = StationaryAR1(torch.tensor(loc), sigma, phi).log_prob(torch.tensor(x))
    assert float(got) == pytest.approx(expected, rel=1e-10)


def test_a_mask_scores_its_contiguous_block_only(rng):
    n, sigma, phi = 30, 0.02, 0.4
    loc = rng.normal(size=(2, n))
    x = loc + rng.normal(scale=0.03, size=(2, n))
    mask = np.zeros((2, n), dtype=bool)
    mask[0, 5:] = True
    mask[1, 3:22] = True
    got = StationaryAR1(torch.tensor(loc), sigma, phi, mask=torch.tensor(mask)).log_prob(
        torch.tensor(x)
    )
    for w in range(2):
        idx = np.flatnonzero(mask[w])
        cov = _ar1_covariance(idx.size, sigma, phi)
        expected = multivariate_normal(loc[w, idx], cov).logpdf(x[w, idx])
        assert float(got[w]) == pytest.approx(expected, rel=1e-10)


def test_ar1_paths_have_the_stationary_variance_and_correlation_and_are_seeded():
    sigma, phi = np.full(400, 0.02), np.full(400, 0.6)
    paths = ar1_paths(np.random.default_rng(3), sigma, phi, 500)
    assert paths.shape == (400, 500)
    var = 0.02**2 / (1 - 0.36)
    # the stationary variance from the first sample on (a pooled estimate over 200 000 values)
    assert paths[:, 0].var() == pytest.approx(var, rel=0.15)
    assert paths.var() == pytest.approx(var, rel=0.03)
    lag1 = np.mean(paths[:, 1:] * paths[:, :-1]) / np.mean(paths**2)
    assert lag1 == pytest.approx(0.6, abs=0.01)
    again = ar1_paths(np.random.default_rng(3), sigma, phi, 500)
    np.testing.assert_array_equal(paths, again)


def test_the_noise_estimate_recovers_sigma_and_phi():
    rng = np.random.default_rng(5)
    residual = np.stack(
        [
            ar1_paths(rng, np.full(4, s), np.full(4, p), 3000)
            for s, p in ((0.01, 0.3), (0.04, -0.2))
        ],
        axis=-1,
    )
    mask = np.ones((4, 3000), dtype=bool)
    mask[:, :10] = False
    log_sigma_x, log_sigma_f, atanh_x, atanh_f = noise_estimate(residual, mask)
    assert np.exp(log_sigma_x) == pytest.approx(0.01, rel=0.02)
    assert np.exp(log_sigma_f) == pytest.approx(0.04, rel=0.02)
    assert np.tanh(atanh_x) == pytest.approx(0.3, abs=0.02)
    assert np.tanh(atanh_f) == pytest.approx(-0.2, abs=0.02)


def test_a_logit_normal_prior_has_its_nominal_value_as_median_and_stays_inside():
    prior = DEFAULT_PRIORS["kv"]
    assert prior.nominal == NOMINAL.kv
    assert prior.to_value(prior.loc()) == pytest.approx(NOMINAL.kv, rel=1e-12)
    z = prior.loc() + prior.spread * np.random.default_rng(0).standard_normal(20000)
    values = prior.to_value(z)
    assert np.median(values) == pytest.approx(NOMINAL.kv, rel=0.02)
    assert values.min() > prior.low and values.max() < prior.high
    assert float(prior.to_value(torch.tensor(prior.loc()))) == pytest.approx(NOMINAL.kv)


@pytest.mark.parametrize(
    ("priors", "message"),
    [
        ({"kv": ParameterPrior(120.0, 5.0, 480.0)}, "inside the physical bounds"),
        ({"kv": ParameterPrior(20.0, 30.0, 480.0)}, "nominal 20 must lie strictly inside"),
        ({"kv": ParameterPrior(120.0, 30.0, 480.0, 0.0)}, "spread must be > 0"),
        ({"kvv": ParameterPrior(120.0, 30.0, 480.0)}, "unknown parameter 'kvv'"),
        ({"kv": (120.0, 30.0, 480.0)}, "must be a ParameterPrior"),
        ({}, "non-empty mapping"),
    ],
)
def test_bad_priors_are_refused_by_name(priors, message):
    with pytest.raises(ValueError, match=message):
        check_priors(priors)


def test_the_fixed_order_linear_algebra_agrees_with_lapack(rng):
    from bayes_fdi.twin.fixed_order import (
        NotPositiveDefinite,
        cholesky,
        inverse_spd,
        matvec,
        solve_spd,
    )

    m = rng.normal(size=(12, 12))
    a = m @ m.T + 12 * np.eye(12)
    b = rng.normal(size=12)
    np.testing.assert_allclose(cholesky(a), np.linalg.cholesky(a), rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(solve_spd(a, b), np.linalg.solve(a, b), rtol=1e-11)
    np.testing.assert_allclose(inverse_spd(a), np.linalg.inv(a), rtol=1e-10, atol=1e-14)
    x = rng.normal(size=(5, 12))
    np.testing.assert_allclose(matvec(a, x), x @ a.T, rtol=1e-12)
    with pytest.raises(NotPositiveDefinite, match="pivot"):
        cholesky(np.diag([1.0, -1.0]))

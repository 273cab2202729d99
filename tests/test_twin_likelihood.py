"""The twin's residual model and priors against closed forms."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.stats import multivariate_normal, norm

from bayes_fdi.actuator import NOMINAL
from bayes_fdi.twin import DEFAULT_PRIORS, ParameterPrior
from bayes_fdi.twin.likelihood import StationaryAR1, ar1_from_innovations, ar1_paths
from bayes_fdi.twin.model import MIN_PRESSURE_DROP, flow_ratio, noise_estimate
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


def _scaled_density(e: np.ndarray, sigma: np.ndarray, phi: float) -> float:
    """The AR(1) density with innovation scales ``sigma[t]`` as the product of its Gaussian
    factors: ``N(e_0; 0, sigma_0^2 / (1 - phi^2)) prod_t N(e_t - phi e_(t-1); 0, sigma_t^2)``."""
    out = norm(0.0, sigma[0] / np.sqrt(1.0 - phi**2)).logpdf(e[0])
    return float(out + norm(0.0, sigma[1:]).logpdf(e[1:] - phi * e[:-1]).sum())


@pytest.mark.parametrize("phi", [-0.5, 0.0, 0.4, 0.85])
def test_a_time_varying_scale_gives_the_product_of_gaussian_factors(rng, phi):
    n = 50
    sigma = 0.01 + 0.05 * rng.uniform(size=n)
    loc = rng.normal(size=n)
    x = loc + rng.normal(scale=0.05, size=n)
    got = float(
        StationaryAR1(torch.tensor(loc), torch.tensor(sigma), phi).log_prob(torch.tensor(x))
    )
    assert got == pytest.approx(_scaled_density(x - loc, sigma, phi), rel=1e-12)
    # and the Gaussian whose precision is L' D^-1 L (L: the AR(1) differencing): a second route
    ell = np.eye(n) - phi * np.eye(n, k=-1)
    variances = np.r_[sigma[0] ** 2 / (1.0 - phi**2), sigma[1:] ** 2]
    covariance = np.linalg.inv(ell.T @ np.diag(1.0 / variances) @ ell)
    assert got == pytest.approx(multivariate_normal(loc, covariance).logpdf(x), rel=1e-9)


def test_a_time_varying_scale_under_a_mask_scores_its_block_with_its_own_scales(rng):
    n, phi = 30, 0.3
    loc = rng.normal(size=(2, n))
    sigma = 0.02 + 0.03 * rng.uniform(size=(2, n))
    x = loc + rng.normal(scale=0.03, size=(2, n))
    mask = np.zeros((2, n), dtype=bool)
    mask[0, 4:] = True
    mask[1, 2:25] = True
    got = StationaryAR1(
        torch.tensor(loc), torch.tensor(sigma), phi, mask=torch.tensor(mask)
    ).log_prob(torch.tensor(x))
    for w in range(2):
        idx = np.flatnonzero(mask[w])
        expected = _scaled_density(x[w, idx] - loc[w, idx], sigma[w, idx], phi)
        assert float(got[w]) == pytest.approx(expected, rel=1e-12)


def test_paths_with_a_time_varying_scale_have_the_recursive_variance():
    n_paths, n_t, phi = 20000, 60, 0.5
    sigma = 0.01 * (1.0 + 4.0 * (np.arange(n_t) >= 30))  # the scale jumps at t = 30
    eps = np.random.default_rng(11).standard_normal((n_paths, n_t))
    paths = ar1_from_innovations(eps, np.broadcast_to(sigma, (n_paths, n_t)), np.full(n_paths, phi))
    variance = np.empty(n_t)
    variance[0] = sigma[0] ** 2 / (1.0 - phi**2)
    for t in range(1, n_t):
        variance[t] = phi**2 * variance[t - 1] + sigma[t] ** 2
    # 20 000 paths: the variance estimates' relative sd is about 1 %
    np.testing.assert_allclose(paths.var(axis=0), variance, rtol=0.05)
    # a constant scale per sample gives the stationary path bit for bit up to rounding
    constant = ar1_from_innovations(eps[:3], np.full((3, n_t), 0.02), np.full(3, phi))
    np.testing.assert_allclose(constant, ar1_from_innovations(eps[:3], np.full(3, 0.02), phi))


def test_the_noise_estimate_recovers_sigma_phi_and_the_pressure_drop_error():
    rng = np.random.default_rng(5)
    n_w, n_t = 4, 3000
    ratio = rng.uniform(0.5, 15.0, size=(n_w, n_t))  # flow over twice the pressure drop
    sigma_f, kappa = 0.004, 0.0025
    scale_f = np.sqrt(sigma_f**2 + (kappa * ratio) ** 2)
    residual = np.stack(
        [
            ar1_paths(rng, np.full(n_w, 0.01), np.full(n_w, 0.3), n_t),
            ar1_from_innovations(rng.standard_normal((n_w, n_t)), scale_f, np.full(n_w, -0.2)),
        ],
        axis=-1,
    )
    mask = np.ones((n_w, n_t), dtype=bool)
    mask[:, :10] = False
    log_sigma_x, log_sigma_f, atanh_x, atanh_f, log_kappa = noise_estimate(residual, mask, ratio)
    # 12 000 innovations: sd of the estimates about 1 % (sigma_X), 3 % (kappa), 0.01 (phi)
    assert np.exp(log_sigma_x) == pytest.approx(0.01, rel=0.03)
    assert np.tanh(atanh_x) == pytest.approx(0.3, abs=0.03)
    assert np.exp(log_kappa) == pytest.approx(kappa, rel=0.06)
    assert np.exp(log_sigma_f) == pytest.approx(sigma_f, rel=0.25)
    assert np.tanh(atanh_f) == pytest.approx(-0.2, abs=0.03)
    # without a flow term in the data, kappa stays at its floor and sigma_F is the plain one
    plain = residual.copy()
    plain[..., 1] = ar1_paths(rng, np.full(n_w, 0.04), np.full(n_w, -0.2), n_t)
    _, log_sigma_f, _, atanh_f, log_kappa = noise_estimate(plain, mask, ratio, kappa_floor=1e-6)
    assert np.exp(log_sigma_f) == pytest.approx(0.04, rel=0.03)
    # kappa^2 is the slope of the squared innovations in ratio^2: its sampling sd is about
    # sqrt(2) sigma^2 / (sqrt(n) sd(ratio^2)); a slope of 0 is estimated within 3 sd
    slope_sd = np.sqrt(2.0) * 0.04**2 / (np.sqrt(mask.sum()) * np.std(ratio**2))
    assert np.exp(2.0 * log_kappa) < 3.0 * slope_sd
    assert np.tanh(atanh_f) == pytest.approx(-0.2, abs=0.03)


def test_the_flow_ratio_is_the_flow_above_the_zero_over_twice_the_pressure_drop():
    base = NOMINAL._replace(f_offset=0.02, p1_offset=0.01, p1_gain=1.1, p2_gain=0.9)
    pressures = torch.tensor([[[0.30, 0.10], [0.25, 0.24], [0.5, 0.1]]])  # (W=1, T=3, 2)
    flow = torch.tensor([[0.42, 0.30, 0.01]])
    theta = torch.tensor([0.05])  # the F' zero fitted: it replaces base's
    got = flow_ratio(flow, theta, ("f_offset",), base, pressures).numpy()
    drop = np.array([(0.30 - 0.01) / 1.1 - 0.10 / 0.9, (0.25 - 0.01) / 1.1 - 0.24 / 0.9,
                     (0.5 - 0.01) / 1.1 - 0.1 / 0.9])  # fmt: skip
    drop = np.maximum(drop, MIN_PRESSURE_DROP)  # the second drop is negative: floored
    expected = np.maximum(np.array([0.42, 0.30, 0.01]) - 0.05, 0.0) / (2.0 * drop)
    np.testing.assert_allclose(got[0], expected, rtol=1e-6)
    assert got[0, 2] == 0.0


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

"""Full posteriors through the estimators: ``RVR(...).fit(X, y).fit_posterior(X, y)``."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from bayes_fdi.rvm import RVR
from bayes_fdi.rvm.posterior import fit_posterior


def _sinc(n: int, seed: int, noise: float = 0.1):
    rng = np.random.default_rng(seed)
    X = rng.uniform(-5, 5, (n, 1))
    return X, np.sinc(X[:, 0] / np.pi) + noise * rng.standard_normal(n)


@pytest.fixture(scope="module")
def sinc_fit():
    X, y = _sinc(60, seed=0)
    rvr = RVR(width=1.5).fit(X, y)
    post = rvr.fit_posterior(X, y, num_samples=800, warmup_steps=400, seed=0)
    return X, y, rvr, post


def test_rvr_nuts_posterior_converges_and_agrees_with_type2(sinc_fit):
    _, _, rvr, post = sinc_fit
    assert post.kind == "regression" and post.inference == "nuts" and post.basis == "active"
    names = (("bias",) if rvr.alpha_.size == rvr.relevance_indices_.size + 1 else ()) + tuple(
        f"rv{i}" for i in rvr.relevance_indices_
    )
    assert post.basis_names == names
    assert post.weights.shape == (2, 800, rvr.alpha_.size)
    d = post.diagnostics
    assert d.n_divergences == 0
    assert d.max_r_hat < 1.01
    # full posterior vs the type-II fit (an independent implementation): on this well-determined
    # problem the predictive means agree to a small fraction of the predictive std
    Xt = np.linspace(-5, 5, 101)[:, None]
    mean, std = post.predict(Xt, return_std=True)
    mean2, std2 = rvr.predict(Xt, return_std=True)
    assert np.max(np.abs(mean - mean2) / std2) < 0.1
    assert np.all((std / std2 > 0.9) & (std / std2 < 1.3))
    # noise level: posterior of beta brackets the type-II estimate
    lo, hi = np.percentile(post.log_beta, [1, 99])
    assert lo < np.log(rvr.beta_) < hi


def test_rvr_posterior_predictive_intervals_are_calibrated(sinc_fit):
    _, _, _, post = sinc_fit
    Xt, yt = _sinc(600, seed=11)
    mean, std = post.predict(Xt, return_std=True)
    inside = np.abs(yt - mean) < 1.6448536 * std
    # 90% intervals on fresh data; binomial sd at n=600 is 0.012
    assert 0.86 < inside.mean() < 0.94


def test_rvr_posterior_numpy_and_torch_io(sinc_fit):
    _, _, _, post = sinc_fit
    Xt = np.linspace(-4, 4, 9)[:, None]
    mean = post.predict(Xt)
    assert isinstance(mean, np.ndarray) and mean.shape == (9,)
    mean_t, std_t = post.predict(torch.as_tensor(Xt), return_std=True)
    assert isinstance(mean_t, torch.Tensor) and isinstance(std_t, torch.Tensor)
    np.testing.assert_allclose(mean_t.numpy(), mean, rtol=1e-12)
    with pytest.raises(ValueError, match="predict_proba"):
        post.predict_proba(Xt)


def test_posterior_is_independent_of_later_refits(sinc_fit):
    X, y, _, _ = sinc_fit
    rvr = RVR(width=1.5).fit(X, y)
    p1 = rvr.fit_posterior(X, y, inference="svi", num_samples=100, svi_steps=100, seed=1)
    before = p1.predict(X[:5])
    rvr.fit(X[:30] * 2.0, -y[:30])  # refit the estimator on other data
    np.testing.assert_array_equal(p1.predict(X[:5]), before)


def test_svi_through_rvr_close_to_nuts_and_reproducible(sinc_fit):
    X, y, rvr, post = sinc_fit
    kw = {"inference": "svi", "num_samples": 500, "svi_steps": 800, "seed": 3}
    svi = rvr.fit_posterior(X, y, **kw)
    again = fit_posterior(rvr, X, y, **kw)
    np.testing.assert_array_equal(svi.weights, again.weights)
    Xt = np.linspace(-5, 5, 41)[:, None]
    m_n, s_n = post.predict(Xt, return_std=True)
    m_s, s_s = svi.predict(Xt, return_std=True)
    assert np.max(np.abs(m_s - m_n) / s_n) < 0.15
    assert np.all(np.abs(s_s / s_n - 1) < 0.15)


def test_fit_posterior_rejects_bad_input(sinc_fit):
    X, y, rvr, _ = sinc_fit
    with pytest.raises(ValueError, match="fit"):
        fit_posterior(RVR(), X, y)
    with pytest.raises(ValueError, match="entries"):
        rvr.fit_posterior(X, y[:-1])
    with pytest.raises(ValueError, match="basis"):
        rvr.fit_posterior(X, y, basis="some")
    with pytest.raises(ValueError, match="inference"):
        rvr.fit_posterior(X, y, inference="gibbs")
    with pytest.raises(ValueError, match="NaN"):
        rvr.fit_posterior(X, np.where(np.arange(y.size) == 3, np.nan, y))


@pytest.mark.slow
def test_rvr_posterior_on_all_basis_functions():
    """basis='all': every training row + bias; converges and agrees with the active basis."""
    X, y = _sinc(30, seed=4)
    rvr = RVR(width=1.5).fit(X, y)
    full = rvr.fit_posterior(X, y, basis="all", num_samples=1500, warmup_steps=800, seed=0)
    assert full.weights.shape[2] == 31 and full.basis_names[0] == "bias"
    assert full.diagnostics.n_divergences == 0
    assert full.diagnostics.max_r_hat < 1.05
    active = rvr.fit_posterior(X, y, num_samples=500, warmup_steps=500, seed=0)
    Xt = np.linspace(-4.5, 4.5, 31)[:, None]
    m_f, s_f = full.predict(Xt, return_std=True)
    m_a, s_a = active.predict(Xt, return_std=True)
    assert np.max(np.abs(m_f - m_a) / s_a) < 0.5
    # weakly determined extra weights can only add predictive uncertainty, not remove much
    assert np.all(s_f > 0.9 * s_a)

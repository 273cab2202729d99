"""Full posteriors through the estimators: ``RVR(...).fit(X, y).fit_posterior(X, y)``.

NUTS draws depend chaotically on the last bits of the arithmetic (another BLAS kernel gives other
chains), so every check here must hold for any seed; the spreads quoted are over seeds 0..19.
"""

from __future__ import annotations

import warnings

import arviz as az
import numpy as np
import pytest
import torch
from sklearn.exceptions import ConvergenceWarning

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
    post = rvr.fit_posterior(X, y, num_samples=400, warmup_steps=300, num_chains=4, seed=0)
    return X, y, rvr, post


def test_rvr_nuts_posterior_converges_and_agrees_with_type2(sinc_fit):
    _, _, rvr, post = sinc_fit
    assert post.kind == "regression" and post.inference == "nuts" and post.basis == "active"
    names = (("bias",) if rvr.alpha_.size == rvr.relevance_indices_.size + 1 else ()) + tuple(
        f"rv{i}" for i in rvr.relevance_indices_
    )
    assert post.basis_names == names
    assert post.weights.shape == (4, 400, rvr.alpha_.size)
    d = post.diagnostics
    assert d.n_divergences == 0  # none over seeds 0..19
    # bulk ESS over seeds 0..19: 783 to 1127; 400 is 50 per split chain, and then R-hat > 1.05
    # has probability 1e-5 for stationary chains (see test_posterior.py::test_nuts_converges).
    # Seeds 0..19 gave max R-hat 1.0021 to 1.0139 (two above 1.01)
    assert d.min_ess_bulk > 400
    assert d.max_r_hat < 1.05
    # full posterior vs the type-II fit (an independent implementation). They differ by the
    # hyperparameter uncertainty type-II ignores, small on this well-determined problem (4 basis
    # functions, 60 points): over seeds 0..19 the largest mean gap was 0.055 of a
    # predictive sd and the sd ratio stayed within 1.017 to 1.030; the Monte Carlo error of the
    # mean is about 0.01 sd (1600 draws)
    Xt = np.linspace(-5, 5, 101)[:, None]
    mean, std = post.predict(Xt, return_std=True)
    mean2, std2 = rvr.predict(Xt, return_std=True)
    assert np.max(np.abs(mean - mean2) / std2) < 0.1
    assert np.all((std / std2 > 0.9) & (std / std2 < 1.3))
    # noise level: the posterior of beta brackets the type-II estimate (a 98 % interval)
    lo, hi = np.percentile(post.log_beta, [1, 99])
    assert lo < np.log(rvr.beta_) < hi


def test_rvr_posterior_predictive_intervals_are_calibrated(sinc_fit):
    _, _, _, post = sinc_fit
    Xt, yt = _sinc(600, seed=11)
    mean, std = post.predict(Xt, return_std=True)
    inside = np.abs(yt - mean) < 1.6448536 * std
    # 90 % intervals on fresh data: binomial sd at n = 600 is 0.012, so +-0.04 is 3.3 sd. The
    # test points are fixed, so chains only move the coverage by Monte Carlo error: 0.870 to
    # 0.875 over seeds 0..19 (RVR with 4 basis functions covers a little under 90 % here)
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
    np.testing.assert_array_equal(svi.weights, again.weights)  # same seed: identical computation
    Xt = np.linspace(-5, 5, 41)[:, None]
    m_n, s_n = post.predict(Xt, return_std=True)
    m_s, s_s = svi.predict(Xt, return_std=True)
    # SVI's Gaussian guide is an approximation: its predictive mean is within 15 % of a
    # predictive sd of NUTS's and its sd within 15 % (docs/posteriors.md: 2-8 % lower sd)
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
    # 31 overlapping basis functions: a multimodal posterior (docs/posteriors.md), only a loose
    # convergence check
    assert full.diagnostics.max_r_hat < 1.05
    active = rvr.fit_posterior(X, y, num_samples=500, warmup_steps=500, seed=0)
    Xt = np.linspace(-4.5, 4.5, 31)[:, None]
    m_f, s_f = full.predict(Xt, return_std=True)
    m_a, s_a = active.predict(Xt, return_std=True)
    # the extra basis functions are mostly switched off: the predictions move by a fraction of
    # a predictive sd
    assert np.max(np.abs(m_f - m_a) / s_a) < 0.5
    # weakly determined extra weights can only add predictive uncertainty, not remove much
    assert np.all(s_f > 0.9 * s_a)


def test_az_compare_ranks_the_better_kernel_width_first(sinc_fit):
    """LOO from to_arviz() alone: a kernel width 5x too wide underfits sinc and loses clearly."""
    X, y, _, good = sinc_fit
    wide = RVR(width=8.0).fit(X, y)
    with warnings.catch_warnings():
        # the wide model mixes slowly; its elpd is ~50 below the good one's, far beyond any
        # Monte Carlo error, so short chains decide the ranking
        warnings.simplefilter("ignore", ConvergenceWarning)
        bad = wide.fit_posterior(X, y, num_samples=100, warmup_steps=100, seed=0)
    table = az.compare({"width=1.5": good.to_arviz(), "width=8": bad.to_arviz()})
    assert list(table.index) == ["width=1.5", "width=8"]
    # "clearly": the elpd difference exceeds 4 standard errors of the difference
    assert table.loc["width=8", "elpd_diff"] > 4 * table.loc["width=8", "dse"]
    ax = np.ravel(az.plot_ppc(good.to_arviz(), num_pp_samples=20, random_seed=0))[0]
    labels = ax.get_legend_handles_labels()[1]
    assert labels == ["Posterior predictive", "Observed", "Posterior predictive mean"]
    assert len(ax.get_lines()) == 20 + 3  # 20 replicate densities and the 3 labelled lines

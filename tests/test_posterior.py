"""Tests of the full-posterior sparse Bayesian models (bayes_fdi.rvm.posterior).

Every check compares against an independent computation: dense N x N Gaussian evidence, the
closed-form weight posterior, a grid posterior, ArviZ's diagnostics, a Laplace approximation.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pyro
import pytest
import torch
from pyro import poutine
from pyro.infer import MCMC, NUTS
from pyro.infer.mcmc.util import initialize_model
from scipy import stats
from scipy.special import expit, logsumexp
from sklearn.exceptions import ConvergenceWarning

from bayes_fdi.rvm.posterior import (
    Hyperpriors,
    RVMPosterior,
    SparseBayesClassificationModel,
    SparseBayesRegressionModel,
    effective_sample_size,
    r_hat,
    sample_posterior,
)


def _bump_problem(n: int = 30, seed: int = 1, noise: float = 0.3):
    """Bias + one Gaussian bump: y = 0.5 + 2 exp(-x^2/2) + noise."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(-3, 3, n)
    Phi = np.column_stack([np.ones(n), np.exp(-(x**2) / 2)])
    y = Phi @ np.array([0.5, 2.0]) + noise * rng.standard_normal(n)
    return Phi, y


def _bump_design(x: np.ndarray) -> np.ndarray:
    return np.column_stack([np.ones(x.size), np.exp(-(x**2) / 2)])


@pytest.fixture(scope="module")
def bump_nuts() -> tuple[SparseBayesRegressionModel, RVMPosterior]:
    Phi, y = _bump_problem()
    model = SparseBayesRegressionModel(Phi, y)
    post = sample_posterior(model, num_samples=300, warmup_steps=300, num_chains=2, seed=3)
    return model, post


def _closed_form(Phi, t, alpha, beta):
    Sigma = np.linalg.inv(np.diag(alpha) + beta * Phi.T @ Phi)
    return beta * Sigma @ Phi.T @ t, Sigma


def test_log_evidence_and_gradient_match_dense_gaussian(rng):
    n, m = 25, 4
    Phi = rng.standard_normal((n, m))
    t = rng.standard_normal(n)
    model = SparseBayesRegressionModel(Phi, t)
    log_alpha = torch.tensor(rng.normal(size=(3, m)), requires_grad=True)
    log_beta = torch.tensor(rng.normal(size=3), requires_grad=True)
    value = model.log_evidence(log_alpha, log_beta)
    value.sum().backward()
    for b in range(3):
        a, be = np.exp(log_alpha[b].detach().numpy()), np.exp(log_beta[b].item())
        C = np.eye(n) / be + Phi @ np.diag(1 / a) @ Phi.T
        ref = stats.multivariate_normal(np.zeros(n), C).logpdf(t)
        assert value[b].item() == pytest.approx(ref, rel=1e-10, abs=1e-9)
    # gradient of the dense N x N formulation, by autograd
    la2 = log_alpha.detach().clone().requires_grad_()
    lb2 = log_beta.detach().clone().requires_grad_()
    P, tt = torch.as_tensor(Phi), torch.as_tensor(t)
    C = (
        torch.exp(-lb2)[:, None, None] * torch.eye(n, dtype=torch.float64)
        + (P * torch.exp(-la2)[:, None, :]) @ P.T
    )
    dense = torch.distributions.MultivariateNormal(torch.zeros(n, dtype=torch.float64), C)
    dense.log_prob(tt).sum().backward()
    torch.testing.assert_close(log_alpha.grad, la2.grad, rtol=1e-8, atol=1e-10)
    torch.testing.assert_close(log_beta.grad, lb2.grad, rtol=1e-8, atol=1e-10)


def test_pyro_models_match_potentials(rng):
    """The declared Pyro models and the hand-written NUTS potentials are the same density."""
    Phi = rng.standard_normal((20, 3))
    reg = SparseBayesRegressionModel(Phi, rng.standard_normal(20), Hyperpriors(0.7, 0.3, 0.2, 0.1))
    _, pot, _, _ = initialize_model(reg.model)
    la, lb = torch.tensor(rng.normal(size=3)), torch.tensor(0.4, dtype=torch.float64)
    got = pot({"alpha": la, "beta": lb})  # unconstrained sites = logs
    assert got.item() == pytest.approx(reg.potential({"log_alpha": la, "log_beta": lb}).item())

    t = (rng.random(20) < 0.5).astype(float)
    for param in ("centred", "noncentred"):
        clf = SparseBayesClassificationModel(Phi, t, Hyperpriors(0.7, 0.3), param)
        _, pot, _, _ = initialize_model(clf.model)
        name = clf.latent_names[1]
        v = torch.tensor(rng.normal(size=3))
        got = pot({"alpha": la, name: v})
        assert got.item() == pytest.approx(clf.potential({"log_alpha": la, name: v}).item())


def test_exact_weight_draws_match_closed_form(rng):
    n, m = 30, 3
    Phi = rng.standard_normal((n, m))
    t = Phi @ np.array([1.0, -0.5, 0.0]) + 0.5 * rng.standard_normal(n)
    model = SparseBayesRegressionModel(Phi, t)
    alpha, beta = np.array([0.5, 2.0, 50.0]), 3.0
    mu, Sigma = _closed_form(Phi, t, alpha, beta)
    s = 20000
    la = torch.tensor(np.log(alpha)).expand(s, m)
    lb = torch.full((s,), np.log(beta), dtype=torch.float64)
    w = model.sample_weights(la, lb, generator=torch.Generator().manual_seed(0)).numpy()
    se = np.sqrt(np.diag(Sigma) / s)
    assert np.all(np.abs(w.mean(0) - mu) < 4.5 * se)
    sd = np.sqrt(np.diag(Sigma))
    assert np.allclose(np.cov(w.T), Sigma, atol=0.04 * np.outer(sd, sd).max())


def test_noncentred_pyro_model_with_fixed_hyperparameters_gives_closed_form(rng):
    """NUTS on the non-centred Pyro model, alpha and beta fixed: weights ~ N(mu, Sigma)."""
    n, m = 30, 3
    Phi = rng.standard_normal((n, m))
    t = Phi @ np.array([1.0, -0.5, 0.2]) + 0.5 * rng.standard_normal(n)
    model = SparseBayesRegressionModel(Phi, t)
    alpha, beta = np.array([0.5, 2.0, 5.0]), 3.0
    mu, Sigma = _closed_form(Phi, t, alpha, beta)
    conditioned = poutine.condition(
        model.noncentred_model,
        data={"alpha": torch.tensor(alpha), "beta": torch.tensor(beta, dtype=torch.float64)},
    )
    pyro.set_rng_seed(0)
    mcmc = MCMC(NUTS(conditioned), num_samples=500, warmup_steps=150, disable_progbar=True)
    mcmc.run()
    z = mcmc.get_samples()["z"].numpy()
    w = z / np.sqrt(alpha)
    ess = effective_sample_size(w[None])
    se = np.sqrt(np.diag(Sigma) / ess)
    assert np.all(np.abs(w.mean(0) - mu) < 4.5 * se)
    assert np.allclose(w.std(0), np.sqrt(np.diag(Sigma)), rtol=0.15)


def _grid_posterior(phi, t, hp, la_grid, lb_grid):
    """p(log alpha, log beta | t) on a grid for one basis function (rank-one covariance).

    C = s2 I + v phi phi^T, so |C| and t^T C^-1 t have scalar closed forms (Sherman-Morrison),
    checked against scipy's dense multivariate normal at a few points.
    """
    n = t.size
    la, lb = np.meshgrid(la_grid, lb_grid, indexing="ij")
    s2, v = np.exp(-lb), np.exp(-la)
    pp, pt, tt = phi @ phi, phi @ t, t @ t
    logdet = n * np.log(s2) + np.log1p(v * pp / s2)
    quad = (tt - v * pt**2 / (s2 + v * pp)) / s2
    log_ev = -0.5 * (n * np.log(2 * np.pi) + logdet + quad)
    for i, j in ((0, 0), (40, 17), (-1, -1)):
        C = s2[i, j] * np.eye(n) + v[i, j] * np.outer(phi, phi)
        dense = stats.multivariate_normal(np.zeros(n), C).logpdf(t)
        assert log_ev[i, j] == pytest.approx(dense, rel=1e-9)
    log_p = (
        log_ev
        + stats.gamma(hp.a_alpha, scale=1 / hp.b_alpha).logpdf(np.exp(la))
        + la
        + stats.gamma(hp.a_beta, scale=1 / hp.b_beta).logpdf(np.exp(lb))
        + lb
    )
    return np.exp(log_p - logsumexp(log_p))


def test_nuts_matches_grid_posterior_and_converges():
    rng = np.random.default_rng(5)
    n = 15
    x = rng.uniform(-2, 2, n)
    Phi = np.exp(-(x[:, None] ** 2) / 2)
    t = 1.5 * Phi[:, 0] + 0.4 * rng.standard_normal(n)
    model = SparseBayesRegressionModel(Phi, t)
    post = sample_posterior(model, num_samples=400, warmup_steps=300, num_chains=2, seed=0)
    d = post.diagnostics
    assert d.n_divergences == 0
    assert d.max_r_hat < 1.01
    la_grid = np.linspace(-14.0, 10.0, 481)
    lb_grid = np.linspace(-1.5, 4.0, 221)
    p = _grid_posterior(Phi[:, 0], t, model.hyperpriors, la_grid, lb_grid)
    for draws, grid, marg in (
        (post.log_alpha[..., 0], la_grid, p.sum(1)),
        (post.log_beta, lb_grid, p.sum(0)),
    ):
        assert marg[0] < 1e-4 and marg[-1] < 1e-4  # grid covers the mass
        mean = (grid * marg).sum()
        sd = np.sqrt(((grid - mean) ** 2 * marg).sum())
        ess = effective_sample_size(draws)
        assert abs(draws.mean() - mean) < 4.0 * sd / np.sqrt(ess)
        assert draws.std() == pytest.approx(sd, rel=0.15)
        # whole-distribution check: Kolmogorov distance to the grid CDF
        cdf = np.cumsum(marg)
        ecdf = np.searchsorted(np.sort(draws.ravel()), grid, side="right") / draws.size
        assert np.max(np.abs(ecdf - cdf)) < 1.63 / np.sqrt(ess) + 0.01


def test_svi_lands_close_to_nuts(bump_nuts):
    model, nuts = bump_nuts
    svi = sample_posterior(
        model, inference="svi", num_samples=500, seed=0, svi_steps=800, svi_lr=0.04
    )
    assert svi.weights.shape == (1, 1000, 2)
    assert np.all(np.isfinite(svi.diagnostics.elbo))
    xs = np.linspace(-3, 3, 9)
    m_n, s_n = nuts.predict(_bump_design(xs), return_std=True)
    m_s, s_s = svi.predict(_bump_design(xs), return_std=True)
    assert np.max(np.abs(m_n - m_s)) < 0.1 * s_n.min()
    assert np.allclose(s_s, s_n, rtol=0.15)
    # noise level agrees too
    assert abs(np.exp(-svi.log_beta / 2).mean() - np.exp(-nuts.log_beta / 2).mean()) < 0.03


def test_nuts_diagnostics_on_test_problem(bump_nuts):
    _, post = bump_nuts
    d = post.diagnostics
    assert d.divergences == (0, 0)
    assert d.max_r_hat < 1.01
    assert d.min_ess_bulk > 100
    assert set(d.r_hat) == {"log_alpha", "log_beta", "weights"}
    assert "R-hat" in str(d)


def test_predict_is_mixture_over_draws(bump_nuts):
    _, post = bump_nuts
    xs = np.linspace(-3, 3, 7)
    Phi = _bump_design(xs)
    mean, std = post.predict(Phi, return_std=True)
    f = Phi @ post.weights.reshape(-1, 2).T  # (n, S)
    noise = np.exp(-post.log_beta.ravel())
    np.testing.assert_allclose(mean, f.mean(1), rtol=1e-12)
    # total variance of the mixture of N(f_s, 1/beta_s): E[var] + Var[mean]
    second_moment = (f**2 + noise).mean(1)
    np.testing.assert_allclose(std**2, second_moment - f.mean(1) ** 2, rtol=1e-9)
    m_t, s_t = post.predict(torch.as_tensor(Phi), return_std=True)
    assert isinstance(m_t, torch.Tensor) and isinstance(s_t, torch.Tensor)
    np.testing.assert_allclose(m_t.numpy(), mean)
    # the posterior mean function is close to the truth on this easy problem
    assert np.max(np.abs(mean - Phi @ np.array([0.5, 2.0]))) < 0.35


def test_to_arviz_groups_and_summary(bump_nuts):
    az = pytest.importorskip("arviz")
    _, post = bump_nuts
    idata = post.to_arviz()
    assert "posterior" in idata.groups() and "sample_stats" in idata.groups()
    assert idata.posterior.sizes["chain"] == 2 and idata.posterior.sizes["draw"] == 300
    assert list(idata.posterior["weights"].coords["basis"].values) == list(post.basis_names)
    assert idata.sample_stats["diverging"].dtype == bool
    assert int(idata.sample_stats["diverging"].sum()) == post.diagnostics.n_divergences
    summary = az.summary(idata)
    assert {"mean", "sd", "r_hat", "ess_bulk"} <= set(summary.columns)
    np.testing.assert_allclose(
        summary.loc["log_beta", "mean"], post.log_beta.mean(), rtol=1e-6, atol=1e-3
    )


def test_diagnostics_agree_with_arviz():
    az = pytest.importorskip("arviz")
    rng = np.random.default_rng(0)
    # AR(1) chains with a slight shift in one chain: ESS < draws and R-hat > 1
    x = np.zeros((3, 400, 2))
    for c in range(3):
        for i in range(1, 400):
            x[c, i] = 0.7 * x[c, i - 1] + rng.standard_normal(2)
    x[0] += 0.3
    ds = az.convert_to_dataset({"x": x})
    np.testing.assert_allclose(r_hat(x), az.rhat(ds)["x"].values, rtol=1e-10)
    np.testing.assert_allclose(effective_sample_size(x), az.ess(ds)["x"].values, rtol=1e-8)
    np.testing.assert_allclose(
        effective_sample_size(x, "tail"), az.ess(ds, method="tail")["x"].values, rtol=0.02
    )


def _laplace_type2(Phi, t, n_iter=200):
    """Independent reference: type-II ML (MacKay updates) + Laplace + moderated output."""
    m = Phi.shape[1]
    alpha, w = np.ones(m), np.zeros(m)
    for _ in range(n_iter):
        for _ in range(25):  # Newton / IRLS for the mode
            y = expit(Phi @ w)
            g = Phi.T @ (t - y) - alpha * w
            H = Phi.T @ (Phi * (y * (1 - y))[:, None]) + np.diag(alpha)
            w = w + np.linalg.solve(H, g)
        Sigma = np.linalg.inv(H)
        gamma = 1 - alpha * np.diag(Sigma)
        alpha = gamma / w**2
    return w, Sigma


def test_classification_posterior_close_to_laplace():
    rng = np.random.default_rng(2)
    n = 200
    x = rng.uniform(-3, 3, n)
    Phi = np.column_stack([np.ones(n), x])
    t = (rng.random(n) < expit(Phi @ np.array([-1.0, 2.0]))).astype(float)
    model = SparseBayesClassificationModel(Phi, t)
    assert model.centred.tolist() == [True, True]  # both weights are pinned down by the data
    post = sample_posterior(
        model,
        num_samples=300,
        warmup_steps=200,
        num_chains=4,
        seed=0,
        classes=np.array(["ok", "fault"]),
    )
    d = post.diagnostics
    assert d.n_divergences == 0 and d.max_r_hat < 1.01
    xs = np.linspace(-3, 3, 13)
    Ps = np.column_stack([np.ones(xs.size), xs])
    proba = post.predict_proba(Ps)
    assert proba.shape == (13, 2)
    assert np.all((proba >= 0) & (proba <= 1))
    np.testing.assert_allclose(proba.sum(1), 1.0)
    w, Sigma = _laplace_type2(Phi, t)
    var = np.einsum("ij,jk,ik->i", Ps, Sigma, Ps)
    p_ref = expit(Ps @ w / np.sqrt(1 + np.pi * var / 8))
    assert np.max(np.abs(proba[:, 1] - p_ref)) < 0.03
    labels = post.predict(Ps)
    assert set(labels) <= {"ok", "fault"}
    assert labels[0] == "ok" and labels[-1] == "fault"
    with pytest.raises(ValueError, match="predict_proba"):
        post.predict(Ps, return_std=True)


def test_posterior_is_immutable(bump_nuts):
    _, post = bump_nuts
    with pytest.raises(dataclasses.FrozenInstanceError):
        post.weights = None
    with pytest.raises(ValueError):
        post.weights[0, 0, 0] = 1.0


def test_bad_input_raises_value_error(rng):
    Phi = rng.standard_normal((10, 2))
    t = rng.standard_normal(10)
    with pytest.raises(ValueError, match="NaN"):
        SparseBayesRegressionModel(np.where(np.eye(10, 2) > 0, np.nan, Phi), t)
    with pytest.raises(ValueError, match="rows"):
        SparseBayesRegressionModel(Phi, t[:9])
    with pytest.raises(ValueError, match="0 or 1"):
        SparseBayesClassificationModel(Phi, t)
    with pytest.raises(ValueError, match="positive"):
        SparseBayesRegressionModel(Phi, t, Hyperpriors(a_alpha=-1.0))
    model = SparseBayesRegressionModel(Phi, t)
    with pytest.raises(ValueError, match="inference"):
        sample_posterior(model, inference="mcmc")
    with pytest.raises(ValueError, match="num_samples"):
        sample_posterior(model, num_samples=0)
    with pytest.raises(ValueError, match="init"):
        sample_posterior(model, init={"log_alpha": np.zeros(3), "log_beta": 0.0})


def test_unconverged_chains_warn():
    """Chains started far apart without warm-up cannot agree: R-hat flags it with a warning."""
    Phi, y = _bump_problem()
    model = SparseBayesRegressionModel(Phi, y)
    init = {"log_alpha": np.array([-8.0, 8.0]), "log_beta": 0.0}
    with pytest.warns(ConvergenceWarning, match="R-hat"):
        post = sample_posterior(
            model, num_samples=8, warmup_steps=0, seed=0, init=init, init_jitter=6.0
        )
    assert post.diagnostics.max_r_hat > 1.01


def test_classification_labels_default_to_0_and_1(rng):
    x = rng.uniform(-3, 3, 60)
    Phi = np.column_stack([np.ones(60), x])
    t = (x > 0).astype(float)
    model = SparseBayesClassificationModel(Phi, t)
    post = sample_posterior(model, inference="svi", num_samples=50, svi_steps=100, seed=0)
    labels = post.predict(Phi)
    proba = post.predict_proba(Phi)
    np.testing.assert_array_equal(labels, (proba[:, 1] > 0.5).astype(int))
    assert np.mean(labels == t) > 0.9

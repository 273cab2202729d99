"""Sparse Bayesian linear regression with ARD: the Pyro model and its collapsed NUTS potential.

In the style of ``pyro.contrib.gp.models.GPRegression``: a :class:`~pyro.nn.PyroModule` that
holds the data and declares its priors as :class:`~pyro.nn.PyroSample` attributes (``alpha``,
``beta``), with ``model`` methods. The closed-form evidence, its gradient and the exact weight
conditional are written here by hand (Tipping 2001): no maintained library offers the collapsed
sparse Bayesian evidence.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import pyro
import pyro.distributions as dist
import torch
from pyro.nn import PyroModule, PyroSample, pyro_method

from bayes_fdi.rvm.posterior.hyperpriors import (
    Hyperpriors,
    log_gamma_on_log_scale,
    np_log_gamma_on_log_scale,
)
from bayes_fdi.rvm.posterior.numpy_bridge import (
    DTYPE,
    LOG_2PI,
    NumpyFunction,
    as_pair,
    design_and_targets,
    np_cholesky,
)

__all__ = ["SparseBayesRegressionModel"]


def gamma_prior(a: float, b: float, shape: tuple[int, ...] = ()) -> dist.Distribution:
    """``Gamma(a, b)`` in float64, with ``shape`` as one event (an ARD vector) when given."""
    prior = dist.Gamma(torch.tensor(a, dtype=DTYPE), torch.tensor(b, dtype=DTYPE))
    return prior.expand(list(shape)).to_event(len(shape)) if shape else prior


class SparseBayesRegressionModel(PyroModule):
    """Sparse Bayesian linear regression ``t = Phi w + noise`` with ARD and Gamma hyperpriors.

    Parameters
    ----------
    Phi : array-like or torch.Tensor, shape (n, M)
        Design matrix (e.g. ``RVR.design_matrix(X)``: bias column first, then kernel columns).
    t : array-like or torch.Tensor, shape (n,)
        Targets.
    hyperpriors : Hyperpriors, optional
        Defaults to ``Hyperpriors()``; relative rates are resolved against ``var(t)``.

    Attributes
    ----------
    hyperpriors : Hyperpriors
        The absolute (resolved) hyperpriors used by every method.
    alpha, beta : pyro.nn.PyroSample
        The declared priors ``alpha_i ~ Gamma(a_alpha, b_alpha)`` (one per basis function) and
        ``beta ~ Gamma(a_beta, b_beta)``; read inside a model they are Pyro sample sites.
    """

    kind = "regression"
    latent_names = ("log_alpha", "log_beta")

    def __init__(self, Phi: Any, t: Any, hyperpriors: Hyperpriors | None = None) -> None:
        super().__init__()
        self.Phi, self.t = design_and_targets(Phi, t)
        var = float(self.t.var())
        self.target_scale = var if var > 0 else 1.0
        self.hyperpriors = (hyperpriors or Hyperpriors()).resolve(self.target_scale)
        hp = self.hyperpriors
        self.alpha = PyroSample(gamma_prior(hp.a_alpha, hp.b_alpha, (self.n_basis,)))
        self.beta = PyroSample(gamma_prior(hp.a_beta, hp.b_beta))
        Phi_np, t_np = self.Phi.numpy(), self.t.numpy()
        self._PtP_np = Phi_np.T @ Phi_np
        self._Ptt_np = Phi_np.T @ t_np
        self._tt = float(t_np @ t_np)

    @property
    def n_basis(self) -> int:
        """Number of basis functions ``M``."""
        return int(self.Phi.shape[1])

    # ---- closed-form pieces (numpy: small M x M algebra, far below torch's per-op overhead) -----
    def _factor_np(self, la: np.ndarray, lb: np.ndarray):
        """alpha, beta, L (chol of H = A + beta Phi^T Phi), L^-1, Sigma = H^-1, mu (batched)."""
        alpha, beta = np.exp(la), np.exp(lb)
        eye = np.eye(self.n_basis)
        H = beta[..., None, None] * self._PtP_np + alpha[..., :, None] * eye
        L = np_cholesky(H)
        L_inv = np.linalg.solve(L, np.broadcast_to(eye, H.shape))
        Sigma = np.swapaxes(L_inv, -1, -2) @ L_inv
        mu = beta[..., None] * (Sigma @ self._Ptt_np)
        return alpha, beta, L, L_inv, Sigma, mu

    def _evidence_np(self, la: np.ndarray, lb: np.ndarray):
        """Log evidence and its closed-form gradient w.r.t. ``(log alpha, log beta)``."""
        n = self.Phi.shape[0]
        alpha, beta, L, _, Sigma, mu = self._factor_np(la, lb)
        logdet_H = 2.0 * np.log(np.diagonal(L, axis1=-2, axis2=-1)).sum(-1)
        mu_Ptt = (mu * self._Ptt_np).sum(-1)
        value = -0.5 * (n * LOG_2PI - n * lb + logdet_H - la.sum(-1) + beta * (self._tt - mu_Ptt))
        sigma_diag = np.diagonal(Sigma, axis1=-2, axis2=-1)
        resid2 = self._tt - 2.0 * mu_Ptt + (mu * (mu @ self._PtP_np)).sum(-1)
        g_la = 0.5 * (1.0 - alpha * (mu * mu + sigma_diag))
        g_lb = 0.5 * (n - beta * resid2 - (1.0 - alpha * sigma_diag).sum(-1))
        return value, (g_la, g_lb)

    def _joint_np(self, la: np.ndarray, lb: np.ndarray):
        hp = self.hyperpriors
        value, (g_la, g_lb) = self._evidence_np(la, lb)
        prior_a, dprior_a = np_log_gamma_on_log_scale(la, hp.a_alpha, hp.b_alpha)
        prior_b, dprior_b = np_log_gamma_on_log_scale(lb, hp.a_beta, hp.b_beta)
        return value + prior_a.sum(-1) + prior_b, (g_la + dprior_a, g_lb + dprior_b)

    def log_evidence(self, log_alpha: torch.Tensor, log_beta: torch.Tensor) -> torch.Tensor:
        """Gaussian log marginal likelihood ``log N(t | 0, beta^-1 I + Phi A^-1 Phi^T)``.

        Batched over leading dims of ``log_alpha`` (``(..., M)``) and ``log_beta`` (``(...)``).
        Uses ``|C| = beta^-N |A|^-1 |H|`` and ``t^T C^-1 t = beta t^T t - beta t^T Phi mu`` with
        ``H = A + beta Phi^T Phi`` and ``mu = beta H^-1 Phi^T t``, so only ``M x M`` matrices are
        factorised. Differentiable; the gradient is the closed form
        ``d/d log alpha_i = (1 - alpha_i (mu_i^2 + Sigma_ii)) / 2`` and
        ``d/d log beta = (N - beta ||t - Phi mu||^2 - sum_i gamma_i) / 2`` (Tipping 2001).
        """
        return NumpyFunction.apply(self._evidence_np, *as_pair(log_alpha, log_beta))

    def log_hyperprior(self, log_alpha: torch.Tensor, log_beta: torch.Tensor) -> torch.Tensor:
        """Log prior density of ``(log alpha, log beta)`` (Gamma priors with their Jacobians)."""
        hp = self.hyperpriors
        la, lb = as_pair(log_alpha, log_beta)
        prior_a = log_gamma_on_log_scale(la, hp.a_alpha, hp.b_alpha).sum(-1)
        return prior_a + log_gamma_on_log_scale(lb, hp.a_beta, hp.b_beta)

    def log_joint(self, log_alpha: torch.Tensor, log_beta: torch.Tensor) -> torch.Tensor:
        """Unnormalised log posterior of ``(log alpha, log beta)``, weights integrated out."""
        return NumpyFunction.apply(self._joint_np, *as_pair(log_alpha, log_beta))

    def potential(self, params: Mapping[str, torch.Tensor]) -> torch.Tensor:
        """NUTS potential energy: ``-log_joint`` on the unconstrained ``(log alpha, log beta)``."""
        return -self.log_joint(params["log_alpha"], params["log_beta"])

    def weight_posterior(
        self, log_alpha: torch.Tensor, log_beta: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Conditional weight posterior ``N(mu, Sigma)`` given the hyperparameters.

        Returns ``mu`` (``(..., M)``) and the Cholesky factor ``L`` of the precision
        ``Sigma^-1 = A + beta Phi^T Phi`` (``(..., M, M)``).
        """
        la, lb = (x.detach().numpy() for x in as_pair(log_alpha, log_beta))
        _, _, L, _, _, mu = self._factor_np(la, lb)
        return torch.from_numpy(mu), torch.from_numpy(L)

    def sample_weights(
        self,
        log_alpha: torch.Tensor,
        log_beta: torch.Tensor,
        generator: torch.Generator | None = None,
        batch_size: int = 256,
    ) -> torch.Tensor:
        """Exact draws ``w ~ N(mu, Sigma)``, one per row of ``log_alpha`` (``(S, M)``)."""
        la_all, lb_all = (x.detach().numpy() for x in as_pair(log_alpha, log_beta))
        la_all = la_all.reshape(-1, self.n_basis)
        lb_all = lb_all.reshape(-1)
        out = []
        for start in range(0, la_all.shape[0], batch_size):
            la = la_all[start : start + batch_size]
            _, _, _, L_inv, _, mu = self._factor_np(la, lb_all[start : start + batch_size])
            eps = torch.randn(mu.shape, generator=generator, dtype=DTYPE).numpy()
            # Sigma = L^-T L^-1, so w = mu + L^-T eps has covariance Sigma.
            out.append(mu + np.einsum("...ji,...j->...i", L_inv, eps))
        return torch.from_numpy(np.concatenate(out, 0))

    # ---- Pyro models ----------------------------------------------------------------------------
    @pyro_method
    def model(self) -> None:
        """Collapsed Pyro model: declared priors on ``alpha``, ``beta``; evidence as a factor."""
        alpha, beta = self.alpha, self.beta
        pyro.factor("log_evidence", self.log_evidence(alpha.log(), beta.log()))

    @pyro_method
    def noncentred_model(self) -> torch.Tensor:
        """Uncollapsed non-centred Pyro model: ``w = z / sqrt(alpha)``, ``z ~ N(0, I)``.

        The observations are the site ``t`` (``Normal(Phi w, 1/sqrt(beta))`` per point).
        """
        alpha, beta = self.alpha, self.beta
        z = pyro.sample("z", dist.Normal(torch.zeros(self.n_basis, dtype=DTYPE), 1.0).to_event(1))
        w = pyro.deterministic("weights", z * alpha.rsqrt(), event_dim=1)
        with pyro.plate("data", self.Phi.shape[0]):
            pyro.sample("t", dist.Normal(w @ self.Phi.T, beta.rsqrt()[..., None]), obs=self.t)
        return w

    # ---- initial values -------------------------------------------------------------------------
    def default_init(self) -> dict[str, torch.Tensor]:
        """Start values: weight sd = std(t), noise sd = 10% of std(t) (SparseBayes' beta start)."""
        s = self.target_scale
        return {
            "log_alpha": torch.full((self.n_basis,), -math.log(s), dtype=DTYPE),
            "log_beta": torch.tensor(math.log(100.0 / s), dtype=DTYPE),
        }

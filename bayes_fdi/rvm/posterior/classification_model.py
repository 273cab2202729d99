"""Sparse Bayesian logistic regression with ARD: the Pyro model and its NUTS potential.

Like :mod:`~bayes_fdi.rvm.posterior.regression_model`, a :class:`~pyro.nn.PyroModule` holding the
data and declaring its prior ``alpha`` as a :class:`~pyro.nn.PyroSample`. The potential with its
closed-form gradient, in a per-weight centred / non-centred parametrisation, is written by hand
(no maintained library offers it).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyro
import pyro.distributions as dist
import torch
from pyro.nn import PyroModule, PyroSample, pyro_method

from bayes_fdi.rvm.posterior.hyperpriors import Hyperpriors, np_log_gamma_on_log_scale
from bayes_fdi.rvm.posterior.numpy_bridge import (
    DTYPE,
    LOG_2PI,
    NumpyFunction,
    as_pair,
    design_and_targets,
    np_cholesky,
)
from bayes_fdi.rvm.posterior.regression_model import gamma_prior

__all__ = ["SparseBayesClassificationModel"]


class SparseBayesClassificationModel(PyroModule):
    """Sparse Bayesian logistic regression: ``t ~ Bernoulli(sigmoid(Phi w))``.

    Parameters
    ----------
    Phi : array-like or torch.Tensor, shape (n, M)
        Design matrix.
    t : array-like or torch.Tensor, shape (n,)
        Binary targets in {0, 1}.
    hyperpriors : Hyperpriors, optional
        Only ``a_alpha``, ``b_alpha`` are used; relative rates use a scale of 1 (logit units).
    parametrisation : {"auto", "centred", "noncentred"} or array of bool, shape (M,)
        Per basis function, NUTS samples ``v_i = w_i`` (centred) or ``v_i = w_i sqrt(alpha_i)``
        (non-centred). A weight the data determine makes the non-centred posterior a funnel, a
        weight the prior dominates makes the centred one a funnel, so each weight gets its own
        form: ``"auto"`` (default) centres the weights that are more than 3 posterior standard
        deviations from zero in a Laplace fit with unit prior precision (weights the data pin
        down; the others may be switched off by large ``alpha``); a boolean mask
        (True = centred) sets it directly. SVI always uses :meth:`noncentred_model`.

    Attributes
    ----------
    hyperpriors : Hyperpriors
        The absolute (resolved) hyperpriors.
    alpha : pyro.nn.PyroSample
        The declared prior ``alpha_i ~ Gamma(a_alpha, b_alpha)``, one per basis function.
    centred : numpy.ndarray of bool, shape (M,)
        The parametrisation of each weight (read-only).
    """

    kind = "classification"
    latent_names = ("log_alpha", "v")

    def __init__(
        self,
        Phi: Any,
        t: Any,
        hyperpriors: Hyperpriors | None = None,
        parametrisation: Any = "auto",
    ) -> None:
        super().__init__()
        self.Phi, self.t = design_and_targets(Phi, t)
        if not bool(((self.t == 0) | (self.t == 1)).all()):
            raise ValueError("classification targets t must be 0 or 1")
        self.target_scale = 1.0
        self.hyperpriors = (hyperpriors or Hyperpriors()).resolve(1.0)
        hp = self.hyperpriors
        self.alpha = PyroSample(gamma_prior(hp.a_alpha, hp.b_alpha, (self.n_basis,)))
        self._Phi_np, self._t_np = self.Phi.numpy(), self.t.numpy()
        m = self.n_basis
        if isinstance(parametrisation, str):
            if parametrisation == "centred":
                mask = np.ones(m, dtype=bool)
            elif parametrisation == "noncentred":
                mask = np.zeros(m, dtype=bool)
            elif parametrisation == "auto":
                mask = self.well_determined()
            else:
                raise ValueError(
                    "parametrisation must be 'auto', 'centred', 'noncentred' or a boolean mask, "
                    f"got {parametrisation!r}"
                )
        else:
            mask = np.asarray(parametrisation)
            if mask.shape != (m,) or mask.dtype != bool:
                raise ValueError(f"parametrisation mask must be a bool array of shape ({m},)")
        self._centred_t = torch.tensor(mask)
        self.centred = mask.copy()
        self.centred.flags.writeable = False

    @property
    def n_basis(self) -> int:
        """Number of basis functions ``M``."""
        return int(self.Phi.shape[1])

    def laplace(
        self, alpha: np.ndarray, w0: np.ndarray | None = None, n_newton: int = 50
    ) -> tuple[np.ndarray, np.ndarray]:
        """Posterior mode and Laplace covariance of ``w`` for fixed precisions ``alpha``."""
        w = np.zeros(self.n_basis) if w0 is None else np.array(w0, dtype=float)
        for _ in range(n_newton):
            _, g = self._loglik_np(w)
            p = 0.5 * (1.0 + np.tanh(0.5 * (self._Phi_np @ w)))
            H = (self._Phi_np * (p * (1 - p))[:, None]).T @ self._Phi_np + np.diag(alpha)
            step = np.linalg.solve(H, g - alpha * w)
            w = w + step
            if np.max(np.abs(step)) < 1e-10:
                break
        p = 0.5 * (1.0 + np.tanh(0.5 * (self._Phi_np @ w)))
        H = (self._Phi_np * (p * (1 - p))[:, None]).T @ self._Phi_np + np.diag(alpha)
        L = np_cholesky(H)
        L_inv = np.linalg.solve(L, np.eye(self.n_basis))
        return w, L_inv.T @ L_inv

    def well_determined(self, threshold: float = 3.0) -> np.ndarray:
        """Weights whose Laplace z-score ``|w_i| / sd_i`` exceeds ``threshold`` (unit prior)."""
        w, Sigma = self.laplace(np.ones(self.n_basis))
        return np.abs(w) > threshold * np.sqrt(np.diag(Sigma))

    def log_likelihood(self, w: torch.Tensor) -> torch.Tensor:
        """Bernoulli log likelihood of the targets for weights ``w`` (``(..., M)``)."""
        logits = w @ self.Phi.T
        return (self.t * logits - torch.nn.functional.softplus(logits)).sum(-1)

    def _loglik_np(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        f = w @ self._Phi_np.T
        loglik = (self._t_np * f - np.logaddexp(0.0, f)).sum(-1)
        g_w = (self._t_np - 0.5 * (1.0 + np.tanh(0.5 * f))) @ self._Phi_np
        return loglik, g_w

    def weights_from_latent(self, log_alpha: Any, v: Any) -> Any:
        """Weights ``w`` from the sampled latents (numpy or torch, broadcasting)."""
        if isinstance(v, torch.Tensor):
            return torch.where(self._centred_t, v, v * torch.exp(-0.5 * log_alpha))
        return np.where(self.centred, v, v * np.exp(-0.5 * np.asarray(log_alpha)))

    def latent_from_weights(self, log_alpha: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
        """The sampled latent ``v`` of weights ``w`` (inverse of :meth:`weights_from_latent`)."""
        return torch.where(self._centred_t, w, w * torch.exp(0.5 * log_alpha))

    def _joint_np(self, la: np.ndarray, v: np.ndarray):
        """Log joint of ``(log alpha, v)`` and its gradient (numpy, batched)."""
        hp = self.hyperpriors
        c = self.centred
        alpha, scale = np.exp(la), np.exp(-0.5 * la)
        w = np.where(c, v, v * scale)
        loglik, g_w = self._loglik_np(w)
        prior_a, dprior_a = np_log_gamma_on_log_scale(la, hp.a_alpha, hp.b_alpha)
        log_pv = np.where(c, 0.5 * la - 0.5 * alpha * v * v, -0.5 * v * v)
        value = prior_a.sum(-1) + log_pv.sum(-1) - 0.5 * self.n_basis * LOG_2PI + loglik
        g_la = dprior_a + np.where(c, 0.5 - 0.5 * alpha * v * v, -0.5 * w * g_w)
        g_v = np.where(c, -alpha * v + g_w, -v + scale * g_w)
        return value, (g_la, g_v)

    def log_joint(self, log_alpha: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        """Unnormalised log posterior of the latents ``(log alpha, v)``."""
        return NumpyFunction.apply(self._joint_np, *as_pair(log_alpha, v))

    def potential(self, params: Mapping[str, torch.Tensor]) -> torch.Tensor:
        """NUTS potential energy on the unconstrained latents ``(log alpha, v)``."""
        return -self.log_joint(params["log_alpha"], params["v"])

    def _likelihood(self, w: torch.Tensor) -> None:
        with pyro.plate("data", self.Phi.shape[0]):
            pyro.sample("t", dist.Bernoulli(logits=w @ self.Phi.T), obs=self.t)

    @pyro_method
    def model(self) -> torch.Tensor:
        """Pyro model in this instance's per-weight parametrisation (latent site ``v``)."""
        alpha = self.alpha
        c = self._centred_t
        scale = torch.where(c, alpha.rsqrt(), torch.ones_like(alpha))
        v = pyro.sample("v", dist.Normal(torch.zeros_like(alpha), scale).to_event(1))
        w = pyro.deterministic("weights", torch.where(c, v, v * alpha.rsqrt()), event_dim=1)
        self._likelihood(w)
        return w

    @pyro_method
    def noncentred_model(self) -> torch.Tensor:
        """Non-centred Pyro model: ``w = z / sqrt(alpha)``, ``z ~ N(0, I)``; observations ``t``."""
        alpha = self.alpha
        z = pyro.sample("z", dist.Normal(torch.zeros(self.n_basis, dtype=DTYPE), 1.0).to_event(1))
        w = pyro.deterministic("weights", z * alpha.rsqrt(), event_dim=1)
        self._likelihood(w)
        return w

    def default_init(self) -> dict[str, torch.Tensor]:
        """Start values: unit weight precision, zero weights."""
        return {
            "log_alpha": torch.zeros(self.n_basis, dtype=DTYPE),
            "v": torch.zeros(self.n_basis, dtype=DTYPE),
        }

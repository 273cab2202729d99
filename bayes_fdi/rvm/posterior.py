"""Full posteriors for the sparse Bayesian model behind the RVM (Pyro NUTS / SVI, ArviZ output).

The fast type-II fit (``RVR`` / ``RVC``) returns point estimates of the hyperparameters: one
precision ``alpha_i`` per basis function and, for regression, the noise precision ``beta``. This
module puts hyperpriors on them and integrates them out:

.. math::

    \\alpha_i \\sim \\mathrm{Gamma}(a_\\alpha, b_\\alpha), \\quad
    \\beta \\sim \\mathrm{Gamma}(a_\\beta, b_\\beta), \\quad
    w_i \\mid \\alpha_i \\sim \\mathcal N(0, \\alpha_i^{-1}),

with a Gaussian likelihood ``t ~ N(Phi w, 1/beta)`` (regression) or a Bernoulli likelihood with
logits ``Phi w`` (classification).

Two model forms are provided, in the style of ``pyro.contrib.gp`` (a class holding the data and the
declared priors, with ``model`` methods):

* :class:`SparseBayesRegressionModel` -- ``model`` is *collapsed*: the weights are integrated
  out analytically and the Gaussian log evidence ``log N(t | 0, beta^-1 I + Phi A^-1 Phi^T)``
  enters as a ``pyro.factor``; it is computed from the Cholesky factor of the ``M x M`` matrix
  ``A + beta Phi^T Phi`` (Woodbury identity and matrix determinant lemma). NUTS samples
  ``(log alpha, log beta)`` only, and the weights are then drawn exactly from their Gaussian
  conditional ``N(mu, Sigma)``. ``noncentred_model`` keeps the weights, written as
  ``w = z / sqrt(alpha)`` with ``z ~ N(0, I)``; SVI uses it.
* :class:`SparseBayesClassificationModel` -- Bernoulli likelihood; NUTS samples
  ``(log alpha, w)`` (centred, default on the relevance vectors) or ``(log alpha, z)``
  (non-centred); SVI uses the non-centred form.

:func:`fit_posterior` runs it from a fitted estimator (``RVR(...).fit(X, y).fit_posterior(X, y)``),
:func:`sample_posterior` from a model built on an explicit design matrix. Both return an immutable
:class:`RVMPosterior` with posterior draws, ``predict`` (predictions average over the draws),
``diagnostics`` (rank-normalised split R-hat, bulk/tail ESS, divergences per chain) and
``to_arviz()``.

Hyperprior defaults (:class:`Hyperpriors`) and why they are not Tipping's ``1e-6``: with
``a = b = 1e-6`` the prior on ``log alpha`` is flat up to ``alpha ~ 1e6``. The likelihood does not
decay as ``alpha -> infinity`` (the basis is simply switched off), so the posterior of every
weakly-determined ``log alpha`` has a plateau whose mass grows with its length ``log(1/b)``:
posterior answers then depend on an arbitrary constant, and NUTS spends its time wandering along
the plateau; below the data-determined value the posterior of ``log alpha`` decays only like
``alpha^(a + 1/2)``, a long tail when ``a ~ 0``. The defaults ``a_alpha = 1/2``,
``b_alpha = 5e-5`` (rate relative to the target variance) make the implied marginal prior of each
weight a Cauchy distribution with scale ``sqrt(b/a) = 1%`` of the target standard deviation: a
sparsity-favouring prior with heavy tails (data-determined weights are not shrunk), a plateau that
ends at weights too small to matter for prediction, and a light enough lower tail for NUTS to mix
(R-hat < 1.01 without divergences on our test problems). ``beta`` is determined
by all ``N`` residuals, so its prior can stay Tipping-flat (``a_beta = b_beta = 1e-6``; the rate
matches SparseBayes' ``BetaMaxFactor`` floor ``sigma^2 >= var(t) / 1e6``).
"""

from __future__ import annotations

import copy
import functools
import math
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, NamedTuple

import numpy as np
import pyro
import pyro.distributions as dist
import torch
from pyro.infer import MCMC, NUTS, SVI, JitTrace_ELBO, Trace_ELBO
from pyro.infer.autoguide import AutoMultivariateNormal
from pyro.infer.autoguide.initialization import init_to_value
from scipy import stats
from sklearn.exceptions import ConvergenceWarning

__all__ = [
    "Hyperpriors",
    "OneVsRestPosterior",
    "PosteriorDiagnostics",
    "RVMPosterior",
    "SparseBayesClassificationModel",
    "SparseBayesRegressionModel",
    "effective_sample_size",
    "fit_posterior",
    "r_hat",
    "sample_posterior",
]

_DTYPE = torch.float64
_LOG_2PI = math.log(2.0 * math.pi)


# --------------------------------------------------------------------------------------------------
# Hyperpriors
# --------------------------------------------------------------------------------------------------
class Hyperpriors(NamedTuple):
    """Gamma hyperpriors (shape ``a``, rate ``b``) on the weight precisions and noise precision.

    Parameters
    ----------
    a_alpha, b_alpha : float
        Shape and rate of ``alpha_i ~ Gamma(a_alpha, b_alpha)`` for every basis function.
    a_beta, b_beta : float
        Shape and rate of ``beta ~ Gamma(a_beta, b_beta)`` (regression noise precision).
    relative : bool
        If True (default) the rates are in units of the target variance: the model uses
        ``b * var(t)``, which makes the prior invariant to rescaling the targets (``alpha`` and
        ``beta`` both scale as ``1 / var(t)``). Classification targets are on the logit scale
        and use a scale of 1. Set False to give absolute rates.

    Notes
    -----
    On the log scale (where NUTS samples) the Gamma prior has density
    ``exp(a u - b e^u)`` for ``u = log alpha``: almost flat for small ``a`` below ``u ~ log(1/b)``
    and falling off doubly-exponentially above. See the module docstring for the defaults.
    """

    a_alpha: float = 0.5
    b_alpha: float = 5e-5
    a_beta: float = 1e-6
    b_beta: float = 1e-6
    relative: bool = True

    def resolve(self, scale: float) -> Hyperpriors:
        """Absolute hyperpriors for targets of variance ``scale`` (no-op when not relative)."""
        for name in ("a_alpha", "b_alpha", "a_beta", "b_beta"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(
                    f"hyperprior {name} must be a positive finite number, got {value!r}"
                )
        if not self.relative:
            return self
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"hyperprior scale must be positive and finite, got {scale!r}")
        return Hyperpriors(
            self.a_alpha, self.b_alpha * scale, self.a_beta, self.b_beta * scale, relative=False
        )


def _log_gamma_on_log_scale(u: torch.Tensor, a: float, b: float) -> torch.Tensor:
    """Elementwise log density of ``u = log x`` for ``x ~ Gamma(a, b)`` (Jacobian included)."""
    return a * math.log(b) - math.lgamma(a) + a * u - b * torch.exp(u)


def _as_tensor(x: Any, name: str, ndim: int) -> torch.Tensor:
    if isinstance(x, torch.Tensor):
        out = x.detach().to(device="cpu", dtype=_DTYPE)
    else:
        try:
            out = torch.as_tensor(np.asarray(x, dtype=np.float64), dtype=_DTYPE)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{name} must be numeric array-like: {exc}") from exc
    if out.ndim != ndim:
        raise ValueError(f"{name} must be {ndim}-D, got shape {tuple(out.shape)}")
    if not torch.isfinite(out).all():
        raise ValueError(f"{name} contains NaN or inf")
    return out


def _design_and_targets(Phi: Any, t: Any) -> tuple[torch.Tensor, torch.Tensor]:
    """Validated ``(Phi, t)``: finite ``(n, m)`` design (``n >= 2``, ``m >= 1``) and n targets."""
    Phi_t, t_t = _as_tensor(Phi, "Phi", 2), _as_tensor(t, "t", 1)
    n, m = Phi_t.shape
    if t_t.shape[0] != n:
        raise ValueError(f"Phi has {n} rows but t has {t_t.shape[0]} entries")
    if n < 2 or m < 1:
        raise ValueError(f"need at least 2 rows and 1 basis column, got Phi shape {(n, m)}")
    return Phi_t, t_t


def _np_cholesky(H: np.ndarray) -> np.ndarray:
    """Cholesky factor of a batch of SPD matrices, adding diagonal jitter only if needed."""
    try:
        return np.linalg.cholesky(H)
    except np.linalg.LinAlgError:
        pass
    eye = np.eye(H.shape[-1])
    scale = np.abs(np.diagonal(H, axis1=-2, axis2=-1)).mean(-1)[..., None, None]
    for jitter in (1e-12, 1e-10, 1e-8, 1e-6):
        try:
            return np.linalg.cholesky(H + jitter * scale * eye)
        except np.linalg.LinAlgError:
            continue
    raise ValueError("posterior precision matrix A + beta Phi^T Phi is not positive definite")


def _np_log_gamma_on_log_scale(u: np.ndarray, a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
    """Value and derivative of the log density of ``u = log x``, ``x ~ Gamma(a, b)``."""
    bx = b * np.exp(u)
    return a * math.log(b) - math.lgamma(a) + a * u - bx, a - bx


def _as_pair(x: Any, y: Any) -> tuple[torch.Tensor, torch.Tensor]:
    return torch.as_tensor(x, dtype=_DTYPE), torch.as_tensor(y, dtype=_DTYPE)


class _NumpyFunction(torch.autograd.Function):
    """Bridge: ``fn(*arrays) -> (value, grads)`` computed in numpy, differentiable in torch."""

    @staticmethod
    def forward(ctx, fn, *inputs):  # type: ignore[override]
        value, grads = fn(*(x.detach().cpu().numpy() for x in inputs))
        ctx.save_for_backward(*(torch.as_tensor(g, dtype=_DTYPE) for g in grads))
        return torch.as_tensor(value, dtype=_DTYPE)

    @staticmethod
    def backward(ctx, grad_output):  # type: ignore[override]
        out = []
        for g in ctx.saved_tensors:
            go = grad_output.reshape(grad_output.shape + (1,) * (g.ndim - grad_output.ndim))
            out.append(go * g)
        return (None, *out)


# --------------------------------------------------------------------------------------------------
# Models
# --------------------------------------------------------------------------------------------------
class SparseBayesRegressionModel:
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
    """

    kind = "regression"
    latent_names = ("log_alpha", "log_beta")

    def __init__(self, Phi: Any, t: Any, hyperpriors: Hyperpriors | None = None) -> None:
        self.Phi, self.t = _design_and_targets(Phi, t)
        var = float(self.t.var())
        self.target_scale = var if var > 0 else 1.0
        self.hyperpriors = (hyperpriors or Hyperpriors()).resolve(self.target_scale)
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
        L = _np_cholesky(H)
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
        value = -0.5 * (n * _LOG_2PI - n * lb + logdet_H - la.sum(-1) + beta * (self._tt - mu_Ptt))
        sigma_diag = np.diagonal(Sigma, axis1=-2, axis2=-1)
        resid2 = self._tt - 2.0 * mu_Ptt + (mu * (mu @ self._PtP_np)).sum(-1)
        g_la = 0.5 * (1.0 - alpha * (mu * mu + sigma_diag))
        g_lb = 0.5 * (n - beta * resid2 - (1.0 - alpha * sigma_diag).sum(-1))
        return value, (g_la, g_lb)

    def _joint_np(self, la: np.ndarray, lb: np.ndarray):
        hp = self.hyperpriors
        value, (g_la, g_lb) = self._evidence_np(la, lb)
        prior_a, dprior_a = _np_log_gamma_on_log_scale(la, hp.a_alpha, hp.b_alpha)
        prior_b, dprior_b = _np_log_gamma_on_log_scale(lb, hp.a_beta, hp.b_beta)
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
        return _NumpyFunction.apply(self._evidence_np, *_as_pair(log_alpha, log_beta))

    def log_hyperprior(self, log_alpha: torch.Tensor, log_beta: torch.Tensor) -> torch.Tensor:
        """Log prior density of ``(log alpha, log beta)`` (Gamma priors with their Jacobians)."""
        hp = self.hyperpriors
        la, lb = _as_pair(log_alpha, log_beta)
        return _log_gamma_on_log_scale(la, hp.a_alpha, hp.b_alpha).sum(
            -1
        ) + _log_gamma_on_log_scale(lb, hp.a_beta, hp.b_beta)

    def log_joint(self, log_alpha: torch.Tensor, log_beta: torch.Tensor) -> torch.Tensor:
        """Unnormalised log posterior of ``(log alpha, log beta)``, weights integrated out."""
        return _NumpyFunction.apply(self._joint_np, *_as_pair(log_alpha, log_beta))

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
        la, lb = (x.detach().numpy() for x in _as_pair(log_alpha, log_beta))
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
        la_all, lb_all = (x.detach().numpy() for x in _as_pair(log_alpha, log_beta))
        la_all = la_all.reshape(-1, self.n_basis)
        lb_all = lb_all.reshape(-1)
        out = []
        for start in range(0, la_all.shape[0], batch_size):
            la = la_all[start : start + batch_size]
            _, _, _, L_inv, _, mu = self._factor_np(la, lb_all[start : start + batch_size])
            eps = torch.randn(mu.shape, generator=generator, dtype=_DTYPE).numpy()
            # Sigma = L^-T L^-1, so w = mu + L^-T eps has covariance Sigma.
            out.append(mu + np.einsum("...ji,...j->...i", L_inv, eps))
        return torch.from_numpy(np.concatenate(out, 0))

    # ---- Pyro models ----------------------------------------------------------------------------
    def _priors(self):
        hp = self.hyperpriors
        m = self.n_basis
        alpha = pyro.sample(
            "alpha",
            dist.Gamma(
                torch.tensor(hp.a_alpha, dtype=_DTYPE), torch.tensor(hp.b_alpha, dtype=_DTYPE)
            )
            .expand([m])
            .to_event(1),
        )
        beta = pyro.sample(
            "beta",
            dist.Gamma(
                torch.tensor(hp.a_beta, dtype=_DTYPE), torch.tensor(hp.b_beta, dtype=_DTYPE)
            ),
        )
        return alpha, beta

    def model(self) -> None:
        """Collapsed Pyro model: Gamma priors on ``alpha``, ``beta``; the evidence as a factor."""
        alpha, beta = self._priors()
        pyro.factor("log_evidence", self.log_evidence(alpha.log(), beta.log()))

    def noncentred_model(self) -> torch.Tensor:
        """Uncollapsed non-centred Pyro model: ``w = z / sqrt(alpha)``, ``z ~ N(0, I)``."""
        alpha, beta = self._priors()
        z = pyro.sample(
            "z",
            dist.Normal(torch.zeros(self.n_basis, dtype=_DTYPE), 1.0).to_event(1),
        )
        w = pyro.deterministic("weights", z * alpha.rsqrt(), event_dim=1)
        with pyro.plate("data", self.Phi.shape[0]):
            pyro.sample("t", dist.Normal(w @ self.Phi.T, beta.rsqrt()[..., None]), obs=self.t)
        return w

    # ---- initial values -------------------------------------------------------------------------
    def default_init(self) -> dict[str, torch.Tensor]:
        """Start values: weight sd = std(t), noise sd = 10% of std(t) (SparseBayes' beta start)."""
        s = self.target_scale
        return {
            "log_alpha": torch.full((self.n_basis,), -math.log(s), dtype=_DTYPE),
            "log_beta": torch.tensor(math.log(100.0 / s), dtype=_DTYPE),
        }


class SparseBayesClassificationModel:
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
        (True = centred) sets it directly. SVI always uses
        :meth:`noncentred_model`.
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
        self.Phi, self.t = _design_and_targets(Phi, t)
        if not bool(((self.t == 0) | (self.t == 1)).all()):
            raise ValueError("classification targets t must be 0 or 1")
        self.target_scale = 1.0
        self.hyperpriors = (hyperpriors or Hyperpriors()).resolve(1.0)
        self._Phi_np, self._t_np = self.Phi.numpy(), self.t.numpy()
        m = self.Phi.shape[1]
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
        L = _np_cholesky(H)
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
            c = self._centred_t
            return torch.where(c, v, v * torch.exp(-0.5 * log_alpha))
        return np.where(self.centred, v, v * np.exp(-0.5 * np.asarray(log_alpha)))

    def _joint_np(self, la: np.ndarray, v: np.ndarray):
        """Log joint of ``(log alpha, v)`` and its gradient (numpy, batched)."""
        hp = self.hyperpriors
        c = self.centred
        alpha, scale = np.exp(la), np.exp(-0.5 * la)
        w = np.where(c, v, v * scale)
        loglik, g_w = self._loglik_np(w)
        prior_a, dprior_a = _np_log_gamma_on_log_scale(la, hp.a_alpha, hp.b_alpha)
        log_pv = np.where(c, 0.5 * la - 0.5 * alpha * v * v, -0.5 * v * v)
        value = prior_a.sum(-1) + log_pv.sum(-1) - 0.5 * self.n_basis * _LOG_2PI + loglik
        g_la = dprior_a + np.where(c, 0.5 - 0.5 * alpha * v * v, -0.5 * w * g_w)
        g_v = np.where(c, -alpha * v + g_w, -v + scale * g_w)
        return value, (g_la, g_v)

    def log_joint(self, log_alpha: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        """Unnormalised log posterior of the latents ``(log alpha, v)``."""
        return _NumpyFunction.apply(self._joint_np, *_as_pair(log_alpha, v))

    def potential(self, params: Mapping[str, torch.Tensor]) -> torch.Tensor:
        """NUTS potential energy on the unconstrained latents ``(log alpha, v)``."""
        return -self.log_joint(params["log_alpha"], params["v"])

    def _alpha(self) -> torch.Tensor:
        hp = self.hyperpriors
        return pyro.sample(
            "alpha",
            dist.Gamma(
                torch.tensor(hp.a_alpha, dtype=_DTYPE), torch.tensor(hp.b_alpha, dtype=_DTYPE)
            )
            .expand([self.n_basis])
            .to_event(1),
        )

    def _likelihood(self, w: torch.Tensor) -> None:
        with pyro.plate("data", self.Phi.shape[0]):
            pyro.sample("t", dist.Bernoulli(logits=w @ self.Phi.T), obs=self.t)

    def model(self) -> torch.Tensor:
        """Pyro model in this instance's per-weight parametrisation (latent site ``v``)."""
        alpha = self._alpha()
        c = self._centred_t
        scale = torch.where(c, alpha.rsqrt(), torch.ones_like(alpha))
        v = pyro.sample("v", dist.Normal(torch.zeros_like(alpha), scale).to_event(1))
        w = pyro.deterministic("weights", torch.where(c, v, v * alpha.rsqrt()), event_dim=1)
        self._likelihood(w)
        return w

    def noncentred_model(self) -> torch.Tensor:
        """Non-centred Pyro model: ``w = z / sqrt(alpha)``, ``z ~ N(0, I)``."""
        alpha = self._alpha()
        z = pyro.sample("z", dist.Normal(torch.zeros(self.n_basis, dtype=_DTYPE), 1.0).to_event(1))
        w = pyro.deterministic("weights", z * alpha.rsqrt(), event_dim=1)
        self._likelihood(w)
        return w

    def default_init(self) -> dict[str, torch.Tensor]:
        """Start values: unit weight precision, zero weights."""
        return {
            "log_alpha": torch.zeros(self.n_basis, dtype=_DTYPE),
            "v": torch.zeros(self.n_basis, dtype=_DTYPE),
        }


Model = SparseBayesRegressionModel | SparseBayesClassificationModel


# --------------------------------------------------------------------------------------------------
# Convergence diagnostics (rank-normalised split R-hat and ESS, Vehtari et al. 2021)
# --------------------------------------------------------------------------------------------------
def _split_chains(x: np.ndarray) -> np.ndarray:
    half = x.shape[1] // 2
    return np.concatenate([x[:, :half], x[:, x.shape[1] - half :]], axis=0)


def _z_scale(x: np.ndarray) -> np.ndarray:
    ranks = stats.rankdata(x, method="average").reshape(x.shape)
    return stats.norm.ppf((ranks - 0.375) / (x.size + 0.25))


def _classic_r_hat(x: np.ndarray) -> float:
    n = x.shape[1]
    between = n * np.var(x.mean(axis=1), ddof=1)
    within = np.mean(np.var(x, axis=1, ddof=1))
    if within <= 0:
        return float("nan")
    return float(np.sqrt((between / within + n - 1) / n))


def _ess_2d(x: np.ndarray) -> float:
    """Effective sample size of a (chains, draws) array (Geyer initial monotone sequence)."""
    x = np.asarray(x, dtype=float)
    n_chain, n_draw = x.shape
    if np.ptp(x) < np.finfo(float).resolution:
        return float(x.size)
    centred = x - x.mean(axis=1, keepdims=True)
    m = 1 << (2 * n_draw - 1).bit_length()
    f = np.fft.rfft(centred, n=m, axis=1)
    acov = np.fft.irfft(f * np.conjugate(f), n=m, axis=1)[:, :n_draw] / n_draw
    mean_var = acov[:, 0].mean() * n_draw / (n_draw - 1.0)
    var_plus = mean_var * (n_draw - 1.0) / n_draw
    if n_chain > 1:
        var_plus += np.var(x.mean(axis=1), ddof=1)
    rho = np.zeros(n_draw)
    rho[0] = rho_even = 1.0
    rho[1] = rho_odd = 1.0 - (mean_var - acov[:, 1].mean()) / var_plus
    t = 1
    while t < n_draw - 3 and rho_even + rho_odd > 0.0:
        rho_even = 1.0 - (mean_var - acov[:, t + 1].mean()) / var_plus
        rho_odd = 1.0 - (mean_var - acov[:, t + 2].mean()) / var_plus
        if rho_even + rho_odd >= 0:
            rho[t + 1], rho[t + 2] = rho_even, rho_odd
        t += 2
    max_t = t - 2
    if rho_even > 0:
        rho[max_t + 1] = rho_even
    t = 1
    while t <= max_t - 2:
        if rho[t + 1] + rho[t + 2] > rho[t - 1] + rho[t]:
            rho[t + 1] = rho[t + 2] = (rho[t - 1] + rho[t]) / 2.0
        t += 2
    total = n_chain * n_draw
    tau = -1.0 + 2.0 * rho[: max_t + 1].sum() + rho[max_t + 1 : max_t + 2].sum()
    tau = max(tau, 1.0 / np.log10(total))
    return float(total / tau)


def r_hat(draws: Any) -> np.ndarray:
    """Rank-normalised split R-hat (max of bulk and folded), per parameter.

    Parameters
    ----------
    draws : array-like, shape (chains, draws, ...)
        At least 2 chains and 4 draws.

    Returns
    -------
    numpy.ndarray
        Shape ``draws.shape[2:]``; values below 1.01 indicate converged chains.
    """
    x = np.asarray(draws, dtype=float)
    if x.ndim < 2 or x.shape[0] < 2 or x.shape[1] < 4:
        raise ValueError(f"r_hat needs >= 2 chains and >= 4 draws, got shape {x.shape}")
    flat = x.reshape(x.shape[0], x.shape[1], -1)
    out = np.empty(flat.shape[2])
    for j in range(flat.shape[2]):
        split = _split_chains(flat[:, :, j])
        folded = np.abs(split - np.median(split))
        out[j] = max(_classic_r_hat(_z_scale(split)), _classic_r_hat(_z_scale(folded)))
    return out.reshape(x.shape[2:])


def effective_sample_size(draws: Any, kind: Literal["bulk", "tail"] = "bulk") -> np.ndarray:
    """Bulk (rank-normalised) or tail (5%/95% quantile) effective sample size, per parameter.

    Parameters
    ----------
    draws : array-like, shape (chains, draws, ...)
    kind : {"bulk", "tail"}
    """
    x = np.asarray(draws, dtype=float)
    if x.ndim < 2 or x.shape[1] < 4:
        raise ValueError(f"effective_sample_size needs >= 4 draws, got shape {x.shape}")
    if kind not in ("bulk", "tail"):
        raise ValueError(f"kind must be 'bulk' or 'tail', got {kind!r}")
    flat = x.reshape(x.shape[0], x.shape[1], -1)
    out = np.empty(flat.shape[2])
    for j in range(flat.shape[2]):
        v = flat[:, :, j]
        if kind == "bulk":
            out[j] = _ess_2d(_z_scale(_split_chains(v)))
        else:
            out[j] = min(
                _ess_2d(_split_chains((v <= np.quantile(v, p)).astype(float))) for p in (0.05, 0.95)
            )
    return out.reshape(x.shape[2:])


@dataclass(frozen=True)
class PosteriorDiagnostics:
    """Convergence diagnostics of a posterior fit.

    Attributes
    ----------
    inference : str
        ``"nuts"`` or ``"svi"``.
    r_hat, ess_bulk, ess_tail : dict of str to numpy.ndarray
        Per variable (``log_alpha``, ``log_beta``, ``weights``); empty for SVI (independent draws).
    divergences : tuple of int
        Number of divergent transitions after warm-up, per chain (empty for SVI).
    divergent_draws : tuple of tuple of int
        Indices (within the chain's kept draws) of the divergent transitions, per chain.
    acceptance_rate : tuple of float
        Mean Metropolis acceptance per chain (NUTS).
    step_size : tuple of float
        Adapted step size per chain (NUTS).
    elbo : numpy.ndarray or None
        ELBO per SVI step.
    wall_time_s : float
        Time spent in inference.
    """

    inference: str
    r_hat: dict[str, np.ndarray] = field(default_factory=dict)
    ess_bulk: dict[str, np.ndarray] = field(default_factory=dict)
    ess_tail: dict[str, np.ndarray] = field(default_factory=dict)
    divergences: tuple[int, ...] = ()
    divergent_draws: tuple[tuple[int, ...], ...] = field(default=(), repr=False)
    acceptance_rate: tuple[float, ...] = ()
    step_size: tuple[float, ...] = ()
    elbo: np.ndarray | None = field(default=None, repr=False)
    wall_time_s: float = 0.0

    @property
    def max_r_hat(self) -> float:
        """Largest R-hat over all parameters (nan if not computed)."""
        vals = [np.nanmax(v) for v in self.r_hat.values() if np.size(v)]
        return float(max(vals)) if vals else float("nan")

    @property
    def min_ess_bulk(self) -> float:
        """Smallest bulk ESS over all parameters (nan if not computed)."""
        vals = [np.nanmin(v) for v in self.ess_bulk.values() if np.size(v)]
        return float(min(vals)) if vals else float("nan")

    @property
    def n_divergences(self) -> int:
        """Total number of divergent transitions."""
        return int(sum(self.divergences))

    def __str__(self) -> str:
        if self.inference == "svi":
            final = float(self.elbo[-1]) if self.elbo is not None and self.elbo.size else math.nan
            return f"SVI: final ELBO {final:.4g}, {self.wall_time_s:.1f} s"
        return (
            f"NUTS: max R-hat {self.max_r_hat:.4f}, min bulk ESS {self.min_ess_bulk:.0f}, "
            f"divergences {list(self.divergences)}, {self.wall_time_s:.1f} s"
        )


# --------------------------------------------------------------------------------------------------
# Posterior result
# --------------------------------------------------------------------------------------------------
def _readonly(x: np.ndarray | None) -> np.ndarray | None:
    if x is None:
        return None
    x = np.array(x, dtype=np.float64, copy=True)
    x.flags.writeable = False
    return x


@dataclass(frozen=True, eq=False)
class RVMPosterior:
    """Posterior draws of a sparse Bayesian model; immutable.

    Attributes
    ----------
    kind : {"regression", "classification"}
    inference : {"nuts", "svi"}
    basis : str
        ``"active"`` (basis chosen by type-II ML), ``"all"``, or ``"design"`` (explicit matrix).
    log_alpha : numpy.ndarray, shape (chains, draws, M)
    log_beta : numpy.ndarray or None, shape (chains, draws)
        Log noise precision (regression only).
    weights : numpy.ndarray, shape (chains, draws, M)
    diagnostics : PosteriorDiagnostics
    hyperpriors : Hyperpriors
        Absolute hyperpriors used.
    basis_names : tuple of str
    classes : numpy.ndarray or None
        ``[negative, positive]`` labels for classification.
    design : callable or None
        Maps inputs ``X`` to the design matrix; None means ``predict`` takes design matrices.
    """

    kind: str
    inference: str
    basis: str
    log_alpha: np.ndarray = field(repr=False)
    log_beta: np.ndarray | None = field(repr=False)
    weights: np.ndarray = field(repr=False)
    diagnostics: PosteriorDiagnostics
    hyperpriors: Hyperpriors
    basis_names: tuple[str, ...] = field(repr=False)
    classes: np.ndarray | None = field(default=None, repr=False)
    design: Callable[[Any], Any] | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        for name in ("log_alpha", "log_beta", "weights", "classes"):
            value = getattr(self, name)
            if name == "classes":
                if value is not None:
                    value = np.array(value, copy=True)
                    value.flags.writeable = False
            else:
                value = _readonly(value)
            object.__setattr__(self, name, value)
        if self.weights.ndim != 3 or self.log_alpha.shape != self.weights.shape:
            raise ValueError("weights and log_alpha must both have shape (chains, draws, M)")
        if len(self.basis_names) != self.weights.shape[2]:
            raise ValueError("basis_names must have one entry per basis function")

    @property
    def n_draws(self) -> int:
        """Total number of posterior draws (chains x draws)."""
        return int(self.weights.shape[0] * self.weights.shape[1])

    def _design(self, X: Any) -> torch.Tensor:
        Phi = self.design(X) if self.design is not None else X
        if not isinstance(Phi, torch.Tensor):
            Phi = torch.as_tensor(np.asarray(Phi, dtype=np.float64))
        if Phi.ndim != 2 or Phi.shape[1] != self.weights.shape[2]:
            raise ValueError(
                f"design matrix must have shape (n, {self.weights.shape[2]}), "
                f"got {tuple(Phi.shape)}"
            )
        if not torch.isfinite(Phi).all():
            raise ValueError("design matrix contains NaN or inf")
        return Phi

    def _latent(self, X: Any, batch_size: int = 4096) -> tuple[torch.Tensor, bool]:
        """Per-draw linear predictor ``Phi w_s``, shape (n, S)."""
        Phi = self._design(X)
        W = torch.tensor(self.weights.reshape(-1, self.weights.shape[2]))
        W = W.to(device=Phi.device, dtype=Phi.dtype if Phi.is_floating_point() else _DTYPE)
        Phi = Phi.to(W.dtype)
        out = [Phi[i : i + batch_size] @ W.T for i in range(0, Phi.shape[0], batch_size)]
        return torch.cat(out, 0), isinstance(X, torch.Tensor)

    @staticmethod
    def _out(x: torch.Tensor, as_torch: bool) -> Any:
        return x if as_torch else x.detach().cpu().numpy()

    def predict(self, X: Any, return_std: bool = False) -> Any:
        """Posterior predictive mean (and std) averaged over the posterior draws.

        Regression: the predictive distribution is the mixture over draws ``s`` of
        ``N(phi^T w_s, 1/beta_s)``; its mean is the mean of the means and its variance the total
        variance ``E_s[1/beta_s] + Var_s[phi^T w_s]``. Classification: the class label of highest
        averaged probability (``return_std`` is not defined there).

        Parameters
        ----------
        X : array-like or torch.Tensor
            Inputs (or design matrix when the posterior has no ``design``). numpy in -> numpy out,
            torch in -> torch out.
        return_std : bool
        """
        if self.kind == "classification":
            if return_std:
                raise ValueError("return_std is for regression; use predict_proba for classes")
            proba = self.predict_proba(X)
            idx = np.asarray(
                proba.argmax(1).cpu() if isinstance(proba, torch.Tensor) else proba.argmax(1)
            )
            labels = self.classes if self.classes is not None else np.array([0, 1])
            return labels[idx]
        f, as_torch = self._latent(X)
        mean = f.mean(1)
        if not return_std:
            return self._out(mean, as_torch)
        noise_var = torch.exp(-torch.tensor(self.log_beta, dtype=f.dtype, device=f.device)).mean()
        std = torch.sqrt(noise_var + f.var(1, unbiased=False))
        return self._out(mean, as_torch), self._out(std, as_torch)

    def predict_latent(self, X: Any) -> tuple[Any, Any]:
        """Posterior mean and std of the noise-free function ``phi(x)^T w`` over the draws."""
        f, as_torch = self._latent(X)
        return self._out(f.mean(1), as_torch), self._out(f.std(1, unbiased=False), as_torch)

    def predict_proba(self, X: Any) -> Any:
        """Class probabilities ``(n, 2)`` in ``classes`` order: sigmoid averaged over draws."""
        if self.kind != "classification":
            raise ValueError("predict_proba is only defined for classification posteriors")
        f, as_torch = self._latent(X)
        p = torch.sigmoid(f).mean(1)
        return self._out(torch.stack([1.0 - p, p], 1), as_torch)

    def to_arviz(self) -> Any:
        """The draws as an ``arviz.InferenceData`` (groups ``posterior``, ``sample_stats``)."""
        posterior = {"log_alpha": self.log_alpha, "weights": self.weights}
        if self.log_beta is not None:
            posterior["log_beta"] = self.log_beta
        sample_stats = {}
        if self.inference == "nuts":
            sample_stats["diverging"] = self._diverging
        return _to_inference_data(
            posterior,
            sample_stats,
            coords={"basis": list(self.basis_names)},
            dims={"log_alpha": ["basis"], "weights": ["basis"]},
            attrs={"inference": self.inference, "kind": self.kind, "basis": self.basis},
        )

    @property
    def _diverging(self) -> np.ndarray:
        chains, draws = self.weights.shape[:2]
        out = np.zeros((chains, draws), dtype=bool)
        for c, idx in enumerate(self.diagnostics.divergent_draws):
            out[c, list(idx)] = True
        return out


@dataclass(frozen=True, eq=False)
class OneVsRestPosterior:
    """Posteriors of a multi-class RVC's one-vs-rest binary problems; immutable.

    Probabilities follow ``RVC``: each binary posterior gives ``p_k(x)`` (sigmoid averaged over its
    draws) and the class probabilities are ``p_k / sum_j p_j``.

    Attributes
    ----------
    classes : numpy.ndarray
        Class labels, in the order of ``posteriors``.
    posteriors : tuple of RVMPosterior
        Binary posterior of "class k against the rest", one per class.
    """

    classes: np.ndarray = field(repr=False)
    posteriors: tuple[RVMPosterior, ...] = field(repr=False)
    kind: str = "classification"

    def __post_init__(self) -> None:
        classes = np.array(self.classes, copy=True)
        classes.flags.writeable = False
        object.__setattr__(self, "classes", classes)
        object.__setattr__(self, "posteriors", tuple(self.posteriors))
        if len(self.posteriors) != classes.size or classes.size < 3:
            raise ValueError("need one binary posterior per class, and at least 3 classes")

    @property
    def inference(self) -> str:
        """``"nuts"`` or ``"svi"``."""
        return self.posteriors[0].inference

    @property
    def diagnostics(self) -> tuple[PosteriorDiagnostics, ...]:
        """Diagnostics of each one-vs-rest posterior, in class order."""
        return tuple(p.diagnostics for p in self.posteriors)

    def predict_proba(self, X: Any) -> Any:
        """Class probabilities ``(n, n_classes)`` in ``classes`` order."""
        cols = [p.predict_proba(X)[:, 1] for p in self.posteriors]
        if isinstance(cols[0], torch.Tensor):
            P = torch.stack(cols, 1)
            return P / P.sum(1, keepdim=True)
        P = np.stack(cols, 1)
        return P / P.sum(1, keepdims=True)

    def predict(self, X: Any, return_std: bool = False) -> Any:
        """Most probable class labels."""
        if return_std:
            raise ValueError("return_std is for regression; use predict_proba for classes")
        proba = self.predict_proba(X)
        idx = proba.argmax(1)
        return self.classes[np.asarray(idx.cpu() if isinstance(idx, torch.Tensor) else idx)]

    def to_arviz(self) -> Any:
        """One ``InferenceData``; variables ``log_alpha[k]``, ``weights[k]`` per class ``k``."""
        posterior: dict[str, np.ndarray] = {}
        coords: dict[str, Sequence[Any]] = {}
        dims: dict[str, list[str]] = {}
        diverging = []
        for label, p in zip(self.classes, self.posteriors, strict=True):
            dim = f"basis[{label}]"
            posterior[f"log_alpha[{label}]"] = p.log_alpha
            posterior[f"weights[{label}]"] = p.weights
            coords[dim] = list(p.basis_names)
            dims[f"log_alpha[{label}]"] = dims[f"weights[{label}]"] = [dim]
            if p.inference == "nuts":
                diverging.append(p._diverging)
        stats_ = {"diverging": np.any(diverging, axis=0)} if diverging else {}
        return _to_inference_data(
            posterior,
            stats_,
            coords=coords,
            dims=dims,
            attrs={"inference": self.inference, "kind": self.kind, "one_vs_rest": 1},
        )


def _to_inference_data(
    posterior: dict[str, np.ndarray],
    sample_stats: dict[str, np.ndarray],
    *,
    coords: dict[str, Sequence[Any]],
    dims: dict[str, list[str]],
    attrs: dict[str, Any],
) -> Any:
    """All ArviZ calls live here (arviz 0.2x ``from_dict``; add arviz 1.x here)."""
    import arviz as az

    return az.from_dict(
        posterior=posterior,
        sample_stats=sample_stats or None,
        coords=coords,
        dims=dims,
        attrs=attrs,
    )


# --------------------------------------------------------------------------------------------------
# Inference
# --------------------------------------------------------------------------------------------------
def _chain_seeds(seed: int, n: int) -> list[int]:
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(seed).spawn(n)]


def _check_init(model: Model, init: Mapping[str, Any] | None) -> dict[str, torch.Tensor]:
    """Validate start values; classification accepts weights ``w`` or ``z`` for either form."""
    default = model.default_init()
    if init is None:
        return default
    given = {}
    for name, value in init.items():
        value = torch.as_tensor(np.asarray(value, dtype=np.float64), dtype=_DTYPE)
        if not torch.isfinite(value).all():
            raise ValueError(f"init[{name!r}] contains NaN or inf")
        given[name] = value
    if model.kind == "classification" and "log_alpha" in given and "v" not in given:
        half = torch.exp(0.5 * given["log_alpha"])
        if "z" in given:
            given["w"] = given["z"] / half
        if "w" in given:
            c = model._centred_t
            given["v"] = torch.where(c, given["w"], given["w"] * half)
    out = {}
    for name, ref in default.items():
        if name not in given:
            raise ValueError(f"init is missing {name!r} (needs {sorted(default)})")
        if given[name].shape != ref.shape:
            raise ValueError(
                f"init[{name!r}] must have shape {tuple(ref.shape)}, got {tuple(given[name].shape)}"
            )
        out[name] = given[name]
    return out


def _run_nuts(
    model: Model,
    init: dict[str, torch.Tensor],
    *,
    num_samples: int,
    warmup_steps: int,
    num_chains: int,
    seed: int,
    target_accept_prob: float,
    max_tree_depth: int,
    full_mass: bool,
    init_jitter: float,
    progress: bool,
) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Sequential seeded NUTS chains on ``model.potential``; returns (C, S, ...) draws + stats."""
    draws: dict[str, list[np.ndarray]] = {name: [] for name in init}
    stats_: dict[str, list[Any]] = {"divergent_draws": [], "acceptance_rate": [], "step_size": []}
    for chain_seed in _chain_seeds(seed, num_chains):
        pyro.set_rng_seed(chain_seed)
        gen = torch.Generator().manual_seed(chain_seed)
        start = {
            k: v + init_jitter * torch.randn(v.shape, generator=gen, dtype=_DTYPE)
            for k, v in init.items()
        }
        kernel = NUTS(
            potential_fn=model.potential,
            target_accept_prob=target_accept_prob,
            max_tree_depth=max_tree_depth,
            full_mass=full_mass,
        )
        mcmc = MCMC(
            kernel,
            num_samples=num_samples,
            warmup_steps=warmup_steps,
            initial_params=start,
            disable_progbar=not progress,
        )
        mcmc.run()
        for name, value in mcmc.get_samples().items():
            draws[name].append(value.detach().cpu().numpy())
        diag = mcmc.diagnostics()
        stats_["divergent_draws"].append(tuple(int(i) for i in diag["divergences"]["chain 0"]))
        stats_["acceptance_rate"].append(float(diag["acceptance rate"]["chain 0"]))
        stats_["step_size"].append(float(kernel.step_size))
    return {k: np.stack(v, 0) for k, v in draws.items()}, stats_


def _run_svi(
    model: Model,
    init: dict[str, torch.Tensor],
    *,
    steps: int,
    lr: float,
    particles: int,
    num_draws: int,
    seed: int,
    jit: bool,
    progress: bool,
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Full-rank Gaussian SVI on the non-centred model; returns (1, S, ...) draws + ELBO trace."""
    fn = model.noncentred_model
    values = {"alpha": torch.exp(init["log_alpha"])}
    if "log_beta" in init:
        values["beta"] = torch.exp(init["log_beta"])
        # start z at the conditional posterior mean weights, w = z / sqrt(alpha)
        mu, _ = model.weight_posterior(init["log_alpha"], init["log_beta"])
        values["z"] = mu * torch.exp(0.5 * init["log_alpha"])
    else:
        w = model.weights_from_latent(init["log_alpha"], init["v"])
        values["z"] = w * torch.exp(0.5 * init["log_alpha"])
    options = {"num_particles": particles, "vectorize_particles": True, "max_plate_nesting": 1}

    def build(use_jit: bool) -> tuple[AutoMultivariateNormal, SVI]:
        pyro.set_rng_seed(seed)
        pyro.clear_param_store()
        guide = AutoMultivariateNormal(
            fn, init_loc_fn=init_to_value(values=values), init_scale=0.01
        )
        optim = pyro.optim.ClippedAdam({"lr": lr, "lrd": 0.05 ** (1.0 / steps), "clip_norm": 10.0})
        loss = (
            JitTrace_ELBO(ignore_jit_warnings=True, **options) if use_jit else Trace_ELBO(**options)
        )
        return guide, SVI(fn, guide, optim, loss)

    losses = np.empty(steps)
    with warnings.catch_warnings():
        # JitTrace_ELBO relies on torch.jit.trace, deprecated (not removed) in recent torch
        warnings.filterwarnings(
            "ignore", message=".*torch.jit.trace.*", category=DeprecationWarning
        )
        guide, svi = build(jit)
        try:
            losses[0] = svi.step()
        except (RuntimeError, TypeError, NotImplementedError) as exc:
            if not jit:
                raise
            warnings.warn(
                f"JitTrace_ELBO failed ({exc}); falling back to Trace_ELBO",
                RuntimeWarning,
                stacklevel=3,
            )
            guide, svi = build(False)
            losses[0] = svi.step()
        for i in range(1, steps):
            losses[i] = svi.step()
            if progress and (i + 1) % max(1, steps // 10) == 0:
                print(f"SVI step {i + 1}/{steps}: loss {losses[i]:.4g}")
    predictive = pyro.infer.Predictive(
        fn,
        guide=guide,
        num_samples=num_draws,
        parallel=True,
        return_sites=["alpha", "beta", "weights"],
    )
    with torch.no_grad():
        samples = predictive()
    m = model.n_basis
    out = {
        "log_alpha": samples["alpha"].reshape(1, num_draws, m).log().numpy(),
        "weights": samples["weights"].reshape(1, num_draws, m).numpy(),
    }
    if "beta" in samples:
        out["log_beta"] = samples["beta"].reshape(1, num_draws).log().numpy()
    return out, -losses


def _check_int(name: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def sample_posterior(
    model: Model,
    *,
    inference: Literal["nuts", "svi"] = "nuts",
    num_samples: int = 500,
    warmup_steps: int = 500,
    num_chains: int = 2,
    seed: int = 0,
    init: Mapping[str, Any] | None = None,
    target_accept_prob: float = 0.9,
    max_tree_depth: int = 10,
    full_mass: bool = False,
    init_jitter: float = 0.1,
    svi_steps: int = 2000,
    svi_lr: float = 0.03,
    svi_particles: int = 4,
    svi_jit: bool = True,
    progress: bool = False,
    basis: str = "design",
    basis_names: Sequence[str] | None = None,
    design: Callable[[Any], Any] | None = None,
    classes: Any = None,
) -> RVMPosterior:
    """Sample the posterior of a :class:`SparseBayesRegressionModel` / ``ClassificationModel``.

    Parameters
    ----------
    model : SparseBayesRegressionModel or SparseBayesClassificationModel
    inference : {"nuts", "svi"}
        ``"nuts"``: regression samples ``(log alpha, log beta)`` of the collapsed model, then draws
        the weights exactly given each draw; classification samples ``(log alpha, z)``.
        ``"svi"``: full-rank Gaussian guide on the non-centred model (``w = z / sqrt(alpha)``),
        ``num_samples * num_chains`` independent draws from it.
    num_samples, warmup_steps, num_chains : int
        Kept draws and warm-up iterations per chain; chains run one after another.
    seed : int
        Seeds every chain (via ``numpy.random.SeedSequence``), the weight draws and SVI.
    init : dict, optional
        Start values: ``log_alpha`` and ``log_beta`` (regression) or weights ``w`` (or ``z``)
        (classification); default ``model.default_init()``.
        Each chain starts at ``init`` plus ``N(0, init_jitter^2)`` noise.
    target_accept_prob, max_tree_depth, full_mass : NUTS settings.
    svi_steps, svi_lr, svi_particles, svi_jit : SVI settings (ClippedAdam with a learning rate
        decaying 20x; ``svi_particles`` vectorised ELBO particles; ``svi_jit`` traces the ELBO
        with ``JitTrace_ELBO``, about 2x faster).
    progress : bool
        Show progress bars / ELBO.
    basis, basis_names, design, classes
        Recorded on the result; ``design`` maps inputs to design matrices for ``predict``.

    Returns
    -------
    RVMPosterior
    """
    if inference not in ("nuts", "svi"):
        raise ValueError(f"inference must be 'nuts' or 'svi', got {inference!r}")
    num_samples = _check_int("num_samples", num_samples, 4)
    warmup_steps = _check_int("warmup_steps", warmup_steps, 0)
    num_chains = _check_int("num_chains", num_chains, 1)
    seed = _check_int("seed", seed, 0)
    if not 0.0 < target_accept_prob < 1.0:
        raise ValueError(f"target_accept_prob must be in (0, 1), got {target_accept_prob!r}")
    start = _check_init(model, init)
    m = model.n_basis
    names = tuple(basis_names) if basis_names is not None else tuple(f"b{i}" for i in range(m))
    if len(names) != m:
        raise ValueError(f"basis_names has {len(names)} entries for {m} basis functions")

    t0 = time.perf_counter()
    if inference == "nuts":
        raw, st = _run_nuts(
            model,
            start,
            num_samples=num_samples,
            warmup_steps=warmup_steps,
            num_chains=num_chains,
            seed=seed,
            target_accept_prob=target_accept_prob,
            max_tree_depth=_check_int("max_tree_depth", max_tree_depth, 1),
            full_mass=bool(full_mass),
            init_jitter=float(init_jitter),
            progress=progress,
        )
        log_alpha = raw["log_alpha"]
        if model.kind == "regression":
            log_beta = raw["log_beta"]
            gen = torch.Generator().manual_seed(_chain_seeds(seed, num_chains + 1)[-1])
            w = model.sample_weights(
                torch.as_tensor(log_alpha.reshape(-1, m)),
                torch.as_tensor(log_beta.reshape(-1)),
                generator=gen,
            )
            weights = w.numpy().reshape(log_alpha.shape)
        else:
            log_beta = None
            weights = model.weights_from_latent(log_alpha, raw["v"])
        elapsed = time.perf_counter() - t0
        variables = {"log_alpha": log_alpha, "weights": weights}
        if log_beta is not None:
            variables["log_beta"] = log_beta
        diagnostics = PosteriorDiagnostics(
            inference="nuts",
            r_hat={k: r_hat(v) for k, v in variables.items()} if num_chains > 1 else {},
            ess_bulk={k: effective_sample_size(v, "bulk") for k, v in variables.items()},
            ess_tail={k: effective_sample_size(v, "tail") for k, v in variables.items()},
            divergences=tuple(len(d) for d in st["divergent_draws"]),
            divergent_draws=tuple(st["divergent_draws"]),
            acceptance_rate=tuple(st["acceptance_rate"]),
            step_size=tuple(st["step_size"]),
            wall_time_s=elapsed,
        )
        bad_r_hat = num_chains > 1 and diagnostics.max_r_hat > 1.01
        if bad_r_hat or diagnostics.n_divergences:
            warnings.warn(
                f"NUTS chains may not have converged ({diagnostics}); check "
                "posterior.diagnostics, run longer or with more chains. Large R-hat with many "
                "overlapping basis functions usually means a multimodal posterior (chains switch "
                "on different subsets of similar basis functions).",
                ConvergenceWarning,
                stacklevel=2,
            )
    else:
        raw, elbo = _run_svi(
            model,
            start,
            steps=_check_int("svi_steps", svi_steps, 1),
            lr=float(svi_lr),
            particles=_check_int("svi_particles", svi_particles, 1),
            num_draws=num_samples * num_chains,
            seed=seed,
            jit=bool(svi_jit),
            progress=progress,
        )
        log_alpha, weights, log_beta = raw["log_alpha"], raw["weights"], raw.get("log_beta")
        diagnostics = PosteriorDiagnostics(
            inference="svi", elbo=elbo, wall_time_s=time.perf_counter() - t0
        )
    return RVMPosterior(
        kind=model.kind,
        inference=inference,
        basis=basis,
        log_alpha=log_alpha,
        log_beta=log_beta,
        weights=weights,
        diagnostics=diagnostics,
        hyperpriors=model.hyperpriors,
        basis_names=names,
        classes=None if classes is None else np.asarray(classes),
        design=design,
    )


# --------------------------------------------------------------------------------------------------
# Estimator front end
# --------------------------------------------------------------------------------------------------
def _estimator_init(
    estimator: Any, model: Model, basis: str
) -> tuple[dict[str, torch.Tensor], tuple[str, ...]]:
    """Start values and basis names from a fitted RVR / RVC (type-II ML point estimates).

    Column layout (RVM API): ``"active"`` = bias (if kept) then the relevance columns;
    ``"all"`` = bias (if the estimator has ``bias=True``) then every candidate column, so the
    relevance column ``i`` of ``relevance_indices_`` sits at ``offset + i``.
    """
    alpha = np.asarray(estimator.alpha_, dtype=np.float64).reshape(-1)
    rv = np.asarray(estimator.relevance_indices_).reshape(-1).astype(int)
    has_bias = alpha.size == rv.size + 1
    if not np.all(np.isfinite(alpha)) or np.any(alpha <= 0):
        raise ValueError("estimator.alpha_ must be positive and finite over the active basis")
    m = model.n_basis
    if basis == "active":
        if m != alpha.size:
            raise ValueError(f"design matrix has {m} columns but estimator.alpha_ has {alpha.size}")
        cols = np.arange(m)
        names = (("bias",) if has_bias else ()) + tuple(f"rv{i}" for i in rv)
        log_alpha = np.log(alpha)
    else:
        offset = 1 if bool(getattr(estimator, "bias", has_bias)) else 0
        names = (("bias",) if offset else ()) + tuple(f"c{i}" for i in range(m - offset))
        cols = np.concatenate([[0] if has_bias else [], rv + offset]).astype(int)
        if cols.size != alpha.size or (cols.size and cols.max() >= m):
            raise ValueError("estimator's active basis does not fit its basis='all' design matrix")
        # inactive basis functions start where the alpha hyperprior begins to bite (weight ~ 0)
        log_alpha = np.full(m, math.log(0.1 / model.hyperpriors.b_alpha))
        log_alpha[cols] = np.log(alpha)
    init = {"log_alpha": torch.as_tensor(log_alpha, dtype=_DTYPE)}
    if model.kind == "regression":
        beta = float(np.asarray(estimator.beta_))
        if not (math.isfinite(beta) and beta > 0):
            raise ValueError(f"estimator.beta_ must be positive and finite, got {beta!r}")
        init["log_beta"] = torch.tensor(math.log(beta), dtype=_DTYPE)
    else:
        w = np.zeros(m)
        mean = np.asarray(estimator.mean_, dtype=np.float64).reshape(-1)
        if mean.size != cols.size:
            raise ValueError("estimator.mean_ does not match estimator.alpha_")
        w[cols] = mean
        init["w"] = torch.as_tensor(w, dtype=_DTYPE)
    return init, names


def _well_determined_from_estimator(estimator: Any, basis: str, m: int) -> Any:
    """Per-basis centring mask from the type-II fit (``|mean_i| > 3 sd_i``), or "auto"."""
    cov = getattr(estimator, "covariance_", None)
    mean = getattr(estimator, "mean_", None)
    if basis != "active" or cov is None or mean is None:
        return "auto"
    cov = np.asarray(cov, dtype=np.float64)
    mean = np.asarray(mean, dtype=np.float64).reshape(-1)
    if cov.shape != (m, m) or mean.size != m:
        return "auto"
    return np.abs(mean) > 3.0 * np.sqrt(np.diag(cov))


def fit_posterior(
    estimator: Any,
    X: Any,
    y: Any,
    *,
    inference: Literal["nuts", "svi"] = "nuts",
    num_samples: int = 500,
    warmup_steps: int = 500,
    num_chains: int = 2,
    seed: int = 0,
    basis: Literal["active", "all"] = "active",
    hyperpriors: Hyperpriors | None = None,
    svi_steps: int = 2000,
    **kwargs: Any,
) -> RVMPosterior | OneVsRestPosterior:
    """Full posterior of a fitted ``RVR`` / ``RVC`` over its basis (NUTS or SVI).

    Uses only the estimator's public API: ``design_matrix(X, basis=...)``, ``alpha_``, ``beta_``,
    ``mean_``, ``relevance_indices_`` and, for classifiers, ``classes_``. The type-II ML estimates
    are the chains' start values.

    Parameters
    ----------
    estimator : fitted RVR or RVC
        A multi-class RVC (one-vs-rest, ``estimators_``) gives a :class:`OneVsRestPosterior`.
    X : array-like or torch.Tensor, shape (n, d)
        Training inputs (those the estimator was fitted on, for ``basis="all"``).
    y : array-like, shape (n,)
        Targets (regression) or labels among ``estimator.classes_`` (classification).
    inference : {"nuts", "svi"}
    num_samples, warmup_steps, num_chains, seed : see :func:`sample_posterior`.
    basis : {"active", "all"}
        ``"active"``: the basis kept by type-II ML (default). ``"all"``: every training row + bias.
    hyperpriors : Hyperpriors, optional
        Default ``Hyperpriors()`` (rates relative to ``var(y)``).
    svi_steps : int
        Optimisation steps for ``inference="svi"``.
    **kwargs
        Further :func:`sample_posterior` settings (``target_accept_prob``, ``svi_lr``, ...), and
        for classifiers ``parametrisation`` (default: centred where the type-II fit's weight is
        more than 3 standard deviations from 0, see :class:`SparseBayesClassificationModel`).

    Returns
    -------
    RVMPosterior
        ``predict(X, return_std=True)`` (regression), ``predict_proba(X)`` (classification),
        ``diagnostics``, ``to_arviz()``.
    """
    if basis not in ("active", "all"):
        raise ValueError(f"basis must be 'active' or 'all', got {basis!r}")
    for attr in ("alpha_", "design_matrix"):
        if not hasattr(estimator, attr):
            raise ValueError(f"estimator has no {attr!r}: fit it (RVR/RVC) before fit_posterior")
    for forbidden in ("basis", "basis_names", "design", "classes", "init"):
        if forbidden in kwargs:
            raise ValueError(f"{forbidden!r} is set by fit_posterior")
    n = int(X.shape[0]) if hasattr(X, "shape") else len(X)
    y_arr = y.detach().cpu().numpy() if isinstance(y, torch.Tensor) else np.asarray(y)
    if y_arr.ndim != 1 or y_arr.shape[0] != n:
        raise ValueError(f"y must be 1-D with {n} entries (one per row of X), got {y_arr.shape}")
    classes = getattr(estimator, "classes_", None)
    if classes is not None:
        classes = np.asarray(classes)
        unknown = ~np.isin(y_arr, classes)
        if unknown.any():
            raise ValueError(f"y has labels not in estimator.classes_: {np.unique(y_arr[unknown])}")
        subs = getattr(estimator, "estimators_", None)
        if classes.size > 2:
            if subs is None or len(subs) != classes.size:
                raise ValueError(
                    f"{classes.size} classes but estimator.estimators_ does not hold one binary "
                    "one-vs-rest classifier per class"
                )
            parts = []
            for k, (label, sub) in enumerate(zip(classes, subs, strict=True)):
                part = fit_posterior(
                    sub,
                    X,
                    (y_arr == label).astype(int),
                    inference=inference,
                    num_samples=num_samples,
                    warmup_steps=warmup_steps,
                    num_chains=num_chains,
                    seed=int(np.random.SeedSequence([seed, k]).generate_state(1)[0] >> 1),
                    basis=basis,
                    hyperpriors=hyperpriors,
                    svi_steps=svi_steps,
                    **kwargs,
                )
                parts.append(part)
            return OneVsRestPosterior(classes=classes, posteriors=tuple(parts))
        Phi = estimator.design_matrix(X, basis=basis)
        param = kwargs.pop("parametrisation", None)
        if param is None:
            param = _well_determined_from_estimator(estimator, basis, int(Phi.shape[1]))
        model: Model = SparseBayesClassificationModel(
            Phi, (y_arr == classes[1]).astype(np.float64), hyperpriors, param
        )
    else:
        Phi = estimator.design_matrix(X, basis=basis)
        model = SparseBayesRegressionModel(Phi, y_arr.astype(np.float64), hyperpriors)
    init, names = _estimator_init(estimator, model, basis)
    frozen = copy.deepcopy(estimator)
    return sample_posterior(
        model,
        inference=inference,
        num_samples=num_samples,
        warmup_steps=warmup_steps,
        num_chains=num_chains,
        seed=seed,
        init=init,
        svi_steps=svi_steps,
        basis=basis,
        basis_names=names,
        design=functools.partial(frozen.design_matrix, basis=basis),
        classes=classes,
        **kwargs,
    )

"""Laplace approximation of the twin's posterior, and its importance-sampling check.

The posterior mode is found by Levenberg-Marquardt on the model's negative log density
(`bayes_fdi.twin.model.log_joint`) in the unconstrained latent space, with gradients and
curvature from torch autograd: exact for the priors and the AR(1) residual model, Gauss-Newton
for the simulator (its finite-difference derivative is linear in the incoming gradient). The
posterior is then the Gaussian at the mode with the inverse curvature as covariance.
:func:`importance_check` scores Laplace draws under the exact model and reports the Pareto
shape ``k`` of the importance weights (PSIS, Vehtari et al., 2015/2024): below 0.7 the Gaussian
is a usable proposal for the true posterior, and the smoothed weights correct its moments.
Written by hand: Pyro's `AutoLaplaceApproximation` finds the mode with stochastic gradient
steps (hundreds of simulator Jacobians) and needs second derivatives the simulator has not.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import arviz as az
import numpy as np
import torch

from bayes_fdi.twin.model import TwinProblem, log_joint, score

__all__ = ["ImportanceCheck", "LaplaceFit", "fit_laplace", "importance_check"]


class LaplaceFit(NamedTuple):
    """The mode and covariance of the Laplace approximation (unconstrained latent space)."""

    mode: np.ndarray
    covariance: np.ndarray
    log_joint: float
    iterations: int
    converged: bool
    newton_decrement: float


class ImportanceCheck(NamedTuple):
    """Laplace draws scored under the exact model.

    ``draws`` ``(n, d)``, ``log_weights`` (PSIS-smoothed, normalised), ``pareto_k``,
    ``ess`` (effective sample size of the weights), ``outputs`` ``(n, W, T, 2)`` (the
    simulator's X', F' at each draw).
    """

    draws: np.ndarray
    log_weights: np.ndarray
    pareto_k: float
    ess: float
    outputs: np.ndarray


def _value_grad_hessian(problem: TwinProblem, v: np.ndarray):
    x = torch.tensor(v, dtype=torch.float64, requires_grad=True)
    value = -log_joint(problem, x[None])[0]
    (grad,) = torch.autograd.grad(value, x, create_graph=True)
    rows = [torch.autograd.grad(grad[i], x, retain_graph=True)[0] for i in range(x.numel())]
    hess = torch.stack(rows).detach().numpy()
    return float(value.detach()), grad.detach().numpy(), 0.5 * (hess + hess.T)


def _potential(problem: TwinProblem, v: np.ndarray) -> float:
    with torch.no_grad():
        return float(-log_joint(problem, torch.tensor(v, dtype=torch.float64)[None])[0])


def fit_laplace(
    problem: TwinProblem,
    start: np.ndarray,
    *,
    max_iter: int = 40,
    tol: float = 0.1,
    rough_tol: float = 1.0,
) -> LaplaceFit:
    """Levenberg-Marquardt to the posterior mode from ``start``; the Laplace covariance there.

    Converged when the Newton decrement ``g^T H^-1 g / 2`` (the log density the quadratic model
    still promises) is below ``tol`` nats; or below ``rough_tol`` nats when two steps in a row
    fail to deliver it (the simulator's dead zone and backlash make its output, hence the log
    density, rough on that scale: the remaining gain is not there to take). Stops unconverged
    after ``max_iter`` steps, accepted or rejected.
    """
    v = np.asarray(start, dtype=np.float64).copy()
    value, grad, hess = _value_grad_hessian(problem, v)
    damping = 1.0
    decrement = _decrement(grad, hess)
    converged = False
    rejected = 0
    iterations = 0
    for iterations in range(1, max_iter + 1):  # noqa: B007 (reported)
        if decrement < tol or (decrement < rough_tol and rejected >= 2):
            converged = True
            break
        scale = np.maximum(np.abs(np.diag(hess)), 1e-12)
        try:
            step = np.linalg.solve(hess + damping * np.diag(scale), -grad)
        except np.linalg.LinAlgError:
            damping *= 10.0
            continue
        trial = _potential(problem, v + step)
        if math.isfinite(trial) and trial < value:
            v = v + step
            value, grad, hess = _value_grad_hessian(problem, v)
            decrement = _decrement(grad, hess)
            damping = max(damping / 3.0, 1e-9)
            rejected = 0
        else:
            damping *= 4.0
            rejected += 1
            if damping > 1e10:
                break
    covariance = _covariance(hess)
    return LaplaceFit(v, covariance, -value, iterations, converged, decrement)


def _decrement(grad: np.ndarray, hess: np.ndarray) -> float:
    try:
        out = 0.5 * float(grad @ np.linalg.solve(hess, grad))
    except np.linalg.LinAlgError:
        return math.inf
    return out if out >= 0.0 else math.inf


def _covariance(hess: np.ndarray) -> np.ndarray:
    values, vectors = np.linalg.eigh(hess)
    if values.min() <= 0.0:
        raise ValueError(
            "the curvature of the log posterior at the mode is not positive definite (smallest "
            f"eigenvalue {values.min():.3g}): the mode was not reached; raise max_iter or "
            "narrow the priors"
        )
    return (vectors / values) @ vectors.T


def importance_check(
    problem: TwinProblem, fit: LaplaceFit, n_draws: int, rng: np.random.Generator
) -> ImportanceCheck:
    """Draw ``n_draws`` latent vectors from the Laplace Gaussian and weight them by the exact
    posterior density over the Gaussian's (Pareto-smoothed importance sampling)."""
    chol = np.linalg.cholesky(fit.covariance)
    eps = rng.standard_normal((int(n_draws), fit.mode.size))
    draws = fit.mode + eps @ chol.T
    log_q = -0.5 * np.sum(eps**2, axis=1) - np.sum(np.log(np.diag(chol)))
    with torch.no_grad():
        log_p, outputs = score(problem, torch.tensor(draws, dtype=torch.float64))
    raw = log_p.numpy() - log_q
    finite = np.isfinite(raw)
    raw = np.where(finite, raw - raw[finite].max(), -np.inf)
    smoothed, k = az.psislw(raw.copy(), reff=1.0)
    weights = np.exp(smoothed)
    ess = float(1.0 / np.sum(weights**2))
    return ImportanceCheck(draws, smoothed, float(k), ess, outputs.numpy())

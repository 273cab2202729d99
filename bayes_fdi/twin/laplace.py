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

from bayes_fdi.twin.fixed_order import (
    NotPositiveDefinite,
    cholesky,
    inverse_spd,
    matvec,
    solve_spd,
)
from bayes_fdi.twin.model import TwinProblem, log_joint, noise_estimate, score

__all__ = [
    "RELIABLE_PARETO_K",
    "ImportanceCheck",
    "LaplaceFit",
    "fit_laplace",
    "importance_check",
]

#: Largest Pareto shape ``k`` of the importance weights at which the Laplace Gaussian is a
#: usable proposal for the true posterior (Vehtari et al.'s threshold); above it the Gaussian
#: misses part of the posterior's shape and the smoothed weights rest on few draws.
RELIABLE_PARETO_K = 0.7


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


def _profiled(problem: TwinProblem, z: np.ndarray) -> tuple[float, np.ndarray]:
    """Negative log density at ``z`` with the noise parameters at their least-squares AR(1)
    values for the residual there (one simulation); returns it and the full latent vector."""
    with torch.no_grad():
        theta = problem.physical(torch.as_tensor(z, dtype=torch.float64))
        outputs = problem.simulator.outputs(theta.numpy()[None])
        ratio = problem.flow_ratio(theta, torch.as_tensor(outputs[0, ..., 1])).numpy()
        noise = noise_estimate(problem.observed.numpy() - outputs[0], problem.mask.numpy(), ratio)
        v = np.concatenate([z, noise])
        value, _ = score(problem, torch.as_tensor(v)[None], torch.as_tensor(outputs))
    return float(-value[0]), v


def fit_laplace(
    problem: TwinProblem,
    start: np.ndarray,
    *,
    max_iter: int = 40,
    tol: float = 0.01,
    rough_tol: float = 1.0,
) -> LaplaceFit:
    """The posterior mode from ``start`` and the Laplace covariance there.

    Two Levenberg-Marquardt stages: the actuator parameters with the AR(1) noise parameters
    profiled out (set, after every step, to their least-squares values for the residual: far
    from the mode a joint step lets ``phi`` run to 1 and absorb the misfit), then all latent
    variables together, from which the curvature comes. A stage has converged when the Newton
    decrement ``g^T H^-1 g / 2`` (the log density the quadratic model still promises) is below
    ``tol`` nats, or below ``rough_tol`` nats when two steps in a row fail to deliver it (the
    simulator's dead zone and backlash make the log density rough on that scale). Each stage
    stops unconverged after ``max_iter`` steps, accepted or rejected.
    """
    p = problem.n_parameters
    start = np.asarray(start, dtype=np.float64)

    def profile_evaluate(z):
        v = _profiled(problem, z)[1]
        value, grad, hess = _value_grad_hessian(problem, v)
        return value, grad[:p], hess[:p, :p], v

    def profile_trial(z):
        return _profiled(problem, z)[0]

    _, first = _levenberg_marquardt(
        profile_evaluate, profile_trial, start[:p], max_iter=max_iter, tol=tol,
        rough_tol=rough_tol,
    )  # fmt: skip

    def joint_evaluate(v):
        value, grad, hess = _value_grad_hessian(problem, v)
        return value, grad, hess, v

    mode, second = _levenberg_marquardt(
        joint_evaluate, lambda v: _potential(problem, v), first.latent, max_iter=max_iter,
        tol=tol, rough_tol=rough_tol,
    )  # fmt: skip
    covariance = _covariance(second.hess)
    return LaplaceFit(
        mode, covariance, -second.value, first.iterations + second.iterations,
        first.converged and second.converged, second.decrement,
    )  # fmt: skip


class _Stage(NamedTuple):
    value: float
    hess: np.ndarray
    latent: np.ndarray
    iterations: int
    converged: bool
    decrement: float


def _levenberg_marquardt(evaluate, trial_value, x, *, max_iter, tol, rough_tol):
    """Minimise with Marquardt-damped Newton steps; ``evaluate(x)`` gives value, gradient,
    curvature and the full latent vector, ``trial_value(x)`` the value only."""
    x = np.asarray(x, dtype=np.float64).copy()
    value, grad, hess, latent = evaluate(x)
    decrement = _decrement(grad, hess)
    damping = 1.0
    converged = False
    rejected = 0
    iterations = 0
    for iterations in range(1, max_iter + 1):  # noqa: B007 (reported)
        if decrement < tol or (decrement < rough_tol and rejected >= 2):
            converged = True
            break
        scale = np.maximum(np.abs(np.diag(hess)), 1e-12)
        try:
            step = solve_spd(hess + damping * np.diag(scale), -grad)
        except NotPositiveDefinite:
            damping *= 10.0
            continue
        trial = trial_value(x + step)
        if math.isfinite(trial) and trial < value:
            x = x + step
            value, grad, hess, latent = evaluate(x)
            decrement = _decrement(grad, hess)
            damping = max(damping / 3.0, 1e-9)
            rejected = 0
        else:
            damping *= 4.0
            rejected += 1
            if damping > 1e10:
                break
    return x, _Stage(value, hess, latent, iterations, converged, decrement)


def _decrement(grad: np.ndarray, hess: np.ndarray) -> float:
    try:
        return 0.5 * float(np.sum(grad * solve_spd(hess, grad)))
    except NotPositiveDefinite:
        return math.inf


def _covariance(hess: np.ndarray) -> np.ndarray:
    try:
        return inverse_spd(hess)
    except NotPositiveDefinite as exc:
        raise ValueError(
            f"the curvature of the log posterior at the mode is not positive definite ({exc}): "
            "the mode was not reached; raise max_iter or narrow the priors"
        ) from None


def importance_check(
    problem: TwinProblem, fit: LaplaceFit, n_draws: int, rng: np.random.Generator
) -> ImportanceCheck:
    """Draw ``n_draws`` latent vectors from the Laplace Gaussian and weight them by the exact
    posterior density over the Gaussian's (Pareto-smoothed importance sampling)."""
    chol = cholesky(fit.covariance)
    eps = rng.standard_normal((int(n_draws), fit.mode.size))
    draws = fit.mode + matvec(chol, eps)
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

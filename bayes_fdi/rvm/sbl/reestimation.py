"""Tipping's (2001) re-estimation ("EM") solvers: ``alpha_i = gamma_i / mu_i^2``,
``sigma^2 = ||t - Phi mu||^2 / (N - sum gamma)``, pruning large ``alpha`` (Gaussian:
:func:`em_gaussian`; Bernoulli with the Laplace approximation: :func:`em_bernoulli`).

Tipping 2001, "Sparse Bayesian learning and the relevance vector machine" (JMLR), eqs. (10)-(11)
and (26)-(29). Imports the solver family's numerics, :mod:`~bayes_fdi.rvm.sbl.noise` and
:mod:`~bayes_fdi.rvm.sbl.laplace` (not the fast solvers). Written by hand: a few lines on top of
the shared numerics; scikit-learn's ``ARDRegression`` implements the Gaussian case on a fixed
design but not on a kernel design held in blocks, nor the Bernoulli case.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from bayes_fdi.rvm.sbl.design import Design
from bayes_fdi.rvm.sbl.laplace import posterior_mode
from bayes_fdi.rvm.sbl.noise import initial_noise_precision, reestimated_noise_precision
from bayes_fdi.rvm.sbl.precision_factor import factor_precision, gaussian_log_evidence
from bayes_fdi.rvm.sbl.result import SBLResult, result_in_caller_basis, unit_columns

__all__ = ["em_bernoulli", "em_gaussian"]


def em_gaussian(
    design: Design,
    t: Tensor,
    *,
    max_iter: int = 1000,
    tol: float = 1e-3,
    prune: float = 1e8,
    columns: Tensor | None = None,
) -> SBLResult:
    """Tipping's (2001) re-estimation (eqs. 10-11 there), Gaussian noise.

    Starts from the whole candidate basis; costs ``O(M^3 + N M^2)`` per iteration, so it
    is a reference implementation for small problems.

    Parameters
    ----------
    design : Design
        The candidate basis ``B``.
    t : Tensor
        ``(N,)`` targets.
    max_iter : int
        Iteration limit.
    tol : float
        Stop when ``max |Delta log alpha|`` over the active set and ``|Delta log beta|``
        fall below ``tol``, or when an iteration raises the log evidence by less than
        ``1e-3 * tol`` (EM's parameters creep for thousands of iterations after the
        evidence has converged).
    prune : float
        Remove a basis when its (unit-norm) precision exceeds ``prune * beta``: its
        contribution ``b b^T / alpha`` to the marginal covariance is then below
        ``1/prune`` of the noise variance and changes the evidence by at most ~``1/prune``.
    columns : Tensor or None
        Start from these design columns only (indices; all-zero ones are left out as
        always); None: the whole candidate basis.
    """
    N = design.n_samples
    dtype, device = design.dtype, design.device
    norms, valid = unit_columns(design)
    if columns is not None:
        valid = _restricted(valid, columns, device)
    active = valid.nonzero().squeeze(1)
    Phi_all = design.columns(active) / norms[active]
    G_all = Phi_all.T @ Phi_all
    Pt_all = Phi_all.T @ t
    t_sq = float(t @ t)
    t_ref = t_sq if t_sq > 0 else float(N)  # all-zero targets: the scale of a unit target
    beta, beta_max = initial_noise_precision(t, N)
    alpha = torch.full(
        (active.numel(),), active.numel() / max(t_ref, 1e-300), dtype=dtype, device=device
    )
    keep = torch.arange(active.numel(), device=device)  # positions in Phi_all
    alpha_floor = 1e-10 / max(t_ref, 1e-300)  # prior sd at most 1e5 |t| on a unit column
    # a basis whose precision exceeds prune * beta_max is pruned at any noise level; the one
    # kept when all are (a zero target) stays at that level, not at ~1e300 (mu = 0 exactly),
    # so that its precision in the caller's basis (times its column's squared norm) is finite
    alpha_ceiling = prune * beta_max
    trace: list[float] = []
    converged = False
    it = 0
    mu = Sigma = None
    log_ml = -math.inf
    for it in range(1, max_iter + 1):  # noqa: B007
        mu, Sigma, ee, log_ml = _gaussian_posterior(
            Phi_all[:, keep], G_all, Pt_all, t, keep, alpha, beta
        )
        gain = log_ml - trace[-1] if trace else math.inf
        trace.append(log_ml)
        gamma = (1.0 - alpha * Sigma.diagonal()).clamp(0.0, 1.0)
        new_alpha = (gamma / (mu * mu).clamp_min(1e-300)).clamp(alpha_floor, alpha_ceiling)
        new_beta = reestimated_noise_precision(N, float(gamma.sum()), ee, beta_max)
        d_alpha = float((torch.log(new_alpha) - torch.log(alpha)).abs().max())
        d_beta = abs(math.log(new_beta) - math.log(beta))
        if (d_alpha < tol and d_beta < tol) or abs(gain) < 1e-3 * tol:
            converged = True
            break
        alpha, beta = new_alpha, new_beta
        small = alpha < prune * beta
        if not bool(small.any()):  # keep the most relevant basis
            small = alpha == alpha.min()
        keep, alpha = keep[small], alpha[small]
    if not converged:  # statistics of the last hyperparameters
        mu, Sigma, _, log_ml = _gaussian_posterior(
            Phi_all[:, keep], G_all, Pt_all, t, keep, alpha, beta
        )
        trace.append(log_ml)
    return result_in_caller_basis(
        active[keep],
        mu,
        Sigma,
        alpha,
        norms,
        beta=beta,
        trace=trace,
        log_ml=log_ml,
        n_iter=it,
        converged=converged,
    )


def _restricted(valid: Tensor, columns: Tensor, device: torch.device) -> Tensor:
    """``valid`` restricted to the design columns ``columns`` (indices, validated)."""
    columns = torch.as_tensor(columns, dtype=torch.long, device=device)
    if columns.numel() and (int(columns.min()) < 0 or int(columns.max()) >= valid.numel()):
        raise ValueError(f"columns must index the design's {valid.numel()} columns")
    chosen = torch.zeros_like(valid)
    chosen[columns] = True
    valid = valid & chosen
    if not bool(valid.any()):
        raise ValueError("columns contains no usable (non-zero) design column")
    return valid


def _gaussian_posterior(
    Phi: Tensor, G_all: Tensor, Pt_all: Tensor, t: Tensor, keep: Tensor, alpha: Tensor, beta: float
) -> tuple[Tensor, Tensor, float, float]:
    """Posterior mean and covariance of the kept columns ``Phi`` (positions ``keep`` of the
    Gram matrix ``G_all`` and of ``Pt_all = Phi_all^T t``), ``||t - Phi mu||^2`` and the exact
    log evidence."""
    fac = factor_precision(alpha, beta * G_all[keep][:, keep])
    mu = beta * fac.solve(Pt_all[keep])
    Sigma = fac.covariance()
    resid = t - Phi @ mu
    ee = float(resid @ resid)
    return mu, Sigma, ee, gaussian_log_evidence(t.shape[0], beta, ee, alpha, mu, fac)


def em_bernoulli(
    design: Design,
    t: Tensor,
    *,
    max_iter: int = 1000,
    tol: float = 1e-3,
    prune: float = 1e8,
) -> SBLResult:
    """Tipping's (2001) re-estimation with the Laplace approximation (eqs. 26-29 there).

    Parameters
    ----------
    design : Design
        The candidate basis ``B``.
    t : Tensor
        ``(N,)`` targets in ``{0, 1}``.
    max_iter, tol, prune
        As in :func:`em_gaussian` (convergence on ``log alpha`` or the evidence; the Bernoulli noise
        precision ``y(1-y)`` is at most 1/4, so a basis is pruned when ``alpha > prune / 4``).
    """
    dtype, device = design.dtype, design.device
    norms, valid = unit_columns(design)
    active = valid.nonzero().squeeze(1)
    Phi_all = design.columns(active) / norms[active]
    keep = torch.arange(active.numel(), device=device)
    alpha = torch.full(
        (active.numel(),), float(active.numel()) / design.n_samples, dtype=dtype, device=device
    )
    mu = torch.zeros(active.numel(), dtype=dtype, device=device)
    trace: list[float] = []
    converged = False
    it = 0
    mode = None
    for it in range(1, max_iter + 1):  # noqa: B007
        mode = posterior_mode(Phi_all[:, keep], t, alpha, mu)
        gain = mode.log_ml - trace[-1] if trace else math.inf
        trace.append(mode.log_ml)
        gamma = 1.0 - alpha * mode.Sigma.diagonal()
        new_alpha = gamma.clamp_min(1e-300) / (mode.mu * mode.mu).clamp_min(1e-300)
        d_alpha = float((torch.log(new_alpha) - torch.log(alpha)).abs().max())
        if d_alpha < tol or abs(gain) < 1e-3 * tol:
            converged = True
            break
        alpha, mu = new_alpha, mode.mu
        small = alpha < 0.25 * prune
        if not bool(small.any()):
            small = alpha == alpha.min()
        keep, alpha, mu = keep[small], alpha[small], mu[small]
    if not converged:
        mode = posterior_mode(Phi_all[:, keep], t, alpha, mu)
        trace.append(mode.log_ml)
    assert mode is not None
    return result_in_caller_basis(
        active[keep],
        mode.mu,
        mode.Sigma,
        alpha,
        norms,
        beta=math.nan,
        trace=trace,
        log_ml=mode.log_ml,
        n_iter=it,
        converged=converged,
    )

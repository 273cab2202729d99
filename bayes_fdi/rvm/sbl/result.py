"""The solvers' result type (:class:`SBLResult`) and their unit-norm working basis.

Every solver works on unit-norm basis columns (as SparseBayes does): :func:`unit_columns` gives
the norms to divide by, :func:`result_in_caller_basis` maps the weights, covariance and
precisions found on them back to the caller's columns.

Imports :mod:`bayes_fdi.rvm.sbl.design` (for the type of the basis) only.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import Tensor

from bayes_fdi.rvm.sbl.design import Design

__all__ = ["SBLResult", "result_in_caller_basis", "unit_columns"]


class SBLResult(NamedTuple):
    """Result of a sparse Bayesian solver (immutable).

    Attributes
    ----------
    active : Tensor
        ``(M,)`` long indices of the selected columns of the candidate basis, sorted.
    mean : Tensor
        ``(M,)`` posterior mean (mode) of the weights of the active columns.
    covariance : Tensor
        ``(M, M)`` posterior covariance ``(A + Phi^T B Phi)^-1``.
    alpha : Tensor
        ``(M,)`` prior precisions of the active weights.
    beta : float
        Noise precision (Gaussian); ``nan`` for the Bernoulli likelihood.
    evidence_trace : Tensor
        Log marginal likelihood after each iteration.
    log_evidence : float
        Final log marginal likelihood (exact for Gaussian, Laplace for Bernoulli).
    n_iter : int
        Iterations performed.
    converged : bool
        Whether a stopping rule (not the iteration limit) ended the run.
    """

    active: Tensor
    mean: Tensor
    covariance: Tensor
    alpha: Tensor
    beta: float
    evidence_trace: Tensor
    log_evidence: float
    n_iter: int
    converged: bool


#: columns with a norm below this fraction of the largest are left out (`unit_columns`)
RELATIVE_NORM_FLOOR = 2.0**-500


def unit_columns(design: Design) -> tuple[Tensor, Tensor]:
    """Column norms of ``design`` (zero norms replaced by 1) and a mask of its usable columns:
    the solvers divide the columns by these norms.

    A column is usable when its norm exceeds ``2^-500`` times the largest: one below is zero
    beside the others in float64 (its squared norm, by which its precision is mapped back to
    the caller's basis, would leave the normal range), so it is left out like a zero column.
    """
    norms = design.column_norms()
    top = norms.max() if norms.numel() else norms.new_zeros(())
    valid = (norms > 0) & (norms > top * RELATIVE_NORM_FLOOR)
    return torch.where(valid, norms, torch.ones_like(norms)), valid


def result_in_caller_basis(
    active: Tensor,
    mu: Tensor,
    Sigma: Tensor,
    alpha: Tensor,
    norms: Tensor,
    *,
    beta: float,
    trace: list[float],
    log_ml: float,
    n_iter: int,
    converged: bool,
) -> SBLResult:
    """The :class:`SBLResult` of a solver run: unit-norm-basis weights, covariance and
    precisions mapped to the caller's basis, sorted by column index.

    Parameters
    ----------
    active : Tensor
        ``(M,)`` indices of the active columns, in the solver's order.
    mu, Sigma, alpha : Tensor
        Posterior mean, covariance and prior precisions on the unit-norm columns.
    norms : Tensor
        ``(N_B,)`` the norms the columns were divided by (:func:`unit_columns`).
    beta, trace, log_ml, n_iter, converged
        As the fields of :class:`SBLResult` (``trace`` the evidence after each iteration).
    """
    order = torch.argsort(active)
    active = active[order]
    d = norms[active]
    return SBLResult(
        active=active,
        mean=mu[order] / d,
        covariance=Sigma[order][:, order] / (d[:, None] * d[None, :]),
        alpha=alpha[order] * d * d,
        beta=float(beta),
        evidence_trace=torch.tensor(trace, dtype=torch.float64),
        log_evidence=float(log_ml),
        n_iter=n_iter,
        converged=converged,
    )

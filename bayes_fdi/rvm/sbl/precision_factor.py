"""Numerics shared by the sparse Bayesian solvers: the result type, the scaled Cholesky factor
of the posterior precision, the exact Gaussian log evidence, unit-norm columns and the
alignment test.

Written by hand: no maintained library implements Tipping & Faul's sequential solver
(``shared/reference/fast-sbl.md``).
"""

from __future__ import annotations

import math
import warnings
from typing import NamedTuple

import torch
from torch import Tensor

from bayes_fdi.rvm.sbl.design import Design
from bayes_fdi.rvm.sbl.decisions import exact_near_threshold

__all__ = ["NumericalWarning", "SBLResult", "cholesky_jitter"]

# SparseBayes v2: candidates with |cosine| above this to an active column are not added
_ALIGNMENT_MAX = 1.0 - 1e-3
_LOG_2PI = math.log(2.0 * math.pi)


class NumericalWarning(UserWarning):
    """A numerical safeguard (e.g. Cholesky jitter) was needed."""


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


def cholesky_jitter(H: Tensor, *, what: str = "posterior precision") -> Tensor:
    """Lower Cholesky factor of the SPD matrix ``H``, retrying with growing jitter.

    A :class:`NumericalWarning` is emitted when jitter is needed.

    Raises
    ------
    ValueError
        If ``H`` is not positive definite even with jitter ``1e-2 * mean(diag)``.
    """
    L, info = torch.linalg.cholesky_ex(H)
    if int(info) == 0:
        return L
    scale = float(H.diagonal().abs().mean()) or 1.0
    eye = torch.eye(H.shape[0], dtype=H.dtype, device=H.device)
    jitter = 1e-12 * scale
    while jitter <= 1e-2 * scale:
        L, info = torch.linalg.cholesky_ex(H + jitter * eye)
        if int(info) == 0:
            warnings.warn(
                f"{what} not positive definite; added jitter {jitter:.3g} to its diagonal",
                NumericalWarning,
                stacklevel=3,
            )
            return L
        jitter *= 10.0
    raise ValueError(f"{what} is not positive definite (Cholesky failed even with jitter)")


class _Factor(NamedTuple):
    """Cholesky factor of a posterior precision ``H = diag(alpha) + G`` in scaled form.

    ``H = D^-1 (I + D G D) D^-1`` with ``D = diag(alpha^-1/2)``; the scaled matrix has all
    eigenvalues >= 1, so its Cholesky factor ``L`` exists even when ``H`` is badly scaled.
    """

    L: Tensor
    d: Tensor

    def solve(self, b: Tensor) -> Tensor:
        """``H^-1 b`` for a vector ``b``."""
        return self.d * torch.cholesky_solve((self.d * b)[:, None], self.L)[:, 0]

    def solve_matrix(self, B: Tensor) -> Tensor:
        """``H^-1 B`` for a matrix ``B`` (``(M, K)``)."""
        return self.d[:, None] * torch.cholesky_solve(self.d[:, None] * B, self.L)

    def covariance(self) -> Tensor:
        """``Sigma = H^-1`` (explicit: the reported covariance, and ``gamma`` for ``beta``)."""
        return self.d[:, None] * torch.cholesky_inverse(self.L) * self.d[None, :]

    def half_logdet_scaled(self) -> float:
        """``(log|H| - sum log alpha) / 2``, the evidence's log-determinant term."""
        return float(torch.log(self.L.diagonal()).sum())


def _factor(alpha: Tensor, G: Tensor, *, what: str = "posterior precision") -> _Factor:
    d = alpha.rsqrt()
    Hs = d[:, None] * (0.5 * (G + G.T)) * d[None, :]
    Hs.diagonal().add_(1.0)
    return _Factor(cholesky_jitter(Hs, what=what), d)


def _gaussian_log_ml(
    N: int, beta: float, ee: float, alpha: Tensor, mu: Tensor, fac: _Factor
) -> float:
    """Exact ``log N(t | 0, beta^-1 I + Phi A^-1 Phi^T)`` from the posterior statistics."""
    return (
        0.5 * (N * math.log(beta) - beta * ee - N * _LOG_2PI - float((alpha * mu * mu).sum()))
        - fac.half_logdet_scaled()
    )


def _unit_columns(design: Design) -> tuple[Tensor, Tensor]:
    """Column norms (zero norms replaced by 1) and a mask of usable (non-zero) columns."""
    norms = design.column_norms()
    valid = norms > 0
    return torch.where(valid, norms, torch.ones_like(norms)), valid


def _result(
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
    precisions mapped to the caller's basis, sorted by column index."""
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


class _Alignment:
    """Alignment test of SparseBayes: refuse candidates nearly parallel to an active column."""

    def __init__(self, n_basis: int, device: torch.device) -> None:
        self.count = torch.zeros(n_basis, dtype=torch.long, device=device)

    def add(self, col: Tensor) -> None:
        self.count += (col.abs() > _ALIGNMENT_MAX).long()

    def remove(self, col: Tensor) -> None:
        self.count -= (col.abs() > _ALIGNMENT_MAX).long()

    @property
    def free(self) -> Tensor:
        return self.count == 0


def _exact_alignment(
    BtBi: Tensor, design: Design, norms: Tensor, b_i: Tensor, error: float
) -> None:
    """Recompute exactly (in place) the screened cosines ``B^T b_i`` within their error bound
    ``error`` (``Design.screening_error``) of the alignment threshold
    (``sbl_decisions.exact_near_threshold``)."""
    exact_near_threshold(
        BtBi,
        _ALIGNMENT_MAX,
        lambda idx: (design.columns(idx) / norms[idx]).T @ b_i,
        relative=2.0 * error / _ALIGNMENT_MAX,
    )

r"""The fast solvers' factors ``S, Q`` of candidate columns in residual form, without
cancellation: Gaussian noise (:func:`exact_factors`) and per-sample noise precisions, the
Bernoulli model's Laplace approximation (:func:`weighted_exact_factors`).

Rule 1 of :mod:`bayes_fdi.rvm.sbl.decisions`: these are the exact factors every decision is
taken on. Imports :mod:`~bayes_fdi.rvm.sbl.precision_factor` and
:mod:`~bayes_fdi.rvm.sbl.rounding`. Written by hand: no maintained library computes them.
"""

from __future__ import annotations

from torch import Tensor

from bayes_fdi.rvm.sbl.precision_factor import PrecisionFactor
from bayes_fdi.rvm.sbl.rounding import thin_matmul

__all__ = ["exact_factors", "weighted_exact_factors"]


def exact_factors(
    fac: PrecisionFactor,
    Phi: Tensor,
    alpha: Tensor,
    beta: float,
    mu: Tensor,
    resid: Tensor,
    Bc: Tensor,
    Z: Tensor,
) -> tuple[Tensor, Tensor]:
    """``S`` and ``Q`` of candidate columns ``Bc`` in residual form (no cancellation), Gaussian
    noise of precision ``beta``.

    With ``c = beta H^-1 Phi^T b``: ``S = beta ||b - Phi c||^2 + c^T A c`` and
    ``Q = beta (b - Phi c)^T (t - Phi mu) + c^T A mu`` (equal to the textbook
    ``beta b^T b - beta^2 b^T Phi Sigma Phi^T b`` and ``beta b^T t - beta^2 b^T Phi Sigma Phi^T t``
    in exact arithmetic). Cost ``O(N M K)``. :func:`weighted_exact_factors` is the same for
    per-sample noise precisions (the Bernoulli model's Laplace approximation).

    Parameters
    ----------
    fac : PrecisionFactor
        Cholesky factor of ``H = A + beta Phi^T Phi`` (fresh, not rank-one updated).
    Phi : Tensor
        ``(N, M)`` active columns; ``alpha`` ``(M,)`` their precisions; ``beta`` the noise
        precision.
    mu, resid : Tensor
        ``(M,)`` posterior mean ``beta H^-1 Phi^T t`` and ``(N,)`` residual ``t - Phi mu``.
    Bc : Tensor
        ``(N, K)`` candidate columns (active columns allowed).
    Z : Tensor
        ``(M, K)`` their exact Gram entries ``Phi^T Bc``.
    """
    C = beta * fac.solve_matrix(Z)
    R = Bc - thin_matmul(Phi, C)
    AC = alpha[:, None] * C
    S = beta * (R * R).sum(0) + (AC * C).sum(0)
    Q = beta * (R.T @ resid) + AC.T @ mu
    return S, Q


def weighted_exact_factors(
    fac: PrecisionFactor,
    Phi: Tensor,
    alpha: Tensor,
    weights: Tensor,
    mu: Tensor,
    score: Tensor,
    Bc: Tensor,
    WZ: Tensor,
) -> tuple[Tensor, Tensor]:
    """``S`` and ``Q`` in residual form for per-sample noise precisions ``W = diag(weights)``.

    The Laplace approximation of the Bernoulli model at the mode ``mu`` is a Gaussian model
    with noise precisions ``w = y (1 - y)`` and working targets ``t_hat = Phi mu + W^-1 (t - y)``
    (SparseBayes). With ``H = A + Phi^T W Phi`` and ``c = H^-1 Phi^T W b``:

    ``S = (b - Phi c)^T W (b - Phi c) + c^T A c``,
    ``Q = (b - Phi c)^T (t - y) + c^T A mu``,

    equal in exact arithmetic to the textbook ``b^T W b - b^T W Phi Sigma Phi^T W b`` and
    ``b^T W t_hat - b^T W Phi Sigma Phi^T W t_hat = b^T (t - y) - c^T g`` with the gradient
    ``g = Phi^T (t - y) - A mu`` of the log posterior. ``Q`` is thus the factor at the Newton
    update of ``mu``, and an error ``delta`` of the mode changes it only to second order
    (``d(b^T (t - y)) = -b^T W Phi delta`` is cancelled by ``-c^T dg = c^T H delta``): the
    decisions do not depend on how the last Newton step rounded. Cost ``O(N M K)``.

    Parameters
    ----------
    fac : PrecisionFactor
        Cholesky factor of ``H = A + Phi^T W Phi`` (fresh, not rank-one updated).
    Phi : Tensor
        ``(N, M)`` active columns; ``alpha`` ``(M,)`` their precisions.
    weights : Tensor
        ``(N,)`` noise precisions ``w`` (``y (1 - y)`` at the mode).
    mu : Tensor
        ``(M,)`` mode (posterior mean).
    score : Tensor
        ``(N,)`` weighted working residual ``W (t_hat - Phi mu)`` (Bernoulli: ``t - y``).
    Bc : Tensor
        ``(N, K)`` candidate columns (active columns allowed).
    WZ : Tensor
        ``(M, K)`` their weighted Gram entries ``Phi^T W Bc``.
    """
    C = fac.solve_matrix(WZ)
    R = Bc - thin_matmul(Phi, C)
    AC = alpha[:, None] * C
    S = (weights[:, None] * R * R).sum(0) + (AC * C).sum(0)
    Q = R.T @ score + AC.T @ mu
    return S, Q

r"""Screening factors ``S, Q`` of every candidate from a fresh factor, with rigorous bounds of
their error (:func:`screened_factors`, :func:`gaussian_screened_Q`).

Rule 2 of :mod:`bayes_fdi.rvm.sbl.decisions`: screened factors only rank the candidates; their
error bounds say which ones could win and must be recomputed exactly. Imports
:mod:`~bayes_fdi.rvm.sbl.precision_factor` and :mod:`~bayes_fdi.rvm.sbl.rounding`. Written by
hand: no maintained library bounds these errors.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
from torch import Tensor

from bayes_fdi.rvm.sbl.precision_factor import PrecisionFactor
from bayes_fdi.rvm.sbl.rounding import rounding_gamma

__all__ = ["Screening", "factor_trace", "gaussian_screened_Q", "screened_factors"]


class Screening(NamedTuple):
    """Screening factors of every candidate and what their error bounds need
    (:func:`screened_factors`)."""

    S: Tensor  # (N_B,) screened S
    S_error: Tensor  # (N_B,) bound of |S - exact S|
    C: Tensor  # (N_B, M) rows: solve coefficients c = H^-1 z (for the Gaussian model's Q)
    solve_error: Tensor  # (N_B,) bound of ||H^-1/2 (H c - z)||: the solve's error in H-norm
    residual: Tensor  # (N_B,) bound of ||H c - z||
    c_norm: Tensor  # (N_B,) ||c||
    z_norm: Tensor  # (N_B,) ||z||
    trace: float  # upper bound of lambda_max(H^-1) (tr(H^-1) unless given)


def screened_factors(
    fac: PrecisionFactor,
    H: Tensor,
    Z: Tensor,
    diag: Tensor,
    *,
    z_error: Tensor,
    diag_error: Tensor | float = 0.0,
    trace: float | None = None,
) -> Screening:
    """Screening ``S = diag - z^T H^-1 z`` for the rows ``z`` of ``Z`` (``(N_B, M)``) from a
    fresh Cholesky factor, in a form stationary in the solve, with a rigorous error bound.

    With ``c`` the computed ``H^-1 z`` (a Cholesky solve with the factor), ``S`` is evaluated as
    ``f(c) = diag - 2 z^T c + c^T H c`` with ``H`` itself (not the factor): ``f`` is minimal at
    the exact solve, ``f(c) - S = (c - c*)^T H (c - c*) = r^T H^-1 r <= tr(H^-1) ||r||^2`` for
    the solve residual ``r = H c - z`` (computed), so the factor's own backward error enters
    only to second order (``trace``: an upper bound of ``lambda_max(H^-1)``; when not given,
    ``tr(H^-1)`` from :func:`factor_trace`). The remaining terms of the bound:

    * the inputs: each entry ``k`` of a row of ``Z`` within ``z_error[k]`` of the exact one
      (``Design.screening_error``) moves ``S`` by at most ``2 ||c|| ||z_error|| +
      ||z_error||^2 tr(H^-1)``, and ``diag`` by ``diag_error``;
    * rounding of the sums (Higham's ``gamma_n``, eq. 3.5, relative to the sums of absolute
      values, bounded by Cauchy-Schwarz and ``|| |H| |c| || <= ||H||_F ||c||``).

    Cost ``O(M^2 N_B)`` (a Cholesky solve and one product with ``H``) and a few passes over
    ``Z``.
    """
    M = Z.shape[1]
    dt = Z.dtype
    d = fac.d
    # rows c^T = (D z)^T (L L^T)^-1 D: one Cholesky solve on the column-major view of Z
    C = torch.cholesky_solve((Z * d).T, fac.L).T * d
    W = torch.addmm(Z, C, H, beta=-2.0)  # rows: (H c - 2 z)^T
    S = diag + (C * W).sum(1)  # = diag - 2 z^T c + c^T H c
    if trace is None:
        trace = factor_trace(fac)
    H_F = float(torch.linalg.matrix_norm(H)) * (1.0 + rounding_gamma(M * M, dt))
    c_norm = torch.linalg.vector_norm(C, dim=1)
    z_norm = torch.linalg.vector_norm(Z, dim=1)
    r_norm = torch.linalg.vector_norm(W.add_(Z), dim=1)  # W + Z = H c - z
    r_norm += rounding_gamma(M + 2, dt) * (H_F * c_norm + z_norm)
    solve_error = math.sqrt(trace) * r_norm
    ze = float(torch.linalg.vector_norm(z_error))
    S_error = (
        solve_error.square()
        + 2.0 * ze * c_norm
        + ze * ze * trace
        + diag_error
        + rounding_gamma(2 * M + 4, dt) * (diag.abs() + c_norm * (2.0 * z_norm + H_F * c_norm))
    )
    return Screening(S, S_error, C, solve_error, r_norm, c_norm, z_norm, trace)


def factor_trace(fac: PrecisionFactor) -> float:
    """Upper bound of ``tr(H^-1)`` (``>= lambda_max(H^-1)``) from the Cholesky factor,
    ``O(M^3)``."""
    d = fac.d
    M = d.numel()
    trace = float((d * d * torch.cholesky_inverse(fac.L).diagonal()).sum())
    return max(trace, 0.0) * (1.0 + rounding_gamma(3 * M, d.dtype))


def gaussian_screened_Q(
    screening: Screening,
    Z: Tensor,
    b_t: Tensor,
    b_t_error: float,
    mu: Tensor,
    gradient: Tensor,
    gradient_error: Tensor,
    z_error: Tensor,
) -> tuple[Tensor, Tensor]:
    """Screening ``Q = b^T t - z^T mu`` (``b^T t`` scaled as ``z``) of the Gaussian model, in
    a form stationary in both solves, with a rigorous error bound.

    With the computed mean ``mu``, its residual ``g = H mu - beta Phi^T t`` (``gradient``,
    computed directly, within ``gradient_error``) and the screening's ``c``,
    ``f = b^T t - z^T mu + c^T g`` equals the exact ``Q`` up to ``(c - c*)^T H (mu - mu*)``,
    at most ``||H^-1/2 r|| tr(H^-1)^1/2 ||g||`` (Cauchy-Schwarz in the ``H`` inner product):
    second order in the solves' errors. Further terms: the inputs (``z`` entries within
    ``z_error``, ``b^T t`` within ``b_t_error``) and rounding of the sums.

    Returns
    -------
    Q, Q_error : Tensor
        ``(N_B,)`` each.
    """
    M = Z.shape[1]
    Q = b_t - Z @ mu + screening.C @ gradient
    g_norm = float(torch.linalg.vector_norm(gradient))
    g_err = float(torch.linalg.vector_norm(gradient_error))
    mu_norm = float(torch.linalg.vector_norm(mu))
    trace = screening.trace
    c_norm = screening.c_norm
    Q_error = (
        screening.solve_error * ((g_norm + g_err) * math.sqrt(trace))
        + b_t_error
        + float(z_error @ mu.abs())
        + float(torch.linalg.vector_norm(z_error)) * trace * (g_norm + g_err)
        + c_norm * g_err
        + rounding_gamma(M + 3, Z.dtype)
        * (b_t.abs() + screening.z_norm * mu_norm + c_norm * g_norm)
    )
    return Q, Q_error

r"""The fast Gaussian solver's current posterior in ``beta``-free units, with the bounds that
the carried screening factors' updates need (:class:`Posterior`, :func:`posterior_context`).

With ``H_ = diag(alpha / beta) + Phi^T Phi`` (stored Gram entries, each within ``eps`` of the
exact ones) the bounds are: ``||H_||_F``, ``lambda_max(H_^-1)``, how far ``H_`` may fall below
``diag(alpha / beta)`` (``psd``), and the error of the posterior mean weighted by the prior
precisions. See :mod:`bayes_fdi.rvm.sbl.tracked_factors` for their use.

Imports :mod:`~bayes_fdi.rvm.sbl.precision_factor` and :mod:`~bayes_fdi.rvm.sbl.rounding`.
Written by hand: no maintained library bounds these errors.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
from torch import Tensor

from bayes_fdi.rvm.sbl.precision_factor import PrecisionFactor
from bayes_fdi.rvm.sbl.rounding import rounding_gamma

__all__ = ["Posterior", "posterior_context"]


class Posterior(NamedTuple):
    """The current posterior in ``beta``-free units, with the bounds the updates need
    (:func:`posterior_context`)."""

    fac: PrecisionFactor  # Cholesky factor of H = beta * Hb
    beta: float
    abar: Tensor  # (M,) alpha / beta
    root: Tensor  # (M,) abar^1/2
    Hb: Tensor  # (M, M) stored precision diag(abar) + G
    Hb_F: float  # upper bound of ||Hb||_F
    lam: float  # upper bound of lambda_max(Hb^-1)
    psd: float  # Hb >= A / psd (1 for an exactly PSD Gram matrix; slightly above 1 here)
    mu: Tensor  # (M,) posterior mean Hb^-1 Phi^T t
    mu_error_w: float  # bound of ||A^1/2 (mu - exact mu)||
    gradient: Tensor  # (M,) Hb mu - Phi^T t (computed)
    gradient_error: Tensor  # (M,) bound of its rounding

    def solve(self, v: Tensor) -> Tensor:
        """``Hb^-1 v``."""
        return self.beta * self.fac.solve(v)

    def weighted(self, v: Tensor) -> float:
        """``||A^-1/2 v||`` (upper bound, rounding included)."""
        n = float(torch.linalg.vector_norm(v / self.root))
        return n * (1.0 + rounding_gamma(v.numel() + 2, v.dtype))


def posterior_context(
    fac: PrecisionFactor,
    alpha: Tensor,
    beta: float,
    G: Tensor,
    mu: Tensor,
    Phi_t: Tensor,
    eps: float,
) -> Posterior:
    """Bounds of the current posterior from its fresh factor, ``O(M^2)``.

    The exact Gram matrix is positive semi-definite and the stored one is within ``eps`` per
    entry (``Design.screening_error``), so ``Hb >= A - M eps >= A (1 - M eps / min abar)``:
    ``lambda_max(Hb^-1) <= 1 / (min abar - M eps)``. Where that is not positive, every bound
    is infinite and the carried factors are refreshed each iteration.
    """
    M = alpha.numel()
    dt = alpha.dtype
    abar = alpha / beta
    Hb = 0.5 * (G + G.T)
    Hb.diagonal().add_(abar)
    Hb_F = float(torch.linalg.matrix_norm(Hb)) * (1.0 + rounding_gamma(M * M + 1, dt))
    a_min = float(abar.min())
    low = a_min - M * eps
    gamma2 = rounding_gamma(2, dt)
    if low > 0:
        lam, psd = (1.0 / low) * (1.0 + gamma2), (a_min / low) * (1.0 + gamma2)
    else:
        lam = psd = math.inf
    root = abar.sqrt()
    gradient = Hb @ mu - Phi_t
    gradient_error = rounding_gamma(M + 3, dt) * (Hb.abs() @ mu.abs() + Phi_t.abs())
    g_w = float(torch.linalg.vector_norm(gradient / root)) + float(
        torch.linalg.vector_norm(gradient_error / root)
    )
    mu_error_w = math.sqrt(psd) * g_w * (1.0 + rounding_gamma(M + 2, dt))
    return Posterior(
        fac, beta, abar, root, Hb, Hb_F, lam, psd, mu, mu_error_w, gradient, gradient_error
    )

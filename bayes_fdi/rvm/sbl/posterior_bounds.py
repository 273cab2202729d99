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

from bayes_fdi.rvm.sbl.factor_kernels import posterior_bounds_terms, posterior_terms
from bayes_fdi.rvm.sbl.precision_factor import PrecisionFactor
from bayes_fdi.rvm.sbl.rounding import rounding_gamma

__all__ = ["COMPILED_POSTERIOR", "Posterior", "posterior_context"]

#: Compute the posterior's terms compiled
#: (:func:`~bayes_fdi.rvm.sbl.factor_kernels.posterior_terms`) on CPU float64; tests clear it to
#: compare with the torch operations.
COMPILED_POSTERIOR = True


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
    compiled = _compiled_context(fac, alpha, beta, G, mu, Phi_t, eps)
    if compiled is not None:
        return compiled
    M = alpha.numel()
    dt = alpha.dtype
    abar = alpha / beta
    terms = _compiled_terms(G, abar, mu, Phi_t)
    if terms is not None:
        Hb, Hb_F, gradient, abs_product = terms
    else:
        Hb = 0.5 * (G + G.T)
        Hb.diagonal().add_(abar)
        Hb_F = float(torch.linalg.matrix_norm(Hb))
        gradient = Hb @ mu - Phi_t
        abs_product = Hb.abs() @ mu.abs() + Phi_t.abs()
    Hb_F *= 1.0 + rounding_gamma(M * M + 1, dt)
    a_min = float(abar.min())
    low = a_min - M * eps
    gamma2 = rounding_gamma(2, dt)
    if low > 0:
        lam, psd = (1.0 / low) * (1.0 + gamma2), (a_min / low) * (1.0 + gamma2)
    else:
        lam = psd = math.inf
    root = abar.sqrt()
    gradient_error = rounding_gamma(M + 3, dt) * abs_product
    g_w = float(torch.linalg.vector_norm(gradient / root)) + float(
        torch.linalg.vector_norm(gradient_error / root)
    )
    mu_error_w = math.sqrt(psd) * g_w * (1.0 + rounding_gamma(M + 2, dt))
    return Posterior(
        fac, beta, abar, root, Hb, Hb_F, lam, psd, mu, mu_error_w, gradient, gradient_error
    )


def _compiled_terms(
    G: Tensor, abar: Tensor, mu: Tensor, Phi_t: Tensor
) -> tuple[Tensor, float, Tensor, Tensor] | None:
    """``Hb``, ``||Hb||_F``, the gradient and ``|Hb| |mu| + |Phi_t|`` in one compiled pass
    (CPU float64, :data:`COMPILED_POSTERIOR`); None where the torch operations apply (another
    device or dtype, or a squared norm out of float64's range)."""
    tensors = (G, abar, mu, Phi_t)
    if not COMPILED_POSTERIOR or any(
        v.device.type != "cpu" or v.dtype != torch.float64 for v in tensors
    ):
        return None
    M = abar.numel()
    Hb = G.new_empty(M, M)
    gradient, abs_product = G.new_empty(M), G.new_empty(M)
    arrays = [v.numpy() for v in (G, abar, mu, Phi_t)]
    fro_sq = posterior_terms(*arrays, Hb.numpy(), gradient.numpy(), abs_product.numpy())
    if not math.isfinite(fro_sq) or fro_sq > 1e300:
        return None
    return Hb, math.sqrt(fro_sq), gradient, abs_product


def _compiled_context(
    fac: PrecisionFactor,
    alpha: Tensor,
    beta: float,
    G: Tensor,
    mu: Tensor,
    Phi_t: Tensor,
    eps: float,
) -> Posterior | None:
    """:func:`posterior_context` in one compiled call
    (:func:`~bayes_fdi.rvm.sbl.factor_kernels.posterior_bounds_terms`, CPU float64,
    :data:`COMPILED_POSTERIOR`); None where the torch operations apply."""
    tensors = (G, alpha, mu, Phi_t)
    if not COMPILED_POSTERIOR or any(
        v.device.type != "cpu" or v.dtype != torch.float64 for v in tensors
    ):
        return None
    arrays = [v.numpy() for v in tensors]
    ok, *parts, bounds = posterior_bounds_terms(
        arrays[0], arrays[1], float(beta), arrays[2], arrays[3], float(eps)
    )
    if not ok:
        return None
    abar, root, Hb, gradient, gradient_error = (torch.from_numpy(v) for v in parts)
    Hb_F, lam, psd, mu_error_w = (float(b) for b in bounds)
    return Posterior(
        fac, beta, abar, root, Hb, Hb_F, lam, psd, mu, mu_error_w, gradient, gradient_error
    )

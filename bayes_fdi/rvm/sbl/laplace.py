"""The Laplace approximation of the Bernoulli-likelihood weight posterior: its mode by Newton's
method to rounding level, covariance and log evidence (:func:`posterior_mode`).

Tipping 2001, "Sparse Bayesian learning and the relevance vector machine" (JMLR), eqs. 26-28;
the stopping rule (the affine-invariant Newton decrement) makes the mode independent of the
BLAS code path. Used by the fast (:mod:`bayes_fdi.rvm.sbl.bernoulli`) and the re-estimation
(:mod:`bayes_fdi.rvm.sbl.reestimation`) Bernoulli solvers.

Imports :mod:`~bayes_fdi.rvm.sbl.precision_factor` only. Written by hand: no maintained library
finds this mode for a sparse Bayesian prior.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
from torch import Tensor

from bayes_fdi.rvm.sbl.precision_factor import PrecisionFactor, factor_precision

__all__ = ["LaplaceMode", "posterior_mode"]

_POSTERIOR_MODE_ITS = 50
# Newton decrement g^T H^-1 g below which the posterior-mode iteration takes full steps
# (quadratic regime), and below which (relative to 1 + |log posterior|) it stops
_MODE_QUADRATIC = 1e-8
_MODE_FLOOR = 1e-24
_LINE_SEARCH_MIN_STEP = 2.0**-8


class LaplaceMode(NamedTuple):
    """The Laplace approximation at the posterior mode (:func:`posterior_mode`).

    Attributes
    ----------
    mu : Tensor
        ``(M,)`` the mode of the weights.
    Sigma : Tensor
        ``(M, M)`` the covariance ``H^-1`` there.
    y : Tensor
        ``(N,)`` the predicted probabilities ``sigmoid(Phi mu)``.
    w : Tensor
        ``(N,)`` the noise precisions ``y (1 - y)``.
    log_ml : float
        The Laplace log evidence.
    fac : PrecisionFactor
        Fresh Cholesky factor of ``H = A + Phi^T W Phi`` at the mode.
    G : Tensor
        ``(M, M)`` ``Phi^T W Phi``.
    """

    mu: Tensor
    Sigma: Tensor
    y: Tensor
    w: Tensor
    log_ml: float
    fac: PrecisionFactor  # fresh Cholesky factor of H = A + Phi^T W Phi at the mode
    G: Tensor  # Phi^T W Phi


def _log_lik(a: Tensor, t: Tensor) -> Tensor:
    return (
        t * torch.nn.functional.logsigmoid(a) + (1 - t) * torch.nn.functional.logsigmoid(-a)
    ).sum()


def posterior_mode(Phi: Tensor, t: Tensor, alpha: Tensor, mu: Tensor) -> LaplaceMode:
    """Laplace approximation of the Bernoulli-likelihood weight posterior.

    Newton / IRLS on ``log p(t|w) - w^T A w / 2`` (Tipping 2001, eq. 26), then
    ``Sigma = (Phi^T B Phi + A)^-1`` (eq. 28) and the Laplace log evidence.

    The mode is found to rounding level, whatever the scale of the problem, so that it does
    not depend on the BLAS code path (:mod:`~bayes_fdi.rvm.sbl.decisions`): convergence is
    measured by the affine-invariant Newton decrement ``lambda^2 = g^T H^-1 g`` (twice the
    predicted gain of the step). Steps are halved (down to ``2^-8``) while ``lambda^2 > 1e-8``;
    below that the iteration is in its quadratic regime and takes full steps (objective
    comparisons there would be decided by rounding) until ``lambda^2`` stops falling by 4x per
    step -- its rounding floor -- or falls below ``1e-24 (1 + |objective|)``. At most 50 steps.
    """
    G = fac = g = y = w = None
    prev = math.inf
    obj = _objective(Phi, t, alpha, mu)
    scale = 1.0 + abs(obj)  # of the log posterior, for the stopping threshold
    for it in range(_POSTERIOR_MODE_ITS + 1):
        a = Phi @ mu
        y = torch.sigmoid(a)
        w = y * (1 - y)
        G = (Phi.T * w) @ Phi
        fac = factor_precision(alpha, G, what="Hessian of the log posterior")
        g = Phi.T @ (t - y) - alpha * mu
        step = fac.solve(g)
        dec = float(g @ step)
        if it == _POSTERIOR_MODE_ITS or dec <= _MODE_FLOOR * scale:
            break
        if dec <= _MODE_QUADRATIC:
            if dec > 0.25 * prev:  # no quadratic decrease any more: at the rounding floor
                break
            mu = mu + step  # (the objective, needed by damped steps only, is not tracked)
            obj = math.nan
        else:
            if math.isnan(obj):
                obj = _objective(Phi, t, alpha, mu)
            lr = 1.0
            while True:
                cand = mu + lr * step
                new_obj = _objective(Phi, t, alpha, cand)
                if new_obj >= obj or lr <= _LINE_SEARCH_MIN_STEP:
                    break
                lr *= 0.5
            if new_obj < obj:  # no ascent possible at the minimum step: at the mode numerically
                break
            mu, obj = cand, new_obj
            scale = 1.0 + abs(obj)
        prev = dec
    assert G is not None and fac is not None and y is not None and w is not None
    Sigma = fac.covariance()
    log_ml = (
        float(_log_lik(Phi @ mu, t))
        - 0.5 * float((alpha * mu * mu).sum())
        - fac.half_logdet_scaled()
    )
    return LaplaceMode(mu, Sigma, y, w, log_ml, fac, G)


def _objective(Phi: Tensor, t: Tensor, alpha: Tensor, m: Tensor) -> float:
    """Log posterior ``log p(t|m) - m^T A m / 2`` (up to a constant)."""
    return float(_log_lik(Phi @ m, t)) - 0.5 * float((alpha * m * m).sum())

"""The posterior precision's Cholesky factor and what the solvers compute from it.

:func:`factor_precision` factorises ``H = diag(alpha) + G`` in a scaled form that exists even
when ``H`` is badly scaled (:class:`PrecisionFactor`: solves, the covariance, the log
determinant); :func:`cholesky_jitter` is the factorisation with a jitter fallback, which warns
with :class:`NumericalWarning`; :func:`gaussian_log_evidence` is the exact log marginal
likelihood of the Gaussian model from the posterior statistics (Tipping 2001).

Imports torch only: every other module of the solver family may import this one.
Written by hand: the scaled form and the evidence terms are specific to the sparse Bayesian
model; the factorisation itself is torch's.
"""

from __future__ import annotations

import math
import warnings
from typing import NamedTuple

import torch
from torch import Tensor

__all__ = [
    "NumericalWarning",
    "PrecisionFactor",
    "cholesky_jitter",
    "factor_precision",
    "gaussian_log_evidence",
]

_LOG_2PI = math.log(2.0 * math.pi)


class NumericalWarning(UserWarning):
    """A numerical safeguard (e.g. Cholesky jitter) was needed."""


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


class PrecisionFactor(NamedTuple):
    """Cholesky factor of a posterior precision ``H = diag(alpha) + G`` in scaled form.

    ``H = D^-1 (I + D G D) D^-1`` with ``D = diag(alpha^-1/2)``; the scaled matrix has all
    eigenvalues >= 1, so its Cholesky factor ``L`` exists even when ``H`` is badly scaled.

    Attributes
    ----------
    L : Tensor
        ``(M, M)`` lower Cholesky factor of ``I + D G D``.
    d : Tensor
        ``(M,)`` the diagonal of ``D``, ``alpha^-1/2``.
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


def factor_precision(
    alpha: Tensor, G: Tensor, *, what: str = "posterior precision"
) -> PrecisionFactor:
    """The :class:`PrecisionFactor` of ``H = diag(alpha) + G`` (``G`` symmetrised first).

    Parameters
    ----------
    alpha : Tensor
        ``(M,)`` prior precisions (> 0).
    G : Tensor
        ``(M, M)`` the data term, ``beta Phi^T Phi`` or ``Phi^T W Phi``.
    what : str
        How a failure or a jitter warning names the matrix (:func:`cholesky_jitter`).
    """
    d = alpha.rsqrt()
    Hs = d[:, None] * (0.5 * (G + G.T)) * d[None, :]
    Hs.diagonal().add_(1.0)
    return PrecisionFactor(cholesky_jitter(Hs, what=what), d)


def gaussian_log_evidence(
    N: int, beta: float, ee: float, alpha: Tensor, mu: Tensor, fac: PrecisionFactor
) -> float:
    """Exact ``log N(t | 0, beta^-1 I + Phi A^-1 Phi^T)`` from the posterior statistics.

    Parameters
    ----------
    N : int
        Number of samples.
    beta : float
        Noise precision.
    ee : float
        ``||t - Phi mu||^2``.
    alpha, mu : Tensor
        ``(M,)`` prior precisions and posterior mean.
    fac : PrecisionFactor
        Factor of ``H = A + beta Phi^T Phi``.
    """
    return (
        0.5 * (N * math.log(beta) - beta * ee - N * _LOG_2PI - float((alpha * mu * mu).sum()))
        - fac.half_logdet_scaled()
    )

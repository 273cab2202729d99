"""The noise precision ``beta`` of the Gaussian solvers: its start, its upper bound and its
re-estimate (SparseBayes' rules; Tipping 2001 for the re-estimate).

Imports torch only. Written by hand: three lines of arithmetic shared by the fast and the
re-estimation solvers.
"""

from __future__ import annotations

import math

from torch import Tensor

__all__ = ["BETA_MAX_FACTOR", "initial_noise_precision", "reestimated_noise_precision"]

#: SparseBayes v2: the noise variance stays above ``var(t) / BETA_MAX_FACTOR``
BETA_MAX_FACTOR = 1e6


def initial_noise_precision(t: Tensor, N: int) -> tuple[float, float]:
    """SparseBayes' starting noise precision ``1 / (0.1 std(t))^2`` and its upper bound
    ``BETA_MAX_FACTOR / var(t)``, with ``var(t)`` floored at ``1e-12 ||t||^2 / N`` (at ``1e-12``,
    that of a unit target, when every target is 0).

    Parameters
    ----------
    t : Tensor
        ``(N,)`` targets.
    N : int
        Number of samples.

    Returns
    -------
    beta, beta_max : float
    """
    t_var = float(t.var(unbiased=False))
    t_sq = float(t @ t)
    # targets of all zeros carry no scale: they are given that of a unit target (the scale the
    # estimators rescale every other target to), which keeps every precision far from overflow
    var_floor = max(t_var, 1e-12 * t_sq / N, 1e-300) if t_sq > 0 else 1e-12
    beta_max = BETA_MAX_FACTOR / var_floor
    beta = min(1.0 / (0.1 * math.sqrt(var_floor)) ** 2, beta_max)
    return beta, beta_max


def reestimated_noise_precision(N: int, gamma_sum: float, ee: float, beta_max: float) -> float:
    """Tipping's (2001) re-estimate ``beta = (N - sum gamma) / ||t - Phi mu||^2``, within
    ``[1e-300, beta_max]``.

    Parameters
    ----------
    N : int
        Number of samples.
    gamma_sum : float
        ``sum gamma_i``, the number of well-determined weights.
    ee : float
        ``||t - Phi mu||^2``.
    beta_max : float
        Upper bound (:func:`initial_noise_precision`).
    """
    beta = min((N - gamma_sum) / max(ee, 1e-300), beta_max)
    return max(beta, 1e-300)

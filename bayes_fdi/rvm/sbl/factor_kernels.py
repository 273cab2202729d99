r"""Compiled (numba) kernels of the fast Gaussian solver's per-iteration posterior work on CPU
float64 arrays: the posterior's bound terms in one pass (:func:`posterior_terms`) and the
re-estimation update of the scaled Cholesky factor (:func:`reestimate_factor`).

:func:`posterior_terms` computes, for
:func:`~bayes_fdi.rvm.sbl.posterior_bounds.posterior_context`, the stored precision
``Hb = (G + G^T) / 2 + diag(abar)``, its squared Frobenius norm, the gradient ``Hb mu - Phi^T t``
and the sums ``|Hb| |mu|`` behind its rounding bound, in one pass over ``G`` instead of some
fifteen ``M x M`` torch operations. Every value there is either a bound or feeds one (the
carried screening factors), so its rounding changes the cost of a decision, never the decision.

:func:`reestimate_factor` moves the factor ``L`` of the scaled precision
``I + D G D`` (:class:`~bayes_fdi.rvm.sbl.precision_factor.PrecisionFactor`) to a new prior
precision of one column ``k``: with ``r = d_k' / d_k``,
``I + D' G D' = S (I + D G D) S + (1 - r^2) e_k e_k^T`` (``S`` the identity with ``r`` at
``k``), so row ``k`` of ``L`` is scaled by ``r`` and a rank-one update (``r < 1``) or downdate
(``r > 1``) with ``e_k`` follows; it touches only the trailing block ``L[k:, k:]`` (LINPACK's
``dchud`` / ``dchdd`` rotations, Golub & Van Loan, *Matrix Computations*, sec. 6.5.4). The
kernel also returns the amplification of the update's rounding, ``max_j L_jj / L'_jj`` of a
downdate (1 for an update): the caller refactorises afresh when the accumulated bound says so.

Explicit loops, no BLAS, no fast-math: the results do not depend on a BLAS library or a thread
count. Imports numba and numpy only. Written by hand: no maintained library carries these
bounds or updates this scaled factor.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["posterior_terms", "reestimate_factor"]


@njit(cache=True, error_model="numpy")
def posterior_terms(G, abar, mu, Phi_t, Hb, gradient, abs_product):  # pragma: no cover
    """Fill ``Hb`` (``(M, M)``), ``gradient`` and ``abs_product`` (``(M,)``) and return
    ``||Hb||_F^2``.

    ``Hb = (G + G^T) / 2 + diag(abar)``, ``gradient = Hb mu - Phi_t`` and
    ``abs_product = |Hb| |mu| + |Phi_t|``.
    """
    M = abar.shape[0]
    fro = 0.0
    for i in range(M):
        g = 0.0
        a = 0.0
        for j in range(M):
            h = 0.5 * (G[i, j] + G[j, i])
            if i == j:
                h += abar[i]
            Hb[i, j] = h
            fro += h * h
            g += h * mu[j]
            a += abs(h) * abs(mu[j])
        gradient[i] = g - Phi_t[i]
        abs_product[i] = a + abs(Phi_t[i])
    return fro


@njit(cache=True, error_model="numpy")
def reestimate_factor(L, k, r):  # pragma: no cover - compiled
    """Update ``L`` (lower, ``(M, M)``, in place) from ``I + D G D`` to ``I + D' G D'`` where
    only ``d_k`` changed, by ``d_k' = r d_k`` (module docstring).

    Returns the amplification ``max_j L_jj / L'_jj`` of the rounding (1 for an update), or
    ``inf`` when the downdate breaks down (the caller then refactorises afresh).
    """
    M = L.shape[0]
    for j in range(k + 1):
        L[k, j] *= r
    sigma = 1.0 - r * r  # + for an update, - for a downdate
    if sigma == 0.0:
        return 1.0
    sign = 1.0 if sigma > 0.0 else -1.0
    x = np.zeros(M)
    x[k] = math.sqrt(abs(sigma))
    amp = 1.0
    for j in range(k, M):
        ljj = L[j, j]
        xj = x[j]
        rr = ljj * ljj + sign * xj * xj
        if not rr > 0.0:
            return math.inf
        rj = math.sqrt(rr)
        c = rj / ljj
        s = xj / ljj
        L[j, j] = rj
        if sign < 0.0 and ljj / rj > amp:
            amp = ljj / rj
        for i in range(j + 1, M):
            lij = (L[i, j] + sign * s * x[i]) / c
            L[i, j] = lij
            x[i] = c * x[i] - s * lij
    return amp

"""Small dense linear algebra in a fixed order of operations, for the twin's latent space.

The twin's mode search and Laplace approximation work with matrices of 10-20 rows. LAPACK and
BLAS (behind numpy's ``linalg`` and ``@``) order their sums by the code path of the machine
(``OPENBLAS_CORETYPE``, ``MKL_CBWR``, the thread count), so their last bits change from one
machine to the next; the mode search takes accept/reject decisions on a log density made rough
by the simulator's dead zone, and would follow those bits. These routines use only elementwise
numpy operations and numpy's own (pairwise) sums, whose order is fixed, so the same seed gives
the same posterior on every machine. Written by hand for that reason only; at this size their
cost is negligible.
"""

from __future__ import annotations

import numpy as np

__all__ = ["NotPositiveDefinite", "cholesky", "inverse_spd", "matvec", "solve_spd"]


class NotPositiveDefinite(ValueError):
    """The matrix given to :func:`cholesky` is not (numerically) positive definite."""


def matvec(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``a @ x`` for ``a`` ``(..., m, n)`` and ``x`` ``(..., n)``, summed in a fixed order."""
    return np.sum(a * x[..., None, :], axis=-1)


def cholesky(a: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor ``L`` of a symmetric positive definite ``a`` (``a = L L^T``)."""
    a = np.asarray(a, dtype=np.float64)
    n = a.shape[0]
    low = np.zeros_like(a)
    for j in range(n):
        pivot = a[j, j] - np.sum(low[j, :j] ** 2)
        if not pivot > 0.0:
            raise NotPositiveDefinite(f"pivot {j} is {pivot:.3g}")
        low[j, j] = np.sqrt(pivot)
        if j + 1 < n:
            low[j + 1 :, j] = (a[j + 1 :, j] - np.sum(low[j + 1 :, :j] * low[j, :j], axis=1)) / low[
                j, j
            ]
    return low


def _forward(low: np.ndarray, b: np.ndarray) -> np.ndarray:
    y = np.zeros_like(b)
    for i in range(low.shape[0]):
        y[i] = (b[i] - np.sum(low[i, :i] * y[:i])) / low[i, i]
    return y


def _backward(low: np.ndarray, y: np.ndarray) -> np.ndarray:
    n = low.shape[0]
    x = np.zeros_like(y)
    for i in range(n - 1, -1, -1):
        x[i] = (y[i] - np.sum(low[i + 1 :, i] * x[i + 1 :])) / low[i, i]
    return x


def solve_spd(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a^-1 b`` for symmetric positive definite ``a`` and a vector ``b``."""
    low = cholesky(a)
    return _backward(low, _forward(low, np.asarray(b, dtype=np.float64)))


def inverse_spd(a: np.ndarray) -> np.ndarray:
    """``a^-1`` of a symmetric positive definite ``a`` (symmetrised)."""
    low = cholesky(a)
    n = low.shape[0]
    out = np.empty_like(low)
    for k in range(n):
        e = np.zeros(n)
        e[k] = 1.0
        out[:, k] = _backward(low, _forward(low, e))
    return 0.5 * (out + out.T)

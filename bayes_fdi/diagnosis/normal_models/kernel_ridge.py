"""Gaussian-kernel ridge regression: the normal models of the paper's SVM baseline.

`KernelRidgeRegressor` fits ``y(x) = b + sum_i a_i k(x, x_i)`` with a regularisation chosen by
exact leave-one-out error and a *homoscedastic* predictive standard deviation: the leave-one-out
root-mean-square error. Unlike the RVR's eq. (14) std, it does not grow away from the training
data; it is an honest average out-of-sample error, not a posterior.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.linalg import eigh
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.metrics.pairwise import euclidean_distances
from sklearn.utils.validation import check_is_fitted, validate_data

__all__ = ["KernelRidgeRegressor"]


class KernelRidgeRegressor(RegressorMixin, BaseEstimator):
    """Gaussian-kernel ridge regression with leave-one-out ridge choice and error bars.

    The model is ``y(x) = b + sum_i a_i k(x, x_i)`` with ``b`` the training mean and
    ``a = (K + lam I)^{-1} (y - b)``. ``lam`` is chosen from ``alphas`` by the exact
    leave-one-out mean squared error, computed for all candidates from one eigendecomposition
    of ``K`` (``e_i = r_i / (1 - H_ii)``, ``H = K (K + lam I)^{-1}``).

    Parameters
    ----------
    width
        Kernel width sigma in ``exp(-||x - z||^2 / (2 sigma^2))``.
    alphas
        Candidate ridge penalties.

    Attributes
    ----------
    alpha_ : float
        Chosen ridge penalty.
    loo_rmse_ : float
        Leave-one-out RMSE at ``alpha_``; the predictive std returned by ``predict``.
    dual_coef_ : numpy.ndarray
    X_fit_ : numpy.ndarray
    intercept_ : float
    n_features_in_ : int
    """

    def __init__(
        self, width: float = 0.1, alphas: tuple[float, ...] = (1e-6, 1e-4, 1e-3, 1e-2, 1e-1, 1.0)
    ) -> None:
        self.width = width
        self.alphas = alphas

    def _kernel(self, A: np.ndarray, B: np.ndarray) -> np.ndarray:
        d2 = euclidean_distances(A, B, squared=True)
        return np.exp(-d2 / (2.0 * float(self.width) ** 2))

    def fit(self, X: Any, y: Any) -> KernelRidgeRegressor:
        """Fit on ``(n, d)`` inputs and ``(n,)`` targets; returns ``self``."""
        X, y = validate_data(self, X, y, y_numeric=True, dtype=np.float64)
        if not float(self.width) > 0:
            raise ValueError(f"width must be positive, got {self.width}")
        alphas = np.asarray(self.alphas, dtype=np.float64).ravel()
        if alphas.size == 0 or not (alphas > 0).all():
            raise ValueError("alphas must be a non-empty sequence of positive numbers")
        if X.shape[0] < 2:
            raise ValueError(
                f"KernelRidgeRegressor needs at least 2 samples, got n_samples={X.shape[0]}"
            )
        self.intercept_ = float(y.mean())
        t = y - self.intercept_
        lam, U = eigh(self._kernel(X, X))
        lam = np.clip(lam, 0.0, None)
        Ut = U.T @ t
        U2 = U**2
        best = (np.inf, alphas[0])
        for a in alphas:
            inv = 1.0 / (lam + a)
            resid = a * (U @ (inv * Ut))  # (I - H) t = a (K + a I)^{-1} t
            one_minus_h = a * (U2 @ inv)  # diag(I - H)
            loo = float(np.mean((resid / one_minus_h) ** 2))
            if loo < best[0]:
                best = (loo, a)
        self.alpha_ = float(best[1])
        self.loo_rmse_ = float(np.sqrt(best[0]))
        self.dual_coef_ = U @ (Ut / (lam + self.alpha_))
        self.X_fit_ = X
        return self

    def predict(self, X: Any, return_std: bool = False) -> Any:
        """Predicted mean, or ``(mean, std)`` with the constant leave-one-out RMSE as std."""
        check_is_fitted(self, "dual_coef_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        mean = self.intercept_ + self._kernel(X, self.X_fit_) @ self.dual_coef_
        if return_std:
            return mean, np.full(mean.shape, self.loo_rmse_)
        return mean

"""Non-Bayesian baselines that plug into the same pipeline as the RVMs.

- `svm_classifier`: the paper's SVM node classifier (Gaussian kernel, sigma = 2), for
  `bayes_fdi.diagnosis.tree.HierarchicalClassifier`. Its probabilities are Platt-scaled
  on 5-fold out-of-fold decision values (deterministic folds).
- `KernelRidgeRegressor`: Gaussian-kernel ridge regression for the normal models, with a
  regularisation chosen by exact leave-one-out error and a *homoscedastic* predictive standard
  deviation: the leave-one-out root-mean-square error. Unlike the RVR's eq. (14) std, it does
  not grow away from the training data; it is an honest average out-of-sample error, not a
  posterior.
- `svm_fault_diagnoser`: the whole SVM baseline (kernel ridge normal models, SVM tree).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.linalg import eigh
from sklearn.base import BaseEstimator, ClassifierMixin, RegressorMixin
from sklearn.calibration import CalibratedClassifierCV
from sklearn.metrics.pairwise import euclidean_distances
from sklearn.svm import SVC
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_is_fitted, validate_data

__all__ = [
    "SMO_TOL",
    "KernelRidgeRegressor",
    "SVMClassifier",
    "svm_classifier",
    "svm_fault_diagnoser",
]

#: Stopping tolerance of libsvm's SMO solver in `SVMClassifier` (KKT violation). scikit-learn's
#: default 1e-3 leaves decision values ~1e-3 from the optimum, and a 1e-10 change of the inputs
#: then changed the support vectors in 1 of 60 random problems; at 1e-9 none changed and the
#: decision values moved by < 1e-6, at the same fitting cost.
SMO_TOL: float = 1e-9


class SVMClassifier(ClassifierMixin, BaseEstimator):
    """Gaussian-kernel SVM with Platt-scaled probabilities (the paper's baseline node).

    Fits ``SVC(kernel="rbf", gamma=1/(2 sigma^2), C=C)`` on all the data and a sigmoid (Platt)
    map from its decision values to probabilities, learnt on ``cv``-fold out-of-fold decision
    values (``CalibratedClassifierCV(..., method="sigmoid", ensemble=False)``; scikit-learn's
    ``SVC(probability=True)`` is deprecated and does the same internally).

    Parameters
    ----------
    sigma
        Gaussian kernel width, ``k(x, z) = exp(-||x - z||^2 / (2 sigma^2))`` (paper: 2).
    C
        Soft-margin penalty (the paper does not report it; scikit-learn's default 1).
    cv
        Folds for the Platt scaling (reduced to the smallest class count when needed).

    Attributes
    ----------
    classes_ : numpy.ndarray
    support_vectors_ : numpy.ndarray
        Support vectors of the SVM fitted on all the data.
    svc_ : sklearn.svm.SVC
        That SVM.
    calibrated_ : sklearn.calibration.CalibratedClassifierCV
    n_features_in_ : int
    """

    def __init__(self, sigma: float = 2.0, C: float = 1.0, cv: int = 5) -> None:
        self.sigma = sigma
        self.C = C
        self.cv = cv

    def fit(self, X: Any, y: Any) -> SVMClassifier:
        """Fit the SVM and its Platt scaling; returns ``self``."""
        X, y = validate_data(self, X, y, dtype=np.float64)
        check_classification_targets(y)
        if not float(self.sigma) > 0:
            raise ValueError(f"sigma must be positive, got {self.sigma}")
        classes, counts = np.unique(y, return_counts=True)
        if classes.size < 2:
            raise ValueError(
                f"SVMClassifier needs at least 2 classes; got 1 class {classes.tolist()}"
            )
        folds = min(int(self.cv), int(counts.min()))
        if folds < 2:
            raise ValueError(
                "SVMClassifier needs at least 2 samples of every class for its Platt scaling"
            )
        # tol: libsvm's default 1e-3 stops the SMO solver that far from the optimum, and where
        # it stops depends on the last bits of the data (two BLAS code paths gave support
        # vector sets differing by one); at 1e-9 the solution is the exact SVM, at no cost
        gamma = 1.0 / (2.0 * float(self.sigma) ** 2)
        svc = SVC(kernel="rbf", gamma=gamma, C=self.C, tol=SMO_TOL)
        self.calibrated_ = CalibratedClassifierCV(
            svc, method="sigmoid", cv=folds, ensemble=False
        ).fit(X, y)
        self.svc_ = self.calibrated_.calibrated_classifiers_[0].estimator
        self.support_vectors_ = self.svc_.support_vectors_
        self.classes_ = self.calibrated_.classes_
        return self

    def decision_function(self, X: Any) -> np.ndarray:
        """SVM decision values."""
        check_is_fitted(self, "svc_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return self.svc_.decision_function(X)

    def predict_proba(self, X: Any) -> np.ndarray:
        """Platt-scaled class probabilities ``(n, n_classes)`` in ``classes_`` order."""
        check_is_fitted(self, "svc_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return self.calibrated_.predict_proba(X)

    def predict(self, X: Any) -> np.ndarray:
        """Most probable class."""
        proba = self.predict_proba(X)
        return self.classes_[np.argmax(proba, axis=1)]


def svm_classifier(sigma: float = 2.0, C: float = 1.0, cv: int = 5) -> SVMClassifier:
    """The paper's SVM node classifier: Gaussian kernel with ``sigma`` (2 in the paper).

    Returns an unfitted `SVMClassifier` (Platt-scaled probabilities, deterministic).
    """
    if not sigma > 0:
        raise ValueError(f"sigma must be positive, got {sigma}")
    return SVMClassifier(sigma=sigma, C=C, cv=cv)


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


def svm_fault_diagnoser(
    *,
    sigma: float = 2.0,
    C: float = 1.0,
    regression_width: float = 0.1,
    max_train_samples: int | None = 2000,
    random_state: int | None = 0,
    **kwargs: Any,
) -> Any:
    """The paper's SVM baseline as a `bayes_fdi.diagnosis.FaultDiagnoser`.

    Kernel ridge normal models (`KernelRidgeRegressor`, fitted on at most
    ``max_train_samples`` fault-free samples: its cost is cubic) and a
    `bayes_fdi.diagnosis.tree.HierarchicalClassifier` of `svm_classifier` nodes, on the
    same features as the RVM pipeline. Extra keyword arguments go to ``FaultDiagnoser``.
    """
    from bayes_fdi.diagnosis import FaultDiagnoser
    from bayes_fdi.diagnosis.tree import HierarchicalClassifier

    return FaultDiagnoser(
        regressor=KernelRidgeRegressor(width=regression_width),
        classifier=HierarchicalClassifier(
            svm_classifier(sigma=sigma, C=C),
            random_state=random_state,
        ),
        max_train_samples=max_train_samples,
        random_state=random_state,
        **kwargs,
    )

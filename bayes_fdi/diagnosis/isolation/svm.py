"""The paper's SVM node classifier, the non-Bayesian baseline of the isolation tree.

`svm_classifier` makes the paper's SVM node classifier (Gaussian kernel, sigma = 2) for
`bayes_fdi.diagnosis.isolation.tree.HierarchicalClassifier`: an `SVMClassifier`, whose
probabilities are Platt-scaled on 5-fold out-of-fold decision values (deterministic folds).
The whole SVM baseline of the offline pipeline is `bayes_fdi.diagnosis.svm_fault_diagnoser`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.calibration import CalibratedClassifierCV
from sklearn.svm import SVC
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_is_fitted, validate_data

__all__ = [
    "SMO_TOL",
    "SVMClassifier",
    "svm_classifier",
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

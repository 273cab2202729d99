"""Tests of the SVM and kernel-ridge baselines."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.svm import SVC
from sklearn.utils.estimator_checks import estimator_checks_generator

from bayes_fdi.diagnosis import KernelRidgeRegressor
from bayes_fdi.diagnosis.isolation.svm import SMO_TOL, SVMClassifier, svm_classifier


def test_kernel_ridge_loo_matches_brute_force(rng):
    X = rng.uniform(-1, 1, (40, 2))
    y = np.sin(3 * X[:, 0]) + 0.5 * X[:, 1] + 0.05 * rng.standard_normal(40)
    model = KernelRidgeRegressor(width=0.5, alphas=(1e-3, 1e-2, 1e-1)).fit(X, y)
    # Second implementation: refit without each sample, with the intercept fixed to the full
    # training mean (as in the closed form), for every candidate penalty.
    loo = {}
    for a in (1e-3, 1e-2, 1e-1):
        errs = []
        for i in range(40):
            keep = np.arange(40) != i
            Xk, tk = X[keep], y[keep] - y.mean()
            K = np.exp(-((Xk[:, None] - Xk[None]) ** 2).sum(-1) / (2 * 0.5**2))
            coef = np.linalg.solve(K + a * np.eye(39), tk)
            k = np.exp(-((X[i] - Xk) ** 2).sum(-1) / (2 * 0.5**2))
            errs.append(y[i] - (y.mean() + k @ coef))
        loo[a] = float(np.mean(np.square(errs)))
    best = min(loo, key=loo.get)
    assert model.alpha_ == best
    assert model.loo_rmse_ == pytest.approx(np.sqrt(loo[best]), rel=1e-8)
    mean, std = model.predict(X[:5], return_std=True)
    np.testing.assert_allclose(std, model.loo_rmse_)
    np.testing.assert_allclose(mean, model.predict(X[:5]))
    assert np.sqrt(np.mean((model.predict(X) - y) ** 2)) < model.loo_rmse_


def test_svm_node_is_gaussian_kernel_with_sigma(rng):
    X = np.concatenate([rng.normal(-1, 1, (30, 2)), rng.normal(1, 1, (30, 2))])
    y = np.repeat([0, 1], 30)
    clf = svm_classifier(sigma=2.0).fit(X, y)
    ref = SVC(kernel="rbf", gamma=1 / 8, tol=SMO_TOL).fit(X, y)  # exp(-d^2 / (2 * 2^2))
    # the same solver on the same data: identical up to rounding (1e-6 is far above it)
    np.testing.assert_allclose(clf.decision_function(X), ref.decision_function(X), rtol=1e-6)
    np.testing.assert_array_equal(clf.support_vectors_, ref.support_vectors_)
    p = clf.predict_proba(X)
    np.testing.assert_allclose(p.sum(axis=1), 1.0)
    # Platt scaling is monotone in the decision value.
    order = np.argsort(ref.decision_function(X))
    assert np.all(np.diff(p[order, 1]) >= -1e-12)
    with pytest.raises(ValueError, match="at least 2 samples of every class"):
        svm_classifier().fit(X[:31], y[:31])


def _checks():
    for est in (KernelRidgeRegressor(), SVMClassifier(sigma=1.0)):
        for estimator, check in estimator_checks_generator(est, legacy=True):
            name = getattr(check, "func", check).__name__
            if "array_api" not in name:  # needs SCIPY_ARRAY_API; would skip
                yield pytest.param(estimator, check, id=f"{type(est).__name__}-{name}")


@pytest.mark.parametrize("estimator, check", list(_checks()))
def test_sklearn_compatible(estimator, check):
    check(estimator)

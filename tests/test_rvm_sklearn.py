"""scikit-learn's own estimator checks for the RVM estimators."""

from __future__ import annotations

from sklearn.utils.estimator_checks import parametrize_with_checks

from bayes_fdi.rvm import RVC, RVR


@parametrize_with_checks([RVR(), RVC()])
def test_sklearn_compatible(estimator, check):
    check(estimator)

"""The random forest kept as arrays (bayes_fdi.diagnosis.isolation.forest)."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.ensemble import RandomForestClassifier
from sklearn.utils.estimator_checks import parametrize_with_checks

from bayes_fdi import model_files
from bayes_fdi.calibration import TemperatureScaler
from bayes_fdi.diagnosis.isolation import FaultIsolator, ForestClassifier


def _signatures(n: int, seed: int):
    """Ten features whose scales span orders of magnitude, as isolation signatures do; four
    classes shifting one feature each."""
    rng = np.random.default_rng(seed)
    y = np.array([f"f{k}" for k in rng.integers(1, 5, n)])
    X = rng.standard_normal((n, 10)) * np.exp(np.linspace(-4.0, 4.0, 10))
    for k in range(1, 5):
        X[y == f"f{k}", 2 * k] += 3.0 * np.exp(np.linspace(-4.0, 4.0, 10))[2 * k]
    return X, y


def test_probabilities_are_the_fitted_forests():
    X, y = _signatures(600, 0)
    Xt, _ = _signatures(400, 1)
    ours = ForestClassifier(n_estimators=50, random_state=3).fit(X, y)
    theirs = RandomForestClassifier(
        n_estimators=50, min_samples_leaf=3, random_state=3, n_jobs=1
    ).fit(X, y)
    p, q = ours.predict_proba(Xt), theirs.predict_proba(Xt)
    assert list(ours.classes_) == list(theirs.classes_) == ["f1", "f2", "f3", "f4"]
    # each is a mean of 50 leaf proportions in [0, 1], summed in the same tree order: they may
    # differ by the rounding of the leaves' normalisation, at most one ulp per term
    assert np.abs(p - q).max() <= 50 * np.finfo(float).eps
    np.testing.assert_allclose(p.sum(axis=1), 1.0, atol=50 * np.finfo(float).eps)
    assert np.array_equal(ours.predict(Xt), ours.classes_[np.argmax(p, axis=1)])


def test_a_rows_probabilities_do_not_depend_on_the_rows_around_it():
    X, y = _signatures(400, 2)
    Xt, _ = _signatures(60, 3)
    forest = ForestClassifier(n_estimators=30, random_state=0).fit(X, y)
    whole = forest.predict_proba(Xt)
    one_by_one = np.vstack([forest.predict_proba(Xt[i : i + 1]) for i in range(len(Xt))])
    assert np.array_equal(whole, one_by_one)


def test_the_model_file_holds_arrays_and_gives_the_same_probabilities(tmp_path):
    X, y = _signatures(400, 4)
    forest = ForestClassifier(n_estimators=20, random_state=1).fit(X, y)
    path = model_files.save(forest, tmp_path / "forest.npz")
    back = model_files.load(path)
    assert isinstance(back, ForestClassifier)
    assert not any(type(v).__module__.startswith("sklearn") for v in vars(back).values())
    assert np.array_equal(back.predict_proba(X), forest.predict_proba(X))


def test_bad_input_is_refused_naming_the_problem():
    X, y = _signatures(200, 5)
    forest = ForestClassifier(n_estimators=5, random_state=0)
    bad = X.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="contains NaN"):
        forest.fit(bad, y)
    forest.fit(X, y)
    with pytest.raises(ValueError, match="contains NaN"):
        forest.predict_proba(bad)
    with pytest.raises(ValueError, match="X has 4 features, but ForestClassifier is expecting 10"):
        forest.predict_proba(X[:, :4])


def test_the_isolator_runs_it_second_by_second_as_over_the_whole():
    X, y = _signatures(800, 6)
    Xv, yv = _signatures(300, 7)
    iso = FaultIsolator(ForestClassifier(n_estimators=30, random_state=0), random_state=0)
    iso.fit(X, y, validation=(Xv, yv), calibration=(Xv, yv))
    rows = np.vstack([Xv[:40], np.full((1, 10), np.nan)])  # a second with no signature
    whole = iso.run(rows)
    for i in range(rows.shape[0]):
        one = iso.update(rows[i])
        np.testing.assert_array_equal(one.group_proba, whole.group_proba[i])
        np.testing.assert_array_equal(one.fault_proba, whole.fault_proba[i])
    assert np.isnan(whole.group_proba[-1]).all()
    # held-out rows of these well-separated classes are named right
    right = iso.faults_[np.argmax(whole.fault_proba[:40], axis=1)] == yv[:40]
    assert right.mean() >= 0.9


def test_a_group_named_unanimously_is_calibrated_without_error():
    # f1 and f2 look alike, so they form one group; where the forest names that group, the
    # faults' shares averaged over 100 trees sum to 1 + one ulp in some rows, which the
    # calibration used to refuse as a probability above 1
    def alike(n, seed):
        rng = np.random.default_rng(seed)
        y = np.array([f"f{k}" for k in rng.integers(1, 5, n)])
        X = rng.standard_normal((n, 10))
        X[(y == "f1") | (y == "f2"), 0] += 3.0
        X[y == "f3", 2] += 3.0
        X[y == "f4", 4] += 3.0
        return X, y

    X, y = alike(800, 6)
    Xv, yv = alike(4000, 7)
    iso = FaultIsolator(
        ForestClassifier(n_estimators=100, random_state=0),
        calibrator=TemperatureScaler(bounds=(1.0, 50.0)),
        random_state=0,
    )
    iso.fit(X, y, validation=(Xv, yv), calibration=(Xv, yv))
    assert iso.groups_ == (("f1", "f2"), ("f3",), ("f4",))
    raw = iso.fault_proba(Xv) @ iso.membership_
    assert (raw > 1.0).any()  # the case this test is about
    held = iso.summed_groups(iso.fault_proba(Xv))
    assert held.max() == 1.0 and held.min() >= 0.0
    np.testing.assert_allclose(held, raw, rtol=0, atol=4 * np.finfo(float).eps)
    out = iso.run(Xv)
    assert np.all((out.group_proba >= 0) & (out.group_proba <= 1))
    np.testing.assert_allclose(out.group_proba.sum(axis=1), 1.0, rtol=0, atol=1e-12)


@parametrize_with_checks([ForestClassifier(n_estimators=10, random_state=0)])
def test_scikit_learn_compatible(estimator, check):
    check(estimator)

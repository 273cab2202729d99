"""AgeTemperatureScaler (bayes_fdi.calibration.age_temperature): one temperature per age bin of
the evidence, each fitted by TemperatureScaler on its bin's rows; checked against known
miscalibrations, by hand, against TemperatureScaler, and inside the fault isolator."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.base import clone

from bayes_fdi.calibration import AgeTemperatureScaler, TemperatureScaler
from bayes_fdi.calibration.age_temperature import age_bins
from bayes_fdi.calibration.metrics import expected_calibration_error


def _shown(rng, n_runs, per_run, k, power):
    """Seconds of runs whose probabilities are miscalibrated by a known power (``shown = true
    ** power``, renormalised), correlated within a run (one true distribution per run)."""
    logits = rng.normal(0.0, 1.5, (n_runs, k))
    true = np.exp(logits) / np.exp(logits).sum(axis=1, keepdims=True)
    y = np.concatenate([rng.choice(k, per_run, p=p) for p in true])
    true = np.repeat(true, per_run, axis=0)
    return true**power / (true**power).sum(axis=1, keepdims=True), y


def test_age_bins_by_hand():
    got = age_bins([0, 1, 9.9, 10, 29, 30, 1e6], (10, 30))
    np.testing.assert_array_equal(got, [0, 0, 0, 1, 1, 2, 2])
    np.testing.assert_array_equal(age_bins([0, 5, 500], ()), [0, 0, 0])
    for bad in ([-1.0], [np.nan], [[1.0, 2.0]]):
        with pytest.raises(ValueError, match="ages must be a 1-D array"):
            age_bins(bad, (10,))


def test_each_bin_recovers_its_own_known_temperature():
    # young rows over-confident by a power 2 (temperature 2), old rows under-confident by a
    # power 0.5 (temperature 0.5): each bin's temperature recovers its power, and the ECE
    # falls to the noise floor where one pooled temperature leaves it high
    rng = np.random.default_rng(11)
    k = 4
    young, y_young = _shown(rng, 300, 40, k, 2.0)
    old, y_old = _shown(rng, 300, 40, k, 0.5)
    proba, y = np.vstack([young, old]), np.concatenate([y_young, y_old])
    ages = np.concatenate([rng.uniform(1, 10, y_young.size), rng.uniform(300, 900, y_old.size)])
    scaler = AgeTemperatureScaler(edges=(10, 300), classes=np.arange(k)).fit(proba, y, ages)
    assert scaler.temperatures_[0] == pytest.approx(2.0, rel=0.1)
    assert scaler.temperatures_[2] == pytest.approx(0.5, rel=0.1)
    assert scaler.rows_per_bin_.tolist() == [y_young.size, 0, y_old.size]
    # the empty middle bin takes the pooled temperature, which is TemperatureScaler's
    pooled = TemperatureScaler(classes=np.arange(k)).fit(proba, y)
    assert scaler.temperatures_[1] == scaler.pooled_temperature_ == pooled.temperature_
    after = expected_calibration_error(y, scaler.transform(proba, ages), classes=np.arange(k))
    one = expected_calibration_error(y, pooled.transform(proba), classes=np.arange(k))
    assert after.value < 2 * after.noise_floor + 0.01
    assert one.value > after.value + 0.03
    assert scaler.nll_after_ < scaler.nll_before_
    # the diagnosed class never changes
    np.testing.assert_array_equal(scaler.transform(proba, ages).argmax(1), proba.argmax(1))


def test_one_bin_is_temperature_scaling_and_small_bins_pool():
    rng = np.random.default_rng(3)
    proba, y = _shown(rng, 100, 20, 3, 1.7)
    ages = rng.uniform(0, 1000, y.size)
    one = AgeTemperatureScaler(edges=()).fit(proba, y, ages)
    plain = TemperatureScaler().fit(proba, y)
    assert one.temperatures_.tolist() == [plain.temperature_]
    np.testing.assert_array_equal(one.transform(proba, ages), plain.transform(proba))
    # a bin with fewer rows than min_rows takes the pooled temperature
    few = AgeTemperatureScaler(edges=(1.0,), min_rows=50).fit(
        proba, y, np.r_[0.5 * np.ones(10), ages[10:] + 1]
    )
    assert few.rows_per_bin_[0] == 10 and few.temperatures_[0] == few.pooled_temperature_
    assert few.temperatures_[1] != few.pooled_temperature_


def test_bad_settings_and_inputs_are_refused_by_name():
    rng = np.random.default_rng(5)
    proba, y = _shown(rng, 20, 10, 3, 1.0)
    ages = np.arange(y.size, dtype=float)
    with pytest.raises(ValueError, match="edges must be increasing"):
        AgeTemperatureScaler(edges=(30, 10)).fit(proba, y, ages)
    with pytest.raises(ValueError, match="min_rows must be an integer"):
        AgeTemperatureScaler(min_rows=0).fit(proba, y, ages)
    with pytest.raises(ValueError, match="one value per row"):
        AgeTemperatureScaler().fit(proba, y, ages[:-1])
    with pytest.raises(ValueError, match="not fitted"):
        AgeTemperatureScaler().transform(proba, ages)
    fitted = AgeTemperatureScaler().fit(proba, y, ages)
    with pytest.raises(ValueError, match="one value per row"):
        fitted.transform(proba, ages[:3])
    with pytest.raises(ValueError, match="ages must be a 1-D array of finite values"):
        fitted.transform(proba, -ages)
    assert clone(fitted).get_params() == fitted.get_params()
    assert "temperatures_" in repr(fitted)


def test_the_isolator_scales_each_row_by_its_age_and_asks_for_ages():
    # three faults' signatures as Gaussian blobs; a logistic regression (no compiled path) and
    # the compiled tree's path both take the calibration rows' ages and scale each row by its
    # age's temperature
    from sklearn.linear_model import LogisticRegression

    from bayes_fdi.diagnosis.isolation.isolator import FaultIsolator

    rng = np.random.default_rng(21)
    centres = rng.normal(0.0, 1.0, (3, 4))

    def rows(n):
        y = np.repeat(np.array(["f1", "f2", "f3"]), n)
        return centres[np.repeat(np.arange(3), n)] + rng.normal(0.0, 0.9, (3 * n, 4)), y

    X, y = rows(60)
    Xc, yc = rows(200)
    ages = rng.uniform(1, 600, yc.size)
    iso = FaultIsolator(LogisticRegression(), calibrator=AgeTemperatureScaler(min_rows=50))
    with pytest.raises(ValueError, match=r"needs the calibration rows' ages"):
        iso.fit(X, y, calibration=(Xc, yc))
    iso.fit(X, y, calibration=(Xc, yc, ages))
    assert iso.uses_ages and not iso.rows_independent
    cal = iso.calibrator_
    assert cal.rows_per_bin_.sum() == yc.size
    Xt, _ = rows(5)
    t_ages = np.array([2.0, 20.0, 50.0, 200.0, 900.0] * 3)
    out = iso.run(Xt, t_ages)
    want = cal.transform(iso.summed_groups(iso.fault_proba(Xt)), t_ages)
    np.testing.assert_allclose(out.group_proba, want, rtol=1e-12)
    one = iso.update(Xt[4], age=900.0)
    np.testing.assert_allclose(one.group_proba, out.group_proba[4], rtol=1e-12)
    with pytest.raises(ValueError, match="depends on the signatures' ages"):
        iso.run(Xt)
    with pytest.raises(ValueError, match="one value per row"):
        iso.run(Xt, t_ages[:2])
    with pytest.raises(ValueError, match="ages must be finite and >= 0"):
        iso.run(Xt, -t_ages)

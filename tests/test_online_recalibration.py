"""The recalibration of the online diagnoser's group probabilities
(bayes_fdi.diagnosis.online.training): fitted on the per-second probabilities the stream gives
on the calibration runs, the seconds the benchmark scores."""

from __future__ import annotations

import numpy as np
import pytest
from small_online import small_normal_models, small_runs

from bayes_fdi.calibration import (
    AgeTemperatureScaler,
    TemperatureScaler,
    TopLabelScaler,
    expected_calibration_error,
)
from bayes_fdi.diagnosis import OnlineDiagnoser
from bayes_fdi.diagnosis.online.training import CALIBRATION_SECONDS_PER_RUN, detected_seconds


def test_detected_seconds_by_hand():
    # DD rises at 2 (before the onset 3) and at 5; second 6 has no signature
    dd = np.array([0, 0, 1, 1, 0, 1, 1, 1], dtype=bool)
    features = np.arange(16.0).reshape(8, 2)
    features[6, 1] = np.nan
    times = np.arange(8.0)
    rows, ages, hit = detected_seconds(dd, features, times, 3.0)
    assert [r[0] for r in rows] == [6.0, 10.0, 14.0]  # seconds 3, 5, 7
    assert ages == [1, 0, 2]  # seconds since the rise each belongs to (2, 5, 5)
    assert hit  # the rise at 5 follows the onset
    rows, ages, _ = detected_seconds(dd, features, times, 3.0, cap=2)
    assert [r[0] for r in rows] == [6.0, 14.0]  # evenly spaced: the first and the last
    _, _, hit = detected_seconds(dd, features, times, 6.0)
    assert not hit  # DD on from 5: no rise at or after 6


@pytest.fixture(scope="module", params=[TemperatureScaler, TopLabelScaler, AgeTemperatureScaler])
def fitted(request):
    runs = small_runs()
    diag = OnlineDiagnoser(
        small_normal_models(), calibrator=request.param(), max_signatures_per_fault=20
    ).fit(runs.normal, runs.faults, validation_runs=runs.validation,
          calibration_runs=runs.calibration)  # fmt: skip
    return diag, runs.calibration


def _scored_seconds(stream, calibration, faults):
    """The detected seconds after each run's onset with a finite group probability, at most
    CALIBRATION_SECONDS_PER_RUN evenly spaced: read off the decision stream."""
    t = stream["time"].values
    picks = []
    for r in range(stream.sizes["run"]):
        if str(calibration["state"].values[r]) not in faults:
            continue
        gp = stream["group_proba"].isel(run=r).transpose("time", "group").values
        ok = (t >= float(calibration["onset"].values[r])) & stream["DD"].isel(run=r).values
        keep = np.flatnonzero(ok & np.isfinite(gp).all(axis=1))
        if keep.size > CALIBRATION_SECONDS_PER_RUN:
            pos = np.linspace(0, keep.size - 1, CALIBRATION_SECONDS_PER_RUN)
            keep = keep[np.round(pos).astype(np.int64)]
        picks += [(r, k) for k in keep]
    return picks


def test_recalibration_is_fitted_on_the_streams_per_second_probabilities(fitted):
    diag, calibration = fitted
    iso = diag.isolator_
    assert len(iso.groups_) > 1 and iso.calibrator_ is not None
    fitted_cal = iso.calibrator_
    try:  # the stream's probabilities before recalibration
        iso.calibrator_ = None
        raw = diag.run(calibration)
    finally:
        iso.calibrator_ = fitted_cal
    picks = _scored_seconds(raw, calibration, set(iso.faults_))
    assert fitted_cal.n_samples_ == len(picks) > 0
    gp = np.array([raw["group_proba"].values[r, k] for r, k in picks])
    group = {f: g for g, members in zip(iso.group_labels_, iso.groups_, strict=True)
             for f in members}  # fmt: skip
    y = [group[str(calibration["state"].values[r])] for r, _ in picks]
    if isinstance(fitted_cal, AgeTemperatureScaler):
        # the ages: the seconds DD has been on (the signature window's seconds; these runs
        # have no missing samples), counted here from the decision stream
        dd = raw["DD"].transpose("run", "time").values
        run_length = np.zeros(dd.shape)
        for k in range(dd.shape[1]):
            run_length[:, k] = np.where(dd[:, k], (run_length[:, k - 1] if k else 0) + 1, 0)
        ages = np.array([run_length[r, k] for r, k in picks])
        assert ages.min() >= 1 and ages.max() > 100
        again = AgeTemperatureScaler(classes=list(iso.group_labels_)).fit(gp, y, ages)
        np.testing.assert_allclose(fitted_cal.temperatures_, again.temperatures_, rtol=1e-9)
        assert (again.rows_per_bin_ >= again.min_rows).sum() >= 2  # two bins of their own
        assert iso.rows_independent and iso.uses_ages  # the compiled path takes the ages
        stream = diag.run(calibration)
        got = np.array([stream["group_proba"].values[r, k] for r, k in picks])
        np.testing.assert_allclose(got, again.transform(gp, ages), rtol=1e-9, atol=1e-12)
        return
    again = type(fitted_cal)(classes=list(iso.group_labels_)).fit(gp, y)
    assert fitted_cal.temperature_ == pytest.approx(again.temperature_, rel=1e-9)
    if isinstance(again, TopLabelScaler):
        np.testing.assert_allclose(fitted_cal.top_map_, again.top_map_, rtol=1e-6, atol=1e-9)
        assert iso.rows_independent  # the compiled path applies the top map
    # and the calibrated stream (compiled) is those probabilities recalibrated (numpy)
    stream = diag.run(calibration)
    got = np.array([stream["group_proba"].values[r, k] for r, k in picks])
    np.testing.assert_allclose(got, again.transform(gp), rtol=1e-9, atol=1e-12)


def test_the_recalibration_survives_a_model_file(fitted, tmp_path):
    diag, calibration = fitted
    path = diag.save(tmp_path / "diag.bfdi")
    back = OnlineDiagnoser.load(path)
    assert back.isolator_.temperature() == diag.isolator_.temperature()
    for a, b in zip(back.isolator_.temperatures(), diag.isolator_.temperatures(), strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(back.isolator_.top_map(), diag.isolator_.top_map())
    a, b = diag.run(calibration), back.run(calibration)
    np.testing.assert_array_equal(a["group_proba"].values, b["group_proba"].values)


def test_per_second_temperature_removes_a_known_miscalibration():
    # seconds of 300 runs whose probabilities are over-confident by a known power 2.5 and
    # correlated within a run (one true distribution per run): the temperature fitted on the
    # seconds recovers 2.5 and leaves an ECE at the noise floor
    rng = np.random.default_rng(7)
    n_runs, per_run, k = 300, 50, 4
    logits = rng.normal(0.0, 1.5, (n_runs, k))
    true = np.exp(logits) / np.exp(logits).sum(axis=1, keepdims=True)
    y = np.concatenate([rng.choice(k, per_run, p=p) for p in true])
    true = np.repeat(true, per_run, axis=0)
    shown = true**2.5 / (true**2.5).sum(axis=1, keepdims=True)
    before = expected_calibration_error(y, shown, classes=np.arange(k))
    scaler = TemperatureScaler(classes=np.arange(k)).fit(shown, y)
    after = expected_calibration_error(y, scaler.transform(shown), classes=np.arange(k))
    assert scaler.temperature_ == pytest.approx(2.5, rel=0.1)
    assert before.value > 0.08
    assert after.value < 2 * after.noise_floor + 0.01

"""The top-label recalibration (bayes_fdi.calibration.top_label): a temperature, then a beta map
of the largest probability; checked by hand, against a known map and in a model file."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bayes_fdi import model_files
from bayes_fdi.calibration import TemperatureScaler, TopLabelScaler
from bayes_fdi.calibration.top_label import beta_map, top_label_map
from bayes_fdi.diagnosis.isolation.compiled_isolation import IsolationParams, map_top


def test_beta_map_by_hand():
    # (1, 1, 0) is the identity: sigmoid(ln p - ln(1 - p)) = p
    np.testing.assert_allclose(beta_map([0.2, 0.5, 0.9], (1.0, 1.0, 0.0)), [0.2, 0.5, 0.9])
    # (2, 0, 0): sigmoid(2 ln p) = p^2 / (1 + p^2), 0.2 at p = 0.5
    assert beta_map([0.5], (2.0, 0.0, 0.0))[0] == pytest.approx(0.2)


def test_top_label_map_shares_the_rest_in_proportion_by_hand():
    # the identity shifted by c = logit(0.5) - logit(0.6) takes the top 0.6 to 0.5; the others
    # share 0.5 as 0.3 : 0.1
    c = -math.log(1.5)
    out = top_label_map([[0.3, 0.6, 0.1]], (1.0, 1.0, c))
    np.testing.assert_allclose(out, [[0.375, 0.5, 0.125]])


def test_top_label_map_keeps_the_top_class_on_top():
    # a map to about 0.02 would put the second class first: the top stops at p2 / (1 - p1 + p2)
    # = 0.4 / 0.9, where the second class (0.4 of the rest 0.5) reaches it
    out = top_label_map([[0.5, 0.4, 0.1]], (1.0, 1.0, -4.0))
    np.testing.assert_allclose(out, [[4 / 9, 4 / 9, 1 / 9]])
    # all the rest at 0: shared equally
    out = top_label_map([[1.0, 0.0, 0.0]], (0.0, 0.0, math.log(0.8 / 0.2)))
    np.testing.assert_allclose(out, [[0.8, 0.1, 0.1]])


def test_a_known_top_label_miscalibration_is_recovered():
    # two classes; the top class is right with probability g(p) = sigmoid(2 logit(p) + 0.3),
    # in the family of a temperature followed by the beta map: the fitted scaler returns g(p)
    rng = np.random.default_rng(3)
    n = 40_000
    p = rng.uniform(0.5, 0.99, n)
    right = rng.random(n) < 1.0 / (1.0 + np.exp(-(2.0 * np.log(p / (1 - p)) + 0.3)))
    first = rng.random(n) < 0.5  # which column holds the top class
    proba = np.where(first[:, None], np.c_[p, 1 - p], np.c_[1 - p, p])
    y = np.where(first == right, 0, 1)
    scaler = TopLabelScaler(classes=[0, 1]).fit(proba, y)
    grid = np.array([0.55, 0.7, 0.85, 0.95])
    got = scaler.transform(np.c_[grid, 1 - grid])[:, 0]
    want = 1.0 / (1.0 + np.exp(-(2.0 * np.log(grid / (1 - grid)) + 0.3)))
    np.testing.assert_allclose(got, want, atol=0.02)
    assert (scaler.top_map_[:2] >= 0).all()


def test_calibrated_probabilities_stay_nearly_as_they_are():
    rng = np.random.default_rng(4)
    proba = rng.dirichlet(np.full(4, 0.6), 30_000)
    y = np.array([rng.choice(4, p=row) for row in proba])
    scaler = TopLabelScaler(classes=np.arange(4)).fit(proba, y)
    q = scaler.transform(proba)
    assert scaler.temperature_ == pytest.approx(1.0, abs=0.05)
    np.testing.assert_allclose(q.max(axis=1), proba.max(axis=1), atol=0.03)
    np.testing.assert_allclose(q.sum(axis=1), 1.0, rtol=1e-12)
    assert (q.argmax(axis=1) == proba.argmax(axis=1)).all()


def test_the_compiled_row_map_agrees_with_the_numpy_map():
    rng = np.random.default_rng(5)
    rows = rng.dirichlet(np.full(5, 0.4), 200)
    coef = np.array([1.7, 0.6, -0.4])
    want = top_label_map(rows, coef)
    for row, w in zip(rows, want, strict=True):
        got = row.copy()
        map_top(got, coef)
        np.testing.assert_allclose(got, w, rtol=1e-12, atol=1e-15)
    assert "top_map" in IsolationParams._fields


def test_the_scaler_survives_a_model_file_and_an_unfitted_one_says_so(tmp_path):
    rng = np.random.default_rng(6)
    proba = rng.dirichlet(np.full(3, 0.5), 500)
    y = rng.integers(0, 3, 500)
    scaler = TopLabelScaler(classes=[0, 1, 2]).fit(proba, y)
    path = model_files.save(scaler, tmp_path / "scaler.npz")
    back = model_files.load(path)
    np.testing.assert_array_equal(back.transform(proba), scaler.transform(proba))
    with pytest.raises(ValueError, match="not fitted"):
        TopLabelScaler().transform(proba)
    # the temperature alone is TemperatureScaler's
    assert scaler.temperature_ == TemperatureScaler(classes=[0, 1, 2]).fit(proba, y).temperature_


def test_an_older_model_file_loads_with_its_temperature_alone():
    # a format-3 file (tests/data/model_files_format3) recalibrates by a temperature: no top map,
    # and the isolation keeps its compiled path (its stream is checked in test_envelope_rates)
    from pathlib import Path

    from bayes_fdi.diagnosis import OnlineDiagnoser

    path = Path(__file__).parent / "data" / "model_files_format3" / "online.npz"
    assert model_files.read_metadata(path)["format_version"] < model_files.FORMAT_VERSION
    isolator = OnlineDiagnoser.load(path).isolator_
    assert type(isolator.calibrator_) is TemperatureScaler
    assert isolator.top_map().size == 0 and isolator.temperature() > 0
    assert isolator.rows_independent

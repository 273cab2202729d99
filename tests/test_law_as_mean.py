"""The valve law as the flow model's mean (``law_as_mean``): the flow model learns F minus the
nominal valve law's flow at the predicted position, clipped to the sensors' range.

Checked against a vectorised reference of the prediction (the regression plus the clipped law),
against the simulator's physics where the training runs never went (a shut valve: no flow),
whole against second by second, through a model file, and against files saved before the
option."""

from __future__ import annotations

import numpy as np
import pytest
from second_by_second import second_by_second

from bayes_fdi import model_files
from bayes_fdi.actuator import benchmark_inputs, simulate
from bayes_fdi.diagnosis.normal_models.dynamic import DynamicNormalModels
from bayes_fdi.diagnosis.normal_models.dynamic_kernel import NormalModelsParams
from bayes_fdi.diagnosis.normal_models.physics_inputs import flow_model_inputs, valve_law_flow

SMALL = dict(
    x_widths=(8.0,), f_widths=(0.1,), evidence_max_samples=200, max_train_samples=300,
    calibration_folds=2, random_state=0,
)  # fmt: skip
LAW = ("command_lag", "valve_law")


@pytest.fixture(scope="module")
def normal():
    """Fault-free DGen runs whose command stays within 0.25-0.75 (the valve never shuts)."""
    return simulate(benchmark_inputs(4, 400, seed=51), seed=51)


@pytest.fixture(scope="module")
def models(normal):
    plain = DynamicNormalModels(physics_inputs=LAW, **SMALL).fit(normal)
    law = DynamicNormalModels(physics_inputs=LAW, law_as_mean=True, **SMALL).fit(normal)
    return plain, law


@pytest.fixture(scope="module")
def shutting():
    """A run whose command holds the valve near its middle for 200 s, then shuts it (CV 1)."""
    drive = benchmark_inputs(1, 400, seed=52)
    cv = np.where(np.arange(400) < 200, 0.5, 1.0)[None, :]
    return simulate(drive.assign(CV=(("run", "time"), cv)), seed=52)


def test_prediction_is_the_regression_plus_the_clipped_law(models, normal):
    _, nm = models
    assert nm.params_.law_as_mean is True
    test = simulate(benchmark_inputs(1, 300, seed=53), seed=53)
    out = nm.predict(test)
    x_hat = out["X_hat"].values[0]
    drop = (test["P1"] - test["P2"]).values[0]
    s = np.sign(drop) * np.sqrt(np.abs(drop))
    t1, p1 = test["T1"].values[0], test["P1"].values[0]
    V = flow_model_inputs(x_hat, s, t1, p1, nm.valve_law_)
    law = np.clip(valve_law_flow(x_hat, s, t1, p1), 0.0, 1.0)
    expected = np.clip(nm.regressors_["F"].predict(V) + law, 0.0, 1.0)
    np.testing.assert_allclose(out["F_hat"].values[0], expected, rtol=1e-10, atol=1e-12)
    # the regression learnt what the law leaves: far smaller than F itself
    assert np.std(nm.regressors_["F"].predict(V)) < 0.2 * np.std(test["F"].values[0])


def test_a_shut_valve_falls_back_on_the_law(models, normal, shutting):
    plain, law = models
    assert normal["CV"].values.max() < 0.8  # the training never shut the valve
    shut = np.arange(400) >= 260  # the stem has reached its end stop
    assert shutting["X"].values[0, shut].min() > 0.99
    f = shutting["F"].values[0, shut]
    assert f.max() < 0.02  # a shut valve passes no flow (sensor noise only)
    err_law = np.abs(law.predict(shutting)["F_hat"].values[0, shut] - f).max()
    err_plain = np.abs(plain.predict(shutting)["F_hat"].values[0, shut] - f).max()
    # the regression of F itself extrapolates from the open valve's data (it predicts most of
    # the full flow); the law's flow is that of the predicted position, which the position
    # model (trained on the open valve too) puts up to 0.035 short of the end stop, where the
    # law's linear closing stretch passes under 0.1 of full scale
    assert err_law < 0.1 and err_plain > 0.5


def test_stream_and_file_round_trip(models, tmp_path):
    _, nm = models
    test = simulate(benchmark_inputs(1, 120, seed=54), seed=54)
    channels = {c: test[c].values[0] for c in ("CV", "P1", "P2", "T1")}
    whole, _ = nm.run(channels)
    np.testing.assert_array_equal(second_by_second(nm, channels)[0], whole)
    again = model_files.load(model_files.save(nm, tmp_path / "law.model"))
    assert again.law_as_mean and again.params_.law_as_mean
    np.testing.assert_array_equal(again.run(channels)[0], whole)


def test_law_as_mean_needs_the_valve_law():
    normal = simulate(benchmark_inputs(2, 60, seed=55), seed=55)
    with pytest.raises(
        ValueError, match="law_as_mean must be False, or True with the 'valve_law' input"
    ):
        DynamicNormalModels(physics_inputs=("command_lag",), law_as_mean=True).fit(normal)
    with pytest.raises(ValueError, match="law_as_mean"):
        DynamicNormalModels(physics_inputs=("valve_law",), law_as_mean=1).fit(normal)


def test_parameters_saved_before_the_option_keep_their_predictions():
    new = NormalModelsParams.upgrade_model_file({"valve_law": np.ones(6)}, 11)
    assert new["law_as_mean"] is False

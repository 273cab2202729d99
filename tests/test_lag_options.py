"""The command lag's two options of the dynamic normal models: the stem's speed limits
(``lag_speed_limits``) and the lagged command as the position model's mean (``lag_as_mean``).

Checked against the simulator's physics (its stem travels at a limited speed after a large
step), against a vectorised reference of the prediction, whole against second by second, through
a model file, and against the layout of files saved before the options."""

from __future__ import annotations

import math

import numpy as np
import pytest
from second_by_second import second_by_second

from bayes_fdi import model_files
from bayes_fdi.actuator import benchmark_inputs, simulate
from bayes_fdi.actuator.excitation import step_ramp_inputs
from bayes_fdi.diagnosis.normal_models.dynamic import DynamicNormalModels
from bayes_fdi.diagnosis.normal_models.dynamic_kernel import (
    NormalModelsParams,
    dynamic_inputs,
)
from bayes_fdi.diagnosis.normal_models.physics_inputs import SPEED_GRID, lagged_command

SMALL = dict(
    x_widths=(8.0,), f_widths=(0.1,), evidence_max_samples=200, max_train_samples=300,
    calibration_folds=2, random_state=0,
)  # fmt: skip


@pytest.fixture(scope="module")
def steps():
    """Fault-free runs under command steps of up to 0.55 every 40 s at steady pressures and
    temperature (the stem needs several seconds to travel the large steps)."""
    drive = benchmark_inputs(4, 400, seed=41, vary=False)
    held = {c: (("run", "time"), np.repeat(drive[c].values[:, :1], 400, axis=1))
            for c in ("P1", "P2", "T1")}  # fmt: skip
    levels = np.random.default_rng(41).uniform(0.25, 0.8, size=(4, 10))
    cv = (("run", "time"), np.repeat(levels, 40, axis=1))
    return simulate(drive.assign(CV=cv, **held), seed=41)


@pytest.fixture(scope="module")
def lag_mean_models(steps):
    return DynamicNormalModels(
        physics_inputs=("command_lag",), lag_speed_limits=True, lag_as_mean=True, **SMALL
    ).fit(steps)


def test_speed_limits_are_the_simulated_stems_travel_speeds(steps):
    plain = DynamicNormalModels(physics_inputs=("command_lag",), **SMALL).fit(steps)
    assert plain.command_lag_[2:] == (math.inf, math.inf)  # off by default
    np.testing.assert_array_equal(plain.params_.command_lag[2:], [np.inf, np.inf])
    limited = DynamicNormalModels(
        physics_inputs=("command_lag",), lag_speed_limits=True, **SMALL
    ).fit(steps)
    v_rise, v_fall = limited.command_lag_[2:]
    # the stem's travel per second while far from its command (after a large step): the
    # simulated actuator's speed in each direction
    x, cv = steps["X"].values, steps["CV"].values
    dx, gap = np.diff(x, axis=1), (cv - x)[:, 1:]
    up, down = np.median(dx[gap > 0.15]), np.median(-dx[gap < -0.15])
    # the fitted limits are the grid's values nearest those speeds (grid steps of 35 %)
    ratio = SPEED_GRID[2] / SPEED_GRID[1]
    assert up / ratio <= v_rise <= up * ratio and down / ratio <= v_fall <= down * ratio
    assert v_fall < v_rise  # the chamber vents slower than it fills here


def test_lag_as_mean_prediction_is_the_regression_plus_the_lag(lag_mean_models):
    nm = lag_mean_models
    assert nm.params_.lag_as_mean is True
    test = simulate(step_ramp_inputs(1, 600, seed=42), seed=42)
    lag = lagged_command(test["CV"].values, *nm.command_lag_)[0]
    U = np.column_stack([dynamic_inputs(test, nm.n_differences)[0], lag])
    mean = nm.regressors_["X"].predict((U - nm.input_mean_) / nm.input_scale_)
    got = nm.predict(test)["X_hat"].values[0]
    np.testing.assert_allclose(got, np.clip(mean + lag, 0.0, 1.0), rtol=1e-10, atol=1e-12)
    # the regression learnt the difference: far smaller than X itself
    assert np.std(mean) < 0.5 * np.std(test["X"].values[0])


def test_lag_options_stream_and_file_round_trip(lag_mean_models, tmp_path):
    nm = lag_mean_models
    test = simulate(step_ramp_inputs(1, 120, seed=43), seed=43)
    channels = {c: test[c].values[0] for c in ("CV", "P1", "P2")}
    whole, _ = nm.run(channels)
    np.testing.assert_array_equal(second_by_second(nm, channels)[0], whole)
    again = model_files.load(model_files.save(nm, tmp_path / "lag.model"))
    assert again.lag_as_mean and again.lag_speed_limits
    assert again.command_lag_ == nm.command_lag_
    np.testing.assert_array_equal(again.run(channels)[0], whole)


def test_lag_options_need_the_command_lag():
    normal = simulate(benchmark_inputs(2, 60, seed=44), seed=44)
    for name in ("lag_as_mean", "lag_speed_limits"):
        with pytest.raises(ValueError, match=f"{name} must be False, or True with"):
            DynamicNormalModels(**{name: True}).fit(normal)
        with pytest.raises(ValueError, match=name):
            DynamicNormalModels(physics_inputs=("command_lag",), **{name: 1}).fit(normal)


def test_parameters_saved_before_the_options_keep_their_predictions():
    old = {"command_lag": np.array([0.5, 0.3]), "valve_law": np.empty(0)}
    new = NormalModelsParams.upgrade_model_file(dict(old), 10)
    # no speed limits (inf: the lag's step is never clipped) and the plain position model
    np.testing.assert_array_equal(new["command_lag"], [0.5, 0.3, np.inf, np.inf])
    assert new["lag_as_mean"] is False
    none = NormalModelsParams.upgrade_model_file({}, 8)
    assert none["command_lag"].size == 0 and none["lag_as_mean"] is False

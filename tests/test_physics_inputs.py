"""Physics inputs of the dynamic normal models (bayes_fdi.diagnosis.normal_models.physics_inputs):
the command's two-rate lag against its closed-form step response, the valve law against the
actuator model's own flow computation, and the models' compiled stream against the regressions
on the vectorised inputs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bayes_fdi import model_files
from bayes_fdi.actuator import benchmark_inputs, simulate
from bayes_fdi.actuator.excitation import step_ramp_inputs
from bayes_fdi.actuator.valve import flow_rate
from bayes_fdi.diagnosis.normal_models.dynamic import DynamicNormalModels
from bayes_fdi.diagnosis.normal_models.dynamic_kernel import dynamic_inputs, signed_root
from bayes_fdi.diagnosis.normal_models.physics_inputs import (
    fit_command_lag,
    lagged_command,
    valve_law_flow,
)


def test_lag_step_responses_are_the_first_order_closed_form():
    tau_rise, tau_fall = 2.0, 7.0
    cv = np.concatenate([np.zeros(5), np.ones(40), np.full(60, 0.25)])
    y = lagged_command(cv, tau_rise, tau_fall)
    n = np.arange(40)
    # a unit step up at t = 5: y(5 + n) = 1 - exp(-(n + 1) / tau_rise) (the sample's own command
    # acts for its second), then down to 0.25 from where it stood, with tau_fall
    np.testing.assert_allclose(y[:5], 0.0)
    np.testing.assert_allclose(y[5:45], 1.0 - np.exp(-(n + 1) / tau_rise), rtol=1e-12)
    top = y[44]
    m = np.arange(60)
    expected = 0.25 + (top - 0.25) * np.exp(-(m + 1) / tau_fall)
    np.testing.assert_allclose(y[45:], expected, rtol=1e-12)


def test_lag_holds_the_first_command_and_skips_missing_ones():
    cv = np.array([[0.6, 0.6, np.nan, 1.0], [np.nan, 0.3, 0.3, 0.3]])
    y = lagged_command(cv, 1.0, 1.0)
    a = 1.0 - math.exp(-1.0)
    np.testing.assert_allclose(y[0], [0.6, 0.6, np.nan, 0.6 + a * 0.4], equal_nan=True)
    np.testing.assert_allclose(y[1], [np.nan, 0.3, 0.3, 0.3], equal_nan=True)
    with pytest.raises(ValueError, match="tau_fall"):
        lagged_command(cv, 1.0, 0.0)


def test_fit_command_lag_recovers_the_time_constants():
    rng = np.random.default_rng(3)
    cv = np.repeat(rng.uniform(0.3, 0.9, size=(3, 40)), 25, axis=1)  # steps every 25 s
    s = rng.uniform(0.3, 0.5, size=cv.shape)
    x = 0.02 + 0.97 * lagged_command(cv, 2.0, 6.0) - 0.05 * s + rng.normal(0, 1e-3, cv.shape)
    # no speed limit in these runs: none is fitted
    grid, speeds = (1.0, 2.0, 4.0, 6.0, 10.0), (math.inf, 0.02, 0.05, 0.1)
    assert fit_command_lag(cv, x, s, grid=grid, limits=speeds) == (2.0, 6.0, math.inf, math.inf)


def test_fit_command_lag_recovers_the_speed_limits():
    rng = np.random.default_rng(4)
    cv = np.repeat(rng.uniform(0.1, 0.9, size=(4, 30)), 40, axis=1)  # steps of up to 0.8
    s = rng.uniform(0.3, 0.5, size=cv.shape)
    y = lagged_command(cv, 1.0, 2.0, 0.1, 0.03)
    x = 0.02 + 0.97 * y - 0.05 * s + rng.normal(0, 1e-3, cv.shape)
    grid, speeds = (0.5, 1.0, 2.0, 4.0), (math.inf, 0.01, 0.03, 0.1, 0.3)
    assert fit_command_lag(cv, x, s, grid=grid, limits=speeds) == (1.0, 2.0, 0.1, 0.03)


def test_a_large_step_is_travelled_at_the_limited_speed():
    # up by 0.8 with a fast lag: the limit 0.1/s sets the travel until the lag's own step,
    # a (1 - y), falls below it; then the first-order approach (closed form from there)
    cv = np.concatenate([np.zeros(3), np.full(30, 0.8), np.full(40, 0.2)])
    y = lagged_command(cv, 0.5, 0.5, 0.1, 0.05)
    a = 1.0 - math.exp(-2.0)
    np.testing.assert_allclose(y[3:10], 0.1 * np.arange(1, 8), rtol=1e-12)
    k = 4 + int(np.argmax(a * (0.8 - y[3:33]) <= 0.1))  # the first step inside the limit
    np.testing.assert_allclose(y[k:33], 0.8 - (0.8 - y[k - 1]) * (1 - a) ** np.arange(1, 34 - k),
                               rtol=1e-12)  # fmt: skip
    # down by 0.6 at 0.05/s
    np.testing.assert_allclose(np.diff(y[32:40]), -0.05, rtol=1e-12)
    # no limit (inf) is the plain lag, bit for bit
    np.testing.assert_array_equal(
        lagged_command(cv, 2.0, 7.0, math.inf, math.inf), lagged_command(cv, 2.0, 7.0)
    )
    with pytest.raises(ValueError, match="v_fall must be a positive speed"):
        lagged_command(cv, 1.0, 1.0, 0.1, 0.0)


def test_valve_law_is_the_actuator_models_flow():
    rng = np.random.default_rng(5)
    n = 400
    # equal-percentage part, and the linear part near closure (x > 0.975), both unchoked
    x = np.concatenate([rng.uniform(0.0, 0.95, n), rng.uniform(0.976, 0.99, n)])
    p1 = rng.uniform(2.5e6, 3.7e6, 2 * n)  # Pa, the DABLib ranges
    dp = rng.uniform(0.3e6, 1.0e6, 2 * n)
    t1 = rng.uniform(20.0, 110.0, 2 * n)
    expected = flow_rate(x, p1, p1 - dp, t1) / 40.0  # t/h over the F range
    got = valve_law_flow(x, np.sqrt(dp / 4e6), t1 / 200.0, p1 / 4e6)
    np.testing.assert_allclose(got, expected, rtol=1e-12)


@pytest.fixture(scope="module")
def physics_models():
    normal = simulate(step_ramp_inputs(4, 300, seed=21), seed=21)
    nm = DynamicNormalModels(
        x_widths=(8.0,), f_widths=(0.1,), evidence_max_samples=200, max_train_samples=300,
        calibration_folds=2, physics_inputs=("command_lag", "valve_law"), random_state=0,
    ).fit(normal)  # fmt: skip
    return nm, normal


def test_physics_stream_equals_the_regressions_on_the_vectorised_inputs(physics_models):
    nm, _ = physics_models
    test = simulate(step_ramp_inputs(1, 200, seed=22), seed=22)
    got = nm.predict(test)
    cv = test["CV"].values
    U = np.concatenate(
        [dynamic_inputs(test, nm.n_differences)[0], lagged_command(cv, *nm.command_lag_).T], axis=1
    )
    x_mean, x_std = nm.regressors_["X"].predict(
        (U - nm.input_mean_) / nm.input_scale_, return_std=True
    )
    x_hat = np.clip(x_mean, 0.0, 1.0)
    s = signed_root(test["P1"].values, test["P2"].values)[0]
    law = valve_law_flow(x_hat, s, test["T1"].values[0], test["P1"].values[0])
    f_mean, _ = nm.regressors_["F"].predict(np.column_stack([x_hat, s, law]), return_std=True)
    b = np.searchsorted(nm.std_scale_edges_, np.abs(U[:, 2]), side="right")
    np.testing.assert_allclose(got["X_hat"].values[0], x_hat, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(
        got["X_hat_std"].values[0], x_std * nm.std_scale_["X"][b], rtol=1e-10
    )
    np.testing.assert_allclose(got["F_hat"].values[0], np.clip(f_mean, 0, 1), rtol=1e-10,
                               atol=1e-12)  # fmt: skip


def test_physics_stream_is_the_same_whole_or_in_pieces_and_after_a_file(physics_models, tmp_path):
    nm, _ = physics_models
    test = simulate(step_ramp_inputs(1, 120, seed=23), seed=23)
    channels = {c: test[c].values[0] for c in ("CV", "P1", "P2", "T1")}
    whole, _ = nm.run(channels)
    first, state = nm.run({c: v[:50] for c, v in channels.items()})
    rest, _ = nm.run({c: v[50:] for c, v in channels.items()}, state)
    np.testing.assert_array_equal(np.concatenate([first, rest]), whole)
    path = tmp_path / "physics.model"
    model_files.save(nm, path)
    again = model_files.load(path)
    assert again.command_lag_ == nm.command_lag_
    np.testing.assert_array_equal(again.run(channels)[0], whole)
    with pytest.raises(ValueError, match="T1"):
        nm.run({c: channels[c] for c in ("CV", "P1", "P2")})


def test_physics_inputs_are_opt_in():
    normal = simulate(benchmark_inputs(2, 200, seed=31, vary=True), seed=31)
    nm = DynamicNormalModels(
        x_widths=(8.0,), f_widths=(0.1,), evidence_max_samples=100, max_train_samples=200,
        calibration_folds=2, random_state=0,
    ).fit(normal)  # fmt: skip
    assert nm.command_lag_ is None
    assert nm.params_.command_lag.size == 0 and nm.params_.valve_law.size == 0
    assert nm.init_state().history.shape == (2, nm.n_differences)
    # without the valve law, T1 is not needed
    out, _ = nm.run({c: normal[c].values[0] for c in ("CV", "P1", "P2")})
    assert np.isfinite(out[:, 0]).all()
    for bad in (True, "valve_law", ("valve_law", "valve_law"), ("lag",)):
        with pytest.raises(ValueError, match="physics_inputs"):
            DynamicNormalModels(physics_inputs=bad).fit(normal)


def test_online_diagnoser_with_physics_inputs_streams_the_same_per_second(tmp_path):
    from bayes_fdi.actuator import Fault
    from bayes_fdi.calibration import TemperatureScaler
    from bayes_fdi.diagnosis import OnlineDiagnoser

    normal = simulate(step_ramp_inputs(4, 400, seed=41), seed=41)
    specs = [Fault(f, s, 100.0) for f in ("f1", "f18") for s in (0.5, 0.8, 1.0)]
    faults = simulate(step_ramp_inputs(len(specs), 300, seed=42), specs, seed=42)
    models = DynamicNormalModels(
        x_widths=(8.0,), f_widths=(0.1,), evidence_max_samples=200, max_train_samples=300,
        calibration_folds=2, physics_inputs=("command_lag", "valve_law"), random_state=0,
    )  # fmt: skip
    diag = OnlineDiagnoser(models, calibrator=TemperatureScaler(), max_signatures_per_fault=20)
    diag.fit(normal, faults)
    rec = simulate(step_ramp_inputs(1, 200, seed=43), [Fault("f18", 0.8, 100.0)], seed=43)
    stream = diag.run(rec)
    last, records = [], []
    for t in range(rec.sizes["time"]):
        sample = {c: float(rec[c].values[0, t]) for c in ("CV", "P1", "P2", "T1", "X", "F")}
        records.append(diag.update({**sample, "time": float(t)}))
        last.append(dict(diag.last_))
    np.testing.assert_array_equal([r.x_vmv for r in records], stream["VMV_X"].values[0])
    np.testing.assert_array_equal([r.f_vmv for r in records], stream["VMV_F"].values[0])
    assert stream["DD"].values[0, 110:].any()  # f18 is seen
    for key in ("DD", "stat_X", "stat_F"):
        np.testing.assert_array_equal([d[key] for d in last], stream[key].values[0], err_msg=key)
    path = tmp_path / "diagnoser.model"
    diag.save(path)
    again = OnlineDiagnoser.load(path).run(rec)
    np.testing.assert_array_equal(again["F_hat"].values, stream["F_hat"].values)
    np.testing.assert_array_equal(again["DD"].values, stream["DD"].values)

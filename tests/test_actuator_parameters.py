"""The actuator's parameter record: the nominal record reproduces the simulator bit for bit.

``tests/data/actuator_reference/actuator_reference.npz`` was written by the simulator before it
took a parameter record (module constants); every case is recomputed and must give the same
bytes (reference and fast integrator, both holds, all 19 faults abrupt and incipient, noise,
the real hour, fault injection, replicas).
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import numpy as np
import pytest

REFERENCE_DIR = Path(__file__).parent / "data" / "actuator_reference"


def _reference_module():
    spec = importlib.util.spec_from_file_location(
        "actuator_reference", REFERENCE_DIR / "make_reference.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def outputs():
    return _reference_module().reference_outputs()


def test_nominal_parameters_reproduce_the_stored_outputs_bit_for_bit(outputs):
    with np.load(REFERENCE_DIR / "actuator_reference.npz") as stored:
        assert sorted(stored.files) == sorted(outputs)
        for name in stored.files:
            expected = stored[name]
            got = outputs[name]
            assert got.dtype == expected.dtype and got.shape == expected.shape, name
            if not np.array_equal(got, expected, equal_nan=True):
                diff = np.nanmax(np.abs(got - expected))
                pytest.fail(f"{name}: differs from the stored output (max |diff| {diff:.3g})")


# --- the record ----------------------------------------------------------------------------
from bayes_fdi.actuator import (  # noqa: E402
    NOMINAL,
    PARAMETER_INFO,
    PARAMETERS,
    ActuatorParameters,
    Fault,
    benchmark_inputs,
    flow_rate,
    simulate,
)
from bayes_fdi.actuator import parameters as parameters_module  # noqa: E402


def test_the_nominal_record_holds_dablibs_values_and_every_field_has_unit_and_bounds():
    assert NOMINAL == ActuatorParameters()
    assert NOMINAL.kv == PARAMETERS["Kv"][0] == 120.0
    assert NOMINAL.spring == 60892.0 and NOMINAL.diaphragm_area == 0.029
    assert NOMINAL.preload == 0.009525 and NOMINAL.supply_pressure == 600e3
    assert NOMINAL.backlash * PARAMETERS["X0"][0] == PARAMETERS["db"][0]
    assert list(PARAMETER_INFO) == list(ActuatorParameters._fields)
    for name, value in zip(NOMINAL._fields, NOMINAL, strict=True):
        info = PARAMETER_INFO[name]
        assert info.low < value < info.high or (info.low == value == 0.0), name
    assert NOMINAL.validated() == NOMINAL


def test_the_kernel_vector_is_laid_out_as_its_index_constants_say():
    vector = ActuatorParameters(kv=101.0, t1_gain=1.1, plug_diameter=0.04).as_vector()
    assert vector.shape == (parameters_module.VECTOR_SIZE,)
    for k, name in enumerate(ActuatorParameters._fields):
        constant = "IDX_" + {
            "diaphragm_area": "AREA",
            "chamber_volume": "VOLUME",
            "positioner_gain": "KP",
            "setpoint_lag": "TAU",
            "inflow_coefficient": "K_IN",
            "supply_pressure": "SUPPLY",
        }.get(name, name.upper())
        assert getattr(parameters_module, constant) == k, name
    assert vector[parameters_module.IDX_KV] == 101.0
    assert vector[parameters_module.IDX_PLUG_AREA] == pytest.approx(np.pi * 0.04**2 / 4)
    assert vector[parameters_module.IDX_KVR_KNEE] == pytest.approx(np.exp(-5 * 0.975))


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"kv": -1.0}, "kv = -1.0 m^3/h lies outside"),
        ({"spring": float("nan")}, "spring"),
        ({"x_gain": 2.0}, "x_gain"),
        ({"backlash": "0.01"}, "backlash must be a real number"),
        ({"mass": True}, "mass must be a real number"),
        ({"mass": 1.0}, "damping / mass = 1500 1/s exceeds 1000"),
    ],
)
def test_a_parameter_outside_its_bounds_is_refused_by_name(change, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        ActuatorParameters(**change).validated()
    inputs = benchmark_inputs(n_runs=1, duration=5)
    with pytest.raises(ValueError, match="simulate: ActuatorParameters.*" + re.escape(message)):
        simulate(inputs, parameters=ActuatorParameters(**change))


def test_parameters_per_run_must_match_the_runs():
    inputs = benchmark_inputs(n_runs=2, duration=5)
    with pytest.raises(ValueError, match="got 1 parameter records for 2 runs"):
        simulate(inputs, parameters=[NOMINAL])
    with pytest.raises(ValueError, match="parameters\\[1\\] must be an ActuatorParameters"):
        simulate(inputs, parameters=[NOMINAL, {"kv": 1.0}])
    with pytest.raises(ValueError, match="parameters must be None, an ActuatorParameters"):
        simulate(inputs, parameters={"kv": 100.0})


# --- what the parameters do (closed forms and the faults that change the same quantity) -----
@pytest.fixture(scope="module")
def inputs():
    return benchmark_inputs(n_runs=2, duration=120, vary=True, seed=21)


def _sim(inputs, parameters=None, faults=None, **kw):
    kw = {"noise": False, "warmup": 0, **kw}
    return simulate(inputs, faults, parameters=parameters, **kw)


def test_one_record_per_run_gives_each_run_its_own_model(inputs):
    a, b = ActuatorParameters(kv=100.0), ActuatorParameters(spring=50000.0, x_offset=0.02)
    both = _sim(inputs, [a, b])
    alone_a = _sim(inputs.isel(run=[0]), a)
    alone_b = _sim(inputs.isel(run=[1]), b)
    for name in ("X", "F", "P1"):
        np.testing.assert_array_equal(both[name].values[0], alone_a[name].values[0])
        np.testing.assert_array_equal(both[name].values[1], alone_b[name].values[0])


def test_the_flow_scales_with_kv_and_the_stem_does_not_see_it(inputs):
    nominal = _sim(inputs)
    scaled = _sim(inputs, ActuatorParameters(kv=132.0))
    np.testing.assert_array_equal(scaled.X.values, nominal.X.values)
    ok = (nominal.F.values > 0.01) & (scaled.F.values < 1.0)
    np.testing.assert_allclose(scaled.F.values[ok], 1.1 * nominal.F.values[ok], rtol=1e-12)


def test_the_characteristic_is_equal_percentage_with_the_given_exponent():
    slow = ActuatorParameters(characteristic=3.5)
    f = flow_rate(np.array([0.3, 0.5]), 3.5e6, 2.6e6, 43.0, parameters=slow)
    assert f[1] / f[0] == pytest.approx(np.exp(-3.5 * 0.2), rel=1e-12)
    doubled = flow_rate(0.4, 3.5e6, 2.6e6, 43.0, parameters=ActuatorParameters(kv=240.0))
    assert doubled == pytest.approx(2 * flow_rate(0.4, 3.5e6, 2.6e6, 43.0), rel=1e-12)


def test_a_transmitter_calibration_acts_on_its_reading_only(inputs):
    nominal = _sim(inputs)
    gain, offset = 1.05, -0.01
    p = _sim(inputs, ActuatorParameters(x_gain=gain, x_offset=offset, f_gain=0.9, f_offset=0.02))
    # the returned channels are clipped to [0, 1] like any reading
    expected_x = np.clip(gain * nominal.X.values + offset, 0.0, 1.0)
    np.testing.assert_allclose(p.X.values, expected_x, atol=1e-15)
    inside = nominal.F.values < 1.0  # DGen's pressures saturate F' at low X
    assert inside.mean() > 0.5
    np.testing.assert_allclose(
        p.F.values[inside], 0.9 * nominal.F.values[inside] + 0.02, atol=1e-15
    )


def test_an_input_transmitter_offset_changes_what_the_plant_sees_not_the_reading(inputs):
    # P1' reads 0.02 full scale high: the plant runs at P1' - 0.02; the returned P1' is the
    # reading again
    biased = _sim(inputs, ActuatorParameters(p1_offset=0.02, t1_gain=1.1))
    np.testing.assert_allclose(biased.P1.values, inputs.P1.values, atol=1e-15)
    np.testing.assert_allclose(biased.T1.values, inputs.T1.values, atol=1e-15)
    true_inputs = inputs.copy(deep=True)
    true_inputs["P1"] = inputs.P1 - 0.02
    true_inputs["T1"] = inputs.T1 / 1.1
    direct = _sim(true_inputs)
    # the two conversions round differently (1e-16); the positioner's dead zone is neutrally
    # stable and keeps such differences (1e-6 here, against the noise's 1.4e-3)
    np.testing.assert_allclose(biased.F.values, direct.F.values, atol=1e-5)
    np.testing.assert_allclose(biased.X.values, direct.X.values, atol=1e-5)


@pytest.mark.parametrize(
    ("fault", "parameters"),
    [
        (Fault("f11", 0.3), ActuatorParameters(spring=60892.0 * (1.0 - 0.3))),
        (Fault("f16", 0.25), ActuatorParameters(supply_pressure=600e3 * (1.0 - 0.25))),
        (Fault("f4", 0.04), ActuatorParameters(backlash=0.01 + 0.04)),
    ],
)
def test_a_parameter_equals_the_fault_that_changes_it(inputs, fault, parameters):
    # DABLib's faults scale the same quantities: a fault present from t = 0 (no warm-up) and
    # the changed parameter give the same run
    by_fault = _sim(inputs, faults=fault)
    by_parameter = _sim(inputs, parameters)
    for integrator in ("fast", "reference"):
        by_fault = _sim(inputs, faults=fault, integrator=integrator)
        by_parameter = _sim(inputs, parameters, integrator=integrator)
        np.testing.assert_array_equal(by_parameter.X.values, by_fault.X.values)
        np.testing.assert_array_equal(by_parameter.F.values, by_fault.F.values)

"""Fault transplant: exact identities, and the direct simulation of the faulty plant."""

from __future__ import annotations

import numpy as np
import pytest

from bayes_fdi.actuator import FAULT_NAMES, NOMINAL, SIGNED_FAULTS, Fault, simulate
from bayes_fdi.datasets import (
    MEASUREMENT_FAULTS,
    STATES,
    load_lublin_example,
    make_dataset,
    state_order,
    validate_dataset,
)
from bayes_fdi.twin import (
    MEASUREMENT_BIAS_SCALE,
    MeasurementFault,
    transplant,
    transplant_library,
)

CHANNELS = ("CV", "P1", "P2", "T1", "X", "F")


@pytest.fixture(scope="module")
def hour():
    return load_lublin_example()


def _runs(ds, n):
    return ds.isel(run=[0] * n).assign_coords(run=np.arange(n))


def test_a_zero_strength_fault_returns_the_healthy_data_exactly(hour):
    window = hour.isel(time=slice(1200, 1500))
    faults = [Fault(name, 0.0, onset=50.0) for name in FAULT_NAMES]
    faults += [Fault(n, 0.0, 20.0, "incipient", 100.0) for n in ("f2", "f13", "f17", "f19")]
    faults += [MeasurementFault(n, 0.0, 40.0) for n in MEASUREMENT_FAULTS]
    draw = NOMINAL._replace(kv=97.0, backlash=0.02, x_offset=0.01, f_offset=0.03)
    out = transplant(_runs(window, len(faults)), faults, draw)
    for c in CHANNELS:
        np.testing.assert_array_equal(out[c].values, np.repeat(window[c].values, len(faults), 0))
    assert list(out.state.values) == [f.name for f in faults]


def test_a_measurement_bias_or_drift_adds_exactly_to_its_reading_alone(hour):
    window = hour.isel(time=slice(0, 400))
    faults = [
        MeasurementFault("bias_X", 0.3, onset=100.0),
        MeasurementFault("bias_F", -0.5, onset=50.0, profile="incipient", ramp=200.0),
        MeasurementFault("bias_P1", 0.2, onset=10.0),
        MeasurementFault("bias_P2", -0.25, onset=300.0, profile="incipient", ramp=50.0),
    ]
    out = transplant(_runs(window, 4), faults, NOMINAL)
    t = np.arange(400.0)
    for r, fault in enumerate(faults):
        channel = fault.name.split("_")[1]
        if fault.profile == "abrupt":
            bias = np.where(t >= fault.onset, fault.strength * MEASUREMENT_BIAS_SCALE, 0.0)
        else:
            frac = np.clip((t - fault.onset) / fault.ramp, 0.0, 1.0)
            bias = fault.strength * MEASUREMENT_BIAS_SCALE * frac
        expected = window[channel].values[0] + bias
        assert 0.0 < expected.min() and expected.max() < 1.0  # no clipping in this test
        np.testing.assert_array_equal(out[channel].values[r], expected)
        for other in set(CHANNELS) - {channel}:
            np.testing.assert_array_equal(out[other].values[r], window[other].values[0])


def test_the_flow_sensor_fault_scales_the_recorded_flow_exactly(hour):
    window = hour.isel(time=slice(500, 800))
    fault = Fault("f19", -0.4, onset=100.0)
    offset = 0.02
    out = transplant(_runs(window, 1), [fault], NOMINAL._replace(f_offset=offset))
    f = window.F.values[0]
    value = np.where(np.arange(300) >= 100, -0.4, 0.0)
    expected = np.clip(f - value * (f - offset), 0, 1)
    np.testing.assert_array_equal(out.F.values[0], expected)
    np.testing.assert_allclose(expected, np.clip(offset + (f - offset) * (1 - value), 0, 1))
    np.testing.assert_array_equal(out.X.values[0], window.X.values[0])


def test_a_transplant_onto_simulated_data_is_the_simulated_faulty_plant(hour):
    # the twin's parameters are the plant's: healthy + (faulty - nominal) = faulty
    inputs = hour.isel(time=slice(2000, 2300))
    true = NOMINAL._replace(kv=105.0, characteristic=5.2, backlash=0.015, x_offset=0.01)
    faults = [
        Fault(name, (-0.6 if name in SIGNED_FAULTS and name != "f4" else 0.6), onset=80.0)
        for name in FAULT_NAMES
    ] + [Fault("f17", 0.5, 50.0, "incipient", 150.0), Fault("f18", 0.8, 30.0, "incipient", 90.0)]
    n = len(faults)
    many = _runs(inputs, n)
    healthy = simulate(many, [None] * n, parameters=true, seed=11)
    for c in ("P1", "P2", "T1"):  # noise-free input readings: the plant's and the twin's inputs
        healthy[c] = many[c]
    direct = simulate(many, faults, parameters=true, seed=11)
    direct_clean = simulate(many, faults, parameters=true, noise=False)
    out = transplant(healthy, faults, true)
    for r, fault in enumerate(faults):
        tol = 1e-9
        if fault.name == "f19":  # the recorded flow's noise is scaled too
            tol = abs(fault.strength) * 6 * 0.0015
        for c in ("X", "F"):
            np.testing.assert_allclose(out[c].values[r], direct[c].values[r], atol=tol, err_msg=c)
        for c in ("P1", "P2", "T1"):
            np.testing.assert_allclose(out[c].values[r], direct_clean[c].values[r], atol=1e-12)


def test_transplant_refuses_what_it_cannot_do(hour):
    window = hour.isel(time=slice(0, 100))
    with pytest.raises(ValueError, match="one fault \\(or None\\) per run"):
        transplant(window, [None, None], NOMINAL)
    with pytest.raises(ValueError, match=r"MeasurementFault\.name must be one of"):
        transplant(window, [MeasurementFault("bias_Q", 0.1)], NOMINAL)
    with pytest.raises(ValueError, match=r"run 0: MeasurementFault\.strength must lie in"):
        transplant(window, [MeasurementFault("bias_X", 1.5)], NOMINAL)
    with pytest.raises(ValueError, match="got 2 parameter records for 1 runs"):
        transplant(window, [None], [NOMINAL, NOMINAL])


def test_the_measurement_fault_labels_are_valid_states_in_a_stated_order():
    ds = make_dataset({"X": np.zeros((2, 5))}, state=["bias_X", "f3"], onset=[1.0, 2.0])
    validate_dataset(ds, require=("X",))
    labels = ["bias_P1", "f10", "fn", "bias_X", "f2"]
    assert sorted(labels, key=state_order) == ["fn", "f2", "f10", "bias_X", "bias_P1"]
    assert not set(MEASUREMENT_FAULTS) & set(STATES)
    with pytest.raises(ValueError, match="unknown state label"):
        make_dataset({"X": np.zeros((1, 5))}, state="drift_Q")


def test_the_library_spreads_seeded_faults_over_the_recording(hour):
    lib = transplant_library(hour, NOMINAL, runs_per_fault=4, duration=300, seed=3)
    names = [*FAULT_NAMES, *MEASUREMENT_FAULTS]
    assert lib.sizes == {"run": 4 * len(names), "time": 300}
    assert list(lib.state.values) == [n for n in names for _ in range(4)]
    strength = np.abs(lib.strength.values)
    assert strength.min() >= 0.1 and strength.max() <= 1.0
    assert set(lib.profile.values) == {"abrupt", "incipient"}
    onset = lib.onset.values
    assert onset.min() >= 30.0 and onset.max() <= 150.0 and np.all(onset == np.round(onset))
    incipient = lib.profile.values == "incipient"
    assert np.all((lib.ramp.values[incipient] >= 60) & (lib.ramp.values[incipient] <= 600))
    # each fault's four windows come from the four quarters of the recording
    starts = np.asarray(lib.attrs["source_time"]).reshape(len(names), 4)
    quarter = (3600 - 300 + 1) / 4
    assert np.all(np.floor(starts / quarter) == np.arange(4))
    assert np.any(lib.strength.values < 0)  # signed faults take both signs
    again = transplant_library(hour, NOMINAL, runs_per_fault=4, duration=300, seed=3)
    other = transplant_library(hour, NOMINAL, runs_per_fault=4, duration=300, seed=4)
    for c in CHANNELS:
        np.testing.assert_array_equal(lib[c].values, again[c].values)
    assert not np.array_equal(lib.onset.values, other.onset.values)


def test_the_library_takes_each_profiles_strengths_from_every_slice_of_the_range(hour):
    """Stratified strengths: the abrupt and the incipient runs of a fault (of each
    sign, for a signed fault) fall one in each equal slice of the range, counted here from the
    strengths alone; the uniform draw is the plain ``uniform(low, high)`` of each run's stream,
    recomputed here; both share every other draw (windows, onsets, ramps)."""
    faults = ["f1", "f17", "bias_F"]
    low, high = 0.1, 1.0
    kw = {"faults": faults, "runs_per_fault": 12, "duration": 120}
    for seed in (0, 1):
        lib = transplant_library(hour, NOMINAL, seed=seed, strength_draw="stratified", **kw)
        uni = transplant_library(hour, NOMINAL, seed=seed, **kw)  # the default
        for name in ("onset", "ramp", "profile", "state"):
            np.testing.assert_array_equal(lib[name].values, uni[name].values)
        np.testing.assert_array_equal(lib.attrs["source_time"], uni.attrs["source_time"])
        np.testing.assert_array_equal(np.sign(lib.strength.values), np.sign(uni.strength.values))
        state, profile = lib.state.values.astype(str), lib.profile.values.astype(str)
        for i, fault in enumerate(faults):
            for kind in ("abrupt", "incipient"):
                for sign in (-1.0, 1.0):
                    cell = (state == fault) & (profile == kind)
                    if fault != "f1":  # signed faults: a cell per sign
                        cell &= np.sign(lib.strength.values) == sign
                    m = np.abs(lib.strength.values[cell])
                    n = m.size
                    assert n == (6 if fault == "f1" else 3)
                    assert sorted(np.floor((m - low) / (high - low) * n).astype(int)) == list(
                        range(n)
                    )
            for k in range(12):  # the uniform draw: each run's own stream, second number
                rng = np.random.default_rng([seed, i, k])
                rng.uniform()  # the window's draw
                expected = rng.uniform(low, high)
                assert abs(uni.strength.values[12 * i + k]) == expected
    with pytest.raises(ValueError, match="strength_draw must be one of"):
        transplant_library(hour, NOMINAL, strength_draw="latin", **kw)


def test_strength_slices_give_each_cell_a_permutation_of_its_slices():
    from bayes_fdi.twin.transplant import strength_slices

    rng = np.random.default_rng(5)
    for runs, signed in ((12, True), (12, False), (5, False), (1, True), (6, True)):
        out = strength_slices(runs, signed, rng)
        cells = {}
        for k, (j, n) in enumerate(out):
            cells.setdefault((k % 2, (1, -1, -1, 1)[k % 4] if signed else 1), []).append((j, n))
        for members in cells.values():
            assert sorted(j for j, _ in members) == list(range(len(members)))
            assert {n for _, n in members} == {len(members)}

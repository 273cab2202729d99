"""simulate / benchmark_inputs / inject_faults: API behaviour, inputs, noise and seeds."""

import numpy as np
import pytest
import xarray as xr

from bayes_fdi.actuator import (
    NOISE_STD,
    Fault,
    benchmark_inputs,
    inject_faults,
    simulate,
    simulate_replicas,
)
from bayes_fdi.datasets import make_dataset


def test_benchmark_inputs_are_dgen_closed_form():
    ds = benchmark_inputs(n_runs=2, duration=300)
    t = np.arange(300.0)
    np.testing.assert_allclose(ds.CV.values[1], 0.5 + 0.25 * np.sin(2 * np.pi * 0.01 * t))
    np.testing.assert_allclose(ds.P1.values[0] * 4e6, 3.5e6 + 175e3 * np.sin(2 * np.pi * 0.1 * t))
    np.testing.assert_allclose(ds.P2.values[0] * 4e6, 2.6e6 + 26e3 * np.sin(2.0 * t))
    np.testing.assert_allclose(ds.T1.values, 43.0 / 200.0)
    assert list(ds.state.values) == ["fn", "fn"]


def test_benchmark_inputs_variation_is_seeded_and_bounded():
    a = benchmark_inputs(n_runs=4, duration=200, vary=True, seed=5)
    b = benchmark_inputs(n_runs=4, duration=200, vary=True, seed=5)
    c = benchmark_inputs(n_runs=4, duration=200, vary=True, seed=6)
    xr.testing.assert_identical(a, b)
    assert not np.allclose(a.CV.values, c.CV.values)
    assert not np.allclose(a.CV.values[0], a.CV.values[1])
    amp = (a.CV.max("time") - a.CV.min("time")).values / 2
    assert np.all((amp <= 0.25 * 1.2 + 1e-12) & (amp >= 0.25 * 0.8 * 0.9))
    with pytest.raises(ValueError, match="n_runs"):
        benchmark_inputs(n_runs=0)
    with pytest.raises(ValueError, match="CV"):
        benchmark_inputs(cv_mean=0.9)


def test_simulate_returns_a_new_dataset_with_measured_channels():
    inputs = benchmark_inputs(n_runs=2, duration=100)
    before = inputs.copy(deep=True)
    ds = simulate(inputs, [None, Fault("f17", 0.5, onset=40.0)], seed=3)
    xr.testing.assert_identical(inputs, before)  # inputs not mutated
    assert set(ds.data_vars) == {"CV", "P1", "P2", "T1", "X", "F"}
    np.testing.assert_array_equal(ds.CV.values, inputs.CV.values)  # CV undisturbed
    assert list(ds.state.values) == ["fn", "f17"]
    assert ds.attrs["seed"] == 3 and ds.attrs["integrator"] == "fast"
    # measured P2' shows the f17 pressure change: P2 (1 - f) after onset, plus noise
    ratio = ds.P2.values[1, 45:] / inputs.P2.values[1, 45:]
    assert abs(ratio.mean() - 0.5) < 0.002
    noise = ds.P1.values[0] - inputs.P1.values[0]
    assert abs(noise.std() - NOISE_STD) < 0.25 * NOISE_STD


def test_f7_raises_measured_temperature_and_f19_scales_measured_flow():
    inputs = benchmark_inputs(n_runs=3, duration=120)
    faults = [None, Fault("f7", 0.5, onset=30.0), Fault("f19", -0.5, onset=30.0)]
    ds, states = simulate(inputs, faults, seed=0, noise=False, return_states=True)
    assert np.all(ds.T1.values[1, 30:] == 1.0)  # 43 + 200 + 50 C > 200 C full scale
    np.testing.assert_allclose(ds.T1.values[1, :30], 43.0 / 200.0)
    flow = states.F_true.values[2, 30:] / 40.0
    np.testing.assert_allclose(ds.F.values[2, 30:], np.clip(1.5 * flow, 0.0, 1.0), rtol=1e-12)


def test_faults_read_from_dataset_coordinates():
    base = benchmark_inputs(n_runs=3, duration=80)
    labelled = make_dataset(
        {c: base[c].values for c in ("CV", "P1", "P2", "T1")},
        state=["fn", "f16", "f18"],
        strength=[0.0, 0.75, 0.5],
        onset=[0.0, 20.0, 10.0],
        profile=["abrupt", "abrupt", "incipient"],
        ramp=[0.0, 0.0, 30.0],
    )
    explicit = [
        None,
        Fault("f16", 0.75, 20.0),
        Fault("f18", 0.5, 10.0, "incipient", 30.0),
    ]
    xr.testing.assert_equal(simulate(labelled, seed=2), simulate(base, explicit, seed=2))


def test_single_fault_applies_to_every_run():
    inputs = benchmark_inputs(n_runs=3, duration=60, vary=True)
    fault = Fault("f18", 0.4, onset=10.0)
    a = simulate(inputs, fault, seed=1)
    b = simulate(inputs, [fault] * 3, seed=1)
    xr.testing.assert_identical(a, b)
    assert list(a.state.values) == ["f18"] * 3


def test_incipient_fault_grows_along_its_ramp():
    inputs = benchmark_inputs(n_runs=2, duration=200)
    _, st = simulate(
        inputs,
        [None, Fault("f18", 1.0, onset=20.0, profile="incipient", ramp=100.0)],
        noise=False,
        return_states=True,
    )
    extra = st.F_true.values[1] - st.F_true.values[0]
    # the valve is untouched; the bypass adds Q_b = 100 Kv_b sqrt(dp[MPa] / rho) t/h with
    # Kv_b = 19.75 f(t), rho = 1000, unchoked here, f(t) the FGen ramp
    t = np.arange(200.0)
    f = np.clip((t - 20.0) / 100.0, 0.0, 1.0)
    dp = (inputs.P1.values[1] - inputs.P2.values[1]) * 4e6
    q_bypass = 100.0 * 19.75 * f * np.sqrt(dp / 1e6 / 1000.0)
    np.testing.assert_allclose(extra, q_bypass, rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(st.X_true.values[1], st.X_true.values[0])


def test_same_seed_same_data_and_noise_independent_of_the_batch():
    inputs = benchmark_inputs(n_runs=4, duration=60, vary=True, seed=2)
    a = simulate(inputs, seed=11)
    b = simulate(inputs, seed=11)
    c = simulate(inputs, seed=12)
    xr.testing.assert_identical(a, b)
    assert not np.array_equal(a.X.values, c.X.values)
    alone = simulate(inputs.isel(run=[2]), seed=11)
    np.testing.assert_array_equal(alone.X.values[0], a.X.values[2])
    np.testing.assert_array_equal(alone.F.values[0], a.F.values[2])


def test_replicas_equal_separate_simulations_also_on_the_rails():
    # f1 (clogging) and f10 big hold X and F on the rails for most of the run: there, adding
    # noise before the clip (simulate) and after a clip would differ, so equality checks that
    # the replicas add their noise to the unclipped outputs as simulate does.
    inputs = benchmark_inputs(n_runs=3, duration=200, vary=True, seed=5)
    faults = [None, Fault("f1", 1.0, 50.0), Fault("f10", 1.0, 50.0)]
    replicas = simulate_replicas(inputs, faults, seeds=[7, 8])
    for seed, got in zip([7, 8], replicas, strict=True):
        xr.testing.assert_identical(got, simulate(inputs, faults, seed=seed))
    with pytest.raises(ValueError, match="seed must be an integer"):
        simulate_replicas(inputs, faults, seeds=[-1])
    with pytest.raises(ValueError, match="at least one seed"):
        simulate_replicas(inputs, faults, seeds=[])


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda ds: ds.drop_vars("T1"), "T1"),
        (lambda ds: ds.assign(CV=ds.CV.where(ds.time != 5)), "NaN"),
        (lambda ds: ds.assign(CV=ds.CV * 3), "normalised"),
        (lambda ds: ds.assign(P2=ds.P1 + 0.01), "P1 < P2"),
        (lambda ds: ds.assign_coords(time=ds.time * 2), "1 Hz"),
    ],
)
def test_bad_inputs_raise_value_error(change, message):
    inputs = benchmark_inputs(n_runs=2, duration=30)
    with pytest.raises(ValueError, match=message):
        simulate(change(inputs))


def test_bad_arguments_raise_value_error():
    inputs = benchmark_inputs(n_runs=2, duration=30)
    with pytest.raises(ValueError, match="2 runs"):
        simulate(inputs, [None])
    with pytest.raises(ValueError, match="run 1"):
        simulate(inputs, [None, Fault("f1", 2.0)])
    with pytest.raises(ValueError, match="integrator"):
        simulate(inputs, integrator="euler")
    with pytest.raises(ValueError, match="seed"):
        simulate(inputs, seed=-1)


def test_inject_faults_adds_the_model_difference_to_the_record():
    inputs = benchmark_inputs(n_runs=3, duration=150, vary=True, seed=8)
    record = simulate(inputs, seed=5)  # stands in for a real noisy record
    faults = [None, Fault("f18", 0.5, onset=60.0), Fault("f17", 0.3, onset=60.0)]
    injected = inject_faults(record, faults)
    # the model is driven by the record's own (measured) inputs
    _, nominal = simulate(record, [None] * 3, noise=False, return_states=True)
    _, faulty = simulate(record, faults, noise=False, return_states=True)
    xr.testing.assert_equal(injected.isel(run=0), record.isel(run=0))
    for r in (1, 2):
        # before the onset the record is untouched
        for ch in ("X", "F", "P1", "P2", "T1"):
            np.testing.assert_array_equal(injected[ch].values[r, :60], record[ch].values[r, :60])
        # the unclipped model difference (the model's own 40 t/h saturation must not mask it)
        delta = (faulty.F_true.values[r] - nominal.F_true.values[r]) / 40.0
        expected = record.F.values[r] + delta
        np.testing.assert_allclose(injected.F.values[r], np.clip(expected, 0, 1), atol=1e-12)
    ratio = injected.P2.values[2, 70:].mean() / record.P2.values[2, 70:].mean()
    assert ratio == pytest.approx(0.7, rel=1e-3)
    assert list(injected.state.values) == ["fn", "f18", "f17"]


def test_progress_batches_give_the_same_data():
    # progress=True simulates in batches of 64 runs; the result must not depend on batching
    inputs = benchmark_inputs(n_runs=70, duration=20, vary=True, seed=9)
    faults = [None if r % 3 else Fault("f16", 0.6, onset=5.0) for r in range(70)]
    xr.testing.assert_identical(
        simulate(inputs, faults, seed=1, progress=True),
        simulate(inputs, faults, seed=1, progress=False),
    )

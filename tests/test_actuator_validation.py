"""Validation: fast vs reference integrator, fidelity to the real hour, fault signatures."""

import numpy as np
import pytest

from bayes_fdi.actuator import (
    FAULT_NAMES,
    NOISE_STD,
    Fault,
    benchmark_inputs,
    inject_faults,
    simulate,
)
from bayes_fdi.datasets.lublin import load_lublin_example

#: Mean change of X' / F' at strength 0.75 under DGen inputs over a 200 s window, from
#: the table of docs/damadics.md (measured on DABLib v1.22's model). f15: not measured there.
REFERENCE_SIGNATURES = {
    "f1": (-0.26, 0.36),
    "f2": (0.0, -0.25),
    "f3": (0.0, 0.11),
    "f4": (0.07, -0.09),
    "f5": (0.0, -0.01),
    "f6": (0.0, 0.32),
    "f7": (-0.22, 0.36),
    "f8": (0.0, 0.0),
    "f9": (-0.004, 0.005),
    "f10": (-0.09, 0.19),
    "f11": (0.01, -0.02),
    "f12": (-0.01, 0.02),
    "f13": (0.0, 0.36),
    "f14": (0.0, 0.0),
    "f16": (-0.08, 0.18),
    "f17": (-0.01, 0.12),
    "f18": (0.0, 0.36),
    "f19": (0.0, 0.13),
}
#: the benchmark's fault directions (-1 for f12, f14, f19)
DIRECTION = {"f12": -1.0, "f14": -1.0, "f19": -1.0}


def _rms(a, b):
    return float(np.sqrt(np.mean((np.asarray(a) - np.asarray(b)) ** 2)))


@pytest.fixture(scope="module")
def real_hour():
    return load_lublin_example()


@pytest.mark.parametrize("hold", ["linear", "zero"])
def test_fast_matches_reference_on_test_inputs_nominal_and_faults(hold):
    names = [None, "f1", "f2", "f3", "f6", "f7", "f10", "f16", "f17", "f18", "f19"]
    inputs = benchmark_inputs(n_runs=len(names), duration=350, vary=True, seed=4)
    faults = [None if n is None else Fault(n, 0.75 * DIRECTION.get(n, 1.0), 100.0) for n in names]
    fast = simulate(inputs, faults, noise=False, integrator="fast", hold=hold)
    ref = simulate(inputs, faults, noise=False, integrator="reference", hold=hold)
    for r, name in enumerate(names):
        for ch in ("X", "F"):
            err = _rms(fast[ch].values[r], ref[ch].values[r])
            assert err <= NOISE_STD, (name, ch, err)


def test_fast_is_within_the_reference_discretisation_error_on_sensitive_faults():
    # with smooth (linearly interpolated) inputs the positioner idles in its E/P dead zone,
    # where the stem position is only neutrally stable: any integration error persists. For
    # the faults that make the loop most sensitive (softer spring f11, E/P gain f12, stem
    # sensor f13 which also scales X' by up to 2.25) the fast path is compared with the
    # reference's own error, the change of the 2.5 ms RK4 when its step is halved
    from bayes_fdi.actuator.simulate import _check_inputs, _run_model

    names = ["f11", "f12", "f13"]
    inputs = benchmark_inputs(n_runs=3, duration=350, vary=True, seed=4)
    faults = [Fault(n, 0.75 * DIRECTION.get(n, 1.0), 100.0) for n in names]
    u = _check_inputs(inputs, who="test")
    kw = {"warmup": 30, "progress": False, "who": "test", "hold": "linear"}
    out = {}
    for key, integrator, steps in (
        ("fast", "fast", None),
        ("ref", "reference", None),
        ("ref_half_step", "reference", 800),
    ):
        raw, _ = _run_model(u, faults, integrator=integrator, steps=steps, **kw)
        out[key] = np.clip(raw, 0.0, 1.0)
    for r, name in enumerate(names):
        for c, ch in enumerate(("X", "F")):
            err = _rms(out["fast"][r, :, c], out["ref"][r, :, c])
            own = _rms(out["ref_half_step"][r, :, c], out["ref"][r, :, c])
            assert err <= max(NOISE_STD, 1.5 * own), (name, ch, err, own)


def test_fast_matches_reference_on_the_real_hour(real_hour):
    runs = real_hour.isel(time=slice(0, 1800))
    faults = [None, Fault("f16", 0.75, 600.0), Fault("f18", 0.5, 600.0), Fault("f17", 0.3, 600.0)]
    batch = runs.isel(run=[0, 0, 0, 0]).assign_coords(run=np.arange(4))
    fast = simulate(batch, faults, noise=False, integrator="fast")
    ref = simulate(batch, faults, noise=False, integrator="reference")
    assert fast.attrs["hold"] == "linear"
    for r in range(4):
        for ch in ("X", "F"):
            assert _rms(fast[ch].values[r], ref[ch].values[r]) <= NOISE_STD


@pytest.fixture(scope="module")
def large_play_effects():
    """Per-run mean changes of X', F' for f4 and f15 at 0.75 over 20 DGen phase variations."""
    n = 20
    inputs = benchmark_inputs(n_runs=3 * n, duration=350, vary=True, seed=1)
    faults = [None] * n + [Fault("f4", 0.75, 100.0)] * n + [Fault("f15", 0.75, 100.0)] * n
    w = slice(150, 350)
    out = {}
    for integrator in ("fast", "reference"):
        ds = simulate(inputs, faults, noise=False, integrator=integrator)
        for k, name in enumerate(("f4", "f15"), start=1):
            rows = slice(k * n, (k + 1) * n)
            out[integrator, name] = np.stack(
                [ds[ch].values[rows, w].mean(1) - ds[ch].values[:n, w].mean(1) for ch in "XF"], 1
            )
    return out


@pytest.mark.parametrize("name", ["f4", "f15"])
def test_large_play_faults_agree_in_distribution(large_play_effects, name):
    # f4 and f15 (big backlash) make the loop hunt; the hunting is not converged pointwise even
    # in the reference integrator (2.5 ms vs 1.25 ms steps differ by 0.04-0.1 RMS in X), so the
    # integrators are compared on the distribution of the window effects over input phases
    fast = large_play_effects["fast", name]
    ref = large_play_effects["reference", name]
    np.testing.assert_allclose(fast.mean(0), ref.mean(0), atol=0.01)
    np.testing.assert_allclose(fast.std(0), ref.std(0), atol=0.01)


def test_nominal_model_reproduces_the_real_hour(real_hour):
    """Fidelity to real plant data (Lublin Actuator 3, 11 Oct 2001, 1 h): X RMS <= 3 % and
    F RMS <= 6 % of range (measured: 2.0 % and 5.2 %)."""
    sim = simulate(real_hour, seed=0)
    x_err = _rms(sim.X.values, real_hour.X.values)
    f_err = _rms(sim.F.values, real_hour.F.values)
    assert x_err <= 0.03
    assert f_err <= 0.06
    # and far better than the trivial "X = CV" model (an independent baseline)
    assert x_err < 0.5 * _rms(real_hour.CV.values, real_hour.X.values)


def test_linear_hold_reconstructs_the_record_better_than_zero_order_hold(real_hour):
    # the samples of a record are values at instants: interpolating between them (as
    # Simulink's From Workspace does for DABLib) fits the plant better than holding them
    linear = simulate(real_hour, seed=0, hold="linear")
    zero = simulate(real_hour, seed=0, hold="zero")
    for ch in ("X", "F"):
        assert _rms(linear[ch].values, real_hour[ch].values) < 0.8 * _rms(
            zero[ch].values, real_hour[ch].values
        )


@pytest.fixture(scope="module")
def signatures():
    names = list(FAULT_NAMES)
    inputs = benchmark_inputs(n_runs=len(names) + 1, duration=350)
    faults = [None] + [Fault(n, 0.75 * DIRECTION.get(n, 1.0), onset=100.0) for n in names]
    ds = simulate(inputs, faults, seed=0)
    w = slice(150, 350)  # a 200 s window after the onset transient
    out = {}
    for i, name in enumerate(names, start=1):
        out[name] = tuple(
            float((ds[ch].values[i, w] - ds[ch].values[0, w]).mean()) for ch in ("X", "F")
        )
    return out


@pytest.mark.parametrize("name", sorted(REFERENCE_SIGNATURES, key=lambda n: int(n[1:])))
def test_fault_signature_matches_the_reference_table(signatures, name):
    dx, df = signatures[name]
    rx, rf = REFERENCE_SIGNATURES[name]
    if name == "f4":
        # friction makes the loop hunt with big spikes: a single window's mean depends on the
        # hunting's phase (test_f4_signature_over_input_phases checks the distribution)
        assert dx > 0.02 and df < 0
        return
    tol_x = 0.01 + 0.05 * abs(rx)
    tol_f = 0.01 + 0.05 * abs(rf)
    assert abs(dx - rx) <= tol_x, (dx, rx)
    assert abs(df - rf) <= tol_f, (df, rf)


def test_f4_signature_over_input_phases(large_play_effects):
    # over 20 phase variations the reference's single value (+0.07 / -0.09) lies within the
    # range of our per-run effects, and the mean effect has its sign
    effects = large_play_effects["fast", "f4"]
    rx, rf = REFERENCE_SIGNATURES["f4"]
    assert effects[:, 0].min() <= rx <= effects[:, 0].max()
    assert effects[:, 1].min() <= rf <= effects[:, 1].max()
    assert effects[:, 0].mean() > 0.02 and effects[:, 1].mean() < -0.02


def test_undetectable_faults_leave_the_outputs_unchanged(signatures):
    for name in ("f8", "f14"):
        assert max(abs(v) for v in signatures[name]) < 2e-3


def test_f15_loses_position_control(signatures):
    # f15 (not measured in the reference): a feedback play of 0.75 stroke leaves the
    # positioner blind to stem motion; the stem drifts closed and the flow collapses
    dx, df = signatures["f15"]
    assert dx > 0.2 and df < -0.3


def test_injected_faults_on_the_real_hour_move_x_and_f_as_the_table_says(real_hour):
    hour = real_hour.isel(time=slice(0, 900))
    batch = hour.isel(run=[0, 0, 0]).assign_coords(run=np.arange(3))
    faulty = inject_faults(batch, [None, Fault("f18", 0.75, 300.0), Fault("f16", 0.75, 300.0)])
    w = slice(400, 900)
    d_f18 = (faulty.F.values[1, w] - hour.F.values[0, w]).mean()
    assert d_f18 > 0.2  # bypass opened: more flow
    np.testing.assert_allclose(faulty.X.values[1], hour.X.values[0], atol=1e-12)
    assert (faulty.X.values[2, w] - hour.X.values[0, w]).mean() < -0.05  # supply drop: opens

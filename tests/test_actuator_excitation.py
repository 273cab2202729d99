"""The excitation families (bayes_fdi.actuator.excitation): seeded, in range, and what each
family promises (the sine frequencies, the held levels, the controller's integral action)."""

from __future__ import annotations

import numpy as np
import pytest

from bayes_fdi.actuator import simulate
from bayes_fdi.actuator.excitation import (
    LevelLoop,
    OperatingRange,
    level_loop_inputs,
    sine_sum_inputs,
    step_ramp_inputs,
)
from bayes_fdi.datasets import validate_dataset

GENERATORS = (sine_sum_inputs, step_ramp_inputs, level_loop_inputs)


@pytest.mark.parametrize("generate", GENERATORS)
def test_inputs_are_seeded_normalised_and_keep_p1_above_p2(generate):
    a = generate(3, 900, seed=4)
    b = generate(3, 900, seed=4)
    c = generate(3, 900, seed=5)
    validate_dataset(a, require=("CV", "P1", "P2", "T1"))
    for ch in ("CV", "P1", "P2", "T1"):
        np.testing.assert_array_equal(a[ch].values, b[ch].values)
        assert not np.array_equal(a[ch].values, c[ch].values)
        assert a[ch].values.min() >= 0.0 and a[ch].values.max() <= 1.0
    assert (a["P1"].values > a["P2"].values).all()
    # one run's inputs do not depend on how many runs are drawn
    np.testing.assert_array_equal(generate(1, 900, seed=4)["CV"].values[0], a["CV"].values[0])
    assert a.attrs["generator"] in ("sine-sum", "step-ramp", "level-loop")


def test_operating_points_are_drawn_inside_their_range():
    op = OperatingRange(
        p1=(3.0e6, 3.2e6),
        dp=(0.5e6, 0.6e6),
        t1=(50.0, 60.0),
        p1_drift=0.0,
        p2_drift=0.0,
        t1_drift=0.0,
        p1_noise=0.0,
        p2_noise=0.0,
        t1_noise=0.0,
    )
    ds = sine_sum_inputs(20, 50, seed=1, operating=op)
    p1, p2, t1 = ds["P1"].values * 4e6, ds["P2"].values * 4e6, ds["T1"].values * 200.0
    assert np.ptp(p1, axis=1).max() == 0.0  # no drift, no noise: constant levels
    assert p1.min() >= 3.0e6 and p1.max() <= 3.2e6
    assert (p1 - p2).min() >= 0.5e6 - 1e-6 and (p1 - p2).max() <= 0.6e6 + 1e-6
    assert t1.min() >= 50.0 and t1.max() <= 60.0


def test_sine_sum_puts_its_power_at_the_drawn_frequencies():
    ds = sine_sum_inputs(
        4,
        4000,
        seed=2,
        n_sines=1,
        frequencies=(0.01, 0.04),
        cv_amplitude=(0.1, 0.1),
        cv_mean=(0.5, 0.5),
    )
    for cv in ds["CV"].values:
        spectrum = np.abs(np.fft.rfft(cv - cv.mean())) ** 2
        freq = np.fft.rfftfreq(cv.size)
        peak = freq[np.argmax(spectrum)]
        assert 0.01 - 1 / 4000 <= peak <= 0.04 + 1 / 4000
        # one sine of amplitude 0.1: the whole variance (0.1^2 / 2) at the peak's bins
        assert np.var(cv) == pytest.approx(0.005, rel=0.02)


def test_sine_sum_p1_oscillates_with_the_drawn_sines_and_keeps_the_rest_of_the_run():
    """P1's oscillation is added to the run without it: CV, P2, T1 unchanged where the drop
    allows, the added part a sine of the drawn amplitude at a frequency in the band, P1 and the
    drop kept in their limits."""
    op = OperatingRange(
        p1=(3.0e6, 3.0e6), dp=(0.3e6, 0.3e6), p1_drift=0.0, p2_drift=0.0, p1_noise=0.0,
        p2_noise=0.0,
    )  # fmt: skip
    kw = dict(n_sines=1, frequencies=(0.01, 0.04), operating=op)
    still = sine_sum_inputs(4, 4000, seed=6, **kw)
    moving = sine_sum_inputs(4, 4000, seed=6, p1_amplitude=(0.2e6, 0.2e6), **kw)
    for ch in ("CV", "P2", "T1"):
        np.testing.assert_array_equal(moving[ch].values, still[ch].values)
    added = (moving["P1"].values - still["P1"].values) * 4e6
    for wave in added:
        spectrum = np.abs(np.fft.rfft(wave)) ** 2
        peak = np.fft.rfftfreq(wave.size)[np.argmax(spectrum)]
        assert 0.01 - 1 / 4000 <= peak <= 0.04 + 1 / 4000
        # one sine of amplitude 0.2 MPa (P1 at 3 MPa stays far from its limits): its variance
        # is 0.2^2 / 2 MPa^2, up to the leakage of a non-integer number of periods
        assert np.var(wave) == pytest.approx(0.02e12, rel=0.02)
    assert moving.attrs["excitation_p1_high"] == 0.2e6 and "excitation_p1_high" not in still.attrs
    # the drop of 0.3 MPa swings by 0.2 MPa and stays above its 0.05 MPa floor; P1 in range
    drop = (moving["P1"].values - moving["P2"].values) * 4e6
    # (sampled at 1 Hz over tens of periods, some second falls within 2 % of the trough)
    assert drop.min() == pytest.approx(0.1e6, rel=0.02) and drop.max() <= 0.5e6 + 1.0
    low = sine_sum_inputs(2, 2000, seed=7, p1_amplitude=(0.9e6, 0.9e6), operating=op)
    p1, p2 = low["P1"].values * 4e6, low["P2"].values * 4e6
    assert (p1 - p2).min() >= 0.05e6 - 1e-3 and p1.min() >= 0.2e6 and p1.max() <= 3.98e6


def test_step_ramp_holds_levels_for_at_least_the_shortest_hold():
    ds = step_ramp_inputs(3, 3000, seed=3, hold_seconds=(50, 100), ramp_share=0.0)
    for cv in ds["CV"].values:
        changes = np.flatnonzero(np.diff(cv) != 0)
        assert changes.size >= 3029 // 100 - 1
        assert np.diff(changes).min() >= 50  # every level is held >= 50 s (steps only)
        assert cv.min() >= 0.35 and cv.max() <= 0.9


@pytest.mark.parametrize("characteristic, kv_ratio", [(5.0, 1.0), (3.6, 0.75), (6.2, 1.3)])
def test_level_loop_integral_action_holds_the_level_at_the_set_point(characteristic, kv_ratio):
    """With a constant set-point and demand the PI loop settles: the level's mean equals the
    set-point and the CV equals the opening that balances inflow and demand (r exp(-n X) = d /
    sqrt(dp / dp_nominal) for the valve's equal-percentage law of exponent n and Kv ratio r)."""
    loop = LevelLoop(
        characteristic=characteristic,
        kv_ratio=kv_ratio,
        kp=(2.0, 2.0),
        ti=(60.0, 60.0),
        level_noise=(0.0, 0.0),
        setpoint=(0.5, 0.5),
        demand=(0.05, 0.05),
        demand_drift=0.0,
        setpoint_hold=(1e6, 1e6),
    )
    op = OperatingRange(dp=(0.9e6, 0.9e6), p1_drift=0.0, p2_drift=0.0, p1_noise=0.0, p2_noise=0.0)
    ds = level_loop_inputs(2, 3000, seed=1, loop=loop, operating=op)
    tail = slice(2000, None)
    np.testing.assert_allclose(ds["level"].values[:, tail], 0.5, atol=1e-6)
    balance = -np.log(0.05 / kv_ratio) / characteristic
    np.testing.assert_allclose(ds["CV"].values[:, tail], balance, atol=1e-6)


def test_the_actuator_model_runs_on_every_family():
    for generate in GENERATORS:
        runs = simulate(generate(2, 300, seed=1)[["CV", "P1", "P2", "T1"]], seed=1)
        assert np.isfinite(runs["X"].values).all() and np.isfinite(runs["F"].values).all()


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: sine_sum_inputs(0, 10), "n_runs"),
        (lambda: sine_sum_inputs(1, 10, frequencies=(0.1, 0.01)), "frequencies"),
        (lambda: sine_sum_inputs(1, 10, p1_amplitude=(-1.0, 1.0)), "p1_amplitude"),
        (lambda: step_ramp_inputs(1, 10, ramp_share=2.0), "ramp_share"),
        (lambda: level_loop_inputs(1, 10, loop=LevelLoop(kp=(-1.0, 1.0))), "loop.kp"),
        (lambda: level_loop_inputs(1, 10, loop=LevelLoop(kv_ratio=0.0)), "loop.kv_ratio"),
    ],
)
def test_bad_arguments_are_named(call, message):
    with pytest.raises(ValueError, match=message):
        call()

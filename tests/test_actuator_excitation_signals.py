"""The further excitation families (bayes_fdi.actuator.excitation_signals): seeded, in range,
and what each family claims (the telegraph's two levels on a clock, the chirp's sweep and P1
sine, the flow loop holding the flow against the P1 steps)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bayes_fdi.actuator import flow_rate, simulate
from bayes_fdi.actuator.excitation import OperatingRange
from bayes_fdi.actuator.excitation_signals import (
    SIGNAL_FAMILIES,
    chirp_inputs,
    flow_loop_inputs,
    telegraph_inputs,
)
from bayes_fdi.datasets import validate_dataset

GENERATORS = (telegraph_inputs, chirp_inputs, flow_loop_inputs)
STILL = OperatingRange(p1_noise=0.0, p2_noise=0.0, t1_noise=0.0)


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
    assert a.attrs["generator"] in SIGNAL_FAMILIES
    # the operating levels lie in the default operating range (the training campaigns' too)
    p1 = a["P1"].values * 4e6
    assert 2.5e6 - 0.2e6 < p1.min() and p1.max() < 3.7e6 + 0.2e6


def test_telegraph_takes_two_levels_switching_only_on_its_clock():
    ds = telegraph_inputs(
        4, 6000, seed=2, clock_seconds=(5, 5), cv_mean=(0.6, 0.6), cv_amplitude=(0.1, 0.1)
    )
    for cv in ds["CV"].values:
        np.testing.assert_allclose(np.unique(cv), [0.5, 0.7])
        switches = np.flatnonzero(np.diff(cv) != 0) + 1
        assert (switches % 5 == 0).all()  # only on the 5-s clock's ticks
        # a fair coin at each of the 1199 ticks: the share of switches is 0.5 +- 4.5 sigma
        share = switches.size / 1199
        assert abs(share - 0.5) < 4.5 * math.sqrt(0.25 / 1199)


def test_chirp_sweeps_its_band_and_p1_is_a_sine_at_its_frequency():
    ds = chirp_inputs(
        2, 4000, seed=3, frequencies=(0.01, 0.1), sweep_seconds=(1000, 1000),
        cv_mean=(0.6, 0.6), cv_amplitude=(0.2, 0.2), operating=STILL,
    )  # fmt: skip
    for r in range(2):
        centred = ds["CV"].values[r] - 0.6

        def crossing_rate(lo, hi, centred=centred):
            """Frequency (Hz) from the sign changes in [lo, hi) s."""
            signs = np.signbit(centred[lo:hi])
            return np.count_nonzero(signs[1:] != signs[:-1]) / (2.0 * (hi - lo))

        # the frequency at time t is 0.01 * 10 ** (1 - |t / 1000 mod 2 - 1|)
        assert 0.009 < crossing_rate(0, 200) < 0.0165  # 0.0100 .. 0.0158 Hz
        assert 0.075 < crossing_rate(900, 1100) < 0.1  # 0.079 .. 0.100 Hz
        assert 0.009 < crossing_rate(1800, 2200) < 0.0165  # down again, and up
        p1 = ds["P1"].values[r] - ds["P1"].values[r].mean()
        spectrum = np.abs(np.fft.rfft(p1)) ** 2
        assert np.fft.rfftfreq(p1.size)[np.argmax(spectrum)] == pytest.approx(0.05)
        # all of P1's motion is that sine (no noise asked): amplitude in [100, 200] kPa
        amplitude = math.sqrt(2.0 * np.var(p1)) * 4e6
        assert 100e3 * 0.98 < amplitude < 200e3 * 1.02


def test_flow_loop_holds_the_flow_against_the_p1_steps():
    """The valve's static flow with the stem lagging CV, computed here again from the dataset:
    under a constant set-point the loop keeps the flow steady through the P1 steps, where the
    same valve held at CV's mean would let the flow follow them."""
    ds = flow_loop_inputs(
        3, 3000, seed=5, kp=(0.1, 0.1), ti=(8.0, 8.0), setpoint_hold=(1e6, 1e6),
        p1_step=(0.3e6, 0.3e6), p1_hold=(100, 200), flow_noise=0.0, operating=STILL,
    )  # fmt: skip
    p1, p2, t1 = ds["P1"].values * 4e6, ds["P2"].values * 4e6, ds["T1"].values * 200
    cv = ds["CV"].values
    x = np.empty_like(cv)
    a = math.exp(-1.0 / 2.0)
    x[:, 0] = 0.6
    for k in range(1, cv.shape[1]):
        x[:, k] = a * x[:, k - 1] + (1 - a) * cv[:, k - 1]
    tail = slice(500, None)
    closed = np.log(flow_rate(x, p1, p2, t1))[:, tail]
    held = np.log(flow_rate(cv.mean(axis=1, keepdims=True), p1, p2, t1))[:, tail]
    assert np.ptp(p1[:, tail], axis=1).min() > 0.2e6  # the P1 steps happen

    def spread(log_flow):
        return np.median(np.abs(log_flow - np.median(log_flow, axis=1, keepdims=True)), axis=1)

    assert (spread(closed) < 0.1 * spread(held)).all()
    # the controller closes the valve (CV up) when P1 rises
    assert all(np.corrcoef(c[tail], p[tail])[0, 1] > 0.8 for c, p in zip(cv, p1, strict=True))


def test_the_actuator_model_runs_on_every_family():
    for generate in GENERATORS:
        runs = simulate(generate(2, 300, seed=1)[["CV", "P1", "P2", "T1"]], seed=1)
        assert np.isfinite(runs["X"].values).all() and np.isfinite(runs["F"].values).all()


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: telegraph_inputs(0, 10), "n_runs"),
        (lambda: telegraph_inputs(1, 10, cv_mean=(0.9, 0.95)), "cv_mean ± cv_amplitude"),
        (lambda: chirp_inputs(1, 10, frequencies=(0.0, 0.1)), "frequencies must satisfy"),
        (lambda: chirp_inputs(1, 10, p1_frequency=0.7), "p1_frequency"),
        (lambda: flow_loop_inputs(1, 10, ti=(0.5, 2.0)), "ti must satisfy"),
        (lambda: flow_loop_inputs(1, 10, flow_noise=-1.0), "flow_noise"),
    ],
)
def test_bad_arguments_are_named(call, message):
    with pytest.raises(ValueError, match=message):
        call()

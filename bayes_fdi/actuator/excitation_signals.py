"""Further excitation families: a random telegraph command, a chirp, a PI flow loop.

They complement the families of `bayes_fdi.actuator.excitation` (sums of sines, steps and ramps,
a PI level loop) with shapes those do not contain; the benchmark's shift test
(``sim/benchmark-shift.toml``) drives the actuator with them to see how a diagnoser trained on
other excitations copes. Each gives the same dataset type (1 Hz, normalised ``CV, P1, P2, T1``,
state ``"fn"``), seeded per run (``numpy.random.default_rng([seed, family, run])``, the family
index in :data:`SIGNAL_FAMILIES`), so a run does not depend on how many runs are drawn:

`telegraph_inputs`
    CV a pseudo-random binary command: two levels, a clock of a few seconds, at each tick the
    next level drawn at random (a PRBS-like test signal: a flat spectrum up to about the clock
    rate, fast steps both ways). P1, P2 and T1 held at drawn levels with fast fluctuations.
`chirp_inputs`
    CV a sine whose frequency sweeps log-linearly up and down a band, P1 a sine at a fixed
    frequency (0.05 Hz by default) around a drawn level.
`flow_loop_inputs`
    CV the output of a fast PI flow controller that holds the valve's flow at a set-point
    changed in steps, against step disturbances of the inlet pressure P1: a loop whose
    controller moves CV against P1. The loop uses the model's static flow law
    (`bayes_fdi.actuator.flow_rate`, nominal valve) and the stem as a first-order lag behind
    CV; the CV it produces is then an input of the actuator model like any other (the loop is
    open at a fault).

Operating points are drawn from the same `~bayes_fdi.actuator.excitation.OperatingRange` as the
other families (levels only; the motion around them is each family's own).

Written by hand: no maintained library generates control-loop excitation for this model.
"""

from __future__ import annotations

import math

import numpy as np
import xarray as xr

from bayes_fdi.actuator.excitation import (
    DEFAULT_OPERATING,
    P_RANGE,
    T_RANGE,
    OperatingRange,
    check_band,
    check_run_shape,
    excitation_dataset,
)
from bayes_fdi.actuator.valve import flow_rate

__all__ = ["SIGNAL_FAMILIES", "chirp_inputs", "flow_loop_inputs", "telegraph_inputs"]

#: Family names (the attribute ``generator`` of the datasets) and their seed stream index.
SIGNAL_FAMILIES: dict[str, int] = {"telegraph": 11, "chirp": 12, "flow-loop": 13}


def _levels(rng: np.random.Generator, n: int, op: OperatingRange) -> dict[str, np.ndarray]:
    """P1, P2 [Pa] and T1 [°C] held at levels drawn in ``op``, with its fast fluctuations."""
    p1, dp, t1 = rng.uniform(*op.p1), rng.uniform(*op.dp), rng.uniform(*op.t1)
    return {
        "P1": p1 + rng.standard_normal(n) * op.p1_noise,
        "P2": (p1 - dp) + rng.standard_normal(n) * op.p2_noise,
        "T1": t1 + rng.standard_normal(n) * op.t1_noise,
    }


def _dataset(cv: np.ndarray, points: list[dict], family: str, seed: int, attrs: dict):
    """`excitation_dataset` of the runs, their P1, P2, T1 kept within the sensors' ranges."""
    for p in points:
        p["P1"] = np.clip(p["P1"], 0.05 * P_RANGE, 0.995 * P_RANGE)
        p["P2"] = np.clip(np.minimum(p["P2"], p["P1"] - 0.05e6), 0.04e6, None)
        p["T1"] = np.clip(p["T1"], 1.0, 0.99 * T_RANGE)
    return excitation_dataset(cv, points, family, seed, attrs)


def telegraph_inputs(
    n_runs: int = 1,
    duration: int = 3600,
    *,
    seed: int = 0,
    clock_seconds: tuple[float, float] = (3.0, 12.0),
    cv_mean: tuple[float, float] = (0.5, 0.7),
    cv_amplitude: tuple[float, float] = (0.05, 0.15),
    operating: OperatingRange = DEFAULT_OPERATING,
) -> xr.Dataset:
    """CV a pseudo-random binary command: ``mean ± amplitude``, the level redrawn at random (a
    fair coin) at every tick of a clock.

    Each run draws its clock period (whole seconds) in ``clock_seconds``, its mean in
    ``cv_mean`` and its half-swing in ``cv_amplitude``; so CV takes exactly two values, changes
    only on the clock's ticks, and switches at about half of them.
    """
    who = "telegraph_inputs"
    n_runs, duration = check_run_shape(n_runs, duration, who)
    c_lo, c_hi = check_band(clock_seconds, "clock_seconds", who, 1.0, 1e6)
    m_lo, m_hi = check_band(cv_mean, "cv_mean", who, 0.0, 1.0)
    a_lo, a_hi = check_band(cv_amplitude, "cv_amplitude", who, 0.0, 0.5)
    if m_lo - a_hi < 0.0 or m_hi + a_hi > 1.0:
        raise ValueError(f"{who}: cv_mean ± cv_amplitude must stay within [0, 1]")
    cv = np.empty((n_runs, duration))
    points = []
    for r in range(n_runs):
        rng = np.random.default_rng([int(seed), SIGNAL_FAMILIES["telegraph"], r])
        clock = max(1, round(rng.uniform(c_lo, c_hi)))
        mean, swing = rng.uniform(m_lo, m_hi), rng.uniform(a_lo, a_hi)
        bits = rng.integers(0, 2, -(-duration // clock))
        cv[r] = (mean + swing * (2.0 * bits - 1.0)).repeat(clock)[:duration]
        points.append(_levels(rng, duration, operating))
    attrs = {"clock_low": c_lo, "clock_high": c_hi}
    return _dataset(cv, points, "telegraph", int(seed), attrs)


def chirp_inputs(
    n_runs: int = 1,
    duration: int = 3600,
    *,
    seed: int = 0,
    frequencies: tuple[float, float] = (0.004, 0.08),
    sweep_seconds: tuple[float, float] = (300.0, 900.0),
    cv_mean: tuple[float, float] = (0.5, 0.7),
    cv_amplitude: tuple[float, float] = (0.1, 0.2),
    p1_frequency: float = 0.05,
    p1_amplitude: tuple[float, float] = (100e3, 200e3),
    operating: OperatingRange = DEFAULT_OPERATING,
) -> xr.Dataset:
    """CV a sine whose frequency sweeps log-linearly from the low to the high end of
    ``frequencies`` (Hz) in ``sweep_seconds`` and back, over and over (the phase stays
    continuous); P1 a sine at ``p1_frequency`` (Hz) of amplitude drawn in ``p1_amplitude`` (Pa)
    around its drawn level. Each run draws its sweep time, CV mean, CV amplitude, P1 amplitude
    and the phases; CV is clipped to [0.02, 0.98].
    """
    who = "chirp_inputs"
    n_runs, duration = check_run_shape(n_runs, duration, who)
    f_lo, f_hi = check_band(frequencies, "frequencies", who, 1e-5, 0.25)
    s_lo, s_hi = check_band(sweep_seconds, "sweep_seconds", who, 2.0, 1e7)
    m_lo, m_hi = check_band(cv_mean, "cv_mean", who, 0.0, 1.0)
    a_lo, a_hi = check_band(cv_amplitude, "cv_amplitude", who, 0.0, 0.5)
    p_lo, p_hi = check_band(p1_amplitude, "p1_amplitude", who, 0.0, 1e6)
    if not (math.isfinite(p1_frequency) and 0.0 <= p1_frequency <= 0.5):
        raise ValueError(f"{who}: p1_frequency must lie in [0, 0.5] Hz, got {p1_frequency!r}")
    t = np.arange(duration, dtype=np.float64)
    cv = np.empty((n_runs, duration))
    points = []
    for r in range(n_runs):
        rng = np.random.default_rng([int(seed), SIGNAL_FAMILIES["chirp"], r])
        sweep = rng.uniform(s_lo, s_hi)
        up_down = 1.0 - np.abs(((t / sweep) % 2.0) - 1.0)  # 0 -> 1 -> 0 over two sweeps
        frequency = f_lo * (f_hi / f_lo) ** up_down
        phase = rng.uniform(0.0, 2 * np.pi) + 2 * np.pi * np.concatenate(
            ([0.0], np.cumsum(frequency[:-1]))
        )
        cv[r] = np.clip(rng.uniform(m_lo, m_hi) + rng.uniform(a_lo, a_hi) * np.sin(phase), 0.02,
                        0.98)  # fmt: skip
        point = _levels(rng, duration, operating)
        p1_phase = rng.uniform(0.0, 2 * np.pi)
        point["P1"] = point["P1"] + rng.uniform(p_lo, p_hi) * np.sin(
            2 * np.pi * p1_frequency * t + p1_phase
        )
        points.append(point)
    attrs = {"f_low": f_lo, "f_high": f_hi, "p1_frequency": float(p1_frequency)}
    return _dataset(cv, points, "chirp", int(seed), attrs)


def _steps(
    rng: np.random.Generator, n: int, hold: tuple[float, float], values: tuple[float, float]
) -> np.ndarray:
    """A signal held at values drawn uniformly in ``values`` for times drawn in ``hold`` (s)."""
    out = np.empty(n)
    t = 0
    while t < n:
        length = max(1, round(rng.uniform(*hold)))
        out[t : t + length] = rng.uniform(*values)
        t += length
    return out


def flow_loop_inputs(
    n_runs: int = 1,
    duration: int = 3600,
    *,
    seed: int = 0,
    kp: tuple[float, float] = (0.05, 0.15),
    ti: tuple[float, float] = (4.0, 15.0),
    setpoint_cv: tuple[float, float] = (0.4, 0.8),
    setpoint_hold: tuple[float, float] = (60.0, 600.0),
    p1_step: tuple[float, float] = (0.1e6, 0.35e6),
    p1_hold: tuple[float, float] = (30.0, 300.0),
    flow_noise: float = 0.01,
    positioner_seconds: float = 2.0,
    operating: OperatingRange = DEFAULT_OPERATING,
) -> xr.Dataset:
    """CV of a fast PI flow loop against steps of the inlet pressure (module docstring).

    The flow set-point is the static flow at a CV drawn in ``setpoint_cv`` at the run's level
    pressures, redrawn every ``setpoint_hold`` s. P1 jumps to its level plus a value drawn
    uniformly within ± the run's ``p1_step`` every ``p1_hold`` s (kept 0.1 MPa above P2 and
    inside ``operating.p1``). The controller acts on the logarithm of the flow (the valve is
    equal-percentage), gain ``kp`` (CV per unit of log-flow error) and integral time ``ti``
    (s), with a relative flow measurement noise ``flow_noise``; CV is clipped to [0, 1] with
    anti-windup.
    """
    who = "flow_loop_inputs"
    n_runs, duration = check_run_shape(n_runs, duration, who)
    names = ("kp", "ti", "setpoint_cv", "setpoint_hold", "p1_step", "p1_hold")
    bands = dict(zip(names, (kp, ti, setpoint_cv, setpoint_hold, p1_step, p1_hold), strict=True))
    limits = {"setpoint_cv": (0.0, 1.0), "ti": (1.0, 1e6), "setpoint_hold": (1.0, 1e7),
              "p1_hold": (1.0, 1e7), "kp": (0.0, 10.0), "p1_step": (0.0, 2e6)}  # fmt: skip
    b = {k: check_band(v, k, who, *limits[k]) for k, v in bands.items()}
    if not (math.isfinite(flow_noise) and 0.0 <= flow_noise < 0.5):
        raise ValueError(f"{who}: flow_noise must lie in [0, 0.5), got {flow_noise!r}")
    if not (math.isfinite(positioner_seconds) and positioner_seconds > 0):
        raise ValueError(f"{who}: positioner_seconds must be > 0, got {positioner_seconds!r}")
    rngs = [np.random.default_rng([int(seed), SIGNAL_FAMILIES["flow-loop"], r])
            for r in range(n_runs)]  # fmt: skip
    points, setpoint, gains = [], np.empty((n_runs, duration)), np.empty((n_runs, 2))
    for r, rng in enumerate(rngs):
        point = _levels(rng, duration, operating)
        p1_level, p2_level = float(point["P1"].mean()), float(point["P2"].mean())
        step = rng.uniform(*b["p1_step"])
        low, high = max(operating.p1[0], p2_level + 0.1e6), operating.p1[1]
        p1_steps = _steps(rng, duration, b["p1_hold"], (-step, step))
        point["P1"] = np.clip(point["P1"] + p1_steps, low, max(low, high))
        t1_level = float(point["T1"].mean())
        sp_cv = _steps(rng, duration, b["setpoint_hold"], b["setpoint_cv"])
        setpoint[r] = np.log(flow_rate(sp_cv, p1_level, p2_level, t1_level))
        gains[r] = rng.uniform(*b["kp"]), rng.uniform(*b["ti"])
        points.append(point)
    noise = np.stack([rng.standard_normal(duration) for rng in rngs]) * flow_noise
    cv = _run_flow_loop(points, setpoint, gains, noise, positioner_seconds)
    attrs = {"kp_low": b["kp"][0], "kp_high": b["kp"][1], "ti_low": b["ti"][0]}
    return _dataset(cv, points, "flow-loop", int(seed), attrs)


def _run_flow_loop(points, setpoint, gains, noise, positioner_seconds) -> np.ndarray:
    """The PI flow loop over time, vectorised over the runs; returns CV (runs, time)."""
    n_runs, duration = setpoint.shape
    p1, p2, t1 = (np.stack([p[c] for p in points]) for c in ("P1", "P2", "T1"))
    kp, ti = gains[:, 0], gains[:, 1]
    a_pos = math.exp(-1.0 / positioner_seconds)
    x = np.full(n_runs, 0.6)  # a few steps of bumpless settling follow from the integral
    integral = x / kp * ti
    cv = np.empty((n_runs, duration))
    for k in range(duration):
        flow = flow_rate(x, p1[:, k], np.minimum(p2[:, k], p1[:, k] - 0.05e6), t1[:, k])
        error = np.log(np.maximum(flow, 1e-6)) + noise[:, k] - setpoint[:, k]  # high: close
        out = kp * (error + integral / ti)
        cv[:, k] = np.clip(out, 0.0, 1.0)
        integral += np.where(cv[:, k] == out, error, 0.0)  # anti-windup
        x = a_pos * x + (1.0 - a_pos) * cv[:, k]
    return cv

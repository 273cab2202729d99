"""Inputs of other shapes than DGen's sines: the excitation families a real valve sees.

The benchmark's generator (`bayes_fdi.actuator.benchmark_inputs`) drives the actuator with one
sine per input; a valve in a plant is driven by a controller. These generators give the same
dataset type (1 Hz, normalised ``CV, P1, P2, T1``, state ``"fn"``) for other excitations, each
seeded per run (``numpy.random.default_rng([seed, family, run])``):

`sine_sum_inputs`
    CV a sum of sines with frequencies drawn log-uniformly in a band and random amplitudes.
`step_ramp_inputs`
    CV held at random levels for random times, moving between them by steps or ramps.
`level_loop_inputs`
    CV the output of a PI level controller of a tank whose inflow the valve sets, with set-point
    changes and a drifting outflow demand: the excitation of a level loop such as the Lublin
    boiler feed-water valve. The loop is simulated with a static flow law of the valve
    (equal-percentage characteristic, nominal unless `LevelLoop` gives the valve's exponent
    and Kv ratio; the positioner as a first-order lag); the CV it produces
    is then an input of the actuator model like any other, so a fault changes the valve but not
    the controller's reaction to it (the loop is open at the fault).

The operating point (P1, P2, T1) of every run is drawn from `OperatingRange` and moves slowly
(an Ornstein-Uhlenbeck drift of the levels plus small fast fluctuations), so that P1 > P2 and
the values stay within the normalised range.

Written by hand: no maintained library generates control-loop excitation for this model.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
import xarray as xr

from bayes_fdi.datasets import make_dataset
from bayes_fdi.memory import check_memory

__all__ = [
    "FAMILIES",
    "P_RANGE",
    "T_RANGE",
    "LevelLoop",
    "OperatingRange",
    "check_band",
    "check_count",
    "check_run_shape",
    "excitation_dataset",
    "level_loop_inputs",
    "sine_sum_inputs",
    "step_ramp_inputs",
]

#: Family names (the attribute ``generator`` of the datasets) and their seed stream index.
FAMILIES: dict[str, int] = {"sine-sum": 1, "step-ramp": 2, "level-loop": 3}
#: float64 values held per (run, second) at the peak of a generator.
_VALUES_PER_SAMPLE = 16
P_RANGE = 4e6  #: full scale of P1', P2' [Pa]
T_RANGE = 200.0  #: full scale of T1' [°C]


class OperatingRange(NamedTuple):
    """Where the operating point of a run is drawn (uniformly) and how much it moves.

    Pressures in Pa, temperature in °C; ``*_drift`` are the standard deviations of the slow
    Ornstein-Uhlenbeck drift of each level (time constant ``drift_seconds``), ``*_noise`` those
    of its fast fluctuation (white, held for one second).
    """

    p1: tuple[float, float] = (2.5e6, 3.7e6)
    dp: tuple[float, float] = (0.3e6, 1.2e6)  #: P1 - P2
    t1: tuple[float, float] = (20.0, 110.0)
    p1_drift: float = 60e3
    p2_drift: float = 30e3
    t1_drift: float = 2.0
    p1_noise: float = 15e3
    p2_noise: float = 8e3
    t1_noise: float = 0.1
    drift_seconds: float = 300.0


#: The default operating range of every generator.
DEFAULT_OPERATING = OperatingRange()


def check_count(value: Any, name: str, who: str) -> int:
    """``value`` as an integer >= 1, else a ValueError naming ``who`` and ``name``."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise ValueError(f"{who}: {name} must be an integer >= 1, got {value!r}")
    return int(value)


def check_band(band: Any, name: str, who: str, low: float, high: float) -> tuple[float, float]:
    """``band`` as a pair ``(a, b)`` with ``low <= a <= b <= high``, else a ValueError."""
    try:
        a, b = (float(v) for v in band)
    except (TypeError, ValueError):
        raise ValueError(f"{who}: {name} must be a pair (low, high), got {band!r}") from None
    if not (math.isfinite(a) and math.isfinite(b) and low <= a <= b <= high):
        raise ValueError(f"{who}: {name} must satisfy {low} <= low <= high <= {high}, got {band}")
    return a, b


def _ou(rng: np.random.Generator, n: int, std: float, tau: float) -> np.ndarray:
    """A stationary Ornstein-Uhlenbeck path of ``n`` seconds (standard deviation ``std``)."""
    a = math.exp(-1.0 / tau)
    e = rng.standard_normal(n) * std * math.sqrt(1.0 - a * a)
    x = np.empty(n)
    x[0] = rng.standard_normal() * std
    for t in range(1, n):
        x[t] = a * x[t - 1] + e[t]
    return x


def _pressures_in_range(p1: np.ndarray, p2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """P1 within [0.05, 0.995] of full scale, P2 at least 0.05 MPa below it and above 0.01 of
    full scale [Pa]."""
    p1 = np.clip(p1, 0.05 * P_RANGE, 0.995 * P_RANGE)
    return p1, np.clip(np.minimum(p2, p1 - 0.05e6), 0.01 * P_RANGE, None)


def _operating_point(rng: np.random.Generator, n: int, op: OperatingRange) -> dict[str, np.ndarray]:
    """P1, P2 [Pa] and T1 [°C] of one run: drawn levels, slow drift and fast fluctuation."""
    p1 = rng.uniform(*op.p1)
    dp = rng.uniform(*op.dp)
    t1 = rng.uniform(*op.t1)
    tau = float(op.drift_seconds)
    p1_t = p1 + _ou(rng, n, op.p1_drift, tau) + rng.standard_normal(n) * op.p1_noise
    p2_t = (p1 - dp) + _ou(rng, n, op.p2_drift, tau) + rng.standard_normal(n) * op.p2_noise
    t1_t = t1 + _ou(rng, n, op.t1_drift, tau) + rng.standard_normal(n) * op.t1_noise
    p1_t, p2_t = _pressures_in_range(p1_t, p2_t)
    t1_t = np.clip(t1_t, 1.0, 0.99 * T_RANGE)
    return {"P1": p1_t, "P2": p2_t, "T1": t1_t}


def excitation_dataset(
    cv: np.ndarray, points: list[dict[str, np.ndarray]], family: str, seed: int, attrs: dict
) -> xr.Dataset:
    """The dataset of a generator's runs: CV, and each run's P1, P2 [Pa] and T1 [°C] in
    ``points`` normalised to full scale; ``attrs`` become ``excitation_*`` attributes."""
    channels = {
        "CV": cv,
        "P1": np.stack([p["P1"] for p in points]) / P_RANGE,
        "P2": np.stack([p["P2"] for p in points]) / P_RANGE,
        "T1": np.stack([p["T1"] for p in points]) / T_RANGE,
    }
    return make_dataset(
        channels,
        state="fn",
        campaign=family,
        seed=seed,
        attrs={"generator": family, **{f"excitation_{k}": v for k, v in attrs.items()}},
    )


def check_run_shape(n_runs: Any, duration: Any, who: str) -> tuple[int, int]:
    """A generator's ``n_runs`` and ``duration`` checked, and the memory they need."""
    n_runs = check_count(n_runs, "n_runs", who)
    duration = check_count(duration, "duration", who)
    check_memory(8.0 * _VALUES_PER_SAMPLE * n_runs * duration, f"{who}: {n_runs} x {duration} s")
    return n_runs, duration


def sine_sum_inputs(
    n_runs: int = 1,
    duration: int = 3600,
    *,
    seed: int = 0,
    n_sines: int = 3,
    frequencies: tuple[float, float] = (0.002, 0.05),
    cv_mean: tuple[float, float] = (0.45, 0.75),
    cv_amplitude: tuple[float, float] = (0.05, 0.2),
    p1_amplitude: tuple[float, float] = (0.0, 0.0),
    operating: OperatingRange = DEFAULT_OPERATING,
) -> xr.Dataset:
    """CV a sum of ``n_sines`` sines; the operating point drawn from ``operating``.

    Each run draws its mean in ``cv_mean``, each sine its frequency log-uniformly in
    ``frequencies`` (Hz, at most 0.5), its phase uniformly, and its amplitude so that the
    amplitudes sum to a total drawn in ``cv_amplitude``. CV is clipped to [0.02, 0.98].

    With ``p1_amplitude`` above zero (Pa), P1 also oscillates around its drifting level: a sum
    of ``n_sines`` sines drawn in the same way, their amplitudes summing to a total drawn in
    ``p1_amplitude``, while P2 keeps its own level, so that the pressure drop swings with P1
    (as DGen's 0.1 Hz sine of P1 makes it swing, but at every operating point and frequency).
    P1 stays in [0.05, 0.995] of full scale and P2 at least 0.05 MPa below it. The default,
    no oscillation, draws nothing more.
    """
    who = "sine_sum_inputs"
    n_runs, duration = check_run_shape(n_runs, duration, who)
    n_sines = check_count(n_sines, "n_sines", who)
    f_lo, f_hi = check_band(frequencies, "frequencies", who, 1e-5, 0.5)
    if f_lo <= 0:
        raise ValueError(f"{who}: frequencies must be positive")
    m_lo, m_hi = check_band(cv_mean, "cv_mean", who, 0.0, 1.0)
    a_lo, a_hi = check_band(cv_amplitude, "cv_amplitude", who, 0.0, 1.0)
    p_lo, p_hi = check_band(p1_amplitude, "p1_amplitude", who, 0.0, 1e6)
    t = np.arange(duration, dtype=np.float64)
    cv = np.empty((n_runs, duration))
    points = []

    def sines(rng: np.random.Generator, total: tuple[float, float]) -> np.ndarray:
        f = np.exp(rng.uniform(math.log(f_lo), math.log(f_hi), n_sines))
        share = rng.dirichlet(np.ones(n_sines)) * rng.uniform(*total)
        phase = rng.uniform(0.0, 2.0 * np.pi, n_sines)
        return (share[:, None] * np.sin(2 * np.pi * f[:, None] * t + phase[:, None])).sum(axis=0)

    for r in range(n_runs):
        rng = np.random.default_rng([int(seed), FAMILIES["sine-sum"], r])
        wave = sines(rng, (a_lo, a_hi))
        cv[r] = np.clip(rng.uniform(m_lo, m_hi) + wave, 0.02, 0.98)
        point = _operating_point(rng, duration, operating)
        if p_hi > 0.0:
            wave = sines(rng, (p_lo, p_hi))
            point["P1"], point["P2"] = _pressures_in_range(point["P1"] + wave, point["P2"])
        points.append(point)
    attrs = {"n_sines": n_sines, "f_low": f_lo, "f_high": f_hi}
    if p_hi > 0.0:
        attrs["p1_low"], attrs["p1_high"] = p_lo, p_hi
    return excitation_dataset(cv, points, "sine-sum", int(seed), attrs)


def step_ramp_inputs(
    n_runs: int = 1,
    duration: int = 3600,
    *,
    seed: int = 0,
    hold_seconds: tuple[float, float] = (20.0, 300.0),
    ramp_share: float = 0.5,
    ramp_seconds: tuple[float, float] = (10.0, 200.0),
    cv_range: tuple[float, float] = (0.35, 0.9),
    operating: OperatingRange = DEFAULT_OPERATING,
) -> xr.Dataset:
    """CV held at random levels in ``cv_range`` for ``hold_seconds``, moving to the next level
    by a step or, with probability ``ramp_share``, by a ramp lasting ``ramp_seconds``."""
    who = "step_ramp_inputs"
    n_runs, duration = check_run_shape(n_runs, duration, who)
    h_lo, h_hi = check_band(hold_seconds, "hold_seconds", who, 1.0, 1e7)
    r_lo, r_hi = check_band(ramp_seconds, "ramp_seconds", who, 1.0, 1e7)
    c_lo, c_hi = check_band(cv_range, "cv_range", who, 0.0, 1.0)
    if not 0.0 <= float(ramp_share) <= 1.0:
        raise ValueError(f"{who}: ramp_share must lie in [0, 1], got {ramp_share!r}")
    cv = np.empty((n_runs, duration))
    points = []
    for r in range(n_runs):
        rng = np.random.default_rng([int(seed), FAMILIES["step-ramp"], r])
        level = rng.uniform(c_lo, c_hi)
        t = 0
        while t < duration:
            hold = max(1, round(rng.uniform(h_lo, h_hi)))
            cv[r, t : t + hold] = level
            t += hold
            target = rng.uniform(c_lo, c_hi)
            if t < duration and rng.uniform() < ramp_share:
                n = max(1, round(rng.uniform(r_lo, r_hi)))
                path = level + (target - level) * np.arange(1, n + 1) / n
                cv[r, t : t + n] = path[: max(0, min(n, duration - t))]
                t += n
            level = target
        points.append(_operating_point(rng, duration, operating))
    attrs = {"hold_low": h_lo, "hold_high": h_hi, "ramp_share": float(ramp_share)}
    return excitation_dataset(cv, points, "step-ramp", int(seed), attrs)


class LevelLoop(NamedTuple):
    """The level loop of `level_loop_inputs` (normalised level; flows as shares of the valve's
    full-open flow at the nominal pressure drop). Pairs are ranges: each run draws its value
    uniformly in them."""

    area_seconds: tuple[float, float] = (60.0, 240.0)  #: seconds to fill the tank's span
    kp: tuple[float, float] = (0.8, 4.0)  #: controller gain (CV per unit level error)
    ti: tuple[float, float] = (60.0, 300.0)  #: integral time [s]
    level_noise: tuple[float, float] = (0.001, 0.012)  #: level measurement noise (std)
    setpoint: tuple[float, float] = (0.4, 0.6)
    setpoint_hold: tuple[float, float] = (300.0, 1200.0)  #: seconds between set-point changes
    setpoint_ramp: float = 60.0  #: seconds a set-point change takes
    demand: tuple[float, float] = (0.02, 0.09)  #: outflow demand level
    demand_drift: float = 0.1  #: relative std of the demand's drift
    positioner_seconds: float = 2.0  #: the stem's first-order lag behind CV
    dp_nominal: float = 0.9e6  #: pressure drop of the nominal flow [Pa]
    #: the valve's equal-percentage exponent n in the loop's flow law (inflow ~ exp(-n X))
    characteristic: float = 5.0
    kv_ratio: float = 1.0  #: the valve's flow coefficient over the nominal one


#: The default level loop of `level_loop_inputs`.
DEFAULT_LOOP = LevelLoop()


def _setpoints(rng: np.random.Generator, n: int, loop: LevelLoop) -> np.ndarray:
    """Set-point levels held for random times, each change a ramp of ``setpoint_ramp`` s."""
    out = np.empty(n)
    level, t = rng.uniform(*loop.setpoint), 0
    while t < n:
        hold = max(1, round(rng.uniform(*loop.setpoint_hold)))
        out[t : t + hold] = level
        t += hold
        target = rng.uniform(*loop.setpoint)
        ramp = max(1, round(loop.setpoint_ramp))
        path = level + (target - level) * np.arange(1, ramp + 1) / ramp
        out[t : t + ramp] = path[: max(0, min(ramp, n - t))]
        t += ramp
        level = target
    return out


def _loop_run(
    rng: np.random.Generator, n: int, dp: np.ndarray, loop: LevelLoop
) -> tuple[np.ndarray, np.ndarray]:
    """CV and the measured level of one run of the PI level loop (the valve sets the inflow)."""
    area, kp, ti, noise = (rng.uniform(*r) for r in (loop.area_seconds, loop.kp, loop.ti,
                                                        loop.level_noise))  # fmt: skip
    setpoint = _setpoints(rng, n, loop)
    demand = rng.uniform(*loop.demand) * np.exp(_ou(rng, n, loop.demand_drift, 600.0))
    flow_scale = loop.kv_ratio * np.sqrt(np.maximum(dp, 0.0) / loop.dp_nominal)
    n_char = loop.characteristic
    x_stem = float(np.clip(-math.log(max(demand[0] / flow_scale[0], 1e-6)) / n_char, 0.0, 1.0))
    level = setpoint[0]
    integral = x_stem / kp * ti  # a bumpless start at the balancing opening
    cv = np.empty(n)
    measured = rng.standard_normal(n) * noise
    a_pos = math.exp(-1.0 / loop.positioner_seconds)
    for k in range(n):
        measured[k] += level
        error = measured[k] - setpoint[k]  # direct acting: a high level closes the valve
        out = kp * (error + integral / ti)
        cv[k] = min(max(out, 0.0), 1.0)
        if cv[k] == out:  # anti-windup: integrate only while the output is not clipped
            integral += error
        x_stem = a_pos * x_stem + (1.0 - a_pos) * cv[k]
        inflow = math.exp(-n_char * x_stem) * flow_scale[k]  # X is the fraction of closing
        level = min(max(level + (inflow - demand[k]) / area, 0.0), 1.0)
    return cv, measured


def level_loop_inputs(
    n_runs: int = 1,
    duration: int = 3600,
    *,
    seed: int = 0,
    loop: LevelLoop = DEFAULT_LOOP,
    operating: OperatingRange = DEFAULT_OPERATING,
) -> xr.Dataset:
    """CV of a PI level loop whose inflow the valve sets (see the module docstring).

    The set-point jumps to a level drawn in ``loop.setpoint`` every ``loop.setpoint_hold``
    seconds; the outflow demand drifts around a level drawn in ``loop.demand``. The dataset also
    holds the measured tank level of each run as the coordinate ``level`` (not a channel of the
    actuator). CV is clipped to [0, 1] by the controller, with anti-windup.
    """
    who = "level_loop_inputs"
    n_runs, duration = check_run_shape(n_runs, duration, who)
    for name in ("area_seconds", "kp", "ti", "level_noise", "setpoint_hold", "demand"):
        check_band(getattr(loop, name), f"loop.{name}", who, 0.0, 1e9)
    if not (loop.positioner_seconds > 0 and loop.setpoint_ramp >= 1):
        raise ValueError(f"{who}: the positioner lag and the set-point ramp must be positive")
    if not (loop.characteristic > 0 and loop.kv_ratio > 0):
        raise ValueError(f"{who}: loop.characteristic and loop.kv_ratio must be positive")
    cv = np.empty((n_runs, duration))
    level = np.empty((n_runs, duration))
    points = []
    for r in range(n_runs):
        rng = np.random.default_rng([int(seed), FAMILIES["level-loop"], r])
        point = _operating_point(rng, duration, operating)
        cv[r], level[r] = _loop_run(rng, duration, point["P1"] - point["P2"], loop)
        points.append(point)
    attrs = {"kp_low": loop.kp[0], "kp_high": loop.kp[1]}
    ds = excitation_dataset(cv, points, "level-loop", int(seed), attrs)
    return ds.assign_coords(level=(("run", "time"), level))

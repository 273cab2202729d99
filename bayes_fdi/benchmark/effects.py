"""What a scenario's fault does to the measured signals, against the sensor noise.

`fault_effects` compares noise-free simulations with and without each fault: a fault whose
effect stays below the noise cannot be detected by any method, which the report says.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.actuator import NOISE_STD, benchmark_inputs, simulate
from bayes_fdi.benchmark.scenarios import BenchmarkScenario

__all__ = ["MEASURED", "fault_effects"]

#: The measured channels compared.
MEASURED = ("X", "F", "P1", "P2", "T1")


def fault_effects(
    scenarios: Sequence[BenchmarkScenario],
    inputs: Callable[[int], xr.Dataset] | None = None,
) -> list[dict[str, Any]]:
    """The effect of each scenario's fault on the measured signals, against the sensor noise.

    Noise-free simulations with and without the fault (same inputs; clipped to the sensors'
    range as the measurements are) are compared over the faulty part ``[t_from, t_hor)``. Per
    channel: the RMS and the largest absolute difference in units of the measurement noise
    :data:`~bayes_fdi.actuator.NOISE_STD`. ``deflection`` is ``sqrt(sum_t sum_c (e_c(t) /
    sigma)^2)`` over X, F, P1, P2, T1: the separation that an ideal detector knowing the exact
    noise-free signal with and without the fault (a matched filter) would see against white
    noise, an upper bound for any method using these signals; ``oracle_time`` is the first
    second after ``t_from`` at which its running value reaches 5 (``None`` if never).

    ``inputs(duration)`` gives the one run of inputs (CV, P1, P2, T1) the faults are compared
    under; default DGen's sines without variation (the benchmark's).
    """
    out: list[dict[str, Any]] = []
    by_horizon: dict[float, list[BenchmarkScenario]] = {}
    for s in scenarios:
        by_horizon.setdefault(s.t_hor, []).append(s)
    for t_hor, group in by_horizon.items():
        duration = round(t_hor)
        if inputs is None:
            drive = benchmark_inputs(n_runs=len(group) + 1, duration=duration, vary=False)
        else:
            one = inputs(duration)[["CV", "P1", "P2", "T1"]].isel(run=[0])
            drive = xr.concat([one] * (len(group) + 1), dim="run")
            drive = drive.assign_coords(run=np.arange(len(group) + 1))
        clean = simulate(drive, [None] + [s.fault_spec() for s in group], noise=False)
        for r, s in enumerate(group, start=1):
            faulty = np.arange(duration) >= s.t_from
            e = (
                np.stack(
                    [clean[c].values[r, faulty] - clean[c].values[0, faulty] for c in MEASURED]
                )
                / NOISE_STD
            )
            running = np.sqrt(np.cumsum((e**2).sum(axis=0)))
            reach = np.flatnonzero(running >= 5.0)
            out.append(
                {
                    "scenario": s.name,
                    "rms": {c: float(np.sqrt(np.mean(e[i] ** 2))) for i, c in enumerate(MEASURED)},
                    "max": {c: float(np.max(np.abs(e[i]))) for i, c in enumerate(MEASURED)},
                    "deflection": float(running[-1]),
                    "oracle_time": float(reach[0]) if reach.size else None,
                }
            )
    order = {s.name: i for i, s in enumerate(scenarios)}
    return sorted(out, key=lambda d: order[d["scenario"]])

"""Test inputs of the DAMADICS benchmark generator (DABLib's DGen block)."""

from __future__ import annotations

import math

import numpy as np
import xarray as xr

from bayes_fdi.datasets import make_dataset
from bayes_fdi.memory import check_memory

#: float64 values held per (run, second) at the peak of `benchmark_inputs`: the four signals,
#: their normalised copies and the dataset's copies
_VALUES_PER_SAMPLE = 14

__all__ = ["benchmark_inputs"]


def _check_non_negative(value, name: str) -> None:
    value = float(value)
    if not math.isfinite(value) or value < 0:
        raise ValueError(f"benchmark_inputs: {name} must be >= 0")


def benchmark_inputs(
    n_runs: int = 1,
    duration: int = 350,
    *,
    seed: int = 0,
    vary: bool = False,
    cv_mean: float = 0.5,
    cv_amplitude: float = 0.25,
    cv_frequency: float = 0.01,
    p1_mean: float = 3.5e6,
    p1_amplitude: float = 175e3,
    p1_frequency: float = 0.1,
    p2_mean: float = 2.6e6,
    p2_amplitude: float = 26e3,
    p2_omega: float = 2.0,
    t1: float = 43.0,
    amplitude_jitter: float = 0.2,
    campaign: str = "dgen",
) -> xr.Dataset:
    """Inputs of the benchmark's test generator (DGen), sampled at 1 Hz, normalised.

    ``CV = cv_mean + cv_amplitude sin(2 pi cv_frequency t + phi_cv)``,
    ``P1 = p1_mean + p1_amplitude sin(2 pi p1_frequency t + phi_1)`` [Pa],
    ``P2 = p2_mean + p2_amplitude sin(p2_omega t + phi_2)`` [Pa] and a constant ``T1`` [°C];
    DGen's defaults are 0.5 + 0.25 sin(2 pi 0.01 t), 3.5 MPa + 175 kPa sin(2 pi 0.1 t),
    2.6 MPa + 26 kPa sin(2 t) and 43 °C, with all phases 0.

    The signals are evaluated at the integer seconds ``t = 0 .. duration - 1`` and the simulator
    holds each sample for one second (zero-order hold, as DGen's own 1 s outputs and real 1 Hz
    plant records are). P2's 2 rad/s sine (0.318 Hz, period 3.14 s) lies below the 0.5 Hz
    Nyquist frequency, so its 1 Hz samples are not aliased, but they are coarse (about three
    per period) and the held staircase differs from the continuous sine by up to its amplitude;
    this is what a 1 Hz record of such a pressure contains, and all the simulator can know.

    Parameters
    ----------
    n_runs, duration
        Number of runs and their length in seconds (samples).
    seed
        Seed of the run-to-run variation (used only when ``vary`` is true).
    vary
        If true, every run draws its own phases ``phi`` uniformly in ``[0, 2 pi)`` for the three
        sines and scales each sine's amplitude by a factor uniform in
        ``[1 - amplitude_jitter, 1 + amplitude_jitter]``; means, frequencies and T1 stay fixed.
        Run ``r`` uses the stream ``numpy.random.default_rng([seed, r])``.
    amplitude_jitter
        Relative amplitude spread of ``vary`` (``0 <= amplitude_jitter < 1``).
    campaign
        Stored in the dataset's ``campaign`` attribute.

    Returns
    -------
    xarray.Dataset
        ``n_runs`` fault-free runs with channels ``CV, P1, P2, T1`` (normalised: P/4 MPa,
        T1/200 °C), state ``"fn"``; the generator parameters are stored in the attributes.

    Examples
    --------
    >>> ds = benchmark_inputs(n_runs=2, duration=10)
    >>> ds.sizes["run"], ds.sizes["time"], round(float(ds.P1[0, 0]), 4)
    (2, 10, 0.875)
    """
    if isinstance(n_runs, bool) or not isinstance(n_runs, int | np.integer) or n_runs < 1:
        raise ValueError(f"benchmark_inputs: n_runs must be an integer >= 1, got {n_runs!r}")
    if isinstance(duration, bool) or not isinstance(duration, int | np.integer) or duration < 1:
        raise ValueError(f"benchmark_inputs: duration must be an integer >= 1, got {duration!r}")
    check_memory(
        8.0 * _VALUES_PER_SAMPLE * n_runs * duration,
        f"benchmark_inputs: {n_runs} run(s) x {duration} s",
    )
    if not 0.0 <= float(amplitude_jitter) < 1.0:
        raise ValueError("benchmark_inputs: amplitude_jitter must lie in [0, 1)")
    for name, value in (
        ("cv_frequency", cv_frequency),
        ("p1_frequency", p1_frequency),
        ("p2_omega", p2_omega),
        ("cv_amplitude", cv_amplitude),
        ("p1_amplitude", p1_amplitude),
        ("p2_amplitude", p2_amplitude),
    ):
        _check_non_negative(value, name)
    t = np.arange(duration, dtype=np.float64)
    phases = np.zeros((n_runs, 3))
    gains = np.ones((n_runs, 3))
    if vary:
        for r in range(n_runs):
            rng = np.random.default_rng([int(seed), r])
            phases[r] = rng.uniform(0.0, 2.0 * np.pi, 3)
            gains[r] = rng.uniform(1.0 - amplitude_jitter, 1.0 + amplitude_jitter, 3)
    cv = cv_mean + cv_amplitude * gains[:, :1] * np.sin(
        2 * np.pi * cv_frequency * t + phases[:, :1]
    )
    p1 = p1_mean + p1_amplitude * gains[:, 1:2] * np.sin(
        2 * np.pi * p1_frequency * t + phases[:, 1:2]
    )
    p2 = p2_mean + p2_amplitude * gains[:, 2:3] * np.sin(p2_omega * t + phases[:, 2:3])
    channels = {
        "CV": cv,
        "P1": p1 / 4e6,
        "P2": p2 / 4e6,
        "T1": np.full((n_runs, duration), t1 / 200.0),
    }
    for name, arr in channels.items():
        if arr.min() < 0.0 or arr.max() > 1.0:
            raise ValueError(
                f"benchmark_inputs: the parameters drive {name} outside its normalised range [0, 1]"
            )
    if (p1 < p2).any():
        raise ValueError("benchmark_inputs: the parameters make P1 < P2 (reverse flow)")
    params = {
        "cv_mean": cv_mean,
        "cv_amplitude": cv_amplitude,
        "cv_frequency": cv_frequency,
        "p1_mean": p1_mean,
        "p1_amplitude": p1_amplitude,
        "p1_frequency": p1_frequency,
        "p2_mean": p2_mean,
        "p2_amplitude": p2_amplitude,
        "p2_omega": p2_omega,
        "t1": t1,
        "vary": int(bool(vary)),
        "amplitude_jitter": amplitude_jitter,
    }
    attrs = {"generator": "DGen", **{f"dgen_{k}": float(v) for k, v in params.items()}}
    return make_dataset(channels, state="fn", campaign=campaign, seed=seed, attrs=attrs)

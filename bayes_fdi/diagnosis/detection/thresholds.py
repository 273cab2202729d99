"""Detector thresholds for a false-alarm budget.

`cusum_arl` is Siegmund's approximation of the in-control average run length (ARL) of a
one-sided CUSUM on N(0, 1) data and `cusum_threshold` inverts it; `empirical_arl` and
`calibrate_threshold` measure the run length between false alarms on held-out fault-free
innovations, with the hysteresis of `~bayes_fdi.diagnosis.detection.decision.detection_decision`,
and extrapolate it (log ARL is linear in the threshold for large thresholds, as Siegmund's formula
shows), so non-Gaussian real residuals get an honest threshold. `fit_threshold` is the online
diagnoser's threshold for a false-alarm budget: the measured one, bounded below by the
detector's threshold on white Gaussian innovations.

Written by hand: no maintained library in the dependencies computes CUSUM run lengths.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy import optimize

from bayes_fdi.diagnosis.detection.decision import detection_decision

__all__ = [
    "FEW_ALARMS",
    "calibrate_threshold",
    "cusum_arl",
    "cusum_threshold",
    "empirical_arl",
    "fit_threshold",
]


#: The fewest alarms a threshold of the calibration grid may give to enter the fit when fewer
#: than two thresholds give ``min_alarms``.
FEW_ALARMS = 3


def cusum_arl(threshold: Any, k: float) -> np.ndarray:
    """Siegmund's approximation of a one-sided CUSUM's in-control ARL on N(0, 1) data.

    ``ARL0 = (exp(2 k b) - 2 k b - 1) / (2 k^2)`` with ``b = h + 1.166`` (for ``k > 0``;
    ``b^2`` for ``k = 0``), the mean number of samples before ``S+`` first exceeds ``h``
    (Siegmund 1985, *Sequential Analysis*, eq. 2.55; Basseville & Nikiforov 1993, eq. 5.2.44).
    """
    b = np.asarray(threshold, dtype=np.float64) + 1.166
    if k == 0:
        return b**2
    a = 2.0 * k * b
    with np.errstate(over="ignore"):  # an infinite ARL for an enormous threshold is right
        return (np.exp(a) - a - 1.0) / (2.0 * k * k)


def cusum_threshold(arl: float, k: float, *, n_sides: int = 1) -> float:
    """The CUSUM threshold whose in-control ARL is ``arl`` (Siegmund's approximation).

    ``n_sides`` one-sided CUSUMs that run together (two per two-sided CUSUM and channel) raise
    a first alarm about ``n_sides`` times as often: each gets ``n_sides * arl``.
    """
    if not arl > 1:
        raise ValueError(f"arl must exceed 1, got {arl}")
    target = float(arl) * int(n_sides)
    return float(optimize.brentq(lambda h: float(cusum_arl(h, k)) - target, -1.0, 1e4))


def empirical_arl(
    detector: Any, innovations: Sequence[Any], threshold: float, clear: float = 0.0
) -> tuple[float, int, int]:
    """Mean run length between false alarms of a detector on fault-free innovations.

    Every run (a sequence of ``(n,)`` or ``(n, n_channels)`` innovations; one fresh detector
    per channel, ``detector.with_threshold(threshold)``) is processed as the online
    diagnoser does, with the hysteresis of `detection_decision` (off at ``clear``). An alarm is
    a rising edge of DD.

    Returns
    -------
    arl : float
        Finite samples / alarms (``inf`` with no alarm).
    alarms : int
    samples : int
    """
    alarms = 0
    samples = 0
    for run in innovations:
        e = np.asarray(run, dtype=np.float64)
        e = e[:, None] if e.ndim == 1 else e
        test = detector.with_threshold(threshold)
        stats = np.column_stack([test.run(e[:, j])[0].statistic for j in range(e.shape[1])])
        dd = detection_decision(stats, threshold, min(clear, threshold))
        alarms += int(dd[:1].sum() + (dd[1:] & ~dd[:-1]).sum())
        samples += int(np.isfinite(e).all(axis=1).sum())
    return (samples / alarms if alarms else math.inf), alarms, samples


def calibrate_threshold(
    detector: Any,
    innovations: Sequence[Any],
    target_arl: float,
    *,
    clear: float = 0.0,
    grid: Sequence[float] | None = None,
    min_alarms: int = 10,
    floor: float | None = None,
) -> dict[str, Any]:
    """The threshold that meets a false-alarm budget, measured on fault-free innovations.

    The empirical ARL (`empirical_arl`) is measured on a grid of thresholds low enough to give
    at least ``min_alarms`` alarms each (when fewer than two do, as on short data or for a
    statistic whose alarms merge, those with at least `FEW_ALARMS`); ``log(ARL)`` is fitted as
    a straight line in the threshold (its large-threshold form for a CUSUM, Siegmund, and a
    good description of the GLR's) by least squares, and the threshold where the line reaches
    ``target_arl`` is taken, or the lowest measured threshold whose ARL already exceeds the
    target if that is smaller. A ``floor`` (e.g. the theoretical threshold for Gaussian
    innovations) bounds it below.

    Returns
    -------
    dict
        ``threshold``, ``fit`` (intercept, slope), ``grid``, ``arl``, ``alarms``,
        ``samples`` and ``floor``.
    """
    if not target_arl > 1:
        raise ValueError(f"target_arl must exceed 1, got {target_arl}")
    grid = np.arange(1.0, 30.01, 1.0) if grid is None else np.asarray(grid, dtype=np.float64)
    arls, counts, samples = [], [], 0
    for h in grid:
        arl, n_alarms, samples = empirical_arl(detector, innovations, float(h), clear)
        arls.append(arl)
        counts.append(n_alarms)
        if n_alarms < min_alarms:
            break
    ok = np.asarray(counts) >= min_alarms
    if ok.sum() < 2:  # short data, or alarms that merge: fit on thresholds with a few alarms
        for h in grid[len(counts) :]:
            if counts[-1] < FEW_ALARMS:
                break
            arl, n_alarms, samples = empirical_arl(detector, innovations, float(h), clear)
            arls.append(arl)
            counts.append(n_alarms)
        ok = np.asarray(counts) >= FEW_ALARMS
    arls_a = np.asarray(arls)
    counts_a = np.asarray(counts)
    used = grid[: arls_a.size]
    if ok.sum() >= 2:
        slope, intercept = np.polyfit(used[ok], np.log(arls_a[ok]), 1)
    else:
        slope, intercept = math.nan, math.nan
    if slope > 0:
        h = (math.log(target_arl) - intercept) / slope
    else:
        h = math.inf
    reached = used[arls_a >= target_arl]
    if reached.size and reached[0] < h:
        h = float(reached[0])
    if floor is not None:
        h = max(h, float(floor))
    return {
        "threshold": float(h),
        "fit": (float(intercept), float(slope)),
        "grid": used.tolist(),
        "arl": arls_a.tolist(),
        "alarms": counts_a.tolist(),
        "samples": int(samples),
        "floor": None if floor is None else float(floor),
    }


def fit_threshold(
    detector: Any,
    innovations: Sequence[Any],
    target_arl: float,
    *,
    clear: float = 0.0,
    random_state: int | None = None,
) -> dict[str, Any]:
    """The threshold of a false-alarm budget for the online diagnoser's detector.

    The larger of the threshold that meets ``target_arl`` on white Gaussian innovations
    (``detector.gaussian_threshold``: Siegmund's approximation for the CUSUM, a seeded
    simulation for the GLR) and the one measured on fault-free innovations
    (`calibrate_threshold` over thresholds 1, 2, ..., 60, hysteresis off at ``clear``).

    Parameters
    ----------
    detector
        A `~bayes_fdi.diagnosis.detection.detectors.CUSUM` or
        `~bayes_fdi.diagnosis.detection.detectors.GLR` (its own threshold is not used).
    innovations
        Fault-free innovations, one ``(n, n_channels)`` array per run.
    target_arl
        The budget: mean samples between false alarms.
    clear
        The detection decision's clear level.
    random_state
        Seed of the GLR's simulation.

    Returns
    -------
    dict
        `calibrate_threshold`'s report; ``floor`` is the Gaussian threshold.
    """
    first = np.asarray(innovations[0], dtype=np.float64)
    n_channels = 1 if first.ndim == 1 else first.shape[1]
    floor = detector.gaussian_threshold(
        target_arl, n_channels=n_channels, clear=clear, random_state=random_state
    )
    grid = np.arange(1.0, 60.01, 1.0)
    return calibrate_threshold(
        detector, innovations, target_arl, clear=clear, floor=floor, grid=grid
    )

"""The detector's estimated change point behind a detection, for the input envelope's onset check.

`change_ages` dates the change that raised a detection: the start of the current excursion,
above the detection decision's clear level, of the statistic that exceeded the threshold (for
the CUSUM, clear level 0, the last second both its sums were at 0), or the detector's own
estimate (`~bayes_fdi.diagnosis.detection.detectors.DetectorOutput.since`, the GLR's best
window) where that reaches further back. The input envelope
(`bayes_fdi.diagnosis.online.envelope.InputEnvelope`) judges a detection by the inputs before
that second; the excursions' lengths carry over from one chunk to the next in its state.

Written by hand: a run length over a boolean series, in numpy.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["change_ages"]


def change_ages(
    statistics: Any, since: Any, threshold: float, clear: float, excursion: Any = None
) -> tuple[np.ndarray, np.ndarray]:
    """Per second, the age (seconds, counting that second) of the estimated change behind a
    detection raised then, and the excursion counters after the last second.

    A statistic's *excursion* is the run of seconds in which it stands above the clear level
    (where the detection decision counts the evidence as gone; a NaN statistic, a gap, continues
    it): for the CUSUM, whose clear level is 0, the seconds since both its sums were last at 0,
    also where the whitened residuals of a fault alternate in sign and the sums take turns. The
    age is, over the outputs whose statistic exceeds ``threshold``, the largest of the
    excursion's length and the detector's own ``since`` (the GLR's best window); 0 where no
    statistic exceeds the threshold.

    Parameters
    ----------
    statistics, since
        ``(..., n, outputs)`` the detectors' statistics and change ages (NaN and -1 in a gap)
        of consecutive seconds.
    threshold, clear
        The detection decision's threshold and clear level.
    excursion
        ``(..., outputs)`` the excursions' lengths before the first second (default 0).

    Returns
    -------
    ages : numpy.ndarray
        ``(..., n)`` int64.
    excursion : numpy.ndarray
        ``(..., outputs)`` int64, the lengths after the last second.
    """
    stats = np.asarray(statistics, dtype=np.float64)
    ages = np.asarray(since, dtype=np.float64)
    if stats.shape != ages.shape or stats.ndim < 2:
        raise ValueError(f"statistics {stats.shape} and since {ages.shape} must be (..., n, c)")
    carry_shape = stats.shape[:-2] + stats.shape[-1:]
    carry = np.zeros(carry_shape, np.int64) if excursion is None else np.asarray(excursion)
    if carry.shape != carry_shape:
        raise ValueError(f"excursion must have shape {carry_shape}, got {carry.shape}")
    n = stats.shape[-2]
    t = np.arange(n).reshape(n, 1)
    with np.errstate(invalid="ignore"):
        reset = np.isfinite(stats) & (stats <= clear)
        raising = np.isfinite(stats) & (stats > threshold)
    last_reset = np.maximum.accumulate(np.where(reset, t, -1), axis=-2)
    length = np.where(last_reset >= 0, t - last_reset, np.expand_dims(carry, -2) + t + 1)
    age = np.where(raising, np.maximum(length, ages), 0.0).max(axis=-1, initial=0.0)
    end = length[..., -1, :] if n else carry
    return age.astype(np.int64), np.asarray(end, dtype=np.int64)

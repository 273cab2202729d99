"""Calibration of the dynamic normal models' predictive standard deviations by command speed.

The out-of-fold residuals of a cross-fit (`cross_fit_folds`: runs, or time blocks when there are
fewer runs than folds, dealt to the folds at random) give one std factor per bin of the command
speed ``|CV(t) - CV(t-1)|`` (`speed_bin_factors`): the stem lags a fast command, so the
residuals spread more there. Each factor is fitted by maximum likelihood, ``sqrt(mean(z^2))``,
or by coverage (the central interval of level ``q`` covers a share ``q`` of the residuals,
robust to a heavy tail). Censored samples (a measurement and its prediction at the same rail,
``z = 0`` by construction) say nothing about the scale and are left out.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from bayes_fdi.diagnosis.normal_models.std_scaler import StdScaler

__all__ = [
    "SpeedBinFactors",
    "cross_fit_folds",
    "out_of_fold_predictions",
    "speed_bin_factors",
    "speed_bins",
]


class SpeedBinFactors(NamedTuple):
    """Std factors of X and F by command-speed bin."""

    edges: np.ndarray  #: inner edges of the speed bins
    scale: dict  #: ``{"X": (bins,), "F": (bins,)}``
    scale_all: dict  #: ``{"X": float, "F": float}`` fitted on every bin together
    factor: dict  #: ``{"X": (n,), "F": (n,)}`` the factor of every sample


def cross_fit_folds(n_runs: int, n_times: int, k: int, rng: np.random.Generator) -> np.ndarray:
    """``(n_runs, n_times)`` fold of every sample: whole runs when there are at least ``k``
    runs, else time blocks of each run, dealt to the ``k`` folds in a random order."""
    blocks = 1 if n_runs >= k else min(n_times, -(-k // n_runs))
    block_of_time = (np.arange(n_times) * blocks) // n_times
    segment = np.arange(n_runs)[:, None] * blocks + block_of_time[None, :]
    n_seg = n_runs * blocks
    fold_of_segment = np.empty(n_seg, dtype=np.int64)
    fold_of_segment[rng.permutation(n_seg)] = np.arange(n_seg) % k
    return fold_of_segment[segment]


def out_of_fold_predictions(
    finite: np.ndarray,
    n_runs: int,
    n_times: int,
    k: int,
    rng: np.random.Generator,
    columns: int,
    predict_fold: Callable[[np.ndarray, np.ndarray], np.ndarray],
) -> np.ndarray:
    """``(n_runs * n_times, columns)`` predictions of each sample by models fitted without it.

    The folds are `cross_fit_folds`'; ``predict_fold(train, held_runs)`` fits on the rows
    ``train`` (the fold's complement where ``finite``) and returns the predictions of the runs
    ``held_runs``, ``(len(held_runs), n_times, columns)``, of which the fold's samples are kept. NaN
    where a fold has under 10 rows to fit on.
    """
    fold = cross_fit_folds(n_runs, n_times, k, rng).ravel()
    pred = np.full((n_runs * n_times, columns), np.nan)
    for f in range(k):
        held = fold == f
        train = np.flatnonzero(finite & ~held)
        if train.size < 10 or not held.any():
            continue
        held_runs = np.unique(np.flatnonzero(held) // n_times)
        part = predict_fold(train, held_runs).reshape(-1, columns)
        rows_of = (held_runs[:, None] * n_times + np.arange(n_times)[None, :]).ravel()
        keep = held[rows_of]
        pred[rows_of[keep]] = part[keep]
    return pred


def speed_bins(edges: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """Bin index of each command speed given the inner bin ``edges`` (-1 where not finite)."""
    bins = np.searchsorted(edges, speed, side="right")
    return np.where(np.isfinite(speed), bins, -1)


def _scale(z: np.ndarray, fallback: float, coverage: float | None) -> float:
    """`StdScaler`'s factor of standardised residuals ``z`` (``fallback`` for under 10 or all 0)."""
    if z.size < 10 or not np.any(z != 0):
        return fallback
    method = {"method": "mle"} if coverage is None else {"method": "coverage", "level": coverage}
    try:
        return float(StdScaler(**method).fit(z, np.zeros_like(z), np.ones_like(z)).scale_)
    except ValueError:  # a zero factor (most residuals exactly 0): no scale to fit
        return fallback


def speed_bin_factors(
    z: dict[str, np.ndarray],
    censored: dict[str, np.ndarray],
    used: np.ndarray,
    speed: np.ndarray,
    n_bins: int,
    coverage: float | None,
    levels: Sequence[float] | None = None,
) -> SpeedBinFactors:
    """Std factors of X and F per command-speed bin (quantile bins of the used samples' speed).

    The same for any other binning variable in place of the speed (the input novelty).

    Parameters
    ----------
    z, censored
        ``{"X": (n,), "F": (n,)}`` out-of-fold standardised residuals, and which are censored.
    used
        ``(n,)`` the samples with both residuals.
    speed
        ``(n,)`` command speed (NaN where undefined: those samples take ``scale_all``).
    n_bins
        Bins of the speed (fewer when quantiles coincide).
    coverage
        None: maximum likelihood; a level ``q``: calibrated by coverage.
    levels
        The quantiles of the speed that cut the bins (default: ``n_bins`` bins of equal mass).
    """
    fast = speed[used & np.isfinite(speed)]
    levels = np.arange(1, n_bins) / n_bins if levels is None else np.asarray(levels, float)
    edges = np.quantile(fast, levels) if (levels.size and fast.size) else []
    edges = np.unique(np.asarray(edges, dtype=np.float64))
    nb = edges.size + 1
    bins = speed_bins(edges, speed)
    rows = {c: used & ~censored[c] for c in ("X", "F")}
    scale_all = {c: _scale(z[c][rows[c]], 1.0, coverage) for c in ("X", "F")}
    scale = {
        c: np.array(
            [_scale(z[c][rows[c] & (bins == b)], scale_all[c], coverage) for b in range(nb)]
        )
        for c in ("X", "F")
    }
    factor = {
        c: np.where(bins >= 0, scale[c][np.clip(bins, 0, nb - 1)], scale_all[c]) for c in ("X", "F")
    }
    return SpeedBinFactors(edges, scale, scale_all, factor)

"""Interval calibration of the normal models: cross-fitted std factors per command-speed bin.

`NormalModels` (``interval_calibration="cross-fit"``) makes the predictive standard deviations of
its regressors honest out of sample with `cross_fit_std_scales`: the fault-free runs are split into
folds by run (by contiguous time block when there are fewer runs than folds), each output's
regressor is refitted without each fold, and the held-out standardised residuals fit one
`~bayes_fdi.diagnosis.normal_models.std_scaler.StdScaler` factor per bin of the command speed
``|dCV/dt|`` (`command_speed`,
`~bayes_fdi.diagnosis.normal_models.speed_factors.speed_bins`). The rules in full are the Notes of
`~bayes_fdi.diagnosis.normal_models.static.NormalModels`.
"""

from __future__ import annotations

import time
from typing import Any, NamedTuple

import numpy as np
import xarray as xr
from sklearn.base import clone

from bayes_fdi.datasets import OUTPUT_CHANNELS
from bayes_fdi.diagnosis.normal_models.speed_factors import cross_fit_folds, speed_bins
from bayes_fdi.diagnosis.normal_models.std_scaler import StdScaler

__all__ = [
    "CrossFitScales",
    "command_speed",
    "cross_fit_std_scales",
    "predict_with_std",
]


class CrossFitScales(NamedTuple):
    """Result of `cross_fit_std_scales` (the ``std_scale*_`` attributes of `NormalModels`).

    Attributes
    ----------
    scale : dict
        Output name -> one factor per ``|dCV/dt|`` bin.
    scale_all : dict
        Output name -> the factor fitted on all held-out residuals together.
    edges : numpy.ndarray
        Inner bin edges of ``|dCV/dt|`` (per second).
    fold : numpy.ndarray
        ``(n_runs, n_times)`` fold of each sample (-1: not used, e.g. NaN).
    seconds : float
        Wall-clock seconds of the refits and held-out predictions.
    """

    scale: dict[str, np.ndarray]
    scale_all: dict[str, float]
    edges: np.ndarray
    fold: np.ndarray
    seconds: float


def predict_with_std(est: Any, X: np.ndarray, chunk: int) -> tuple[np.ndarray, np.ndarray]:
    """Predictive means and standard deviations of ``est`` on ``X``, ``chunk`` rows a call.

    ``est.predict(X, return_std=True)`` must return ``(mean, std)``; both come back as flat
    float64 arrays.
    """
    means, stds = [], []
    for start in range(0, X.shape[0], chunk):
        out = est.predict(X[start : start + chunk], return_std=True)
        if not (isinstance(out, tuple) and len(out) == 2):
            raise ValueError(
                f"{type(est).__name__}.predict(X, return_std=True) must return (mean, std)"
            )
        means.append(np.asarray(out[0], dtype=np.float64).ravel())
        stds.append(np.asarray(out[1], dtype=np.float64).ravel())
    if not means:
        return np.empty(0), np.empty(0)
    return np.concatenate(means), np.concatenate(stds)


def command_speed(runs: xr.Dataset) -> np.ndarray:
    """``|dCV/dt|`` per sample (per second, central differences), flattened run-major."""
    cv = np.asarray(runs["CV"].transpose("run", "time").values, dtype=np.float64)
    if cv.shape[1] < 2:
        return np.full(cv.size, np.nan)
    t = np.asarray(runs["time"].values, dtype=np.float64)
    return np.abs(np.gradient(cv, t, axis=1)).ravel()


def cross_fit_std_scales(
    runs: xr.Dataset,
    U: np.ndarray,
    targets: dict[str, np.ndarray],
    finite: np.ndarray,
    regressors: dict[str, Any],
    *,
    width_param: str,
    n_folds: int,
    n_bins: int,
    method: str,
    max_samples: int | None,
    chunk_size: int,
    random_state: int | None,
) -> CrossFitScales:
    """Cross-fitted scale factors of the regressors' predictive stds, per ``|dCV/dt|`` bin.

    Parameters
    ----------
    runs
        The fault-free training runs (their sizes and ``CV``).
    U
        ``(n_runs * n_times, n_inputs)`` model inputs, run-major.
    targets
        Output name -> ``(n_runs * n_times,)`` observed values.
    finite
        Samples with finite inputs and outputs (the only ones put in folds).
    regressors
        Output name -> the fitted regressor; each fold refits a clone with its parameters (a
        width ``"auto"`` replaced by the width the fit found, read from ``<width_param>_``).
    width_param
        Name of the regressors' kernel-width parameter.
    n_folds, n_bins, method, max_samples
        ``calibration_folds``, ``calibration_bins``, ``calibration_method`` and
        ``calibration_max_samples`` of `NormalModels`.
    chunk_size
        Samples per ``predict`` call.
    random_state
        Seed of the fold split and of the refits' subsamples (``None``: unseeded).

    Returns
    -------
    CrossFitScales
        The factors, the bin edges, the fold of every sample and the time taken.
    """
    k = int(n_folds)
    n_runs, n_times = runs.sizes["run"], runs.sizes["time"]
    rng = np.random.default_rng(None if random_state is None else [int(random_state), 7919])
    # segments: whole runs, or contiguous time blocks when there are fewer runs than folds
    fold = np.where(finite, cross_fit_folds(n_runs, n_times, k, rng).ravel(), -1)
    speed = command_speed(runs)
    t0 = time.perf_counter()
    z = {name: np.full(U.shape[0], np.nan) for name in OUTPUT_CHANNELS}
    for name, y in targets.items():
        fitted = regressors[name]
        est0 = clone(fitted)  # the final fit's parameters, width search included
        if est0.get_params().get(width_param, None) == "auto" and hasattr(
            fitted, f"{width_param}_"
        ):  # keep the width the final fit found instead of searching again per fold
            est0.set_params(**{width_param: getattr(fitted, f"{width_param}_")})
        for f in range(k):
            held = np.flatnonzero(fold == f)
            train = np.flatnonzero((fold >= 0) & (fold != f))
            if held.size == 0 or train.size < 2:
                continue
            if max_samples is not None and train.size > int(max_samples):
                train = np.sort(rng.choice(train, size=int(max_samples), replace=False))
            est = clone(est0).fit(U[train], y[train])
            mean, std = predict_with_std(est, U[held], int(chunk_size))
            ok = np.isfinite(std) & (std > 0)
            z[name][held[ok]] = (y[held[ok]] - mean[ok]) / std[ok]
    seconds = time.perf_counter() - t0
    used = np.all([np.isfinite(z[name]) for name in OUTPUT_CHANNELS], axis=0)
    nb = int(n_bins)
    fast = speed[used]
    fast = fast[np.isfinite(fast)]
    edges = np.quantile(fast, np.arange(1, nb) / nb) if (nb > 1 and fast.size) else []
    edges = np.asarray(edges, dtype=np.float64)
    bins = speed_bins(edges, speed)
    scale: dict[str, np.ndarray] = {}
    scale_all: dict[str, float] = {}
    for name in OUTPUT_CHANNELS:
        zn = z[name][used]
        scaler = StdScaler(method=method)
        scale_all[name] = scaler.fit(zn, np.zeros_like(zn), np.ones_like(zn)).scale_
        scales = np.full(nb, scale_all[name])
        for b in range(nb):
            zb = z[name][used & (bins == b)]
            if zb.size >= 10 and np.any(zb != 0):
                scales[b] = scaler.fit(zb, np.zeros_like(zb), np.ones_like(zb)).scale_
        scale[name] = scales
    return CrossFitScales(scale, scale_all, edges, fold.reshape(n_runs, n_times), seconds)

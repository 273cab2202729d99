"""Diagnosing runs of which a window holds no complete sample, for the SEVA records.

`FaultDiagnoser.diagnose` refuses a run with a window whose features cannot be computed (no
sample with every channel finite). :func:`diagnose_allowing_empty_windows` diagnoses such runs
window by window instead: the empty windows get a NaN distribution (their records are BLIND by
the screening of `bayes_fdi.diagnosis.seva.rules`), the others are diagnosed as ``diagnose``
would, so one empty window does not take the whole batch down.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.datasets import CHANNELS
from bayes_fdi.diagnosis.isolation.features import extract_features, window_bounds

__all__ = ["DIAGNOSIS_VARIABLES", "diagnose_allowing_empty_windows"]

#: The variables of a diagnosis that the SEVA records read (``features`` when present).
DIAGNOSIS_VARIABLES = ("proba", "X_hat", "X_hat_std", "F_hat", "F_hat_std", "features")


def _empty_windows(diagnoser: Any, runs: xr.Dataset) -> np.ndarray | None:
    """``(n_runs, n_windows)``: True where a window holds no sample with every channel finite.

    None when ``diagnoser`` is not windowed (no ``window`` attribute, or ``window=None``).
    """
    window = getattr(diagnoser, "window", None)
    if window is None:
        return None
    bounds = window_bounds(runs.sizes["time"], window, getattr(diagnoser, "step", None))
    finite = np.ones((runs.sizes["run"], runs.sizes["time"]), dtype=bool)
    for c in CHANNELS:
        if c in runs:
            finite &= np.isfinite(np.asarray(runs[c].transpose("run", "time").values, dtype=float))
    cum = np.concatenate([np.zeros((finite.shape[0], 1)), np.cumsum(finite, axis=1)], axis=1)
    return (cum[:, bounds[:, 1]] - cum[:, bounds[:, 0]]) == 0


def _diagnose_with_empty_windows(diagnoser: Any, runs: xr.Dataset) -> xr.Dataset:
    """The windowed diagnosis of a `FaultDiagnoser`, NaN for windows without features.

    ``FaultDiagnoser.diagnose`` refuses a run with a window whose features cannot be computed
    (no finite residual); here such windows get a NaN distribution (their records are BLIND
    by the screening) and the other windows of the run are diagnosed as ``diagnose`` would,
    through the diagnoser's public parts (``normal_models_``, ``feature_names_``,
    ``predict_features``, ``classes_``).
    """
    res = diagnoser.normal_models_.residuals(runs)
    names = tuple(diagnoser.feature_names_)
    step = getattr(diagnoser, "step", None)
    feats, _ = extract_features(res, names, diagnoser.window, step)
    n_runs, n_win, n_feat = feats.shape
    flat = feats.reshape(-1, n_feat)
    ok = np.all(np.isfinite(flat), axis=1)
    classes = np.asarray(diagnoser.classes_).astype(str)
    proba = np.full((flat.shape[0], classes.size), np.nan)
    if ok.any():
        proba[ok] = diagnoser.predict_features(flat[ok])
    bounds = window_bounds(runs.sizes["time"], diagnoser.window, step)
    times = np.asarray(runs["time"].values, dtype=np.float64)
    out = res[["X_hat", "X_hat_std", "F_hat", "F_hat_std"]].assign_coords(
        {
            "class": classes,
            "feature": list(names),
            "window_start": ("window", times[bounds[:, 0]]),
            "window_end": ("window", times[bounds[:, 1] - 1] + 1.0),
        }
    )
    out["proba"] = (("run", "window", "class"), proba.reshape(n_runs, n_win, classes.size))
    out["features"] = (("run", "window", "feature"), feats)
    return out


def diagnose_allowing_empty_windows(diagnoser: Any, runs: xr.Dataset) -> xr.Dataset:
    """``diagnoser.diagnose(runs)``; runs with an all-missing window diagnosed window by window.

    One window without a single complete sample must not take the whole batch down: the runs
    holding such a window are diagnosed window by window (NaN distributions for the empty
    ones) when the diagnoser is a windowed `FaultDiagnoser` (or exposes the same public parts:
    ``normal_models_``, ``feature_names_``, ``predict_features``, ``classes_``); other
    diagnosers get ``diagnose`` and its error.
    """
    empty = _empty_windows(diagnoser, runs)
    parts = ("normal_models_", "feature_names_", "predict_features", "classes_")
    if empty is None or not empty.any() or not all(hasattr(diagnoser, a) for a in parts):
        return diagnoser.diagnose(runs)
    gappy = empty.any(axis=1)
    pieces = [_diagnose_with_empty_windows(diagnoser, runs.isel(run=np.flatnonzero(gappy)))]
    if not gappy.all():
        pieces.append(diagnoser.diagnose(runs.isel(run=np.flatnonzero(~gappy))))
    pieces = [p[[v for v in DIAGNOSIS_VARIABLES if v in p.data_vars]] for p in pieces]
    order = np.concatenate([np.flatnonzero(gappy), np.flatnonzero(~gappy)])
    joined = xr.concat(pieces, dim="run", coords="minimal", compat="override", join="override")
    return joined.isel(run=np.argsort(order, kind="stable"))

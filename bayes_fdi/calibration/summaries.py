"""The numbers of a calibration report: class-distribution and normal-model summaries.

:func:`classification_summary` (accuracy, log loss, Brier score and the ECEs of one column of
the report), :func:`normal_model_summary` (coverage, CRPS and PIT of the normal models),
:func:`split_in_time` and :func:`time_split_summary` (fit on the first part of a record, score
on the rest), and the helpers that read a diagnosis into labels and probabilities.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.calibration.intervals import (
    DEFAULT_LEVELS,
    crps_gaussian,
    interval_coverage,
    pit_histogram,
    pit_values,
)
from bayes_fdi.calibration.metrics import ECEResult, brier, expected_calibration_error, log_loss

__all__ = [
    "classification_summary",
    "labelled_rows",
    "normal_model_summary",
    "public_values",
    "split_in_time",
    "time_split_summary",
]


def _ece_dict(res: ECEResult) -> dict[str, Any]:
    return {
        "value": res.value,
        "ci_low": res.ci_low,
        "ci_high": res.ci_high,
        "mce": res.mce,
        "debiased": res.debiased,
        "noise_floor": res.noise_floor,
        "strategy": res.strategy,
        "classwise": res.classwise,
        "bin_edges": np.asarray(res.bin_edges).tolist(),
        "bin_counts": np.asarray(res.bin_counts).tolist(),
        "bin_confidence": np.asarray(res.bin_confidence).tolist(),
        "bin_accuracy": np.asarray(res.bin_accuracy).tolist(),
    }


def classification_summary(
    y_true: Any,
    proba: Any,
    classes: Any,
    *,
    n_bins: int = 15,
    n_bootstrap: int = 500,
    random_state: int | None = 0,
) -> dict[str, Any]:
    """Calibration and scores of a class distribution (the numbers of one report column).

    Returns
    -------
    dict
        ``n``, ``accuracy``, ``log_loss``, ``brier`` (multi-class, [0, 2]), ``ece``
        (top-label, equal-width bins), ``ece_quantile`` (top-label, equal-mass bins),
        ``ece_classwise`` (equal-width); each ECE as a dict with bootstrap interval, MCE and bins.
    """
    y = np.asarray(y_true)
    p = np.asarray(proba, dtype=np.float64)
    cls = np.asarray(classes)
    kw = {"classes": cls, "n_bins": n_bins, "n_bootstrap": n_bootstrap}
    top = expected_calibration_error(y, p, random_state=random_state, **kw)
    n_q = min(n_bins, y.shape[0])
    quant = expected_calibration_error(
        y, p, strategy="quantile", random_state=random_state, **(kw | {"n_bins": n_q})
    )
    cw = expected_calibration_error(y, p, classwise=True, random_state=random_state, **kw)
    return {
        "n": int(y.shape[0]),
        "accuracy": float(np.mean(cls[np.argmax(p, axis=1)] == y)),
        "log_loss": log_loss(y, p, classes=cls),
        "brier": brier(y, p, classes=cls),
        "ece": _ece_dict(top),
        "ece_quantile": _ece_dict(quant),
        "ece_classwise": _ece_dict(cw),
        "_results": (top, quant, cw),
    }


def _aligned(diag: xr.Dataset, runs: xr.Dataset, name: str, hat: str) -> tuple[np.ndarray, ...]:
    """Measured ``name`` and the predictions ``hat``/``hat_std`` on the diagnosis' time grid."""
    if hat not in diag or f"{hat}_std" not in diag:
        raise ValueError(f"diagnosis lacks {hat!r} or {hat + '_std'!r}")
    mean = diag[hat].transpose("run", ...)
    std = diag[f"{hat}_std"].transpose("run", ...)
    meas = runs[name]
    if "time" in mean.dims and "time" in mean.coords:
        meas = meas.sel(time=mean["time"].values)
    y = np.asarray(meas.transpose("run", "time").values, dtype=np.float64)
    m = np.asarray(mean.values, dtype=np.float64).reshape(y.shape)
    s = np.asarray(std.values, dtype=np.float64).reshape(y.shape)
    return y, m, s


def normal_model_summary(
    diagnosis: xr.Dataset,
    runs: xr.Dataset,
    *,
    levels: tuple[float, ...] = DEFAULT_LEVELS,
    outputs: tuple[str, ...] = ("X", "F"),
) -> dict[str, Any]:
    """Coverage, mean interval width, CRPS and PIT of the normal models on ``runs``.

    ``runs`` should be fault-free (the normal models describe the fault-free actuator).
    Samples where the measurement or the prediction is not finite are excluded and counted
    (``n_excluded``).

    Returns
    -------
    dict
        Per output: ``n``, ``n_excluded``, ``coverage`` (``CoverageResult.as_dict()``),
        ``crps`` (mean), ``rmse``, ``mean_std``, ``pit_density`` and ``pit_edges`` (10 bins),
        and ``_pit`` (the PIT values, for plotting).
    """
    out: dict[str, Any] = {}
    for name in outputs:
        y, m, s = _aligned(diagnosis, runs, name, f"{name}_hat")
        ok = np.isfinite(y) & np.isfinite(m) & np.isfinite(s) & (s > 0)
        y, m, s = y[ok], m[ok], s[ok]
        if y.size == 0:
            raise ValueError(f"no finite fault-free samples of {name} to score")
        cov = interval_coverage(y, m, s, levels=levels)
        pit = pit_values(y, m, s)
        dens, edges = pit_histogram(pit, 10)
        out[name] = {
            "n": int(y.size),
            "n_excluded": int((~ok).sum()),
            "coverage": cov.as_dict(),
            "crps": float(crps_gaussian(y, m, s).mean()),
            "rmse": float(np.sqrt(np.mean((y - m) ** 2))),
            "mean_std": float(np.mean(s)),
            "pit_density": dens.tolist(),
            "pit_edges": edges.tolist(),
            "_pit": pit,
        }
    return out


def split_in_time(runs: xr.Dataset, fraction: float = 0.5) -> tuple[xr.Dataset, xr.Dataset]:
    """Split every run at ``fraction`` of its length: ``(first part, second part)``.

    Both parts keep their original ``time`` coordinate (the second part starts at the split
    time), so nothing is re-labelled.
    """
    if not 0 < fraction < 1:
        raise ValueError(f"fraction must lie in (0, 1), got {fraction}")
    n = runs.sizes["time"]
    cut = round(fraction * n)
    if cut < 1 or cut >= n:
        raise ValueError(f"cannot split {n} samples at fraction {fraction}")
    return runs.isel(time=slice(0, cut)), runs.isel(time=slice(cut, n))


def time_split_summary(
    normal_model: Any,
    runs: xr.Dataset,
    *,
    fraction: float = 0.5,
    levels: tuple[float, ...] = DEFAULT_LEVELS,
) -> dict[str, Any]:
    """Fit a normal model on the first part of fault-free runs, score it on the rest.

    This is the honest test of the normal models on a single real record (e.g. the Lublin
    hour): fit on its first half, test on its second half, which the model has not seen and
    which lies later in time.

    Parameters
    ----------
    normal_model
        An unfitted model with ``fit(runs) -> self`` and ``predict(runs) -> Dataset`` of
        ``X_hat``, ``X_hat_std``, ``F_hat``, ``F_hat_std`` (e.g.
        ``bayes_fdi.diagnosis.normal_models.static.NormalModels``).
    runs
        Fault-free runs.
    fraction
        Share of each run used for fitting (default 0.5).
    levels
        Central-interval levels.

    Returns
    -------
    dict
        As :func:`normal_model_summary` (without private entries), plus ``fraction``,
        ``n_fit_samples`` and ``split_time`` (s).
    """
    first, second = split_in_time(runs, fraction)
    model = normal_model.fit(first)
    summary = normal_model_summary(model.predict(second), second, levels=levels)
    out = public_values(summary)
    out["fraction"] = float(fraction)
    out["n_fit_samples"] = int(first.sizes["run"] * first.sizes["time"])
    out["split_time"] = float(second["time"].values[0])
    return out


def labelled_rows(
    diag: xr.Dataset, runs: xr.Dataset
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """True labels, class distributions and features, one row per run (or run and window).

    For windowed diagnoses a window whose last sample is at or before its run's fault
    ``onset`` is labelled ``"fn"`` (the fault is not yet present), as FaultDiagnoser labels
    its training windows.
    """
    if "state" not in runs.coords:
        raise ValueError("runs must carry the per-run coordinate 'state'")
    states = np.asarray(runs["state"].values).astype(str)
    proba_da = diag["proba"]
    feats = None
    if "window" in proba_da.dims:
        proba = np.asarray(proba_da.transpose("run", "window", "class").values, dtype=np.float64)
        last = np.asarray(diag["window_end"].values, dtype=np.float64) - 1.0
        onset = (
            np.asarray(runs["onset"].values, dtype=np.float64)
            if "onset" in runs.coords
            else np.full(states.size, -np.inf)
        )
        y = np.where(last[None, :] <= onset[:, None], "fn", states[:, None]).ravel()
        proba = proba.reshape(-1, proba.shape[-1])
        if "features" in diag:
            f = diag["features"].transpose("run", "window", ...).values
            feats = np.asarray(f, dtype=np.float64).reshape(proba.shape[0], -1)
    else:
        proba = np.asarray(proba_da.transpose("run", "class").values, dtype=np.float64)
        y = states
        if "features" in diag:
            f = diag["features"].transpose("run", ...).values
            feats = np.asarray(f, dtype=np.float64).reshape(proba.shape[0], -1)
    return y, proba, feats


def public_values(d: Any) -> Any:
    """``d`` without its private (``_``-prefixed) keys, as plain JSON values (NaN as None)."""
    if isinstance(d, dict):
        return {k: public_values(v) for k, v in d.items() if not str(k).startswith("_")}
    if isinstance(d, list | tuple):
        return [public_values(v) for v in d]
    if isinstance(d, float) and not math.isfinite(d):
        return None
    if isinstance(d, np.generic):
        return public_values(d.item())
    return d

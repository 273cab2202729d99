"""Calibration report of a fitted diagnoser on a test dataset (``bayes-fdi calibration-report``).

:func:`write_calibration_report` diagnoses the test runs and writes into ``out_dir``:

- ``report.md``: the whole tree's calibration (top-label ECE with equal-width and equal-mass
  bins and bootstrap intervals, classwise ECE, MCE, log loss, Brier score, accuracy)
  before and after recalibration by one temperature, vector scaling and Dirichlet
  calibration side by side, the ECE under other binnings with its noise floor; the binary
  calibration of every tree node; the normal models' central-interval coverage
  (50/80/90/95 %), mean widths, CRPS and PIT histograms on the fault-free test runs;
- ``figures/*.png``: reliability diagrams before/after recalibration, PIT histograms;
- ``calibration.json``: every number of the report.

It only uses the diagnoser's public contract: ``diagnose(runs)`` returning the Dataset of
``CONTRACTS.md`` (``proba (run, class)``, ``features (run, feature)``, ``X_hat``,
``X_hat_std``, ``F_hat``, ``F_hat_std``) and, for the per-node table,
``diagnoser.classifier_.nodes_`` (nodes with ``.left``, ``.right``, ``.estimator``).

The recalibrators are fitted on held-out data: on ``calibration_runs`` when given,
otherwise by cross-fitting on the test runs (``n_folds`` seeded folds stratified by class,
five by default; each fold is recalibrated by recalibrators fitted on the other folds), so no
run is scored by a recalibrator fitted on itself. The report's "after" column is, in every
fit, the recalibrator of lowest cross-validated log loss on that fit's fitting runs alone
(:func:`recalibrate`).
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.calibration import (
    DEFAULT_LEVELS,
    DirichletScaler,
    ECEResult,
    TemperatureScaler,
    brier,
    cross_val_log_loss,
    crps_gaussian,
    expected_calibration_error,
    interval_coverage,
    log_loss,
    node_calibration,
    pit_histogram,
    pit_values,
    plot_pit_histogram,
    reliability_diagram,
)
from bayes_fdi.calibration.recalibration import fold_indices

__all__ = [
    "RECALIBRATORS",
    "classification_summary",
    "configure_parser",
    "make_recalibrator",
    "normal_model_summary",
    "recalibrate",
    "run_from_cli",
    "split_in_time",
    "time_split_summary",
    "write_calibration_report",
]


# --------------------------------------------------------------------------------------
# numbers
# --------------------------------------------------------------------------------------
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
        ``bayes_fdi.diagnosis.normal_models.NormalModels``).
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
    out = _strip_private(summary)
    out["fraction"] = float(fraction)
    out["n_fit_samples"] = int(first.sizes["run"] * first.sizes["time"])
    out["split_time"] = float(second["time"].values[0])
    return out


def _samples(
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


#: Recalibrators compared by the report, in column order.
RECALIBRATORS: tuple[str, ...] = ("temperature", "vector", "dirichlet")

_RECAL_LABELS = {"temperature": "temperature", "vector": "vector", "dirichlet": "Dirichlet"}


def make_recalibrator(name: str, classes: Any, seed: int = 0) -> Any:
    """A fresh recalibrator: ``"temperature"`` (:class:`TemperatureScaler`), ``"vector"``
    (:class:`DirichletScaler` with ``parametrization="diagonal"``) or ``"dirichlet"``
    (:class:`DirichletScaler`, full matrix, ODIR penalty cross-validated with seed ``seed``).
    """
    if name == "temperature":
        return TemperatureScaler(classes=classes)
    if name == "vector":
        return DirichletScaler(parametrization="diagonal", classes=classes, random_state=seed)
    if name == "dirichlet":
        return DirichletScaler(classes=classes, random_state=seed)
    raise ValueError(f"unknown recalibrator {name!r}; choose from {RECALIBRATORS}")


def _fit_and_select(
    p_fit: np.ndarray,
    y_fit: np.ndarray,
    classes: np.ndarray,
    methods: tuple[str, ...],
    cv: int,
    seed: int,
) -> tuple[dict[str, Any], str, dict[str, Any]]:
    """Fit every method on ``(p_fit, y_fit)``; select the one of lowest cross-validated
    log loss on these data alone (temperature when too few runs to cross-validate)."""
    fitted = {m: make_recalibrator(m, classes, seed).fit(p_fit, y_fit) for m in methods}
    n = y_fit.shape[0]
    scores: dict[str, float] = {}
    if n >= 2 * cv:
        for m in methods:
            scores[m] = cross_val_log_loss(
                make_recalibrator(m, classes, seed), p_fit, y_fit, classes=classes, cv=cv,
                random_state=seed,
            )  # fmt: skip
        selected = min(methods, key=lambda m: (scores[m], methods.index(m)))
        why = f"lowest {cv}-fold cross-validated log loss on the {n} fitting runs"
    else:
        selected = "temperature" if "temperature" in methods else methods[0]
        why = f"only {n} fitting runs (< {2 * cv}): no cross-validation, {selected} by default"
    info: dict[str, Any] = {
        "n_fit": int(n),
        "cv_log_loss": scores,
        "selected": selected,
        "why": why,
    }
    for m, est in fitted.items():
        d: dict[str, Any] = {"nll_fit_before": est.nll_before_, "nll_fit_after": est.nll_after_}
        if m == "temperature":
            d["temperature"] = est.temperature_
        else:
            d.update(
                reg_lambda=est.reg_lambda_, reg_mu=est.reg_mu_, fallback=est.fallback_,
                parametrization=est.parametrization_, converged=est.converged_,
            )  # fmt: skip
        info[m] = d
    return fitted, selected, info


def recalibrate(
    y: Any,
    proba: Any,
    classes: Any,
    *,
    calibration: tuple[Any, Any] | None = None,
    n_folds: int = 5,
    methods: tuple[str, ...] = RECALIBRATORS,
    cv: int = 5,
    seed: int = 0,
) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Recalibrated class distributions of every method and of the selected one.

    With ``calibration=(proba_cal, y_cal)`` each method is fitted on those runs and applied to
    ``proba``. Without, the runs are **cross-fitted**: split into ``n_folds`` folds
    (stratified by class, seeded), each fold recalibrated by methods fitted on the other
    folds, so that no run is scored by a recalibrator fitted on itself. In every fit the
    method whose ``cv``-fold cross-validated log loss *on the fitting runs* is lowest is the
    selected one (``"after"``); the scored runs never enter the choice. Folds may select
    different methods.

    Parameters
    ----------
    y, proba, classes
        Labels, class distributions ``(n, K)`` and column labels of the scored runs.
    calibration
        Optional held-out ``(proba_cal, y_cal)``.
    n_folds
        Cross-fitting folds (>= 2) when no calibration runs are given.
    methods
        Names of :func:`make_recalibrator`.
    cv
        Folds of the selection's cross-validation (and of the Dirichlet penalty's).
    seed
        Seed of the folds.

    Returns
    -------
    proba_by_method : dict
        ``method -> (n, K)`` recalibrated distributions, plus ``"after"`` (the selected).
    info : dict
        Per fit (``fits``: one entry, or one per fold): runs, cross-validated log losses,
        selected method, temperature and penalties.
    """
    yv = np.asarray(y)
    p = np.asarray(proba, dtype=np.float64)
    cls = np.asarray(classes)
    methods = tuple(methods)
    if not methods:
        raise ValueError("methods must name at least one recalibrator")
    for m in methods:
        if m not in RECALIBRATORS:
            raise ValueError(f"unknown recalibrator {m!r}; choose from {RECALIBRATORS}")
    out = {m: np.empty_like(p) for m in (*methods, "after")}
    fits = []
    if calibration is not None:
        p_cal = np.asarray(calibration[0], dtype=np.float64)
        y_cal = np.asarray(calibration[1])
        fitted, sel, info = _fit_and_select(p_cal, y_cal, cls, methods, cv, seed)
        for m, est in fitted.items():
            out[m] = est.transform(p)
        out["after"] = out[sel].copy()
        info["scored"] = int(yv.shape[0])
        fits.append(info)
        how = "fitted on the calibration runs"
    else:
        if int(n_folds) != n_folds or not 2 <= n_folds <= yv.shape[0]:
            raise ValueError(f"n_folds must be an integer in [2, {yv.shape[0]}], got {n_folds!r}")
        lookup = {c: i for i, c in enumerate(cls.tolist())}
        y_idx = np.array([lookup[v] for v in yv.tolist()], dtype=np.intp)
        for fold in fold_indices(y_idx, int(n_folds), seed):
            rest = np.setdiff1d(np.arange(yv.shape[0]), fold)
            fitted, sel, info = _fit_and_select(p[rest], yv[rest], cls, methods, cv, seed)
            for m, est in fitted.items():
                out[m][fold] = est.transform(p[fold])
            out["after"][fold] = out[sel][fold]
            info["scored"] = int(fold.size)
            fits.append(info)
        how = f"{int(n_folds)}-fold cross-fitted on the test runs (folds stratified by class)"
    return out, {"how": how, "methods": list(methods), "fits": fits}


def _strip_private(d: Any) -> Any:
    if isinstance(d, dict):
        return {k: _strip_private(v) for k, v in d.items() if not str(k).startswith("_")}
    if isinstance(d, list | tuple):
        return [_strip_private(v) for v in d]
    if isinstance(d, float) and not math.isfinite(d):
        return None
    if isinstance(d, np.generic):
        return _strip_private(d.item())
    return d


# --------------------------------------------------------------------------------------
# report
# --------------------------------------------------------------------------------------
def _num(v: float | None) -> str:
    return "–" if v is None or not np.isfinite(v) else f"{v:.4f}"


def _fmt_ece(e: dict[str, Any]) -> str:
    """``plug-in (bias-corrected [basic CI])``, or just the plug-in without bootstrap."""
    if e["ci_low"] is None or not np.isfinite(e["ci_low"]):
        return f"{e['value']:.4f}"
    return f"{e['value']:.4f} ({_num(e['debiased'])} [{e['ci_low']:.4f}, {e['ci_high']:.4f}])"


def write_calibration_report(
    diagnoser: Any,
    test_runs: xr.Dataset,
    out_dir: str | Path,
    *,
    calibration_runs: xr.Dataset | None = None,
    n_bins: int = 15,
    n_bootstrap: int = 500,
    seed: int = 0,
    title: str = "Calibration report",
    n_folds: int = 5,
    methods: tuple[str, ...] = RECALIBRATORS,
) -> Path:
    """Diagnose ``test_runs`` and write a calibration report (Markdown + figures + JSON).

    Parameters
    ----------
    diagnoser
        A fitted diagnoser (``FaultDiagnoser`` contract: ``diagnose(runs)``; ``classifier_``
        with ``nodes_`` for the per-node table, optional).
    test_runs
        Labelled test runs (coordinate ``state``); runs whose state the diagnoser does not
        know are excluded from the classification metrics and counted in the report.
        Fault-free (``"fn"``) runs are used for the normal-model section.
    out_dir
        Output folder (created).
    calibration_runs
        Held-out labelled runs on which the recalibrators are fitted; default:
        ``n_folds``-fold cross-fitting on the test runs (see :func:`recalibrate`).
    n_bins, n_bootstrap, seed
        ECE bins, bootstrap resamples and the seed of bootstrap, cross-fitting and
        cross-validation.
    title
        First heading of the report.
    n_folds
        Cross-fitting folds when no ``calibration_runs`` are given (default 5).
    methods
        Recalibrators compared (:data:`RECALIBRATORS`); the report's ``after`` column is, in
        every fit, the one of lowest cross-validated log loss on the fitting runs.

    Returns
    -------
    pathlib.Path
        Path of ``report.md``.
    """
    return _write_report(
        diagnoser,
        test_runs,
        out_dir,
        calibration_runs=calibration_runs,
        n_bins=n_bins,
        n_bootstrap=n_bootstrap,
        seed=seed,
        title=title,
        n_folds=n_folds,
        methods=methods,
    )[0]


def _write_report(
    diagnoser: Any,
    test_runs: xr.Dataset,
    out_dir: str | Path,
    *,
    calibration_runs: xr.Dataset | None,
    n_bins: int,
    n_bootstrap: int,
    seed: int,
    title: str,
    n_folds: int,
    methods: tuple[str, ...],
) -> tuple[Path, dict[str, Any]]:
    """:func:`write_calibration_report`, also returning the content of ``calibration.json``."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    fig_dir = out / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    if "state" not in test_runs.coords:
        raise ValueError("test_runs must carry the per-run coordinate 'state'")

    diag = diagnoser.diagnose(test_runs)
    classes = np.asarray([str(c) for c in diag["class"].values])
    y_samples, proba, feats_all = _samples(diag, test_runs)
    known = np.isin(y_samples, classes)
    y, p = y_samples[known], proba[known]
    if y.size < 2:
        raise ValueError("fewer than two test samples have a state the diagnoser knows")
    y_all = np.asarray(test_runs["state"].values).astype(str)
    results: dict[str, Any] = {
        "title": title,
        "classes": classes.tolist(),
        "n_test_runs": int(y_all.size),
        "n_samples": int(y_samples.size),
        "windowed": bool("window" in diag["proba"].dims),
        "n_excluded_unknown_state": int((~known).sum()),
        "excluded_states": sorted(set(y_samples[~known].tolist())),
    }
    kw = {"n_bins": n_bins, "n_bootstrap": n_bootstrap, "random_state": seed}

    # ---- recalibration on held-out data
    if calibration_runs is not None:
        if "state" not in calibration_runs.coords:
            raise ValueError("calibration_runs must carry the per-run coordinate 'state'")
        ycal, pcal, _ = _samples(diagnoser.diagnose(calibration_runs), calibration_runs)
        kcal = np.isin(ycal, classes)
        if kcal.sum() < 1:
            raise ValueError("no calibration run has a state the diagnoser knows")
        calibration = (pcal[kcal], ycal[kcal])
    else:
        calibration = None
    p_by, info = recalibrate(
        y, p, classes, calibration=calibration, n_folds=n_folds, methods=methods, seed=seed
    )
    fits = info["fits"]
    temps = [f["temperature"]["temperature"] for f in fits if "temperature" in f]
    recal: dict[str, Any] = {
        "method": f"recalibrators {info['how']}; 'after' = the one of lowest cross-validated "
        "log loss on the fitting runs of each fit",
        "how": info["how"],
        "methods": info["methods"],
        "selected": [f["selected"] for f in fits],
        "n_fit": int(sum(f["n_fit"] for f in fits)) if calibration is None else fits[0]["n_fit"],
        "fits": fits,
    }
    if temps:
        recal["temperature"] = temps[0] if calibration is not None else temps
    columns = {"before": p, **{m: p_by[m] for m in methods}, "after": p_by["after"]}
    summaries = {k: classification_summary(y, v, classes, **kw) for k, v in columns.items()}
    results["recalibration"] = recal
    results["whole_tree"] = summaries

    # ---- how the ECE depends on the binning (value, debiased, interval, floor)
    # (the report's own binnings, n_bins equal width and equal mass, are already in summaries)
    binning = []
    for strategy in ("uniform", "quantile"):
        for nb in sorted({int(n_bins), 10, 5}, reverse=True):
            nb_ = min(nb, y.size) if strategy == "quantile" else nb
            row: dict[str, Any] = {"strategy": strategy, "n_bins": nb_}
            for k, v in columns.items():
                if nb == n_bins:
                    e = summaries[k]["_results"][0 if strategy == "uniform" else 1]
                else:
                    e = expected_calibration_error(y, v, classes=classes, strategy=strategy,
                                                   **(kw | {"n_bins": nb_}))  # fmt: skip
                row[k] = {
                    "value": e.value,
                    "debiased": e.debiased,
                    "ci_low": e.ci_low,
                    "ci_high": e.ci_high,
                    "noise_floor": e.noise_floor,
                }
            binning.append(row)
    results["ece_binning"] = binning

    # ---- reliability diagrams
    shown = ["before", *methods]
    fig, axes = plt.subplots(1, len(shown), figsize=(4.5 * len(shown), 4.5), squeeze=False)
    sel = sorted(set(recal["selected"]))
    for ax, k in zip(axes[0], shown, strict=True):
        mark = " (selected)" if k in sel else ""
        label = "before" if k == "before" else f"{_RECAL_LABELS[k]}{mark}"
        reliability_diagram(summaries[k]["_results"][0], ax=ax,
                            title=f"{label}: ECE {_fmt_ece(summaries[k]['ece'])}")  # fmt: skip
    fig.suptitle("Whole tree, top-label reliability (equal-width bins)", fontsize=10)
    fig.tight_layout()
    fig.savefig(fig_dir / "reliability_whole_tree.png", dpi=120)
    plt.close(fig)

    # ---- per node
    nodes = getattr(getattr(diagnoser, "classifier_", None), "nodes_", None)
    node_rows = []
    node_note = ""
    if nodes is None:
        node_note = "The diagnoser exposes no `classifier_.nodes_`; per-node calibration skipped."
    elif feats_all is None:
        node_note = "The diagnosis has no `features`; per-node calibration skipped."
    else:
        feats = feats_all[known]
        scaler = getattr(diagnoser, "scaler_", None)
        if scaler is not None:  # the tree sees standardised features
            feats = np.asarray(scaler.transform(feats), dtype=np.float64)
        for nc in node_calibration(nodes, feats, y, n_bins=min(n_bins, 10), random_state=seed):
            node_rows.append(
                {
                    "index": nc.index,
                    "left": list(nc.left),
                    "right": list(nc.right),
                    "n": nc.n_samples,
                    "accuracy": nc.accuracy,
                    "ece": None if nc.ece is None else nc.ece.value,
                    "mce": None if nc.ece is None else nc.ece.mce,
                    "log_loss": nc.log_loss,
                    "brier": nc.brier,
                }
            )
    results["nodes"] = node_rows

    # ---- normal models on fault-free runs
    fn = np.flatnonzero(y_all == "fn")
    normal: dict[str, Any] = {}
    if fn.size:
        normal = normal_model_summary(diag.isel(run=fn), test_runs.isel(run=fn))
        fig, axes = plt.subplots(1, len(normal), figsize=(4.5 * len(normal), 3.2))
        for ax, (name, d) in zip(np.atleast_1d(axes), normal.items(), strict=True):
            plot_pit_histogram(d["_pit"], 10, ax=ax, title=f"PIT of {name} (n = {d['n']})")
        fig.tight_layout()
        fig.savefig(fig_dir / "pit_normal_models.png", dpi=120)
        plt.close(fig)
    results["normal_models"] = normal
    results["n_fault_free_runs"] = int(fn.size)

    # ---- write
    clean = _strip_private(results)
    (out / "calibration.json").write_text(json.dumps(clean, indent=2))
    report = out / "report.md"
    report.write_text(_markdown(clean, node_note))
    return report, clean


def _markdown(r: dict[str, Any], node_note: str) -> str:
    wt = r["whole_tree"]
    rc = r["recalibration"]
    cols = ["before", *rc["methods"], "after"]
    names = {"before": "before", "after": "after (selected)", **_RECAL_LABELS}
    head = "| metric | " + " | ".join(names[c] for c in cols) + " |"
    rule = "|---" * (len(cols) + 1) + "|"

    def row(label: str, get: Callable[[dict[str, Any]], str]) -> str:
        return f"| {label} | " + " | ".join(get(wt[c]) for c in cols) + " |"

    fit_lines = []
    for i, f in enumerate(rc["fits"]):
        cvs = ", ".join(f"{_RECAL_LABELS[m]} {v:.4f}" for m, v in f["cv_log_loss"].items())
        extra = []
        if "temperature" in f:
            extra.append(f"T = {f['temperature']['temperature']:.3f}")
        for m in ("vector", "dirichlet"):
            if m in f:
                d = f[m]
                lam = f"λ = {d['reg_lambda']:.3g}, " if m == "dirichlet" else ""
                fb = f", fell back: {d['fallback']}" if d["fallback"] else ""
                extra.append(f"{_RECAL_LABELS[m]} {lam}μ = {d['reg_mu']:.3g}{fb}")
        fit_lines.append(
            f"- fit {i + 1}: {f['n_fit']} fitting runs, {f['scored']} scored; "
            f"selected **{_RECAL_LABELS[f['selected']]}** ({f['why']}"
            + (f": {cvs}" if cvs else "")
            + "); "
            + "; ".join(extra)
            + "."
        )
    bin_lines = [
        "| binning | " + " | ".join(names[c] for c in cols) + " | noise floor (before / after) |",
        "|---" * (len(cols) + 2) + "|",
    ]
    for b in r["ece_binning"]:
        kind = "equal width" if b["strategy"] == "uniform" else "equal mass"
        bin_lines.append(
            f"| {b['n_bins']} bins, {kind} | "
            + " | ".join(_fmt_ece(b[c]) for c in cols)
            + f" | {b['before']['noise_floor']:.4f} / {b['after']['noise_floor']:.4f} |"
        )
    lines = [
        f"# {r['title']}",
        "",
        f"Test runs: {r['n_test_runs']}"
        + (f", diagnosed in {r['n_samples']} windows" if r.get("windowed") else "")
        + f" ({r['n_excluded_unknown_state']} excluded from the "
        f"classification metrics because their state is not among the diagnoser's classes"
        + (f": {', '.join(r['excluded_states'])}" if r["excluded_states"] else "")
        + f"). Classes: {', '.join(r['classes'])}.",
        "",
        "## Whole tree",
        "",
        f"Recalibration: {rc['how']}. Compared: one temperature; vector scaling (one power and "
        "one offset per class); Dirichlet calibration (a full linear map of the "
        "log-probabilities, off-diagonal and intercept penalty chosen by cross-validation). "
        "Vector and Dirichlet scaling can change the diagnosed class (compare the accuracy). "
        "The **after** column is, in every fit, the recalibrator of lowest cross-validated log "
        "loss on that fit's own fitting runs; the scored runs never enter the choice.",
        "",
        *fit_lines,
        "",
        "ECE cells: plug-in estimate (bias-corrected estimate [95 % basic-bootstrap interval "
        "of the population ECE]). The plug-in ECE is biased upwards, so it may lie above the "
        "interval; the bias-corrected value subtracts the bootstrap estimate of that bias. "
        "The noise floor is the ECE a perfectly calibrated model would show on this many "
        "runs: plug-in values near it are indistinguishable from sampling noise. "
        "Brier score is the multi-class one (sum over classes of squared errors, range [0, 2]).",
        "",
        head,
        rule,
        row("accuracy", lambda s: f"{s['accuracy']:.4f}"),
        row("top-label ECE (equal width)", lambda s: _fmt_ece(s["ece"])),
        row("top-label ECE (equal mass)", lambda s: _fmt_ece(s["ece_quantile"])),
        row("classwise ECE", lambda s: _fmt_ece(s["ece_classwise"])),
        row("noise floor of top-label ECE", lambda s: f"{s['ece']['noise_floor']:.4f}"),
        row("MCE (top-label)", lambda s: f"{s['ece']['mce']:.4f}"),
        row("log loss", lambda s: f"{s['log_loss']:.4f}"),
        row("Brier", lambda s: f"{s['brier']:.4f}"),
        "",
        "Top-label ECE for other binnings (fewer bins lower the noise floor but hide the "
        "shape of the reliability curve):",
        "",
        *bin_lines,
        "",
        "![reliability](figures/reliability_whole_tree.png)",
        "",
        "## Tree nodes",
        "",
    ]
    if r["nodes"]:
        lines += [
            "Each node's binary calibration on the test runs of its classes "
            "(outcome: the run's class is on the right).",
            "",
            "| node | left | right | n | accuracy | ECE | MCE | log loss | Brier |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for n in r["nodes"]:

            def f(v):
                return "–" if v is None else f"{v:.4f}"

            lines.append(
                f"| {n['index']} | {' '.join(n['left'])} | {' '.join(n['right'])} | {n['n']} | "
                f"{f(n['accuracy'])} | {f(n['ece'])} | {f(n['mce'])} | {f(n['log_loss'])} | "
                f"{f(n['brier'])} |"
            )
    else:
        lines.append(node_note or "No nodes.")
    lines += ["", "## Normal models (fault-free test runs)", ""]
    if r["normal_models"]:
        lines += [
            f"{r['n_fault_free_runs']} fault-free runs. Central predictive intervals "
            "mean ± z·std; CRPS in normalised units (lower is better).",
            "",
            "| output | level | coverage | mean width |",
            "|---|---|---|---|",
        ]
        for name, d in r["normal_models"].items():
            for lv, c in d["coverage"].items():
                lines.append(f"| {name} | {lv} | {c['coverage']:.4f} | {c['mean_width']:.4g} |")
        lines += [
            "",
            "| output | n samples | excluded (non-finite) | CRPS | RMSE | mean std |",
            "|---|---|---|---|---|---|",
        ]
        for name, d in r["normal_models"].items():
            lines.append(
                f"| {name} | {d['n']} | {d['n_excluded']} | {d['crps']:.4g} | {d['rmse']:.4g} | "
                f"{d['mean_std']:.4g} |"
            )
        lines += ["", "![PIT](figures/pit_normal_models.png)"]
    else:
        lines.append("No fault-free test runs: normal-model calibration not assessed.")
    lines.append("")
    return "\n".join(lines)


# --------------------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------------------
def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``bayes-fdi calibration-report``."""
    parser.add_argument("--train", required=True, help="training dataset (.nc)")
    parser.add_argument("--test", required=True, help="test dataset (.nc)")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument(
        "--calibration", default=None, help="held-out dataset (.nc) to fit the recalibrators on"
    )
    parser.add_argument("--method", choices=("rvm", "svm"), default="rvm")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--n-bins", type=int, default=15)
    parser.add_argument("--n-bootstrap", type=int, default=500)
    parser.add_argument(
        "--n-folds",
        type=int,
        default=5,
        help="cross-fitting folds on the test runs when no --calibration is given (default 5)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")


def _build_diagnoser(method: str, seed: int) -> Any:
    """A fresh diagnoser of the chosen method (RVM defaults or SVM nodes)."""
    try:
        from bayes_fdi.diagnosis import FaultDiagnoser
    except ImportError as err:  # pragma: no cover - until the diagnosis stream is merged
        raise RuntimeError(f"bayes_fdi.diagnosis is not available: {err}") from None
    if method == "rvm":
        return FaultDiagnoser(random_state=seed)
    from bayes_fdi.diagnosis.baselines import svm_fault_diagnoser

    return svm_fault_diagnoser(random_state=seed)


def run_from_cli(args: argparse.Namespace) -> int:
    """Fit a diagnoser on ``--train`` (fn runs + all labelled runs); report on ``--test``."""
    from bayes_fdi.datasets import load_dataset

    train = load_dataset(args.train)
    test = load_dataset(args.test)
    cal = load_dataset(args.calibration) if args.calibration else None
    if "state" not in train.coords:
        raise ValueError(f"{args.train} has no per-run 'state' coordinate")
    normal = train.isel(run=np.flatnonzero(train["state"].values == "fn"))
    if normal.sizes["run"] == 0:
        raise ValueError(f"{args.train} has no fault-free ('fn') runs to fit the normal models")
    from bayes_fdi.progress import busy

    with busy(f"fitting the {args.method.upper()} diagnoser", enabled=not args.quiet):
        diagnoser = _build_diagnoser(args.method, args.seed).fit(normal, train)
    with busy("diagnosing the test runs and writing the report", enabled=not args.quiet):
        path = write_calibration_report(
            diagnoser,
            test,
            args.out,
            calibration_runs=cal,
            n_bins=args.n_bins,
            n_bootstrap=args.n_bootstrap,
            seed=args.seed,
            n_folds=args.n_folds,
            title=f"Calibration report ({args.method.upper()}, test {Path(args.test).name})",
        )
    print(path)
    return 0

"""Calibration report of a fitted diagnoser on a test dataset.

Its command line, ``bayes-fdi calibration-report``, is `bayes_fdi.commands.calibration_report`.

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
`bayes_fdi.diagnosis.FaultDiagnoser.diagnose` (``proba (run, class)``, ``features (run,
feature)``, ``X_hat``, ``X_hat_std``, ``F_hat``, ``F_hat_std``) and, for the per-node table,
``diagnoser.classifier_.nodes_`` (nodes with ``.left``, ``.right``, ``.estimator``).

The recalibrators are fitted on held-out data: on ``calibration_runs`` when given,
otherwise by cross-fitting on the test runs (``n_folds`` seeded folds stratified by class,
five by default; each fold is recalibrated by recalibrators fitted on the other folds), so no
run is scored by a recalibrator fitted on itself. The report's "after" column is, in every
fit, the recalibrator of lowest cross-validated log loss on that fit's fitting runs alone
(:func:`recalibrate`).

The parts: `bayes_fdi.calibration.summaries` (the numbers), `.recalibrator_selection`
(:func:`recalibrate`) and `.report_markdown` (the text).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.atomic import save_figure, write_text
from bayes_fdi.calibration.intervals import plot_pit_histogram
from bayes_fdi.calibration.metrics import expected_calibration_error, reliability_diagram
from bayes_fdi.calibration.nodes import node_calibration
from bayes_fdi.calibration.recalibrator_selection import (
    RECALIBRATOR_LABELS,
    RECALIBRATORS,
    recalibrate,
)
from bayes_fdi.calibration.report_markdown import format_ece, render_markdown
from bayes_fdi.calibration.summaries import (
    classification_summary,
    labelled_rows,
    normal_model_summary,
    public_values,
)

__all__ = [
    "write_calibration_report",
    "write_report_with_summary",
]


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
    return write_report_with_summary(
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


def write_report_with_summary(
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

    out = Path(out_dir)
    fig_dir = out / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    if "state" not in test_runs.coords:
        raise ValueError("test_runs must carry the per-run coordinate 'state'")

    diag = diagnoser.diagnose(test_runs)
    classes = np.asarray([str(c) for c in diag["class"].values])
    y_samples, proba, feats_all = labelled_rows(diag, test_runs)
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
    calibration = _held_out(diagnoser, calibration_runs, classes)
    p_by, recal = _recalibration(
        y, p, classes, calibration=calibration, n_folds=n_folds, methods=methods, seed=seed
    )
    columns = {"before": p, **{m: p_by[m] for m in methods}, "after": p_by["after"]}
    summaries = {k: classification_summary(y, v, classes, **kw) for k, v in columns.items()}
    results["recalibration"] = recal
    results["whole_tree"] = summaries
    results["ece_binning"] = _ece_by_binning(y, columns, summaries, classes, kw)
    _plot_reliability(summaries, methods, recal["selected"], fig_dir)
    results["nodes"], node_note = _node_rows(
        diagnoser, None if feats_all is None else feats_all[known], y, n_bins, seed
    )
    fn = np.flatnonzero(y_all == "fn")
    results["normal_models"] = _normal_models(diag, test_runs, fn, fig_dir)
    results["n_fault_free_runs"] = int(fn.size)

    clean = public_values(results)
    write_text(out / "calibration.json", json.dumps(clean, indent=2))
    report = write_text(out / "report.md", render_markdown(clean, node_note))
    return report, clean


def _held_out(
    diagnoser: Any, calibration_runs: xr.Dataset | None, classes: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """The probabilities and labels of the held-out runs of known states (None without)."""
    if calibration_runs is None:
        return None
    if "state" not in calibration_runs.coords:
        raise ValueError("calibration_runs must carry the per-run coordinate 'state'")
    ycal, pcal, _ = labelled_rows(diagnoser.diagnose(calibration_runs), calibration_runs)
    kcal = np.isin(ycal, classes)
    if kcal.sum() < 1:
        raise ValueError("no calibration run has a state the diagnoser knows")
    return pcal[kcal], ycal[kcal]


def _recalibration(
    y: np.ndarray,
    p: np.ndarray,
    classes: np.ndarray,
    *,
    calibration: tuple[np.ndarray, np.ndarray] | None,
    n_folds: int,
    methods: tuple[str, ...],
    seed: int,
) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Recalibrated probabilities by method (and ``"after"``), and the report's record of
    the fits (:func:`recalibrate`)."""
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
    return p_by, recal


def _ece_by_binning(
    y: np.ndarray,
    columns: dict[str, np.ndarray],
    summaries: dict[str, dict[str, Any]],
    classes: np.ndarray,
    kw: dict[str, Any],
) -> list[dict[str, Any]]:
    """How the ECE of every column depends on the binning: value, debiased value, interval and
    noise floor with equal-width and equal-mass bins (``n_bins``, 10 and 5)."""
    n_bins = kw["n_bins"]
    binning = []
    for strategy in ("uniform", "quantile"):
        for nb in sorted({int(n_bins), 10, 5}, reverse=True):
            nb_ = min(nb, y.size) if strategy == "quantile" else nb
            row: dict[str, Any] = {"strategy": strategy, "n_bins": nb_}
            for k, v in columns.items():
                if nb == n_bins:  # the report's own binnings, already in the summaries
                    e = summaries[k]["_results"][0 if strategy == "uniform" else 1]
                else:
                    e = expected_calibration_error(
                        y, v, classes=classes, strategy=strategy, **(kw | {"n_bins": nb_})
                    )
                row[k] = {
                    "value": e.value,
                    "debiased": e.debiased,
                    "ci_low": e.ci_low,
                    "ci_high": e.ci_high,
                    "noise_floor": e.noise_floor,
                }
            binning.append(row)
    return binning


def _plot_reliability(
    summaries: dict[str, dict[str, Any]],
    methods: tuple[str, ...],
    selected: list[str],
    fig_dir: Path,
) -> None:
    """Whole-tree reliability diagrams before and after each recalibrator."""
    import matplotlib.pyplot as plt

    shown = ["before", *methods]
    fig, axes = plt.subplots(1, len(shown), figsize=(4.5 * len(shown), 4.5), squeeze=False)
    sel = sorted(set(selected))
    for ax, k in zip(axes[0], shown, strict=True):
        mark = " (selected)" if k in sel else ""
        label = "before" if k == "before" else f"{RECALIBRATOR_LABELS[k]}{mark}"
        reliability_diagram(
            summaries[k]["_results"][0],
            ax=ax,
            title=f"{label}: ECE {format_ece(summaries[k]['ece'])}",
        )
    fig.suptitle("Whole tree, top-label reliability (equal-width bins)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, fig_dir / "reliability_whole_tree.png", dpi=120)


def _node_rows(
    diagnoser: Any, feats: np.ndarray | None, y: np.ndarray, n_bins: int, seed: int
) -> tuple[list[dict[str, Any]], str]:
    """Binary calibration of every tree node on the test rows of known states, or why not."""
    nodes = getattr(getattr(diagnoser, "classifier_", None), "nodes_", None)
    if nodes is None:
        return [], "The diagnoser exposes no `classifier_.nodes_`; per-node calibration skipped."
    if feats is None:
        return [], "The diagnosis has no `features`; per-node calibration skipped."
    scaler = getattr(diagnoser, "scaler_", None)
    if scaler is not None:  # the tree sees standardised features
        feats = np.asarray(scaler.transform(feats), dtype=np.float64)
    return [
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
        for nc in node_calibration(nodes, feats, y, n_bins=min(n_bins, 10), random_state=seed)
    ], ""


def _normal_models(
    diag: xr.Dataset, test_runs: xr.Dataset, fn: np.ndarray, fig_dir: Path
) -> dict[str, Any]:
    """The normal models' intervals on the fault-free test runs ``fn``, and their PIT figure."""
    if not fn.size:
        return {}
    import matplotlib.pyplot as plt

    normal = normal_model_summary(diag.isel(run=fn), test_runs.isel(run=fn))
    fig, axes = plt.subplots(1, len(normal), figsize=(4.5 * len(normal), 3.2))
    for ax, (name, d) in zip(np.atleast_1d(axes), normal.items(), strict=True):
        plot_pit_histogram(d["_pit"], 10, ax=ax, title=f"PIT of {name} (n = {d['n']})")
    fig.tight_layout()
    save_figure(fig, fig_dir / "pit_normal_models.png", dpi=120)
    return normal

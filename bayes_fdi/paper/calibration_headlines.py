"""Headline calibration figures of a fitted RVM pipeline, with its full calibration report.

`calibration_headlines` writes `bayes_fdi.calibration.report`'s report of the diagnoser on its
test runs and returns the figures ``reproduce`` prints: top-label ECE before and after
cross-fitted recalibration (with bootstrap interval and noise floor), the recalibrators chosen,
the normal models' interval coverage and, for a real record, the coverage on its second half.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import xarray as xr

from bayes_fdi.paper.setup import select_regression_width, single_threaded

__all__ = [
    "calibration_headlines",
]


def _ece_headline(e: dict[str, Any]) -> dict[str, Any]:
    keys = ("value", "ci_low", "ci_high", "debiased", "noise_floor")
    return {k: e.get(k) for k in keys}


def calibration_headlines(
    diagnoser: Any,
    test_runs: xr.Dataset,
    out_dir: str | os.PathLike,
    *,
    seed: int = 0,
    real_record: xr.Dataset | None = None,
    n_bootstrap: int = 500,
    n_folds: int = 5,
    title: str = "Calibration report",
) -> dict[str, Any]:
    """Write the calibration report of a fitted diagnoser and return its headline figures.

    Parameters
    ----------
    diagnoser
        Fitted :class:`~bayes_fdi.diagnosis.FaultDiagnoser`.
    test_runs
        Labelled held-out runs (their ``fn`` runs score the normal models).
    out_dir
        Folder of the full report (:func:`bayes_fdi.calibration.report.write_calibration_report`).
    seed
        Seed of the bootstrap and of the cross-fitted recalibration.
    real_record
        A real fault-free record (e.g. the Lublin hour): the normal models, configured as the
        diagnoser's, are fitted on its first half (width chosen there by
        :func:`select_regression_width`) and scored on its second half.
    n_bootstrap
        Bootstrap resamples of the ECE intervals.
    n_folds
        Cross-fitting folds of the recalibration (each test run is recalibrated by
        recalibrators fitted on the other folds; see
        :func:`bayes_fdi.calibration.report.recalibrate`).
    title
        Heading of the full report.

    Returns
    -------
    dict
        ``report`` (path of ``report.md`` relative to the parent of ``out_dir``),
        ``recalibration`` (method, fitted parameters), ``before`` and ``after``
        (``accuracy``, ``log_loss``, ``ece``: top-label, 15 equal-width bins, with bootstrap
        interval, debiased value and noise floor), ``selected`` (recalibrators chosen in the
        folds), ``ece_by_binning`` (before/after with other bin counts and equal-mass bins),
        ``coverage`` (per output, each level:
        nominal, coverage, mean width, on the fault-free test runs) and, with
        ``real_record``, ``real_record_coverage`` (the same on its second half).
    """
    from sklearn.base import clone

    from bayes_fdi.calibration.recalibrator_selection import RECALIBRATORS
    from bayes_fdi.calibration.report import write_report_with_summary
    from bayes_fdi.calibration.summaries import split_in_time, time_split_summary

    out = Path(out_dir)
    with single_threaded():
        path, cal = write_report_with_summary(
            diagnoser,
            test_runs,
            out,
            calibration_runs=None,
            n_bins=15,
            n_bootstrap=n_bootstrap,
            seed=seed,
            title=title,
            n_folds=n_folds,
            methods=RECALIBRATORS,
        )
        head: dict[str, Any] = {
            "report": f"{out.name}/{path.name}",
            "recalibration": cal["recalibration"],
        }
        for when in ("before", "after"):
            d = cal["whole_tree"][when]
            head[when] = {
                "accuracy": d["accuracy"],
                "log_loss": d["log_loss"],
                "ece": _ece_headline(d["ece"]),
            }
        head["selected"] = sorted(set(cal["recalibration"].get("selected", [])))
        head["ece_by_binning"] = [
            {
                "strategy": b["strategy"],
                "n_bins": b["n_bins"],
                "before": _ece_headline(b["before"]),
                "after": _ece_headline(b["after"]),
            }
            for b in cal.get("ece_binning", [])
        ]
        head["coverage"] = {k: v["coverage"] for k, v in cal.get("normal_models", {}).items()}
        if real_record is not None:
            first, _ = split_in_time(real_record, 0.5)
            model = clone(diagnoser.normal_models_)
            width, _ = select_regression_width(first, seed=seed, input_lags=model.input_lags)
            regressor = model.regressor
            if regressor is not None and "width" in regressor.get_params():
                model.set_params(regressor=clone(regressor).set_params(width=width))
            hour = time_split_summary(model, real_record)
            head["real_record_coverage"] = {k: hour[k]["coverage"] for k in ("X", "F") if k in hour}
            head["real_record_width"] = float(width)
    return head

"""Choosing and applying a recalibrator without scoring it on its own fitting runs.

:func:`recalibrate` fits temperature, vector and Dirichlet scaling on held-out runs (or
cross-fits them on the scored runs) and, in every fit, selects the one of lowest
cross-validated log loss on the fitting runs alone; near-ties go to the simplest.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bayes_fdi.calibration.dirichlet import DirichletScaler
from bayes_fdi.calibration.recalibration import LOG_LOSS_RTOL, cross_val_log_loss, fold_indices
from bayes_fdi.calibration.temperature import TemperatureScaler

__all__ = [
    "RECALIBRATORS",
    "RECALIBRATOR_LABELS",
    "make_recalibrator",
    "recalibrate",
]


#: Recalibrators compared by the report, in column order.
RECALIBRATORS: tuple[str, ...] = ("temperature", "vector", "dirichlet")


#: Display names of the recalibrators in reports.
RECALIBRATOR_LABELS = {"temperature": "temperature", "vector": "vector", "dirichlet": "Dirichlet"}


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
    log loss on these data alone (temperature when too few runs to cross-validate).

    Log losses within a relative `LOG_LOSS_RTOL` of the lowest are ties, won by the first
    of ``methods`` (the simplest, in the order of `RECALIBRATORS`).
    """
    fitted = {m: make_recalibrator(m, classes, seed).fit(p_fit, y_fit) for m in methods}
    n = y_fit.shape[0]
    scores: dict[str, float] = {}
    if n >= 2 * cv:
        for m in methods:
            scores[m] = cross_val_log_loss(
                make_recalibrator(m, classes, seed), p_fit, y_fit, classes=classes, cv=cv,
                random_state=seed,
            )  # fmt: skip
        best = min(scores.values())
        # ties (within LOG_LOSS_RTOL, e.g. vector scaling that fell back to one temperature in
        # every cross-validation fit) go to the simplest method, the first in `methods`
        selected = next(m for m in methods if scores[m] <= best + LOG_LOSS_RTOL * abs(best))
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

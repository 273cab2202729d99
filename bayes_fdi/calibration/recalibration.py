"""What the recalibrators share, and the cross-validated log loss that chooses between them.

The recalibrators themselves are `~bayes_fdi.calibration.TemperatureScaler` (one temperature,
`bayes_fdi.calibration.temperature`) and `~bayes_fdi.calibration.DirichletScaler` (Dirichlet
calibration and vector scaling, `bayes_fdi.calibration.dirichlet`). Here:
:func:`cross_val_log_loss` (a recalibrator's held-out log loss, to choose one on calibration
data only) and `LOG_LOSS_RTOL` (when two such log losses tie), and the recalibrators' common
steps: probabilities or logits read as log-probabilities (:func:`log_probabilities`), labels
as column indices (:func:`class_indices`), seeded folds stratified by class
(:func:`fold_indices`) and the row-wise :func:`log_softmax`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from bayes_fdi.calibration.metrics import check_proba, probability_rows

__all__ = [
    "LOG_LOSS_RTOL",
    "class_indices",
    "cross_val_log_loss",
    "fold_indices",
    "log_probabilities",
    "log_softmax",
]

#: Cross-validated log losses within this relative difference of the lowest are a tie (the
#: penalty of `~bayes_fdi.calibration.DirichletScaler` and the recalibrator of the calibration
#: report are then chosen by a fixed rule, not by the last digits). The optimisers stop at a
#: gradient of 1e-9 (Newton) or an inverse temperature within 1e-8 (Brent), so one model fitted
#: twice scores within about 1e-9 of itself (two BLAS code paths gave 0.40072350406 and
#: 0.40072350519 for one temperature scaling); a difference of 1e-6 of a log loss is also far
#: below its sampling error (about 1e-2 on a few hundred runs), so no real preference is lost.
LOG_LOSS_RTOL: float = 1e-6


def log_softmax(z: np.ndarray) -> np.ndarray:
    """Row-wise ``log(softmax(z))`` of a 2-D array, computed stably (shifted by the row max)."""
    shifted = z - np.max(z, axis=1, keepdims=True)
    return shifted - np.log(np.sum(np.exp(shifted), axis=1, keepdims=True))


def log_probabilities(values: Any, *, input: str, floor: float) -> np.ndarray:
    """A recalibrator's input as log-probabilities, validated.

    ``input="proba"``: rows of probabilities (`probability_rows`: finite, in [0, 1] up to
    rounding, summing to 1), raised to ``floor`` before the logarithm; ``input="logits"``:
    unnormalised log-probabilities, taken as they are (finite). At least two class columns.
    """
    a = np.asarray(values, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] < 2:
        raise ValueError(f"expected a 2-D array with >= 2 class columns, got shape {a.shape}")
    if input == "logits":
        if not np.all(np.isfinite(a)):
            raise ValueError("logits contain NaN or inf")
        return a
    if input != "proba":
        raise ValueError(f"input must be 'proba' or 'logits', got {input!r}")
    if not 0 < floor < 1:
        raise ValueError("floor must lie in (0, 1)")
    a = probability_rows(a, "probabilities")
    return np.log(np.maximum(a, floor))


def class_indices(
    y: Any, n_rows: int, classes: Sequence | None, n_cols: int
) -> tuple[np.ndarray, np.ndarray]:
    """Labels ``y`` (``n_rows`` of them) as indices of the ``n_cols`` columns, validated.

    ``classes`` gives the column labels (default: the sorted unique labels of ``y``); returns
    the indices and the classes.
    """
    y = np.asarray(y)
    if y.ndim != 1 or y.shape[0] != n_rows:
        raise ValueError(f"y must be 1-D with {n_rows} labels, got shape {y.shape}")
    if n_rows == 0:
        raise ValueError("no samples to fit on")
    cls = np.unique(y) if classes is None else np.asarray(classes)
    if cls.ndim != 1 or len(np.unique(cls)) != len(cls):
        raise ValueError("classes must be a 1-D sequence of distinct labels")
    if len(cls) != n_cols:
        raise ValueError(f"{n_cols} columns but {len(cls)} classes; pass `classes` in column order")
    lookup = {c: i for i, c in enumerate(cls.tolist())}
    try:
        y_idx = np.array([lookup[v] for v in y.tolist()], dtype=np.intp)
    except KeyError as err:
        raise ValueError(f"label {err.args[0]!r} is not among the classes") from None
    return y_idx, cls


def fold_indices(y_idx: np.ndarray, n_folds: int, seed: int | None) -> list[np.ndarray]:
    """Seeded folds, stratified by class (each class dealt round-robin after shuffling)."""
    rng = np.random.default_rng(seed)
    fold = np.empty(y_idx.shape[0], dtype=np.intp)
    start = 0
    for c in np.unique(y_idx):
        idx = rng.permutation(np.flatnonzero(y_idx == c))
        fold[idx] = (start + np.arange(idx.size)) % n_folds
        start += idx.size  # continue the round robin so fold sizes stay balanced
    return [np.flatnonzero(fold == f) for f in range(n_folds)]


def cross_val_log_loss(
    scaler: Any,
    proba: Any,
    y: Any,
    *,
    classes: Sequence | None = None,
    cv: int = 5,
    random_state: int | None = 0,
) -> float:
    """Mean held-out log loss of a recalibrator, by ``cv``-fold cross-validation.

    Each fold is recalibrated by a fresh copy of ``scaler`` (same ``get_params``, with
    ``classes`` set) fitted on the other folds; folds are stratified by class and seeded.
    Use it to choose a recalibrator on the calibration data only.

    Parameters
    ----------
    scaler
        An unfitted recalibrator with ``get_params``, ``fit(proba, y)`` and
        ``transform(proba)`` (:class:`~bayes_fdi.calibration.TemperatureScaler`,
        :class:`~bayes_fdi.calibration.DirichletScaler`).
    proba, y
        Calibration probabilities ``(n, K)`` and labels.
    classes
        Column labels; default: the sorted unique labels of ``y``.
    cv
        Number of folds (>= 2, at most ``n``).
    random_state
        Seed of the folds.

    Returns
    -------
    float
        Sum over folds of the held-out NLL, divided by ``n``.
    """
    yv, p, cls = check_proba(y, proba, classes)
    if int(cv) != cv or not 2 <= cv <= yv.shape[0]:
        raise ValueError(f"cv must be an integer in [2, n_samples={yv.shape[0]}], got {cv!r}")
    y_idx, _ = class_indices(yv, yv.shape[0], cls, p.shape[1])
    total = 0.0
    for f in fold_indices(y_idx, int(cv), random_state):
        train = np.setdiff1d(np.arange(yv.shape[0]), f)
        est = type(scaler)(**(scaler.get_params() | {"classes": cls}))
        q = est.fit(p[train], yv[train]).transform(p[f])
        total += -np.sum(np.log(np.maximum(q[np.arange(f.size), y_idx[f]], 1e-300)))
    return float(total / yv.shape[0])

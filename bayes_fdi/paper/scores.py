"""Scores of a classifier on labelled test runs: identification ratios, confusion, proper scores.

`classification_metrics` gathers what the paper reports (overall and per-state identification
ratios, the confusion matrix) and the probabilistic scores of `bayes_fdi.calibration` (log
loss and Brier score by scikit-learn, top-label ECE); `paired_comparison` is the exact McNemar
test of two classifiers on the same runs (scipy's binomial test).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from bayes_fdi.calibration import brier, expected_calibration_error, log_loss
from bayes_fdi.calibration.metrics import check_proba

__all__ = [
    "classification_metrics",
    "paired_comparison",
]


def classification_metrics(
    y_true: Sequence[str],
    proba: np.ndarray,
    classes: Sequence[str],
    *,
    y_pred: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Identification ratios, confusion and probabilistic scores of a set of test runs.

    Parameters
    ----------
    y_true
        True states.
    proba
        ``(n, n_classes)`` predicted distributions in the order of ``classes``.
    classes
        Class names.
    y_pred
        Predicted labels (default: the argmax of ``proba``).

    Returns
    -------
    dict
        ``accuracy``; ``per_class`` (state -> identification ratio, in ``classes`` order);
        ``confusion`` (``classes``, ``matrix`` with true states as rows);
        ``log_loss`` (natural log; `bayes_fdi.calibration.log_loss`, scikit-learn's),
        ``brier`` (multi-class, [0, 2]; `bayes_fdi.calibration.brier`, scikit-learn's),
        ``ece`` (top-label, 15 equal-width bins;
        `bayes_fdi.calibration.expected_calibration_error`).
    """
    from sklearn.metrics import confusion_matrix

    classes = [str(c) for c in classes]
    y_true = np.asarray(y_true).astype(str)
    _, proba, _ = check_proba(y_true, proba, classes)
    if y_pred is None:
        y_pred = np.asarray(classes)[np.argmax(proba, axis=1)]
    y_pred = np.asarray(y_pred).astype(str)
    cm = confusion_matrix(y_true, y_pred, labels=classes)
    support = cm.sum(axis=1)
    per_class = {
        c: (float(cm[i, i] / support[i]) if support[i] else float("nan"))
        for i, c in enumerate(classes)
    }
    return {
        "accuracy": float(np.mean(y_true == y_pred)),
        "per_class": per_class,
        "confusion": {"classes": classes, "matrix": cm.astype(int).tolist()},
        "log_loss": log_loss(y_true, proba, classes=classes),
        "brier": brier(y_true, proba, classes=classes),
        "ece": float(expected_calibration_error(y_true, proba, classes=classes, n_bins=15).value),
    }


def paired_comparison(
    y_true: Sequence[str], pred_a: Sequence[str], pred_b: Sequence[str]
) -> dict[str, Any]:
    """Exact McNemar test of two classifiers scored on the same runs.

    Only the runs on which exactly one classifier is right carry information: under the null
    hypothesis of equal accuracy each of them is equally likely to favour either, so the
    count ``a_only`` is Binomial(``a_only + b_only``, 1/2).

    Returns
    -------
    dict
        ``a_only`` (runs only the first gets right), ``b_only``, ``both``, ``neither``
        and ``p_value`` (two-sided exact binomial; 1 when no run is discordant).
    """
    from scipy.stats import binomtest

    y = np.asarray(y_true).astype(str)
    ra = np.asarray(pred_a).astype(str) == y
    rb = np.asarray(pred_b).astype(str) == y
    a_only, b_only = int(np.sum(ra & ~rb)), int(np.sum(~ra & rb))
    n = a_only + b_only
    return {
        "a_only": a_only,
        "b_only": b_only,
        "both": int(np.sum(ra & rb)),
        "neither": int(np.sum(~ra & ~rb)),
        "p_value": float(binomtest(a_only, n, 0.5).pvalue) if n else 1.0,
    }

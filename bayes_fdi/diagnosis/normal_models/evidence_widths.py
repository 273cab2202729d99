"""The RBF widths of the dynamic normal models' two regressions, chosen by evidence.

`search_widths` fits the position model (`~bayes_fdi.rvm.RVR`) at each width of its grid on a
subsample and records its log evidence, then, with the position model of the largest evidence
predicting ``X_hat``, the flow model at each width of its own grid (its inputs need ``X_hat``).
`~bayes_fdi.diagnosis.normal_models.dynamic.DynamicNormalModels` fits both at the widths of
largest evidence.

Written by hand: scikit-learn's searches score by cross-validation, not by a model's evidence,
and cannot chain the flow model's inputs to the position model's predictions.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from bayes_fdi.diagnosis.normal_models.residuals import SENSOR_RANGE

__all__ = ["search_widths"]


def search_widths(
    x_widths: Sequence[float],
    f_widths: Sequence[float],
    Z: np.ndarray,
    x_target: np.ndarray,
    f_target: np.ndarray,
    x_mean: np.ndarray,
    flow_inputs: Callable[[np.ndarray], np.ndarray],
    flow_mean: Callable[[np.ndarray], np.ndarray] | None = None,
) -> dict[str, dict[float, float]]:
    """``{"X": {width: log evidence}, "F": {width: log evidence}}`` on one subsample.

    Parameters
    ----------
    x_widths, f_widths
        The grids of the position and the flow model.
    Z
        The position model's standardised inputs (rows of the subsample).
    x_target, f_target
        What the two models learn on those rows: X minus its prior mean ``x_mean``, and F.
    x_mean
        The position's prior mean on the rows (0, or the lagged command), added back to the
        position model's output to give ``X_hat`` (clipped to the sensors' range).
    flow_inputs
        The flow model's input rows from ``X_hat``.
    flow_mean
        F's prior mean from those input rows (None: 0), subtracted from ``f_target`` as the
        position's is from X.
    """
    from bayes_fdi.rvm import RVR

    evidence: dict[str, dict[float, float]] = {"X": {}, "F": {}}
    for w in x_widths:
        evidence["X"][float(w)] = RVR(width=float(w)).fit(Z, x_target).log_evidence_
    wx = max(evidence["X"], key=evidence["X"].get)
    x_hat = np.clip(RVR(width=wx).fit(Z, x_target).predict(Z) + x_mean, *SENSOR_RANGE)
    V = flow_inputs(x_hat)
    if flow_mean is not None:
        f_target = f_target - flow_mean(V)
    for w in f_widths:
        evidence["F"][float(w)] = RVR(width=float(w)).fit(V, f_target).log_evidence_
    return evidence

"""A temperature followed by a beta calibration map of the top class: :class:`TopLabelScaler`.

One temperature (as `~bayes_fdi.calibration.TemperatureScaler`) sets the shape of the whole
distribution; a monotone three-parameter map of the largest probability (beta calibration, Kull,
Silva Filho and Flach 2017, *Beyond sigmoids: how to obtain well-calibrated probabilities from
binary classifiers with beta calibration*, Electronic Journal of Statistics 11(2)) then bends the
reliability curve, which one temperature cannot: ``q = sigmoid(a ln p - b ln(1 - p) + c)``.
The map is fitted by scikit-learn's logistic regression on whether the top class is right; the
share-out of the remaining probability (`top_label_map`) is written here, as no maintained
library applies a top-label map to a whole distribution.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator

from bayes_fdi.calibration.recalibration import class_indices
from bayes_fdi.calibration.temperature import TemperatureScaler

__all__ = ["TopLabelScaler", "beta_map", "top_label_map"]

#: Top probabilities are clipped to ``[EDGE, 1 - EDGE]`` before their logarithms in the map.
EDGE = 1e-12
#: The mapped top probability stays this much (relative) above the second class's, so that the
#: top class stays the arg-max rather than tying with it.
TIE_MARGIN = 1e-9


def beta_map(p: Any, coef: Any) -> np.ndarray:
    """The beta calibration map ``sigmoid(a ln p - b ln(1 - p) + c)`` of ``coef = (a, b, c)``
    (``p`` clipped to ``[1e-12, 1 - 1e-12]``)."""
    a, b, c = (float(v) for v in coef)
    p = np.clip(np.asarray(p, dtype=np.float64), EDGE, 1.0 - EDGE)
    return 1.0 / (1.0 + np.exp(-(a * np.log(p) - b * np.log1p(-p) + c)))


def top_label_map(q: Any, coef: Any) -> np.ndarray:
    """Rows of probabilities ``q`` with their largest entry mapped by `beta_map`.

    The top class keeps its place: its new probability is at least ``p2 / (1 - p1 + p2)`` (``p1``,
    ``p2`` the two largest; `TIE_MARGIN` above it, and never above ``p1``), where the second
    class would overtake it. The other classes share
    the rest in proportion to their probabilities (equally where they were all 0). Rows sum to 1.
    """
    q = np.array(q, dtype=np.float64, copy=True)
    if q.ndim != 2 or q.shape[1] < 2:
        raise ValueError(f"expected a 2-D array with >= 2 class columns, got shape {q.shape}")
    rows = np.arange(q.shape[0])
    top = np.argmax(q, axis=1)
    p1 = q[rows, top]
    p2 = np.partition(q, -2, axis=1)[:, -2]
    with np.errstate(invalid="ignore", divide="ignore"):
        floor = np.where(p2 > 0, p2 / (1.0 - p1 + p2) * (1.0 + TIE_MARGIN), 0.0)
    new = np.maximum(beta_map(p1, coef), np.minimum(floor, p1))
    rest = q.sum(axis=1) - p1
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(rest[:, None] > 0, q / rest[:, None], 1.0 / (q.shape[1] - 1))
    out = share * (1.0 - new)[:, None]
    out[rows, top] = new
    return out


class TopLabelScaler(BaseEstimator):
    """Recalibrate class distributions with a temperature and a beta map of the top class.

    ``q = top_label_map(softmax(log(p) / T), (a, b, c))``: the temperature ``T`` is fitted
    first (`~bayes_fdi.calibration.TemperatureScaler`, mean negative log-likelihood), then the
    map of the top probability ``sigmoid(a ln p - b ln(1 - p) + c)`` by logistic regression of
    "the top class is right" on ``(ln p, -ln(1 - p))`` (scikit-learn, unpenalised). A negative
    ``a`` or ``b`` would make the map decreasing: that feature is dropped and the rest refitted,
    as in beta calibration. The diagnosed class never changes.

    Parameters
    ----------
    floor, bounds, classes
        As `~bayes_fdi.calibration.TemperatureScaler` (probabilities in, ``floor`` 1e-12,
        ``bounds`` (0.02, 50)).

    Attributes
    ----------
    temperature_ : float
    top_map_ : numpy.ndarray
        ``(3,)``: ``(a, b, c)`` of the top-class map.
    classes_ : numpy.ndarray
    n_samples_ : int
    """

    def __init__(
        self,
        *,
        floor: float = 1e-12,
        bounds: tuple[float, float] = (0.02, 50.0),
        classes: Sequence | None = None,
    ) -> None:
        self.floor = floor
        self.bounds = bounds
        self.classes = classes

    def _temperature(self) -> TemperatureScaler:
        return TemperatureScaler(floor=self.floor, bounds=self.bounds, classes=self.classes)

    def fit(self, proba: Any, y: Any) -> TopLabelScaler:
        """Fit the temperature and the top-class map on held-out ``(proba, y)``."""
        from sklearn.linear_model import LogisticRegression

        scaler = self._temperature().fit(proba, y)
        q = scaler.transform(proba)
        y_idx, cls = class_indices(y, q.shape[0], self.classes, q.shape[1])
        right = (np.argmax(q, axis=1) == y_idx).astype(np.int64)
        p = np.clip(q.max(axis=1), EDGE, 1.0 - EDGE)
        features = np.column_stack([np.log(p), -np.log1p(-p)])
        coef = np.zeros(3)
        rate = float(np.clip(right.mean(), EDGE, 1.0 - EDGE))
        coef[2] = np.log(rate / (1.0 - rate))  # no feature kept: the constant map
        use = [0, 1] if 0 < right.sum() < right.size else []
        while use:
            model = LogisticRegression(C=np.inf, max_iter=1000).fit(features[:, use], right)
            w = model.coef_[0]
            if np.all(w >= 0):
                coef[use], coef[2] = w, float(model.intercept_[0])
                break
            use = [u for u, wu in zip(use, w, strict=True) if wu >= 0]
        self.temperature_ = float(scaler.temperature_)
        self.top_map_ = coef
        self.classes_ = cls
        self.n_samples_ = int(q.shape[0])
        return self

    def transform(self, proba: Any) -> np.ndarray:
        """Recalibrated probabilities; rows sum to 1, the arg-max is unchanged."""
        if not hasattr(self, "top_map_"):
            raise ValueError("TopLabelScaler is not fitted; call fit first")
        scaler = self._temperature()
        scaler.temperature_, scaler.classes_ = self.temperature_, self.classes_
        return top_label_map(scaler.transform(proba), self.top_map_)

    def fit_transform(self, proba: Any, y: Any) -> np.ndarray:
        """``fit`` then ``transform`` on the same data."""
        return self.fit(proba, y).transform(proba)

"""Temperature scaling of a classifier's class distribution: :class:`TemperatureScaler`.

One temperature (Guo et al. 2017, *On calibration of modern neural networks*, ICML) fitted on
held-out data by minimising the negative log-likelihood with scipy's bounded scalar optimiser;
the diagnosed class never changes.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy import optimize
from sklearn.base import BaseEstimator

from bayes_fdi.calibration.recalibration import class_indices, log_probabilities, log_softmax

__all__ = ["TemperatureScaler", "check_temperature_bounds"]


def check_temperature_bounds(bounds: Any, *, name: str = "bounds") -> tuple[float, float]:
    """``(low, high)`` of a temperature search as floats, refused unless ``0 < low < high``
    and both are finite (``name``: the argument's name in the message)."""
    low, high = (float(b) for b in bounds)
    if not 0 < low < high < np.inf:
        raise ValueError(f"{name} must satisfy 0 < low < high < inf, got {bounds!r}")
    return low, high


class TemperatureScaler(BaseEstimator):
    """Recalibrate class distributions with one temperature (Guo et al. 2017).

    ``q = softmax(log(p) / T)``: ``T > 1`` softens over-confident distributions, ``T < 1``
    sharpens under-confident ones; the arg-max (the diagnosed class) never changes. ``T``
    is fitted on held-out data by minimising the mean negative log-likelihood with a
    bounded 1-D optimiser (Brent) on the inverse temperature, where the NLL is convex.

    It is meant for the output of a whole hierarchical tree: products of node
    probabilities along tree paths are typically miscalibrated even when every node is.

    Parameters
    ----------
    input
        ``"proba"`` (default): ``fit``/``transform`` take probabilities, whose logarithms
        serve as logits; ``"logits"``: they take unnormalised log-probabilities.
    floor
        Probabilities below ``floor`` are raised to ``floor`` before taking logarithms
        (default 1e-12, so that a class the model excludes stays excluded up to
        ``floor ** (1/T)`` and log(0) never occurs). Only used with ``input="proba"``.
    bounds
        Search interval of ``T`` (default (0.02, 50)). A fitted value at a bound is reported
        in ``at_bound_``.
    classes
        Column labels; default: the sorted unique labels seen in ``fit``.

    Attributes
    ----------
    temperature_ : float
    classes_ : numpy.ndarray
    nll_before_, nll_after_ : float
        Mean NLL on the fitting data at ``T = 1`` and at ``temperature_``.
    at_bound_ : bool
    n_samples_ : int
    """

    def __init__(
        self,
        *,
        input: str = "proba",
        floor: float = 1e-12,
        bounds: tuple[float, float] = (0.02, 50.0),
        classes: Sequence | None = None,
    ) -> None:
        self.input = input
        self.floor = floor
        self.bounds = bounds
        self.classes = classes

    def _logits(self, values: Any) -> np.ndarray:
        return log_probabilities(values, input=self.input, floor=self.floor)

    def fit(self, proba_or_logits: Any, y: Any) -> TemperatureScaler:
        """Fit the temperature on held-out ``(proba_or_logits, y)``."""
        z = self._logits(proba_or_logits)
        y_idx, cls = class_indices(y, z.shape[0], self.classes, z.shape[1])
        t_lo, t_hi = check_temperature_bounds(self.bounds)
        rows = np.arange(z.shape[0])

        def nll(beta: float) -> float:
            return float(-np.mean(log_softmax(beta * z)[rows, y_idx]))

        res = optimize.minimize_scalar(
            nll, bounds=(1.0 / t_hi, 1.0 / t_lo), method="bounded", options={"xatol": 1e-8}
        )
        beta = float(res.x)
        self.temperature_ = 1.0 / beta
        self.classes_ = cls
        self.nll_before_ = nll(1.0)
        self.nll_after_ = float(res.fun)
        rel = 1e-3
        self.at_bound_ = bool(
            abs(self.temperature_ - t_lo) <= rel * t_lo
            or abs(self.temperature_ - t_hi) <= rel * t_hi
        )
        self.n_samples_ = int(z.shape[0])
        return self

    def transform(self, proba_or_logits: Any) -> np.ndarray:
        """Recalibrated probabilities ``softmax(logits / T)``; rows sum to 1."""
        if not hasattr(self, "temperature_"):
            raise ValueError("TemperatureScaler is not fitted; call fit first")
        z = self._logits(proba_or_logits)
        if z.shape[1] != len(self.classes_):
            raise ValueError(f"expected {len(self.classes_)} columns, got {z.shape[1]}")
        return np.exp(log_softmax(z / self.temperature_))

    def fit_transform(self, proba_or_logits: Any, y: Any) -> np.ndarray:
        """``fit`` then ``transform`` on the same data."""
        return self.fit(proba_or_logits, y).transform(proba_or_logits)

    def __repr__(self) -> str:
        t = f", temperature_={self.temperature_:.4g}" if hasattr(self, "temperature_") else ""
        return f"TemperatureScaler(input={self.input!r}, floor={self.floor!r}{t})"

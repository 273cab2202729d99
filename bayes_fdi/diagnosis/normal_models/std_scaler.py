"""Recalibration of the normal models' Gaussian predictive standard deviations.

`StdScaler` scales predictive standard deviations by one factor fitted on held-out fault-free
data; `NormalModels` uses one per ``|dCV/dt|`` bin. The calibration metrics of such intervals
(coverage, PIT, CRPS) are in `bayes_fdi.calibration.intervals`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import stats

__all__ = ["StdScaler", "check_gaussian"]


def check_gaussian(y: Any, mean: Any, std: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Validate and broadcast observations and Gaussian predictive moments."""
    try:
        y_, m_, s_ = np.broadcast_arrays(
            np.asarray(y, dtype=np.float64),
            np.asarray(mean, dtype=np.float64),
            np.asarray(std, dtype=np.float64),
        )
    except ValueError as err:
        raise ValueError(f"y, mean and std do not broadcast together: {err}") from None
    for name, a in (("y", y_), ("mean", m_), ("std", s_)):
        if not np.all(np.isfinite(a)):
            raise ValueError(
                f"{name} contains NaN or inf; select the finite samples explicitly before scoring"
            )
    if np.any(s_ <= 0):
        raise ValueError("std must be strictly positive")
    if y_.size == 0:
        raise ValueError("no samples to score")
    return y_, m_, s_


class StdScaler:
    """Recalibrate Gaussian predictive standard deviations with one factor.

    ``std_new = scale_ * std``. The factor is fitted on held-out fault-free data
    ``(y, mean, std)``: ``method="mle"`` (default) maximises the Gaussian likelihood,
    ``scale_ = sqrt(mean(((y - mean) / std) ** 2))``; ``method="coverage"`` matches the
    empirical central coverage at ``level``, ``scale_ = quantile(|y - mean| / std, level) /
    z_{(1+level)/2}``. The mean is not changed, so a bias is not fixed (look at the PIT).

    Parameters
    ----------
    method
        ``"mle"`` or ``"coverage"``.
    level
        Coverage level matched by ``method="coverage"`` (default 0.95).

    Attributes
    ----------
    scale_ : float
    n_samples_ : int
    """

    def __init__(self, *, method: str = "mle", level: float = 0.95) -> None:
        self.method = method
        self.level = level

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """Constructor parameters (scikit-learn convention)."""
        return {"method": self.method, "level": self.level}

    def fit(self, y: Any, mean: Any, std: Any) -> StdScaler:
        """Fit the factor on held-out observations and predictions (finite, ``std > 0``)."""
        y_, m_, s_ = check_gaussian(y, mean, std)
        z = np.abs(y_ - m_).ravel() / s_.ravel()
        if self.method == "mle":
            self.scale_ = float(np.sqrt(np.mean(z**2)))
        elif self.method == "coverage":
            if not 0 < self.level < 1:
                raise ValueError(f"level must lie in (0, 1), got {self.level}")
            self.scale_ = float(np.quantile(z, self.level) / stats.norm.ppf(0.5 + self.level / 2))
        else:
            raise ValueError(f"method must be 'mle' or 'coverage', got {self.method!r}")
        if not self.scale_ > 0:
            raise ValueError("the fitted scale is 0: predictions equal the observations exactly")
        self.n_samples_ = int(z.size)
        return self

    def transform(self, std: Any) -> np.ndarray:
        """Recalibrated standard deviations ``scale_ * std``."""
        if not hasattr(self, "scale_"):
            raise ValueError("StdScaler is not fitted; call fit first")
        return self.scale_ * np.asarray(std, dtype=np.float64)

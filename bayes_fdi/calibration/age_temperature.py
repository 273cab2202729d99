"""Temperature scaling by the age of the evidence: :class:`AgeTemperatureScaler`.

An online diagnoser names a fault from a signature that grows second by second after the
detection; the probabilities of its first seconds and those of a settled signature are not
equally reliable, and one temperature (`~bayes_fdi.calibration.TemperatureScaler`) fitted over
all of them is too confident early and not confident enough late. This scaler fits one
temperature per age bin (ages given with the rows: the seconds the signature has grown), each by
`TemperatureScaler` on that bin's rows, the pooled temperature standing in for a bin with too few
rows. Within a bin it is temperature scaling, so the diagnosed class never changes.

The binning is written here; each temperature is `TemperatureScaler`'s (scipy's bounded Brent
search on the mean negative log-likelihood).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator

from bayes_fdi.calibration.recalibration import class_indices, log_probabilities, log_softmax
from bayes_fdi.calibration.temperature import TemperatureScaler

__all__ = ["DEFAULT_AGE_EDGES", "AgeTemperatureScaler", "age_bins"]

#: Upper edges (seconds of evidence, exclusive) of the default age bins: [1, 10), [10, 30),
#: [30, 100), [100, 300) and 300 s or more.
DEFAULT_AGE_EDGES: tuple[float, ...] = (10.0, 30.0, 100.0, 300.0)


def age_bins(ages: Any, edges: Any) -> np.ndarray:
    """The bin of each age: the number of ``edges`` at or below it (an age at an edge opens the
    next bin). Ages must be finite and >= 0."""
    a = np.asarray(ages, dtype=np.float64)
    if a.ndim != 1 or not np.all(np.isfinite(a)) or np.any(a < 0):
        raise ValueError("ages must be a 1-D array of finite values >= 0 (seconds of evidence)")
    return np.searchsorted(np.asarray(edges, dtype=np.float64), a, side="right").astype(np.int64)


class AgeTemperatureScaler(BaseEstimator):
    """Recalibrate class distributions with one temperature per age bin.

    ``q = softmax(log(p) / T_k)`` where ``k`` is the bin of the row's age (the seconds of
    evidence behind it) among ``edges``. Each ``T_k`` is fitted by
    `~bayes_fdi.calibration.TemperatureScaler` on the rows of its bin; a bin with fewer than
    ``min_rows`` rows takes the temperature fitted on all rows (``pooled_temperature_``).

    Parameters
    ----------
    edges
        Increasing upper edges of the age bins (seconds; default `DEFAULT_AGE_EDGES`): the bins
        are ``[0, e1), [e1, e2), ..., [e_last, inf)``.
    min_rows
        Fewest rows a bin needs for a temperature of its own (default 200).
    floor, bounds, classes
        As `~bayes_fdi.calibration.TemperatureScaler` (probabilities in).

    Attributes
    ----------
    temperatures_ : numpy.ndarray
        ``(len(edges) + 1,)``: the temperature of each bin.
    edges_ : numpy.ndarray
        The bins' upper edges (seconds), as fitted.
    pooled_temperature_ : float
    rows_per_bin_ : numpy.ndarray
        ``(len(edges) + 1,)`` int64: the fitting rows in each bin.
    classes_ : numpy.ndarray
    nll_before_, nll_after_ : float
        Mean NLL on the fitting data at ``T = 1`` and with the bins' temperatures.
    n_samples_ : int
    """

    #: ``fit`` and ``transform`` take the rows' ages (what the online isolation passes).
    uses_ages = True

    def __init__(
        self,
        *,
        edges: Sequence[float] = DEFAULT_AGE_EDGES,
        min_rows: int = 200,
        floor: float = 1e-12,
        bounds: tuple[float, float] = (0.02, 50.0),
        classes: Sequence | None = None,
    ) -> None:
        self.edges = edges
        self.min_rows = min_rows
        self.floor = floor
        self.bounds = bounds
        self.classes = classes

    def _check_params(self) -> np.ndarray:
        """The bins' edges as an array, after checking ``edges`` and ``min_rows``."""
        e = np.asarray(self.edges, dtype=np.float64)
        if e.ndim != 1 or not np.all(np.isfinite(e)) or np.any(e <= 0) or np.any(np.diff(e) <= 0):
            raise ValueError(f"edges must be increasing finite values > 0, got {self.edges!r}")
        if int(self.min_rows) != self.min_rows or self.min_rows < 1:
            raise ValueError(f"min_rows must be an integer >= 1, got {self.min_rows!r}")
        return e

    def _scaler(self) -> TemperatureScaler:
        return TemperatureScaler(floor=self.floor, bounds=self.bounds, classes=self.classes)

    def fit(self, proba: Any, y: Any, ages: Any) -> AgeTemperatureScaler:
        """Fit the bins' temperatures on held-out ``(proba, y)`` with the rows' ``ages``."""
        edges = self._check_params()
        proba = np.asarray(proba)
        z = log_probabilities(proba, input="proba", floor=self.floor)
        bins = age_bins(ages, edges)
        if bins.size != z.shape[0]:
            raise ValueError(f"ages must have one value per row ({z.shape[0]}), got {bins.size}")
        y = np.asarray(y)
        pooled = self._scaler().fit(proba, y)
        self.classes_ = pooled.classes_
        self.pooled_temperature_ = float(pooled.temperature_)
        n_bins = edges.size + 1
        self.rows_per_bin_ = np.bincount(bins, minlength=n_bins).astype(np.int64)
        temps = np.full(n_bins, self.pooled_temperature_)
        scaler = self._scaler().set_params(classes=list(self.classes_))
        for k in range(n_bins):
            if self.rows_per_bin_[k] >= self.min_rows:
                sel = bins == k
                temps[k] = float(scaler.fit(proba[sel], y[sel]).temperature_)
        self.temperatures_ = temps
        self.edges_ = edges
        rows = np.arange(z.shape[0])
        y_idx, _ = class_indices(y, z.shape[0], list(self.classes_), z.shape[1])
        self.nll_before_ = float(-np.mean(log_softmax(z)[rows, y_idx]))
        self.nll_after_ = float(-np.mean(log_softmax(z / temps[bins][:, None])[rows, y_idx]))
        self.n_samples_ = int(z.shape[0])
        return self

    def temperature_of(self, ages: Any) -> np.ndarray:
        """The temperature each age's bin takes."""
        if not hasattr(self, "temperatures_"):
            raise ValueError("AgeTemperatureScaler is not fitted; call fit first")
        return self.temperatures_[age_bins(ages, self.edges_)]

    def transform(self, proba: Any, ages: Any) -> np.ndarray:
        """Recalibrated probabilities ``softmax(log(p) / T_k)``, ``k`` the bin of each row's
        age; rows sum to 1."""
        t = self.temperature_of(ages)
        z = log_probabilities(proba, input="proba", floor=self.floor)
        if z.shape[1] != len(self.classes_):
            raise ValueError(f"expected {len(self.classes_)} columns, got {z.shape[1]}")
        if t.size != z.shape[0]:
            raise ValueError(f"ages must have one value per row ({z.shape[0]}), got {t.size}")
        return np.exp(log_softmax(z / t[:, None]))

    def __repr__(self) -> str:
        t = ""
        if hasattr(self, "temperatures_"):
            t = ", temperatures_=[" + ", ".join(f"{v:.4g}" for v in self.temperatures_) + "]"
        return f"AgeTemperatureScaler(edges={tuple(self.edges)!r}{t})"

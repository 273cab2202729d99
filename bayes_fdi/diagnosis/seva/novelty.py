"""Novelty: how unlike the training samples new samples are (nearest-neighbour distance ratio).

RVM predictive standard deviations are *not* used for this: with localised kernels the RVR's
predictive variance shrinks back to the noise level far from the data, so it does not flag
novel inputs.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr
from scipy.spatial import cKDTree

from bayes_fdi.datasets import INPUT_CHANNELS

__all__ = ["NoveltyReference"]


class NoveltyReference:
    """How unlike the training samples new samples are (nearest-neighbour distance ratio).

    Fitted on training rows (e.g. the normal models' input samples CV, P1, P2, T1, or the
    classifier's training features): columns are standardised by the training mean and
    standard deviation; the *scale* is the ``quantile`` of every training sample's distance
    to its nearest other training sample. :meth:`score` returns, per new row, the distance
    to the nearest training row divided by the scale, so about ``1 - quantile`` of samples
    drawn like the training data score above 1, and samples far from all training data
    score >> 1.

    Parameters
    ----------
    quantile
        Quantile of the training nearest-neighbour distances used as the scale (default 0.99).
    max_points
        Training rows kept (a seeded random subset above this size; default 20000).
    random_state
        Seed of that subset.
    """

    def __init__(
        self, *, quantile: float = 0.99, max_points: int = 20_000, random_state: int | None = 0
    ) -> None:
        self.quantile = quantile
        self.max_points = max_points
        self.random_state = random_state

    def fit(self, X: Any) -> NoveltyReference:
        """Fit on training rows ``X`` of shape ``(n, d)`` (finite, n >= 3)."""
        X = np.asarray(X, dtype=np.float64)
        if X.ndim != 2 or X.shape[0] < 3:
            raise ValueError(f"NoveltyReference needs (n >= 3, d) training rows, got {X.shape}")
        if not np.all(np.isfinite(X)):
            raise ValueError("training rows contain NaN or inf")
        if not 0 < self.quantile < 1:
            raise ValueError("quantile must lie in (0, 1)")
        if X.shape[0] > self.max_points:
            rng = np.random.default_rng(self.random_state)
            X = X[rng.choice(X.shape[0], self.max_points, replace=False)]
        self.center_ = X.mean(axis=0)
        sd = X.std(axis=0)
        # constant columns (e.g. a fixed supply pressure) get the scale of the others, so
        # any departure from the constant counts
        floor = np.median(sd[sd > 0]) if np.any(sd > 0) else 1.0
        self.scale_ = np.where(sd > 0, sd, floor)
        Z = (X - self.center_) / self.scale_
        self.tree_ = cKDTree(Z)
        d, _ = self.tree_.query(Z, k=2)
        nn = d[:, 1]
        nn_pos = nn[nn > 0]
        self.threshold_ = float(np.quantile(nn_pos if nn_pos.size else nn, self.quantile))
        if not self.threshold_ > 0:
            self.threshold_ = 1e-12
        self.n_features_in_ = X.shape[1]
        self.n_samples_fit_ = X.shape[0]
        return self

    @classmethod
    def from_runs(
        cls, runs: xr.Dataset, channels: Sequence[str] = INPUT_CHANNELS, **kwargs: Any
    ) -> NoveltyReference:
        """Fit on every finite ``(run, time)`` sample of ``channels`` of a dataset."""
        X = _stack_samples(runs, channels)
        return cls(**kwargs).fit(X[np.all(np.isfinite(X), axis=1)])

    def score(self, X: Any) -> np.ndarray:
        """Nearest-training-row distance ratio per row (> 1: more remote than usual).

        Rows holding an infinite value score ``inf``; NaN rows are refused (ValueError).
        """
        if not hasattr(self, "tree_"):
            raise ValueError("NoveltyReference is not fitted; call fit first")
        X = np.asarray(X, dtype=np.float64)
        if X.ndim != 2 or X.shape[1] != self.n_features_in_:
            raise ValueError(f"expected (n, {self.n_features_in_}) rows, got {X.shape}")
        if np.isnan(X).any():
            raise ValueError("rows to score contain NaN (select the rows that were measured)")
        out = np.full(X.shape[0], np.inf)  # a row with an infinite entry is infinitely remote
        finite = np.all(np.isfinite(X), axis=1)
        if finite.any():
            d, _ = self.tree_.query((X[finite] - self.center_) / self.scale_, k=1)
            out[finite] = d / self.threshold_
        return out


def _stack_samples(runs: xr.Dataset, channels: Sequence[str]) -> np.ndarray:
    missing = [c for c in channels if c not in runs]
    if missing:
        raise ValueError(f"dataset lacks channel(s) {missing}")
    return np.stack([runs[c].values.reshape(-1) for c in channels], axis=1)

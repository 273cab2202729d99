"""Novelty per class: how unlike every fault's training signatures an isolation signature is.

`ClassNovelty` keeps, per class, a seeded subset of its standardised training rows and a radius
(a high quantile of the within-class nearest-neighbour distances); a row's score is its
distance to the nearest prototype of the closest class over that class's radius: below 1 for
rows drawn like a class, far above 1 for a signature unlike every known fault (an "unknown"
fault). `novelty_score_row` is the compiled score of one row, which the online isolator runs
every second (`bayes_fdi.diagnosis.isolation.isolator`).

Written by hand: a per-class radius on top of nearest-neighbour distances, compiled per row so
that a second's score never depends on the batch around it.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba import njit

__all__ = ["ClassNovelty", "NoveltyArrays", "novelty_score_row"]


class NoveltyArrays(NamedTuple):
    """A fitted `ClassNovelty` as the arrays `novelty_score_row` takes."""

    center: np.ndarray  #: ``(d,)`` training mean of the features
    scale: np.ndarray  #: ``(d,)`` their training std (1 where constant)
    prototypes: np.ndarray  #: ``(m, d)`` standardised prototypes of every class, class by class
    offsets: np.ndarray  #: ``(classes + 1,)`` int64: where each class's prototypes begin
    radius: np.ndarray  #: ``(classes,)`` radius of each class


@njit(cache=True, error_model="numpy")
def novelty_score_row(x, novelty):  # pragma: no cover - compiled
    """Novelty of one row under ``novelty`` (`NoveltyArrays`): the smallest, over classes, of
    the distance to the class's nearest prototype over the class radius."""
    center, scale, protos = novelty.center, novelty.scale, novelty.prototypes
    offsets, radius = novelty.offsets, novelty.radius
    d = x.size
    best = np.inf
    for c in range(offsets.size - 1):
        nearest = np.inf
        for i in range(offsets[c], offsets[c + 1]):
            d2 = 0.0
            for j in range(d):
                diff = (x[j] - center[j]) / scale[j] - protos[i, j]
                d2 += diff * diff
            if d2 < nearest:
                nearest = d2
        ratio = math.sqrt(nearest) / radius[c]
        if ratio < best:
            best = ratio
    return best


class ClassNovelty:
    """How unlike every class's training signatures a signature is.

    Features are standardised (training mean and std); each class keeps up to
    ``max_prototypes`` of its training rows (a seeded subset) and a radius, the ``quantile`` of
    its rows' leave-one-out nearest-neighbour distances within the class. The score of a row is
    the smallest, over classes, of its distance to the class's nearest prototype divided by the
    class radius: below 1 for about ``quantile`` of rows drawn like a class, far above 1 for a
    signature unlike every class. Infinite entries score ``inf``.

    Parameters
    ----------
    max_prototypes
        Rows kept per class (default 200).
    quantile
        Quantile of the within-class nearest-neighbour distances taken as the radius.
    random_state
        Seed of the subsets.
    """

    def __init__(
        self, *, max_prototypes: int = 200, quantile: float = 0.99, random_state: int | None = 0
    ) -> None:
        self.max_prototypes = max_prototypes
        self.quantile = quantile
        self.random_state = random_state

    def fit(self, X: Any, y: Any) -> ClassNovelty:
        """Fit on training rows ``X`` ``(n, d)`` with class labels ``y``."""
        X = np.asarray(X, dtype=np.float64)
        y = np.asarray(y).astype(str)
        if X.ndim != 2 or not np.all(np.isfinite(X)):
            raise ValueError("ClassNovelty needs finite (n, d) rows")
        rng = np.random.default_rng(self.random_state)
        self.center_ = X.mean(axis=0)
        sd = X.std(axis=0)
        self.scale_ = np.where(sd > 0, sd, 1.0)
        Z = (X - self.center_) / self.scale_
        protos, offsets, radius, classes = [], [0], [], []
        for c in np.unique(y):
            rows = np.flatnonzero(y == c)
            if rows.size > self.max_prototypes:
                rows = np.sort(rng.choice(rows, self.max_prototypes, replace=False))
            P = Z[rows]
            if P.shape[0] >= 2:
                d2 = ((P[:, None, :] - P[None, :, :]) ** 2).sum(-1)
                np.fill_diagonal(d2, np.inf)
                nn = np.sqrt(d2.min(axis=1))
                r = float(np.quantile(nn, self.quantile))
            else:
                r = 0.0
            radius.append(r if r > 0 else 1e-12)
            protos.append(P)
            offsets.append(offsets[-1] + P.shape[0])
            classes.append(str(c))
        self.classes_ = np.asarray(classes)
        self.prototypes_ = np.ascontiguousarray(np.concatenate(protos))
        self.offsets_ = np.asarray(offsets, dtype=np.int64)
        self.radius_ = np.asarray(radius, dtype=np.float64)
        return self

    def arrays(self) -> NoveltyArrays:
        """The fitted arrays the compiled score takes."""
        return NoveltyArrays(
            self.center_, self.scale_, self.prototypes_, self.offsets_, self.radius_
        )

    def score(self, X: Any) -> np.ndarray:
        """Novelty score of each row (``inf`` for rows with an infinite entry, NaN for NaN)."""
        X = np.ascontiguousarray(np.asarray(X, dtype=np.float64))
        out = np.full(X.shape[0], np.nan)
        arrays = self.arrays()
        for i in range(X.shape[0]):
            row = X[i]
            if np.isnan(row).any():
                continue
            out[i] = np.inf if np.isinf(row).any() else novelty_score_row(row, arrays)
        return out

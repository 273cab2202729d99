"""How far the position model's inputs lie from its training inputs (opt-in: ``std_bins``).

A relevance vector machine's predictive variance does not grow away from its training data: its
basis functions sit on the data, so far from them the prediction falls back on the bias with
the noise variance alone. On inputs that no training run reached (an excitation the training
never used, a valve held at an end stop) the normal models misfit by many standard deviations
and the detector reads the misfit as a fault. The *input novelty* measures that distance: the
Euclidean distance of the standardised position-model inputs ``u`` of a second (levels and
increments of the command and of the pressure-drop root, the lagged command) to the nearest of
`NOVELTY_REFERENCE_ROWS` training rows drawn at random with the fit's seed
(`novelty_reference`), over every input (``std_bins="novelty"``) or over the command's alone
(``"command-novelty"``, the default of the excitation-mix training: its level, increments and
lag; `novelty_columns`), so that a fault that moves the process inputs P1, P2 does not widen the
intervals that should reveal it. The predictive standard deviations then get one factor per bin
of that distance instead of the command speed, fitted by the cross-fit on
out-of-fold seconds (each fold's distances to a reference drawn from its own training rows):
bins at the quantiles `NOVELTY_LEVELS` of the out-of-fold distances, so that the few seconds
farthest from the training runs, where the out-of-fold residuals are largest, get their own
factor.

Written by hand: the distance is computed in the normal models' compiled per-second kernel
(`nearest_distance`), which no nearest-neighbour library reaches; `input_novelty` computes the
same distances for many rows with scikit-learn's k-d tree.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

__all__ = [
    "NOVELTY_LEVELS",
    "NOVELTY_REFERENCE_ROWS",
    "STD_BINS",
    "input_novelty",
    "nearest_distance",
    "novelty_columns",
    "novelty_reference",
]

#: What the predictive standard deviations' bins follow: the command speed ``|dCV|`` (default),
#: the input novelty over every input, or over the command's inputs alone (its level,
#: increments and lag: a fault that moves the process inputs P1, P2 then does not raise it).
STD_BINS: tuple[str, ...] = ("speed", "novelty", "command-novelty")
#: Training rows the novelty is measured against (fewer when the training has fewer).
NOVELTY_REFERENCE_ROWS = 512
#: Quantiles of the out-of-fold novelty at which its std bins are cut.
NOVELTY_LEVELS: tuple[float, ...] = (0.5, 0.9, 0.99, 0.999)


def novelty_columns(std_bins: str, n_differences: int, lagged: bool) -> np.ndarray:
    """The columns of the position model's inputs ``(CV, s, dCV_0 .., ds_0 .., [lag])`` that
    the novelty of ``std_bins`` measures: all, or (``"command-novelty"``) the command's."""
    n_u = 2 + 2 * n_differences + int(lagged)
    if std_bins != "command-novelty":
        return np.arange(n_u)
    return np.array([0, *range(2, 2 + n_differences), *([n_u - 1] if lagged else [])])


def novelty_reference(
    Z: np.ndarray, rows: np.ndarray, rng: np.random.Generator, columns: np.ndarray
) -> np.ndarray:
    """``(m, len(columns))`` reference of the novelty: `NOVELTY_REFERENCE_ROWS` of the
    standardised inputs ``Z`` drawn without replacement among ``rows`` (all of them when
    fewer), in row order, restricted to ``columns``."""
    rows = np.asarray(rows)
    if rows.size > NOVELTY_REFERENCE_ROWS:
        rows = np.sort(rng.choice(rows, size=NOVELTY_REFERENCE_ROWS, replace=False))
    return np.ascontiguousarray(Z[rows][:, columns], dtype=np.float64)


@njit(cache=True, error_model="numpy")
def nearest_distance(u, reference, columns):  # pragma: no cover - compiled
    """Euclidean distance of ``u[columns]`` to the nearest row of ``reference``."""
    best = math.inf
    for i in range(reference.shape[0]):
        d2 = 0.0
        for j in range(columns.size):
            e = u[columns[j]] - reference[i, j]
            d2 += e * e
        if d2 < best:
            best = d2
    return math.sqrt(best)


def input_novelty(Z: Any, reference: Any, columns: Any = None) -> np.ndarray:
    """`nearest_distance` of each row of ``Z`` ``(n, d)`` over ``columns`` (default: all) to
    ``reference`` ``(m, len(columns))``, by scikit-learn's k-d tree (exact distances); NaN
    where a row is not finite."""
    from sklearn.neighbors import NearestNeighbors

    Z = np.asarray(Z, dtype=np.float64)
    Z = Z if columns is None else Z[:, np.asarray(columns)]
    out = np.full(Z.shape[0], np.nan)
    ok = np.isfinite(Z).all(axis=1)
    if ok.any():
        tree = NearestNeighbors(n_neighbors=1, algorithm="kd_tree").fit(reference)
        out[ok] = tree.kneighbors(Z[ok])[0][:, 0]
    return out

"""Evidence-maximising choice of the RBF width (``width="auto"``).

The log evidence of an RVM as a function of ``log sigma`` is smooth but may have
several local maxima, so the search is a coarse log-spaced grid over a range derived
from the data scale (the median pairwise distance), followed by a bounded Brent search
(:func:`scipy.optimize.minimize_scalar`) on ``log sigma`` between the neighbours of the
best grid point.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
import torch
from scipy.optimize import minimize_scalar
from torch import Tensor

__all__ = ["WidthSearch", "data_scale", "search_width"]


class WidthSearch(NamedTuple):
    """Result of :func:`search_width`.

    Attributes
    ----------
    width : float
        The width with the largest log evidence found.
    log_evidence : float
        Its log evidence.
    widths : numpy.ndarray
        Every width evaluated, in evaluation order.
    evidences : numpy.ndarray
        The log evidence at each of ``widths``.
    """

    width: float
    log_evidence: float
    widths: np.ndarray
    evidences: np.ndarray


def data_scale(X: Tensor, max_points: int = 500) -> float:
    """Median pairwise Euclidean distance of (at most ``max_points`` evenly spaced) rows.

    Deterministic; falls back to 1.0 when all sampled rows coincide.
    """
    n = X.shape[0]
    idx = torch.linspace(0, n - 1, min(n, max_points)).round().long().unique()
    Z = X[idx.to(X.device)]
    d = torch.cdist(Z, Z)
    iu = torch.triu_indices(Z.shape[0], Z.shape[0], offset=1, device=Z.device)
    vals = d[iu[0], iu[1]]
    vals = vals[vals > 0]
    return float(vals.median()) if vals.numel() else 1.0


def search_width(
    log_evidence: Callable[[float], float],
    scale: float,
    *,
    bounds: tuple[float, float] = (1.0 / 30.0, 10.0),
    n_grid: int = 13,
    xatol: float = 0.02,
) -> WidthSearch:
    """Maximise ``log_evidence(width)`` over ``width`` in ``scale * bounds``.

    Parameters
    ----------
    log_evidence : callable
        Maps a width to the log evidence of the model fitted with it.
    scale : float
        Data scale (e.g. :func:`data_scale`).
    bounds : (float, float)
        Search range as multiples of ``scale``.
    n_grid : int
        Number of log-spaced grid points of the coarse stage (>= 3).
    xatol : float
        Absolute tolerance on ``log width`` of the refinement.
    """
    if n_grid < 3:
        raise ValueError(f"n_grid must be >= 3, got {n_grid}")
    lo, hi = math.log(scale * bounds[0]), math.log(scale * bounds[1])
    grid = np.linspace(lo, hi, n_grid)
    tried: dict[float, float] = {}

    def neg(log_w: float) -> float:
        value = log_evidence(math.exp(log_w))
        tried[float(log_w)] = value
        return -value if math.isfinite(value) else math.inf

    values = np.array([-neg(g) for g in grid])
    k = int(np.argmax(values))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, n_grid - 1)]
    minimize_scalar(neg, bounds=(a, b), method="bounded", options={"xatol": xatol})
    best = max(tried, key=tried.__getitem__)
    keys = list(tried)
    return WidthSearch(
        width=math.exp(best),
        log_evidence=tried[best],
        widths=np.exp(np.array(keys)),
        evidences=np.array([tried[k_] for k_ in keys]),
    )

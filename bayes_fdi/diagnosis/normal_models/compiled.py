"""The compiled one-sample predictor of a fitted RBF relevance vector regression, for the online
diagnoser's per-second path.

The online diagnoser evaluates its normal models once a second, sample by sample (``update``)
or over a whole recording (``run``), and the two must give the same numbers exactly. Calling the
estimator's torch ``predict`` per sample costs tens of microseconds of overhead, and a batched
matrix product need not round like a single-row one. `LeanRVR` holds an `~bayes_fdi.rvm.RVR`'s
*public* fitted attributes (``relevance_vectors_``, ``mean_``, ``covariance_``, ``beta_``,
``width_``) as plain arrays, and `rvr_predict` evaluates its predictive mean and variance
``1/beta + phi^T Sigma phi`` for one sample in compiled loops with a fixed summation order, so a
sample's result never depends on the batch around it. It agrees with
``predict(X, return_std=True)`` to rounding (tested). The isolation tree's compiled predictor
is `bayes_fdi.diagnosis.isolation.compiled_tree`.

Written by hand: no library compiles an RVM's predictive distribution per sample.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba import njit

__all__ = ["LeanRVR", "rbf_width", "rvr_predict"]


def rbf_width(est: Any) -> float:
    """The RBF width of a fitted RVM (ValueError for other kernels)."""
    from bayes_fdi.rvm.kernels import RBF

    kernel = est.get_params()["kernel"]
    if not (kernel == "rbf" or isinstance(kernel, RBF)):
        raise ValueError(f"lean predictors need an RBF kernel, got {kernel!r}")
    width = getattr(est, "width_", None)
    if width is None or not math.isfinite(float(width)) or width <= 0:
        raise ValueError(f"the fitted estimator has no usable width_ ({width!r})")
    return float(width)


class LeanRVR(NamedTuple):
    """An RBF relevance vector regression as plain arrays (the parameters `rvr_predict` takes).

    Attributes
    ----------
    centres : numpy.ndarray
        ``(m, d)`` relevance vectors.
    weights : numpy.ndarray
        ``(b + m,)`` posterior mean weights, the bias first when ``b = 1``.
    covariance : numpy.ndarray
        ``(b + m, b + m)`` posterior covariance.
    has_bias : bool
    noise_var : float
        ``1 / beta``.
    width : float
        RBF width.
    """

    centres: np.ndarray
    weights: np.ndarray
    covariance: np.ndarray
    has_bias: bool
    noise_var: float
    width: float

    @classmethod
    def from_estimator(cls, est: Any) -> LeanRVR:
        """Build from a fitted `~bayes_fdi.rvm.RVR` (public attributes only)."""
        width = rbf_width(est)
        centres = np.ascontiguousarray(est.relevance_vectors_, dtype=np.float64)
        weights = np.ascontiguousarray(est.mean_, dtype=np.float64).ravel()
        has_bias = weights.size == centres.shape[0] + 1
        if not has_bias and weights.size != centres.shape[0]:
            raise ValueError("mean_ does not match relevance_vectors_")
        cov = np.ascontiguousarray(est.covariance_, dtype=np.float64)
        return cls(centres, weights, cov, bool(has_bias), float(1.0 / est.beta_), width)

    def predict(self, U: Any) -> tuple[np.ndarray, np.ndarray]:
        """Predictive mean and standard deviation of the rows of ``U`` ``(n, d)``."""
        U = np.ascontiguousarray(np.asarray(U, dtype=np.float64))
        mean = np.empty(U.shape[0])
        var = np.empty(U.shape[0])
        phi = np.empty(self.weights.size)
        for i in range(U.shape[0]):
            mean[i], var[i] = rvr_predict(U[i], self, phi)
        return mean, np.sqrt(var)


@njit(cache=True, error_model="numpy")
def rvr_predict(u, model, phi):  # pragma: no cover - compiled
    """Mean and variance of one input row ``u`` under ``model`` (a `LeanRVR`; ``phi``: scratch
    of its weights' size)."""
    centres = model.centres
    weights = model.weights
    cov = model.covariance
    inv_two_w2 = 0.5 / (model.width * model.width)
    off = 0
    if model.has_bias:
        phi[0] = 1.0
        off = 1
    m, d = centres.shape
    for i in range(m):
        d2 = 0.0
        for j in range(d):
            diff = u[j] - centres[i, j]
            d2 += diff * diff
        phi[off + i] = math.exp(-d2 * inv_two_w2)
    n = off + m
    mean = 0.0
    for i in range(n):
        mean += phi[i] * weights[i]
    quad = 0.0
    for i in range(n):
        row = 0.0
        for j in range(n):
            row += cov[i, j] * phi[j]
        quad += phi[i] * row
    if quad < 0.0:
        quad = 0.0
    return mean, model.noise_var + quad

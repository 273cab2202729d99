"""Whitening of the normal models' standardised residuals by an autoregressive filter.

The standardised residuals ``z = (y - y_hat) / std`` of a fault-free actuator are
autocorrelated (the models' errors follow the slow dynamics the static inputs do not capture).
`ARWhitener` fits an AR prediction-error filter on fault-free residuals (Yule-Walker, pooled
over runs, order by BIC) and turns ``z`` into about independent unit-variance innovations ``e``,
which the sequential tests of `bayes_fdi.diagnosis.detection.detectors` then watch. Like every
online component it owns its state (`WhitenState`: the last residuals, created by
``init_state`` and checked by ``check_state``): ``update(z, state)`` (one sample) and
``run(z, state)`` (a sequence) call the same compiled kernel and return the innovations with a
new state. A NaN (a gap) restarts the filter at order 0, growing back with the lower-order
predictors of the same fit.

Written by hand: the Levinson-Durbin recursion gives every lower-order predictor at once (used
after gaps), which ``scipy.linalg.solve_toeplitz`` does not, and no maintained library has a
streaming AR filter whose state survives NaN gaps.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit

from bayes_fdi.diagnosis.component_state import (
    check_state,
    one_sequence,
    stacked_sequences,
    working_state,
)

__all__ = ["ARWhitener", "WhitenState", "levinson_durbin"]


class WhitenState(NamedTuple):
    """The state of an `ARWhitener`."""

    history: np.ndarray  #: ``(order,)`` the last centred residuals, newest first
    valid: np.ndarray  #: ``(1,)`` int64: how many of them follow the last gap


def levinson_durbin(acov: Any, order: int) -> tuple[np.ndarray, np.ndarray]:
    """All AR predictors up to ``order`` from an autocovariance sequence (Levinson-Durbin).

    Parameters
    ----------
    acov
        Autocovariances ``c_0, c_1, ..., c_order`` (``c_0 > 0``).
    order
        Largest AR order.

    Returns
    -------
    predictors : numpy.ndarray
        ``(order + 1, order)``: row ``j`` holds the ``j`` coefficients of the order-``j``
        one-step predictor ``x_t ~ sum_i a_i x_{t-i}`` (zeros after them).
    innovation_var : numpy.ndarray
        ``(order + 1,)``: the prediction-error variance of each order (``c_0`` for order 0).
    """
    c = np.asarray(acov, dtype=np.float64)
    if c.ndim != 1 or c.size < order + 1:
        raise ValueError(f"need {order + 1} autocovariances, got {c.size}")
    if not c[0] > 0:
        raise ValueError("the lag-0 autocovariance must be positive")
    table = np.zeros((order + 1, max(order, 1)))
    var = np.empty(order + 1)
    var[0] = c[0]
    a = np.zeros(0)
    for j in range(1, order + 1):
        refl = (c[j] - np.dot(a, c[j - 1 : 0 : -1])) / var[j - 1]
        a = np.append(a - refl * a[::-1], refl)
        var[j] = var[j - 1] * (1.0 - refl * refl)
        table[j, :j] = a
        if not var[j] > 0:
            raise ValueError("the autocovariances are not positive definite")
    return table[:, :order], var


def _pooled_autocovariance(z: np.ndarray, max_lag: int) -> tuple[np.ndarray, float]:
    """Autocovariance of the rows of ``z`` (NaN gaps: only complete pairs), mean removed."""
    ok = np.isfinite(z)
    mean = float(z[ok].mean())
    d = np.where(ok, z - mean, 0.0)
    acov = np.empty(max_lag + 1)
    n = z.shape[1]
    for lag in range(max_lag + 1):
        a, b = d[:, : n - lag], d[:, lag:]
        pairs = (ok[:, : n - lag] & ok[:, lag:]).sum()
        acov[lag] = float((a * b).sum() / max(pairs, 1))
    return acov, mean


@njit(cache=True, error_model="numpy")
def _whiten_kernel(x, mean, table, std, state, out):  # pragma: no cover - compiled
    """Innovations of ``x`` with the AR predictors ``table`` (``state`` updated in place).

    After a NaN (a gap) the predictor restarts at order 0 and grows back to the full order as
    samples arrive, each order with its own innovation std.
    """
    hist = state.history
    n_valid = state.valid
    p = hist.size
    for t in range(x.size):
        v = x[t]
        if not np.isfinite(v):
            out[t] = np.nan
            n_valid[0] = 0
            continue
        j = n_valid[0]
        pred = 0.0
        for i in range(j):
            pred += table[j, i] * hist[i]
        c = v - mean
        out[t] = (c - pred) / std[j]
        for i in range(p - 1, 0, -1):
            hist[i] = hist[i - 1]
        if p > 0:
            hist[0] = c
        if j < p:
            n_valid[0] = j + 1


@njit(cache=True, error_model="numpy")
def _whiten_runs(x, mean, table, std, state, out):  # pragma: no cover - compiled
    """`_whiten_kernel` over each run (row) of ``x``; ``state`` stacks the runs' states."""
    for r in range(x.shape[0]):
        run_state = WhitenState(state.history[r], state.valid[r])
        _whiten_kernel(x[r], mean, table, std, run_state, out[r])


class ARWhitener:
    """Whitening of standardised residuals by an autoregressive (AR) prediction-error filter.

    ``e_t = (z_t - m - sum_i a_i (z_{t-i} - m)) / s``: the one-step prediction error of an AR
    model fitted on fault-free residuals (Yule-Walker, pooled over runs), scaled to unit
    variance. The order is chosen by BIC up to ``max_order``. After a gap the filter restarts
    with the lower-order predictors of the same fit (Levinson-Durbin), so no sample after the
    gap is lost.

    Parameters
    ----------
    max_order
        Largest AR order considered (default 8).
    order
        A fixed order instead of the BIC choice (default None).

    Attributes
    ----------
    order_ : int
    coef_ : numpy.ndarray
        ``(order_,)`` AR coefficients.
    mean_ : float
    predictors_ : numpy.ndarray
        ``(order_ + 1, order_)`` predictors of every order (row j: order j).
    innovation_std_ : numpy.ndarray
        ``(order_ + 1,)`` innovation standard deviation of every order.
    bic_ : numpy.ndarray
        BIC of orders ``0 .. max_order``.
    """

    def __init__(self, max_order: int = 8, order: int | None = None) -> None:
        self.max_order = max_order
        self.order = order

    def fit(self, z: Any) -> ARWhitener:
        """Fit on fault-free standardised residuals ``z`` (1-D, or 2-D ``(runs, time)``)."""
        z = np.atleast_2d(np.asarray(z, dtype=np.float64))
        if z.ndim != 2:
            raise ValueError(f"z must be 1-D or 2-D (runs, time), got shape {z.shape}")
        max_order = int(self.max_order if self.order is None else self.order)
        if max_order < 0:
            raise ValueError(f"max_order must be >= 0, got {max_order}")
        n = int(np.isfinite(z).sum())
        if n < 10 * (max_order + 1):
            raise ValueError(f"{n} finite residuals are too few for an AR({max_order}) fit")
        acov, mean = _pooled_autocovariance(z, max_order)
        table, var = levinson_durbin(acov, max_order)
        self.bic_ = n * np.log(var) + np.arange(max_order + 1) * np.log(n)
        order = max_order if self.order is not None else int(np.argmin(self.bic_))
        self.order_ = order
        self.mean_ = mean
        self.predictors_ = np.ascontiguousarray(table[: order + 1, :order])
        self.innovation_std_ = np.sqrt(var[: order + 1])
        self.coef_ = self.predictors_[order].copy()
        return self

    def _check(self) -> None:
        if not hasattr(self, "order_"):
            raise ValueError("ARWhitener is not fitted; call fit first")

    def init_state(self) -> WhitenState:
        """A fresh filter state (no past residuals: the next sample starts at order 0)."""
        self._check()
        return WhitenState(np.zeros(self.order_), np.zeros(1, dtype=np.int64))

    def check_state(self, state: Any) -> None:
        """Raise a `ValueError` naming the field unless ``state`` is a state of this filter."""
        check_state(state, self.init_state(), "whitener state")

    def run(self, z: Any, state: WhitenState | None = None) -> tuple[np.ndarray, WhitenState]:
        """Innovations of consecutive standardised residuals of one run.

        Parameters
        ----------
        z
            ``(n,)`` standardised residuals (NaN: a gap).
        state
            The state after the preceding residual (default: a fresh one); not changed.

        Returns
        -------
        innovations : numpy.ndarray
            ``(n,)``, NaN for NaN.
        state : WhitenState
            The state after the last residual.
        """
        self._check()
        x = one_sequence(z)
        state = working_state(self, state)
        out = np.empty_like(x)
        _whiten_kernel(x, self.mean_, self.predictors_, self.innovation_std_, state, out)
        return out, state

    def run_stacked(self, z: Any, state: WhitenState) -> tuple[np.ndarray, WhitenState]:
        """`run` of many runs at once: ``z`` ``(runs, n)``, ``state`` their states stacked
        along a leading run axis (`~bayes_fdi.diagnosis.component_state.stack_states`); returns
        ``(runs, n)`` innovations and the stacked states after them (each run's equal to
        `run`'s)."""
        self._check()
        x, state = stacked_sequences(z, state, self.init_state(), "whitener state")
        out = np.empty_like(x)
        _whiten_runs(x, self.mean_, self.predictors_, self.innovation_std_, state, out)
        return out, state

    def update(self, z: float, state: WhitenState | None = None) -> tuple[float, WhitenState]:
        """The innovation of one standardised residual (`run` on one sample; O(order) time)."""
        out, state = self.run(np.array([z], dtype=np.float64), state)
        return float(out[0]), state

    @classmethod
    def upgrade_model_file(cls, data: dict, format_version: int) -> dict:
        """An `ARWhitener`'s saved attributes in today's layout: files of bayes_fdi 0.1.0 hold
        the state of its own stream (``_state``), which the filter no longer keeps."""
        return {k: v for k, v in data.items() if k != "_state"}

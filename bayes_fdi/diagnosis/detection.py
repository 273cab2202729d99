"""Sequential change detection on the normal models' standardised residuals.

The online diagnoser detects a fault from the residuals of the normal models,
``z = (y - y_hat) / std``, standardised by their calibrated predictive standard deviation. The
standardised residuals of a fault-free actuator are autocorrelated (the models' errors follow
the slow dynamics the static inputs do not capture), so they are first *whitened* by an
autoregressive filter estimated on fault-free data (`ARWhitener`); the innovations ``e`` are
then about independent with unit variance and feed a sequential test:

`CUSUM`
    Page's two-sided cumulative sum ``S+ = max(0, S+ + e - k)``, ``S- = max(0, S- - e - k)``,
    statistic ``max(S+, S-)``, capped at ``cap`` so that the evidence clears in bounded time
    once a fault is gone. A persistent bias below ``k`` (slow model drift on real data) does
    not accumulate.
`GLR`
    The generalised likelihood ratio for a change of unknown size in the mean of unit-variance
    Gaussian innovations within the last ``window`` samples,
    ``g = max_{1 <= L <= window} (sum of the last L innovations)^2 / (2 L)`` (two-sided by
    construction; the evidence clears ``window`` samples after the change is gone).

Each detector is one small class with ``update(x)`` (one sample, O(1) time and memory, in the
style of river's drift detectors) and ``run(x)`` (a whole sequence); both call the same
compiled kernel with the same state, so ``run`` equals ``update`` sample by sample exactly. A
NaN innovation (a gap) leaves the state unchanged and gives a NaN statistic.

Thresholds are set for a false-alarm budget: `cusum_arl` is Siegmund's approximation of the
in-control average run length of a one-sided CUSUM on N(0, 1) data, `cusum_threshold` inverts
it, and `empirical_arl` / `calibrate_threshold` measure the run length on held-out fault-free
innovations and extrapolate it (log ARL is linear in the threshold for large thresholds, as
Siegmund's formula shows), so non-Gaussian real residuals get an honest threshold.
`detection_decision` turns the statistics into the detection decision DD with hysteresis: on
when a statistic exceeds the threshold, off only when every statistic is back at or below the
clear level.

Written by hand: scipy and scikit-learn have no sequential change detectors, and river's
(not a dependency) have neither a vectorised path equal to ``update`` nor NaN gaps; the
Levinson-Durbin recursion of `ARWhitener` is short and gives every lower-order predictor at once
(used after gaps), which ``scipy.linalg.solve_toeplitz`` does not.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numba import njit
from scipy import optimize

__all__ = [
    "CUSUM",
    "GLR",
    "ARWhitener",
    "calibrate_threshold",
    "cusum_arl",
    "cusum_threshold",
    "detection_decision",
    "empirical_arl",
    "levinson_durbin",
]


# ----------------------------------------------------------------------------------------------
# whitening
# ----------------------------------------------------------------------------------------------
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
def _whiten_kernel(x, mean, table, std, hist, n_valid, out):  # pragma: no cover - compiled
    """Innovations of ``x`` with the AR predictors ``table``; ``hist``/``n_valid`` are state.

    After a NaN (a gap) the predictor restarts at order 0 and grows back to the full order as
    samples arrive, each order with its own innovation std.
    """
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
        self.reset()
        return self

    def _check(self) -> None:
        if not hasattr(self, "order_"):
            raise ValueError("ARWhitener is not fitted; call fit first")

    def new_state(self) -> tuple[np.ndarray, np.ndarray]:
        """A fresh filter state: the last ``order_`` centred values and the valid count."""
        self._check()
        return np.zeros(self.order_), np.zeros(1, dtype=np.int64)

    def advance(self, z: Any, state: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        """Innovations of consecutive residuals from an explicit ``state`` (updated in place)."""
        self._check()
        x = np.ascontiguousarray(np.asarray(z, dtype=np.float64))
        if x.ndim != 1:
            raise ValueError(f"expected one sequence (1-D), got shape {x.shape}")
        out = np.empty_like(x)
        _whiten_kernel(x, self.mean_, self.predictors_, self.innovation_std_, state[0],
                       state[1], out)  # fmt: skip
        return out

    def reset(self) -> ARWhitener:
        """Forget the past (the next sample starts at order 0)."""
        self._state = self.new_state()
        return self

    def update(self, z: float) -> float:
        """The innovation of one standardised residual (NaN for NaN; O(order) time)."""
        self._check()
        return float(self.advance(np.array([z], dtype=np.float64), self._state)[0])

    def run(self, z: Any) -> np.ndarray:
        """Innovations of a sequence, continuing from the current state (equals `update`)."""
        self._check()
        return self.advance(z, self._state)


# ----------------------------------------------------------------------------------------------
# sequential tests
# ----------------------------------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def _cusum_kernel(e, k, cap, state, stat, since):  # pragma: no cover - compiled
    """Two-sided CUSUM. state = [S+, S-, n+, n-] (n: samples since the side last was 0)."""
    for t in range(e.size):
        v = e[t]
        if not np.isfinite(v):
            stat[t] = np.nan
            since[t] = -1
            continue
        sp = state[0] + v - k
        sn = state[1] - v - k
        if sp > 0.0:
            state[2] += 1.0
        else:
            sp = 0.0
            state[2] = 0.0
        if sn > 0.0:
            state[3] += 1.0
        else:
            sn = 0.0
            state[3] = 0.0
        if sp > cap:
            sp = cap
        if sn > cap:
            sn = cap
        state[0] = sp
        state[1] = sn
        if sp >= sn:
            stat[t] = sp
            since[t] = state[2]
        else:
            stat[t] = sn
            since[t] = state[3]


@njit(cache=True, error_model="numpy")
def _glr_kernel(e, window, buf, state, stat, since):  # pragma: no cover - compiled
    """Windowed GLR for a mean change; buf: the last ``window`` innovations (ring), state =
    [n stored, next slot]."""
    w = buf.size
    for t in range(e.size):
        v = e[t]
        if not np.isfinite(v):
            stat[t] = np.nan
            since[t] = -1
            continue
        slot = int(state[1])
        buf[slot] = v
        state[1] = (slot + 1) % w
        if state[0] < w:
            state[0] += 1
        n = int(state[0])
        total = 0.0
        best = 0.0
        best_len = 0
        for length in range(1, n + 1):
            total += buf[(slot - length + 1) % w]
            g = total * total / (2.0 * length)
            if g > best:
                best = g
                best_len = length
        stat[t] = best
        since[t] = best_len


class _Detector:
    """Shared machinery: ``update``/``run`` over one compiled kernel and an explicit state."""

    threshold: float

    def new_state(self) -> tuple[np.ndarray, ...]:  # pragma: no cover - abstract
        """A fresh state (no evidence)."""
        raise NotImplementedError

    def _kernel(self, e: np.ndarray, state: tuple, stat: np.ndarray, since: np.ndarray) -> None:
        raise NotImplementedError  # pragma: no cover - abstract

    def _check_params(self) -> None:
        if not (isinstance(self.threshold, int | float) and self.threshold > 0):
            raise ValueError(f"threshold must be a positive number, got {self.threshold!r}")

    def advance(self, e: Any, state: tuple) -> tuple[np.ndarray, np.ndarray]:
        """Statistics of consecutive innovations from an explicit ``state`` (updated in place),
        and per sample the samples since the estimated change (-1 for NaN)."""
        self._check_params()
        x = np.ascontiguousarray(np.asarray(e, dtype=np.float64))
        if x.ndim != 1:
            raise ValueError(f"expected one sequence (1-D), got shape {x.shape}")
        stat = np.empty_like(x)
        since = np.empty(x.size, dtype=np.float64)
        self._kernel(x, state, stat, since)
        return stat, since

    def reset(self) -> _Detector:
        """Forget all evidence (a fresh detector with the same parameters)."""
        self._check_params()
        self._state = self.new_state()
        self.statistic = 0.0
        self.drift_detected = False
        return self

    def run_with_onsets(self, e: Any) -> tuple[np.ndarray, np.ndarray]:
        """`advance` from the detector's own state (continues it)."""
        if not hasattr(self, "_state"):
            self.reset()
        stat, since = self.advance(e, self._state)
        last = stat[np.isfinite(stat)]
        if last.size:
            self.statistic = float(last[-1])
            self.drift_detected = self.statistic > self.threshold
        return stat, since

    def run(self, e: Any) -> np.ndarray:
        """The statistic after each innovation of a sequence (equals repeated `update`)."""
        return self.run_with_onsets(e)[0]

    def update(self, e: float) -> float:
        """Add one innovation; returns the statistic (NaN for a NaN innovation, state kept).

        ``drift_detected`` is then ``statistic > threshold`` (the last finite statistic).
        """
        return float(self.run(np.array([e], dtype=np.float64))[0])


class CUSUM(_Detector):
    """Page's two-sided CUSUM on unit-variance innovations, capped.

    ``S+ = min(cap, max(0, S+ + e - k))``, ``S- = min(cap, max(0, S- - e - k))``; the statistic
    is ``max(S+, S-)``. It detects a mean shift of size ``delta`` (in innovation standard
    deviations) in about ``threshold / (delta - k)`` samples; ``k`` is half the smallest shift
    it is tuned for, and a persistent offset below ``k`` never accumulates.

    Parameters
    ----------
    k
        Reference value (allowance), >= 0 (default 0.5).
    threshold
        Alarm level ``h`` (default 10).
    cap
        Largest value of ``S+`` and ``S-`` (default ``2 * threshold``): once a fault is gone
        the statistic returns to 0 within about ``cap / k`` samples.

    Attributes
    ----------
    statistic : float
        The last finite statistic.
    drift_detected : bool
        ``statistic > threshold``.
    """

    def __init__(self, k: float = 0.5, threshold: float = 10.0, cap: float | None = None) -> None:
        self.k = k
        self.threshold = threshold
        self.cap = cap

    def _check_params(self) -> None:
        super()._check_params()
        if not (isinstance(self.k, int | float) and self.k >= 0):
            raise ValueError(f"k must be a number >= 0, got {self.k!r}")
        if self.cap is not None and not self.cap >= self.threshold:
            raise ValueError(f"cap must be >= threshold, got {self.cap!r}")

    @property
    def cap_(self) -> float:
        """The cap in use."""
        return float(2.0 * self.threshold if self.cap is None else self.cap)

    def new_state(self) -> tuple[np.ndarray]:
        """``([S+, S-, n+, n-],)``: the sums and their samples since they last were 0."""
        return (np.zeros(4),)

    def _kernel(self, e: np.ndarray, state: tuple, stat: np.ndarray, since: np.ndarray) -> None:
        _cusum_kernel(e, float(self.k), self.cap_, state[0], stat, since)


class GLR(_Detector):
    """Windowed generalised likelihood ratio for a mean change in N(0, 1) innovations.

    ``g = max_{1 <= L <= window} S_L^2 / (2 L)`` with ``S_L`` the sum of the last ``L``
    innovations: the log likelihood ratio of "the mean changed ``L`` samples ago to the value
    that fits best" against "no change", maximised over ``L``. Two-sided; ``O(window)`` per
    sample.

    Parameters
    ----------
    window
        Longest change age considered (samples, default 60).
    threshold
        Alarm level (default 10).

    Attributes
    ----------
    statistic : float
    drift_detected : bool
    """

    def __init__(self, window: int = 60, threshold: float = 10.0) -> None:
        self.window = window
        self.threshold = threshold

    def _check_params(self) -> None:
        super()._check_params()
        if isinstance(self.window, bool) or not isinstance(self.window, int) or self.window < 1:
            raise ValueError(f"window must be an integer >= 1, got {self.window!r}")

    def new_state(self) -> tuple[np.ndarray, np.ndarray]:
        """``(ring buffer of the last window innovations, [stored, next slot])``."""
        return np.zeros(int(self.window)), np.zeros(2)

    def _kernel(self, e: np.ndarray, state: tuple, stat: np.ndarray, since: np.ndarray) -> None:
        _glr_kernel(e, int(self.window), state[0], state[1], stat, since)


# ----------------------------------------------------------------------------------------------
# the detection decision with hysteresis
# ----------------------------------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def _decision_kernel(stats, threshold, clear, held, state, dd):  # pragma: no cover - compiled
    """DD with hysteresis over channels; held: last finite statistic per channel (state)."""
    n, c = stats.shape
    for t in range(n):
        for j in range(c):
            if np.isfinite(stats[t, j]):
                held[j] = stats[t, j]
        on = state[0] > 0.5
        if on:
            cleared = True
            for j in range(c):
                if held[j] > clear:
                    cleared = False
            if cleared:
                on = False
        else:
            for j in range(c):
                if np.isfinite(stats[t, j]) and stats[t, j] > threshold:
                    on = True
        state[0] = 1.0 if on else 0.0
        dd[t] = on


def detection_decision(
    stats: Any,
    threshold: float,
    clear: float,
    *,
    state: np.ndarray | None = None,
    held: np.ndarray | None = None,
) -> np.ndarray:
    """The detection decision DD with hysteresis from per-channel statistics.

    DD turns on at the first sample where a channel's statistic exceeds ``threshold`` and turns
    off at the first sample where every channel's last finite statistic is at or below
    ``clear`` ("the evidence has cleared"). A NaN statistic (a gap) brings no new evidence: the
    channel keeps its last value and cannot switch DD on.

    Parameters
    ----------
    stats
        ``(n, n_channels)`` statistics of one run.
    threshold, clear
        Switch-on and switch-off levels (``clear <= threshold``).
    state, held
        Optional state to continue from and update in place: ``state`` a ``(1,)`` array
        (1.0 while DD is on) and ``held`` the ``(n_channels,)`` last finite statistics.

    Returns
    -------
    numpy.ndarray
        ``(n,)`` bool.
    """
    s = np.ascontiguousarray(np.asarray(stats, dtype=np.float64))
    if s.ndim != 2:
        raise ValueError(f"stats must be (n, n_channels), got shape {s.shape}")
    if not clear <= threshold:
        raise ValueError(f"clear ({clear}) must not exceed threshold ({threshold})")
    state = np.zeros(1) if state is None else state
    held = np.zeros(s.shape[1]) if held is None else held
    dd = np.zeros(s.shape[0], dtype=np.bool_)
    _decision_kernel(s, float(threshold), float(clear), held, state, dd)
    return dd


# ----------------------------------------------------------------------------------------------
# thresholds for a false-alarm budget
# ----------------------------------------------------------------------------------------------
def cusum_arl(threshold: Any, k: float) -> np.ndarray:
    """Siegmund's approximation of a one-sided CUSUM's in-control ARL on N(0, 1) data.

    ``ARL0 = (exp(2 k b) - 2 k b - 1) / (2 k^2)`` with ``b = h + 1.166`` (for ``k > 0``;
    ``b^2`` for ``k = 0``), the mean number of samples before ``S+`` first exceeds ``h``
    (Siegmund 1985, *Sequential Analysis*, eq. 2.55; Basseville & Nikiforov 1993, eq. 5.2.44).
    """
    b = np.asarray(threshold, dtype=np.float64) + 1.166
    if k == 0:
        return b**2
    a = 2.0 * k * b
    with np.errstate(over="ignore"):  # an infinite ARL for an enormous threshold is right
        return (np.exp(a) - a - 1.0) / (2.0 * k * k)


def cusum_threshold(arl: float, k: float, *, n_sides: int = 1) -> float:
    """The CUSUM threshold whose in-control ARL is ``arl`` (Siegmund's approximation).

    ``n_sides`` one-sided CUSUMs that run together (two per two-sided CUSUM and channel) raise
    a first alarm about ``n_sides`` times as often: each gets ``n_sides * arl``.
    """
    if not arl > 1:
        raise ValueError(f"arl must exceed 1, got {arl}")
    target = float(arl) * int(n_sides)
    return float(optimize.brentq(lambda h: float(cusum_arl(h, k)) - target, -1.0, 1e4))


def empirical_arl(
    detector: Any, innovations: Sequence[Any], threshold: float, clear: float = 0.0
) -> tuple[float, int, int]:
    """Mean run length between false alarms of a detector on fault-free innovations.

    Every run (a sequence of ``(n,)`` or ``(n, n_channels)`` innovations; one fresh detector
    per channel, a clone of ``detector`` with ``threshold``) is processed as the online
    diagnoser does, with the hysteresis of `detection_decision` (off at ``clear``). An alarm is
    a rising edge of DD.

    Returns
    -------
    arl : float
        Finite samples / alarms (``inf`` with no alarm).
    alarms : int
    samples : int
    """
    alarms = 0
    samples = 0
    for run in innovations:
        e = np.asarray(run, dtype=np.float64)
        e = e[:, None] if e.ndim == 1 else e
        stats = np.column_stack(
            [_with_threshold(detector, threshold).run(e[:, j]) for j in range(e.shape[1])]
        )
        dd = detection_decision(stats, threshold, min(clear, threshold))
        alarms += int(dd[:1].sum() + (dd[1:] & ~dd[:-1]).sum())
        samples += int(np.isfinite(e).all(axis=1).sum())
    return (samples / alarms if alarms else math.inf), alarms, samples


def _with_threshold(detector: Any, threshold: float) -> Any:
    """A fresh copy of ``detector`` with another threshold (same other parameters)."""
    params = {k: getattr(detector, k) for k in ("k", "cap", "window") if hasattr(detector, k)}
    return type(detector)(threshold=float(threshold), **params).reset()


def calibrate_threshold(
    detector: Any,
    innovations: Sequence[Any],
    target_arl: float,
    *,
    clear: float = 0.0,
    grid: Sequence[float] | None = None,
    min_alarms: int = 10,
    floor: float | None = None,
) -> dict[str, Any]:
    """The threshold that meets a false-alarm budget, measured on fault-free innovations.

    The empirical ARL (`empirical_arl`) is measured on a grid of thresholds low enough to give
    at least ``min_alarms`` alarms each; ``log(ARL)`` is fitted as a straight line in the
    threshold (its large-threshold form for a CUSUM, Siegmund, and a good description of the
    GLR's) by least squares, and the threshold where the line reaches ``target_arl`` is taken,
    or the lowest measured threshold whose ARL already exceeds the target if that is smaller.
    A ``floor`` (e.g. the theoretical threshold for Gaussian innovations) bounds it below.

    Returns
    -------
    dict
        ``threshold``, ``fit`` (intercept, slope), ``grid``, ``arl``, ``alarms``,
        ``samples`` and ``floor``.
    """
    if not target_arl > 1:
        raise ValueError(f"target_arl must exceed 1, got {target_arl}")
    grid = np.arange(1.0, 30.01, 1.0) if grid is None else np.asarray(grid, dtype=np.float64)
    arls, counts, samples = [], [], 0
    for h in grid:
        arl, n_alarms, samples = empirical_arl(detector, innovations, float(h), clear)
        arls.append(arl)
        counts.append(n_alarms)
        if n_alarms < min_alarms:
            break
    arls_a = np.asarray(arls)
    counts_a = np.asarray(counts)
    used = grid[: arls_a.size]
    ok = counts_a >= min_alarms
    if ok.sum() >= 2:
        slope, intercept = np.polyfit(used[ok], np.log(arls_a[ok]), 1)
    else:
        slope, intercept = math.nan, math.nan
    if slope > 0:
        h = (math.log(target_arl) - intercept) / slope
    else:
        h = math.inf
    reached = used[arls_a >= target_arl]
    if reached.size and reached[0] < h:
        h = float(reached[0])
    if floor is not None:
        h = max(h, float(floor))
    return {
        "threshold": float(h),
        "fit": (float(intercept), float(slope)),
        "grid": used.tolist(),
        "arl": arls_a.tolist(),
        "alarms": counts_a.tolist(),
        "samples": int(samples),
        "floor": None if floor is None else float(floor),
    }

"""Sequential change detection on the whitened residuals of the normal models.

The online diagnoser detects a fault from the residuals of the normal models,
``z = (y - y_hat) / std``, standardised by their calibrated predictive standard deviation and
whitened (`bayes_fdi.diagnosis.detection.whitening.ARWhitener`) into about independent unit-variance
innovations ``e``, which feed a sequential test:

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

`detection_decision` turns the statistics into the detection decision DD with hysteresis: on
when a statistic exceeds the threshold, off only when every statistic is back at or below the
clear level. The thresholds for a false-alarm budget are in
`bayes_fdi.diagnosis.detection.thresholds`.

Written by hand: scipy and scikit-learn have no sequential change detectors, and river's
(not a dependency) have neither a vectorised path equal to ``update`` nor NaN gaps.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit

__all__ = ["CUSUM", "GLR", "detection_decision"]


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

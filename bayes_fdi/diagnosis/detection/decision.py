"""The detection decision DD: hysteresis over the sequential tests' statistics.

`DetectionDecision` turns the per-channel statistics of the sequential tests
(`bayes_fdi.diagnosis.detection.detectors`) into the detection decision DD: on when a statistic
exceeds the threshold, off only when every channel's statistic is back at or below the clear
level ("the evidence has cleared"). A NaN statistic (a gap) brings no new evidence: the channel
keeps its last value and cannot switch DD on. Like every online component it owns its state
(`DecisionState`), with ``update`` for one second and ``run`` over a chunk through the same
compiled kernel; `detection_decision` is ``run`` from a fresh state.

Written by hand: a few lines of hysteresis that must run compiled, one sample at a time.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit

from bayes_fdi.diagnosis.component_state import check_state, working_state

__all__ = ["DecisionState", "DetectionDecision", "detection_decision"]


class DecisionState(NamedTuple):
    """The state of a `DetectionDecision`."""

    on: np.ndarray  #: ``(1,)`` bool: DD after the last second
    held: np.ndarray  #: ``(n_channels,)`` the last finite statistic of each channel


@njit(cache=True, error_model="numpy")
def _decision_kernel(stats, threshold, clear, state, dd):  # pragma: no cover - compiled
    """DD with hysteresis over channels (``state`` updated in place)."""
    n, c = stats.shape
    held = state.held
    for t in range(n):
        for j in range(c):
            if np.isfinite(stats[t, j]):
                held[j] = stats[t, j]
        on = state.on[0]
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
        state.on[0] = on
        dd[t] = on


class DetectionDecision:
    """The detection decision DD with hysteresis from per-channel statistics.

    DD turns on at the first second where a channel's statistic exceeds ``threshold`` and off at
    the first second where every channel's last finite statistic is at or below ``clear``.

    Parameters
    ----------
    threshold
        Switch-on level.
    clear
        Switch-off level (``clear <= threshold``; default 0).
    n_channels
        Number of statistics per second (default 2: X and F).
    """

    def __init__(self, threshold: float, clear: float = 0.0, n_channels: int = 2) -> None:
        self.threshold = threshold
        self.clear = clear
        self.n_channels = n_channels

    def _check_params(self) -> None:
        if not self.clear <= self.threshold:
            raise ValueError(f"clear ({self.clear}) must not exceed threshold ({self.threshold})")
        n = self.n_channels
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
            raise ValueError(f"n_channels must be an integer >= 1, got {n!r}")

    def init_state(self) -> DecisionState:
        """A fresh state: DD off, no statistic seen (held at 0)."""
        self._check_params()
        return DecisionState(np.zeros(1, dtype=np.bool_), np.zeros(int(self.n_channels)))

    def check_state(self, state: Any) -> None:
        """Raise a `ValueError` naming the field unless ``state`` is a state of this decision."""
        check_state(state, self.init_state(), "decision state")

    def run(
        self, stats: Any, state: DecisionState | None = None
    ) -> tuple[np.ndarray, DecisionState]:
        """DD of consecutive seconds.

        Parameters
        ----------
        stats
            ``(n, n_channels)`` statistics of one run.
        state
            The state after the preceding second (default: a fresh one); not changed.

        Returns
        -------
        dd : numpy.ndarray
            ``(n,)`` bool.
        state : DecisionState
            The state after the last second.
        """
        s = np.ascontiguousarray(np.asarray(stats, dtype=np.float64))
        if s.ndim != 2 or s.shape[1] != self.n_channels:
            raise ValueError(f"stats must be (n, {self.n_channels}), got shape {s.shape}")
        state = working_state(self, state)
        dd = np.zeros(s.shape[0], dtype=np.bool_)
        _decision_kernel(s, float(self.threshold), float(self.clear), state, dd)
        return dd, state

    def update(self, stats: Any, state: DecisionState | None = None) -> tuple[bool, DecisionState]:
        """DD of one second from its ``(n_channels,)`` statistics (`run` on one row)."""
        row = np.asarray(stats, dtype=np.float64).reshape(1, -1)
        dd, state = self.run(row, state)
        return bool(dd[0]), state


def detection_decision(stats: Any, threshold: float, clear: float) -> np.ndarray:
    """DD of one run's ``(n, n_channels)`` statistics from a fresh state
    (`DetectionDecision` ``run``)."""
    s = np.asarray(stats, dtype=np.float64)
    if s.ndim != 2:
        raise ValueError(f"stats must be (n, n_channels), got shape {s.shape}")
    return DetectionDecision(threshold, clear, s.shape[1]).run(s)[0]

"""The detection decision DD: hysteresis with a hold over the sequential tests' statistics.

`DetectionDecision` turns the per-channel statistics of the sequential tests
(`bayes_fdi.diagnosis.detection.detectors`) into the detection decision DD: on when a statistic
exceeds the threshold; once on, off only on sustained in-control evidence: no statistic has
exceeded the threshold for more than ``hold`` seconds *and* every channel's statistic is back at
or below the clear level (an off-delay, as alarm management calls it). A persistent fault whose
residual returns into its band for a while (a saturated channel, a residual passing through zero
within a period of the excitation) but exceeds the threshold again within ``hold`` seconds
therefore keeps DD on; the price is that every alarm, false ones included, lasts at least
``hold`` seconds after its last exceedance, and alarms closer than that merge into one (a hold
never adds an alarm). ``hold = 0`` is plain hysteresis (off at the first second with every
statistic at or below the clear level). A NaN statistic (a gap) brings no new evidence: the
channel keeps its last value, which cannot switch DD on; the seconds of a gap count for the hold.
Like every online component it owns its state (`DecisionState`), with ``update`` for one second
and ``run`` over a chunk through the same compiled kernel; `detection_decision` is ``run`` from a
fresh state.

Written by hand: a few lines of hysteresis that must run compiled, one sample at a time.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit

from bayes_fdi.diagnosis.component_state import (
    check_stacked_state,
    check_state,
    working_state,
    writable_copy,
)

__all__ = ["CLEAR_HOLD", "DecisionState", "DetectionDecision", "detection_decision"]

#: Seconds without a statistic above the threshold before the online diagnoser's DD may clear:
#: one period of the slowest excitation of its training campaigns and of the benchmark (the
#: control value's 0.01 Hz sine of the DAMADICS test generator), so a fault that exceeds the
#: threshold at some phase of every excitation cycle keeps DD on; see ``docs/online.md``.
CLEAR_HOLD = 100


class DecisionState(NamedTuple):
    """The state of a `DetectionDecision`."""

    on: np.ndarray  #: ``(1,)`` bool: DD after the last second
    held: np.ndarray  #: ``(n_channels,)`` the last finite statistic of each channel
    #: ``(1,)`` int64: seconds, while on, since a statistic last exceeded the threshold
    quiet: np.ndarray

    @classmethod
    def upgrade_model_file(cls, data: dict, format_version: int) -> dict:
        """A saved state's fields in today's layout: a state saved before the hold (format
        version 3 and older) had no ``quiet`` count; it is 0, as if a statistic had exceeded
        the threshold in its last second (which hold 0, that of such files, never reads)."""
        return _with_quiet_count(data)


def _with_quiet_count(fields: dict) -> dict:
    """A decision state's fields (by name, arrays with or without a leading run axis) with the
    ``quiet`` count 0 added where they lack it (states saved before the hold)."""
    if "quiet" in fields:
        return fields
    shape = np.shape(fields["on"])
    return {**fields, "quiet": np.zeros(shape, dtype=np.int64)}


@njit(cache=True, error_model="numpy")
def _decision_kernel(stats, threshold, clear, hold, state, dd):  # pragma: no cover - compiled
    """DD with hysteresis and a hold over channels (``state`` updated in place)."""
    n, c = stats.shape
    held = state.held
    for t in range(n):
        for j in range(c):
            if np.isfinite(stats[t, j]):
                held[j] = stats[t, j]
        exceeded = False
        for j in range(c):
            if np.isfinite(stats[t, j]) and stats[t, j] > threshold:
                exceeded = True
        on = state.on[0]
        if on:
            state.quiet[0] = 0 if exceeded else state.quiet[0] + 1
            cleared = state.quiet[0] > hold
            for j in range(c):
                if held[j] > clear:
                    cleared = False
            if cleared:
                on = False
        elif exceeded:
            on = True
            state.quiet[0] = 0
        state.on[0] = on
        dd[t] = on


@njit(cache=True, error_model="numpy")
def _decision_runs(stats, threshold, clear, hold, state, dd):  # pragma: no cover - compiled
    """`_decision_kernel` over each run of ``stats`` ``(runs, n, c)``; ``state`` stacked."""
    for r in range(stats.shape[0]):
        run_state = DecisionState(state.on[r], state.held[r], state.quiet[r])
        _decision_kernel(stats[r], threshold, clear, hold, run_state, dd[r])


class DetectionDecision:
    """The detection decision DD with hysteresis and a hold from per-channel statistics.

    DD turns on at the first second where a channel's statistic exceeds ``threshold``. Once on,
    it turns off at the first second at least ``hold + 1`` seconds after the last second with a
    statistic above ``threshold`` where every channel's last finite statistic is at or below
    ``clear``. With ``hold = 0`` DD turns off at the first second with every statistic at or
    below ``clear``.

    Parameters
    ----------
    threshold
        Switch-on level.
    clear
        Switch-off level (``clear <= threshold``; default 0).
    n_channels
        Number of statistics per second (default 2: X and F).
    hold
        Seconds (a whole number >= 0) without a statistic above ``threshold`` before DD may
        turn off (default 0; the online diagnoser uses `CLEAR_HOLD`). Every alarm lasts at
        least this long after its last exceedance; alarms closer than that merge.
    """

    def __init__(
        self, threshold: float, clear: float = 0.0, n_channels: int = 2, hold: int = 0
    ) -> None:
        self.threshold = threshold
        self.clear = clear
        self.n_channels = n_channels
        self.hold = hold

    @classmethod
    def upgrade_model_file(cls, data: dict, format_version: int) -> dict:
        """A saved decision's attributes in today's layout: one saved before the hold (format
        version 3 and older) keeps its behaviour, ``hold = 0``."""
        return {"hold": 0, **data}

    def _check_params(self) -> None:
        if not self.clear <= self.threshold:
            raise ValueError(f"clear ({self.clear}) must not exceed threshold ({self.threshold})")
        for name in ("n_channels", "hold"):
            n = getattr(self, name)
            low = 1 if name == "n_channels" else 0
            if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < low:
                raise ValueError(f"{name} must be an integer >= {low}, got {n!r}")

    def init_state(self) -> DecisionState:
        """A fresh state: DD off, no statistic seen (held at 0), no quiet second counted."""
        self._check_params()
        return DecisionState(
            np.zeros(1, dtype=np.bool_), np.zeros(int(self.n_channels)), np.zeros(1, np.int64)
        )

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
        _decision_kernel(s, float(self.threshold), float(self.clear), int(self.hold), state, dd)
        return dd, state

    def run_stacked(self, stats: Any, state: DecisionState) -> tuple[np.ndarray, DecisionState]:
        """`run` of many runs at once: ``stats`` ``(runs, n, n_channels)``, ``state`` their
        states stacked along a leading run axis; returns ``(runs, n)`` DD and the stacked states
        after them (each run's equal to `run`'s)."""
        s = np.ascontiguousarray(np.asarray(stats, dtype=np.float64))
        if s.ndim != 3 or s.shape[2] != self.n_channels:
            raise ValueError(f"stats must be (runs, n, {self.n_channels}), got shape {s.shape}")
        check_stacked_state(state, self.init_state(), s.shape[0], "decision state")
        state = writable_copy(state)
        dd = np.zeros(s.shape[:2], dtype=np.bool_)
        _decision_runs(s, float(self.threshold), float(self.clear), int(self.hold), state, dd)
        return dd, state

    def update(self, stats: Any, state: DecisionState | None = None) -> tuple[bool, DecisionState]:
        """DD of one second from its ``(n_channels,)`` statistics (`run` on one row)."""
        row = np.asarray(stats, dtype=np.float64).reshape(1, -1)
        dd, state = self.run(row, state)
        return bool(dd[0]), state


def detection_decision(stats: Any, threshold: float, clear: float, hold: int = 0) -> np.ndarray:
    """DD of one run's ``(n, n_channels)`` statistics from a fresh state
    (`DetectionDecision` ``run``)."""
    s = np.asarray(stats, dtype=np.float64)
    if s.ndim != 2:
        raise ValueError(f"stats must be (n, n_channels), got shape {s.shape}")
    return DetectionDecision(threshold, clear, s.shape[1], hold).run(s)[0]

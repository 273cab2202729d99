"""The input envelope of the online diagnoser: where the normal models were trained.

The normal models are trusted only where they were fitted. `InputEnvelope` is the training
range of the inputs CV, P1, P2, T1 widened by ``margin`` of its span (at least
`INPUT_MARGIN_FLOOR`), and of their dynamics: the mean absolute one-second increment of CV and
P1 over the last ``rate_seconds`` (an exponential average), at most the largest seen in
training widened by ``rate_margin``. The normal models take the recent increments of the
command and of the pressure drop as inputs, so a command moving faster than any training run
(a fast sine, a chattering controller) makes them extrapolate although every level lies inside
its range. A second without detection whose inputs lie outside the envelope (levels,
``outside``; or rates, ``run_flags``) is DAZZLED, and a detection whose change began while the
inputs were outside it is not trusted for isolation (``run``/``update``, an online component
with its `EnvelopeState`): the inputs are averaged over the seconds without detection, and at
each rising edge of DD the average as it stood *before the detector's estimated change point* is
checked against the envelope and the answer held until DD falls. The change point is the start
of the excursion above the decision's clear level of the statistic that raised the detection
(`bayes_fdi.diagnosis.online.change_point.change_ages`: for the CUSUM the last second both its
sums were at 0; the GLR's best window where it reaches further back); the state keeps the
averages of the last ``change_lookback`` seconds to look it up (a change older than that is
judged on the oldest one kept). So a fault that itself moves an input (f7 makes T1 jump, f17
drops P2) is judged on the inputs before its own effect, however many seconds the detector took,
while a plant running outside the training range (another temperature, another pressure) is
caught: its inputs were outside before any change point. ``change_lookback = 0`` judges the
average before the detection's first second (model files saved before the change point was
used). A detection from the stream's first second, before any second without one, is judged on
the inputs of its first second. The rates are judged as they stood before the detection's first
second (they are averaged over every second: CV is the command and P1 the supply pressure, which
no fault of the benchmark moves). With ``command_check`` a detection is also held as begun
outside the envelope from a second of it, within ``change_lookback`` s of its estimated change
point, whose command lies outside: the normal models' residuals grow as the command nears the
end of its training range, so a detector raised by that growth fires while the average before
its change point still lay inside.

Written by hand: a training range, a compiled exponential average and a ring of its past values.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
import xarray as xr
from numba import njit

from bayes_fdi.diagnosis.component_state import (
    check_stacked_state,
    check_state,
    stack_states,
    working_state,
    writable_copy,
)
from bayes_fdi.diagnosis.isolation.signatures import INPUT_REFERENCE_SECONDS

__all__ = [
    "CHANGE_LOOKBACK",
    "ENVELOPE_CHANNELS",
    "INPUT_MARGIN_FLOOR",
    "RATE_CHANNELS",
    "RATE_SECONDS",
    "EnvelopeState",
    "InputEnvelope",
]

#: The inputs the envelope covers, in column order.
ENVELOPE_CHANNELS = ("CV", "P1", "P2", "T1")
#: Smallest widening of the input envelope (normalised full scale, about 14 sensor-noise
#: standard deviations): an input held constant in training (T1 under the DGen sines) would
#: otherwise have an envelope as narrow as its noise.
INPUT_MARGIN_FLOOR = 0.02
#: The inputs whose rates the envelope covers (columns of `ENVELOPE_CHANNELS`).
RATE_CHANNELS = ("CV", "P1")
_RATE_COLUMNS = np.array([ENVELOPE_CHANNELS.index(c) for c in RATE_CHANNELS], dtype=np.int64)
#: Time constant (s) of the average of the inputs' absolute increments.
RATE_SECONDS = 30.0
#: Smallest bound of the mean absolute increment (normalised full scale per second): about the
#: sensor noise's, so that an input held constant in training is not flagged for its noise.
RATE_FLOOR = 0.003
#: Seconds of input averages the onset check keeps to look up the one before a detection's
#: estimated change point: two time constants of the average, longer than the CUSUM takes to
#: detect an abrupt fault above the noise; a plant drifting out of the envelope over longer than
#: that is judged on the average this long before its detection.
CHANGE_LOOKBACK = 120


class EnvelopeState(NamedTuple):
    """The state of an `InputEnvelope`'s onset check."""

    average: np.ndarray  #: ``(4,)`` average of CV, P1, P2, T1 over seconds without detection
    average_set: np.ndarray  #: ``(1,)`` bool: the average has a first value
    novel_at_onset: np.ndarray  #: ``(1,)`` bool: the current detection's change began outside
    detected: np.ndarray  #: ``(1,)`` bool: DD of the last second
    previous: np.ndarray  #: ``(2,)`` CV and P1 of the last second (NaN: none)
    rate: np.ndarray  #: ``(2,)`` average absolute one-second increment of CV and P1
    history: np.ndarray  #: ``(change_lookback, 4)`` the average after each recent second, a ring
    stored: np.ndarray  #: ``(1,)`` int64: averages in the ring (at most ``change_lookback``)
    slot: np.ndarray  #: ``(1,)`` int64: where the next average goes
    excursion: np.ndarray  #: ``(2,)`` int64: seconds each statistic has stood above clear

    @classmethod
    def upgrade_model_file(cls, fields: dict, format_version: int) -> dict:
        """The fields of a state saved before the envelope had rates (model-file format <= 4:
        no last second, rates 0) or looked up the change point (format <= 7: an empty ring, as
        the envelope of such a file has ``change_lookback = 0``); with or without a leading
        run axis."""
        fields = dict(fields)
        runs = np.shape(fields["average"])[:-1]
        fields.setdefault("previous", np.full((*runs, len(RATE_CHANNELS)), np.nan))
        fields.setdefault("rate", np.zeros((*runs, len(RATE_CHANNELS))))
        fields.setdefault("history", np.zeros((*runs, 0, 4)))
        fields.setdefault("stored", np.zeros((*runs, 1), dtype=np.int64))
        fields.setdefault("slot", np.zeros((*runs, 1), dtype=np.int64))
        fields.setdefault("excursion", np.zeros((*runs, 2), dtype=np.int64))
        return fields


@njit(cache=True, error_model="numpy")
def _rates_kernel(x, columns, rate_high, beta, state, t):  # pragma: no cover - compiled
    """Whether the rates stood above ``rate_high`` before second ``t``; then update them."""
    fast = False
    for j in range(columns.size):
        if state.rate[j] > rate_high[j]:
            fast = True
        v = x[t, columns[j]]
        if np.isfinite(v) and np.isfinite(state.previous[j]):
            state.rate[j] += beta * (abs(v - state.previous[j]) - state.rate[j])
        state.previous[j] = v  # NaN: the next increment is skipped
    return fast


@njit(cache=True, error_model="numpy")
def _outside(values, low, high):  # pragma: no cover - compiled
    """Whether one of the ``(4,)`` ``values`` lies outside ``[low, high]``."""
    for j in range(4):
        if values[j] < low[j] or values[j] > high[j]:
            return True
    return False


@njit(cache=True, error_model="numpy")
def _reference_outside(inputs, low, high, age, state, t):  # pragma: no cover - compiled
    """Whether the input average before a change ``age`` seconds old (ending at second ``t``)
    lies outside ``[low, high]``: the ring's average after second ``t - age``, the oldest kept
    if the change is older, the current average without a ring, else the inputs of second
    ``t``."""
    size = state.history.shape[0]
    stored = state.stored[0]
    if size > 0 and stored > 0:
        back = min(max(age - 1, 0), stored - 1)
        return _outside(state.history[(state.slot[0] - 1 - back) % size], low, high)
    if state.average_set[0]:
        return _outside(state.average, low, high)
    return _outside(inputs[t], low, high)  # detected since the stream began: this second


@njit(cache=True, error_model="numpy")
def _remember_average(state):  # pragma: no cover - compiled
    """Push the current average into the ring (once it has a first value)."""
    size = state.history.shape[0]
    if size == 0 or not state.average_set[0]:
        return
    state.history[state.slot[0]] = state.average
    state.slot[0] = (state.slot[0] + 1) % size
    if state.stored[0] < size:
        state.stored[0] += 1


@njit(cache=True, error_model="numpy")
def _onset_kernel(
    dd, ages, inputs, low, high, alpha, columns, rate_high, beta, command, state, out, fast
):  # pragma: no cover - compiled
    """Whether each second's detection began outside the envelope, or (``command``) saw the
    command leave it (``out``), and whether the rates stand above ``rate_high`` after each
    second (``fast``); ``state`` in place."""
    average = state.average
    for t in range(dd.size):
        fast_before = _rates_kernel(inputs, columns, rate_high, beta, state, t)
        fast[t] = False
        for j in range(columns.size):
            if state.rate[j] > rate_high[j]:
                fast[t] = True
        if not dd[t]:
            ok = True
            for j in range(4):
                if not np.isfinite(inputs[t, j]):
                    ok = False
            if ok:
                for j in range(4):
                    if not state.average_set[0]:
                        average[j] = inputs[t, j]
                    else:
                        average[j] += alpha * (inputs[t, j] - average[j])
                state.average_set[0] = True
            state.novel_at_onset[0] = False
            state.detected[0] = False
            out[t] = False
            _remember_average(state)
            continue
        if not state.detected[0]:  # a new detection: were the inputs before its change inside?
            outside = _reference_outside(inputs, low, high, ages[t], state, t)
            state.novel_at_onset[0] = fast_before or outside
        near = ages[t] <= state.history.shape[0]  # within change_lookback s of the change
        if command and near and (inputs[t, 0] < low[0] or inputs[t, 0] > high[0]):
            state.novel_at_onset[0] = True  # held until DD falls
        state.detected[0] = True
        out[t] = state.novel_at_onset[0]
        _remember_average(state)


@njit(cache=True, error_model="numpy")
def _onset_runs(
    dd, ages, inputs, low, high, alpha, columns, rate_high, beta, command, state, out, fast
):  # pragma: no cover - compiled
    """`_onset_kernel` over each run (row) of ``dd``; ``state`` stacks the runs' states."""
    for r in range(dd.shape[0]):
        run_state = EnvelopeState(
            state.average[r], state.average_set[r], state.novel_at_onset[r], state.detected[r],
            state.previous[r], state.rate[r], state.history[r], state.stored[r], state.slot[r],
            state.excursion[r],
        )  # fmt: skip
        _onset_kernel(
            dd[r], ages[r], inputs[r], low, high, alpha, columns, rate_high, beta, command,
            run_state, out[r], fast[r],
        )  # fmt: skip


class InputEnvelope:
    """The training range of the inputs CV, P1, P2, T1 and of the rates of CV and P1, and the
    onset check against it.

    Parameters
    ----------
    margin
        Widening of the range on each side, as a share of its span (default 0.1).
    margin_floor
        Smallest widening (default `INPUT_MARGIN_FLOOR`).
    reference_seconds
        Time constant (s) of the average of the inputs before a detection (default
        `~bayes_fdi.diagnosis.isolation.signatures.INPUT_REFERENCE_SECONDS`, as the isolation
        signatures' input reference).
    rate_margin
        Widening of the largest training rate, as a share of it (default 0.25).
    rate_seconds
        Time constant (s) of the average of the absolute increments (default `RATE_SECONDS`).
    change_lookback
        Seconds of input averages kept to judge a detection by the inputs before its estimated
        change point (default `CHANGE_LOOKBACK`; 0: by the inputs before its first second).
    command_check
        Also judge a detection by the command during it (default True): from a second of a
        detection within ``change_lookback`` s of its estimated change point whose CV lies
        outside the envelope, the detection is held as begun outside it until DD falls. The
        normal models extrapolate there, and their residuals grow as the command nears the end
        of its training range, so a detector raised by that growth fires while the average
        before its change point still lay inside. The command is the one input a fault moves
        only through a control loop, after its own effect; a command that leaves the envelope
        later than that leaves the detection as it was judged.

    Attributes
    ----------
    low_, high_ : numpy.ndarray
        ``(4,)`` the envelope of CV, P1, P2, T1.
    rate_high_ : numpy.ndarray
        ``(2,)`` the largest mean absolute increment of CV and P1 (per second) inside the
        envelope (infinite: no rate check, as in a model saved before the envelope had rates).
    """

    def __init__(
        self,
        margin: float = 0.1,
        margin_floor: float = INPUT_MARGIN_FLOOR,
        reference_seconds: float = INPUT_REFERENCE_SECONDS,
        rate_margin: float = 0.25,
        rate_seconds: float = RATE_SECONDS,
        change_lookback: int = CHANGE_LOOKBACK,
        command_check: bool = True,
    ) -> None:
        self.margin = margin
        self.margin_floor = margin_floor
        self.reference_seconds = reference_seconds
        self.rate_margin = rate_margin
        self.rate_seconds = rate_seconds
        self.change_lookback = change_lookback
        self.command_check = command_check

    @classmethod
    def upgrade_model_file(cls, data: dict, format_version: int) -> dict:
        """An envelope saved before it had rates (model-file format <= 4): no rate check;
        before it looked up the change point (format <= 7): ``change_lookback = 0``, the onset
        check it was saved with; before it judged the command during a detection (format <= 16):
        ``command_check = False``."""
        data = dict(data)
        data.setdefault("change_lookback", 0)
        data.setdefault("command_check", False)
        data.setdefault("rate_margin", 0.25)
        data.setdefault("rate_seconds", RATE_SECONDS)
        if "low_" in data:
            data.setdefault("rate_high_", np.full(len(RATE_CHANNELS), np.inf))
        return data

    def fit(self, normal_runs: xr.Dataset) -> InputEnvelope:
        """The range of CV, P1, P2, T1 over the (NaN-padded) training runs, widened, and the
        largest mean absolute increments of CV and P1 (`training_rates`), widened."""
        if not self.margin >= 0:
            raise ValueError(f"input_margin is out of range: {self.margin!r}")
        if not (self.rate_margin >= 0 and math.isfinite(self.rate_margin)):
            raise ValueError(f"rate_margin must be finite and >= 0, got {self.rate_margin!r}")
        if not (self.rate_seconds >= 1 and math.isfinite(self.rate_seconds)):
            raise ValueError(f"rate_seconds must be finite and >= 1, got {self.rate_seconds!r}")
        self._check_lookback()
        if not isinstance(self.command_check, bool | np.bool_):
            raise ValueError(f"command_check must be True or False, got {self.command_check!r}")
        lows, highs = [], []
        for c in ENVELOPE_CHANNELS:
            v = np.asarray(normal_runs[c].values, dtype=np.float64)
            lo, hi = float(np.nanmin(v)), float(np.nanmax(v))
            span = hi - lo
            margin = max(self.margin * span, self.margin_floor)
            lows.append(lo - margin)
            highs.append(hi + margin)
        self.low_, self.high_ = np.array(lows), np.array(highs)
        self.rate_high_ = np.full(len(RATE_CHANNELS), np.inf)
        rates = self.training_rates(normal_runs)
        self.rate_high_ = np.maximum(rates * (1.0 + self.rate_margin), RATE_FLOOR)
        return self

    def training_rates(self, runs: xr.Dataset) -> np.ndarray:
        """``(2,)`` the largest mean absolute increment of CV and P1 over ``runs`` (the
        average `run_flags` keeps, after each run's first ``rate_seconds``)."""
        x = np.stack(
            [np.asarray(runs[c].transpose("run", "time").values, np.float64) for c in
             ENVELOPE_CHANNELS], axis=-1,
        )  # fmt: skip
        state = stack_states([self.init_state()] * x.shape[0])
        dd = np.zeros(x.shape[:2], dtype=np.bool_)
        largest = np.zeros(len(RATE_CHANNELS))
        warm = min(int(self.rate_seconds), x.shape[1])
        for t in range(x.shape[1]):  # the average after each second, every run at once
            _, _, state = self.run_stacked_flags(x[:, t : t + 1], dd[:, t : t + 1], state)
            if t >= warm:
                largest = np.fmax(largest, np.nanmax(state.rate, axis=0))
        return largest

    @classmethod
    def from_bounds(
        cls, low: Any, high: Any, rate_high: Any = None, **params: Any
    ) -> InputEnvelope:
        """An envelope with the given ``(4,)`` bounds and ``(2,)`` rate bounds (default: no
        rate check) (``params``: the constructor's)."""
        envelope = cls(**params)
        envelope.low_ = np.array(low, dtype=np.float64)
        envelope.high_ = np.array(high, dtype=np.float64)
        if envelope.low_.shape != (4,) or envelope.high_.shape != (4,):
            raise ValueError("low and high must hold the bounds of CV, P1, P2, T1")
        rate = np.inf if rate_high is None else rate_high
        envelope.rate_high_ = np.broadcast_to(np.asarray(rate, np.float64), (2,)).copy()
        if np.any(np.isnan(envelope.rate_high_)) or np.any(envelope.rate_high_ < 0):
            raise ValueError(f"rate_high must hold two bounds >= 0, got {rate_high!r}")
        return envelope

    def _check_lookback(self) -> None:
        lookback = self.change_lookback
        if isinstance(lookback, bool) or not isinstance(lookback, int | np.integer):
            raise ValueError(f"change_lookback must be an int >= 0, got {lookback!r}")
        if lookback < 0:
            raise ValueError(f"change_lookback must be an int >= 0, got {lookback!r}")

    def _check_fitted(self) -> None:
        if not hasattr(self, "low_"):
            raise ValueError("InputEnvelope is not fitted; call fit(normal_runs) first")

    def outside(self, inputs: Any) -> np.ndarray:
        """Per row of ``inputs`` ``(n, 4)`` (CV, P1, P2, T1): whether an input lies outside
        the envelope's levels (False for NaN; the rates need the stream: `run_flags`)."""
        self._check_fitted()
        x = np.asarray(inputs, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != len(ENVELOPE_CHANNELS):
            raise ValueError(f"inputs must be (n, 4), got shape {x.shape}")
        with np.errstate(invalid="ignore"):
            return np.any((x < self.low_) | (x > self.high_), axis=1)

    def init_state(self) -> EnvelopeState:
        """A fresh state: no average yet, no detection, no last second, an empty ring."""
        self._check_lookback()
        flag = np.zeros(1, dtype=np.bool_)
        n = len(RATE_CHANNELS)
        count = np.zeros(1, dtype=np.int64)
        return EnvelopeState(
            np.zeros(4), flag, flag.copy(), flag.copy(), np.full(n, np.nan), np.zeros(n),
            np.zeros((int(self.change_lookback), 4)), count, count.copy(), np.zeros(2, np.int64),
        )  # fmt: skip

    def check_state(self, state: Any) -> None:
        """Raise a `ValueError` naming the field unless ``state`` is an envelope state."""
        check_state(state, self.init_state(), "envelope state")

    def _kernel_args(self) -> tuple:
        low, high = np.ascontiguousarray(self.low_), np.ascontiguousarray(self.high_)
        rate_high = np.ascontiguousarray(self.rate_high_, dtype=np.float64)
        return (low, high, 1.0 / self.reference_seconds, _RATE_COLUMNS, rate_high,
                1.0 / self.rate_seconds, bool(self.command_check))  # fmt: skip

    def run_flags(
        self,
        inputs: Any,
        detected: Any,
        state: EnvelopeState | None = None,
        change_age: Any = None,
    ) -> tuple[np.ndarray, np.ndarray, EnvelopeState]:
        """Per second: whether the current detection's estimated change began while the inputs
        were outside the envelope, or (``command_check``) the command has left it since, within
        ``change_lookback`` s of the change (False while DD is off), and whether the rates of CV
        or P1 stand above their bounds.

        Parameters
        ----------
        inputs
            ``(n, 4)`` CV, P1, P2, T1 of consecutive seconds of one run.
        detected
            ``(n,)`` the detection decision DD.
        state
            The state after the preceding second (default: a fresh one); not changed.
        change_age
            ``(n,)`` per second, seconds since the detector's estimated change point
            (`change_ages`; default 0: a change at that second). Read at DD's rising edges.

        Returns
        -------
        novel_onset, fast : numpy.ndarray
            ``(n,)`` bool.
        state : EnvelopeState
            The state after the last second.
        """
        self._check_fitted()
        x = np.ascontiguousarray(np.asarray(inputs, dtype=np.float64))
        dd = np.ascontiguousarray(np.asarray(detected, dtype=np.bool_))
        if x.ndim != 2 or x.shape[1] != 4 or dd.shape != (x.shape[0],):
            raise ValueError(f"inputs must be (n, 4) and detected (n,), got {x.shape}, {dd.shape}")
        ages = _ages(change_age, dd.shape)
        state = working_state(self, state)
        out = np.zeros(dd.size, dtype=np.bool_)
        fast = np.zeros(dd.size, dtype=np.bool_)
        _onset_kernel(dd, ages, x, *self._kernel_args(), state, out, fast)
        return out, fast, state

    def run(
        self,
        inputs: Any,
        detected: Any,
        state: EnvelopeState | None = None,
        change_age: Any = None,
    ) -> tuple[np.ndarray, EnvelopeState]:
        """`run_flags` without the rates' flags: the ``(n,)`` onset flags and the state."""
        out, _, state = self.run_flags(inputs, detected, state, change_age)
        return out, state

    def run_stacked_flags(
        self, inputs: Any, detected: Any, state: EnvelopeState, change_age: Any = None
    ) -> tuple[np.ndarray, np.ndarray, EnvelopeState]:
        """`run_flags` of many runs at once: ``inputs`` ``(runs, n, 4)``, ``detected`` and
        ``change_age`` ``(runs, n)``, ``state`` their states stacked along a leading run axis;
        returns the
        ``(runs, n)`` flags and the stacked states after them (each run's equal to
        `run_flags`')."""
        self._check_fitted()
        x = np.ascontiguousarray(np.asarray(inputs, dtype=np.float64))
        dd = np.ascontiguousarray(np.asarray(detected, dtype=np.bool_))
        if x.ndim != 3 or x.shape[2] != 4 or dd.shape != x.shape[:2]:
            raise ValueError(
                f"inputs must be (runs, n, 4) and detected (runs, n), got {x.shape}, {dd.shape}"
            )
        ages = _ages(change_age, dd.shape)
        check_stacked_state(state, self.init_state(), x.shape[0], "envelope state")
        state = writable_copy(state)
        out = np.zeros(dd.shape, dtype=np.bool_)
        fast = np.zeros(dd.shape, dtype=np.bool_)
        _onset_runs(dd, ages, x, *self._kernel_args(), state, out, fast)
        return out, fast, state

    def run_stacked(
        self, inputs: Any, detected: Any, state: EnvelopeState, change_age: Any = None
    ) -> tuple[np.ndarray, EnvelopeState]:
        """`run_stacked_flags` without the rates' flags."""
        out, _, state = self.run_stacked_flags(inputs, detected, state, change_age)
        return out, state

    def update(
        self,
        inputs: Any,
        detected: bool,
        state: EnvelopeState | None = None,
        change_age: int = 0,
    ) -> tuple[bool, EnvelopeState]:
        """`run` on one second (``inputs`` ``(4,)``): a bool and the new state."""
        row = np.asarray(inputs, dtype=np.float64).reshape(1, -1)
        out, state = self.run(row, np.array([bool(detected)]), state, np.array([change_age]))
        return bool(out[0]), state


def _ages(change_age: Any, shape: tuple[int, ...]) -> np.ndarray:
    """``change_age`` as a contiguous int64 array of ``shape`` (zeros for None)."""
    if change_age is None:
        return np.zeros(shape, dtype=np.int64)
    ages = np.asarray(change_age)
    if ages.shape != shape:
        raise ValueError(f"change_age must have shape {shape}, got {ages.shape}")
    if not np.issubdtype(ages.dtype, np.integer):
        raise ValueError(f"change_age must hold integers (seconds), got {ages.dtype}")
    return np.ascontiguousarray(ages, dtype=np.int64)

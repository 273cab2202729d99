"""The input envelope of the online diagnoser: where the normal models were trained.

The normal models are trusted only where they were fitted. `InputEnvelope` is the training
range of the inputs CV, P1, P2, T1 widened by ``margin`` of its span (at least
`INPUT_MARGIN_FLOOR`): a second whose inputs lie outside it is DAZZLED (``outside``), and a
detection that began while the inputs were outside it is not trusted for isolation
(``run``/``update``, an online component with its `EnvelopeState`): the inputs are averaged over
the seconds without detection, and at each rising edge of DD that average is checked against the
envelope and the answer held until DD falls. The average of the seconds *before* the detection
is what counts: a fault that itself moves an input (f7 makes T1 jump) is detected within
seconds, before the average has moved, while a plant running outside the training range
(another temperature, another pressure) is caught. A detection from the stream's first second,
before any second without one, is judged on the inputs of its first second.

Written by hand: a training range and a compiled exponential average.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import xarray as xr
from numba import njit

from bayes_fdi.diagnosis.component_state import check_state, working_state
from bayes_fdi.diagnosis.isolation.signatures import INPUT_REFERENCE_SECONDS

__all__ = ["ENVELOPE_CHANNELS", "INPUT_MARGIN_FLOOR", "EnvelopeState", "InputEnvelope"]

#: The inputs the envelope covers, in column order.
ENVELOPE_CHANNELS = ("CV", "P1", "P2", "T1")
#: Smallest widening of the input envelope (normalised full scale, about 14 sensor-noise
#: standard deviations): an input held constant in training (T1 under the DGen sines) would
#: otherwise have an envelope as narrow as its noise.
INPUT_MARGIN_FLOOR = 0.02


class EnvelopeState(NamedTuple):
    """The state of an `InputEnvelope`'s onset check."""

    average: np.ndarray  #: ``(4,)`` average of CV, P1, P2, T1 over seconds without detection
    average_set: np.ndarray  #: ``(1,)`` bool: the average has a first value
    novel_at_onset: np.ndarray  #: ``(1,)`` bool: the current detection began outside
    detected: np.ndarray  #: ``(1,)`` bool: DD of the last second


@njit(cache=True, error_model="numpy")
def _onset_kernel(dd, inputs, low, high, alpha, state, out):  # pragma: no cover - compiled
    """Whether each second's detection began outside ``[low, high]`` (``state`` in place)."""
    average = state.average
    for t in range(dd.size):
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
            continue
        if not state.detected[0]:  # a new detection: were the inputs before it inside?
            novel = False
            if state.average_set[0]:
                for j in range(4):
                    if average[j] < low[j] or average[j] > high[j]:
                        novel = True
            else:  # detected since the stream began: judge the inputs of this second
                for j in range(4):
                    if inputs[t, j] < low[j] or inputs[t, j] > high[j]:
                        novel = True
            state.novel_at_onset[0] = novel
        state.detected[0] = True
        out[t] = state.novel_at_onset[0]


class InputEnvelope:
    """The training range of the inputs CV, P1, P2, T1, and the onset check against it.

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

    Attributes
    ----------
    low_, high_ : numpy.ndarray
        ``(4,)`` the envelope of CV, P1, P2, T1.
    """

    def __init__(
        self,
        margin: float = 0.1,
        margin_floor: float = INPUT_MARGIN_FLOOR,
        reference_seconds: float = INPUT_REFERENCE_SECONDS,
    ) -> None:
        self.margin = margin
        self.margin_floor = margin_floor
        self.reference_seconds = reference_seconds

    def fit(self, normal_runs: xr.Dataset) -> InputEnvelope:
        """The range of CV, P1, P2, T1 over the (NaN-padded) training runs, widened."""
        if not self.margin >= 0:
            raise ValueError(f"input_margin is out of range: {self.margin!r}")
        lows, highs = [], []
        for c in ENVELOPE_CHANNELS:
            v = np.asarray(normal_runs[c].values, dtype=np.float64)
            lo, hi = float(np.nanmin(v)), float(np.nanmax(v))
            span = hi - lo
            margin = max(self.margin * span, self.margin_floor)
            lows.append(lo - margin)
            highs.append(hi + margin)
        self.low_, self.high_ = np.array(lows), np.array(highs)
        return self

    @classmethod
    def from_bounds(cls, low: Any, high: Any, **params: Any) -> InputEnvelope:
        """An envelope with the given ``(4,)`` bounds (``params``: the constructor's)."""
        envelope = cls(**params)
        envelope.low_ = np.array(low, dtype=np.float64)
        envelope.high_ = np.array(high, dtype=np.float64)
        if envelope.low_.shape != (4,) or envelope.high_.shape != (4,):
            raise ValueError("low and high must hold the bounds of CV, P1, P2, T1")
        return envelope

    def _check_fitted(self) -> None:
        if not hasattr(self, "low_"):
            raise ValueError("InputEnvelope is not fitted; call fit(normal_runs) first")

    def outside(self, inputs: Any) -> np.ndarray:
        """Per row of ``inputs`` ``(n, 4)`` (CV, P1, P2, T1): whether an input lies outside
        the envelope (False for NaN)."""
        self._check_fitted()
        x = np.asarray(inputs, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != len(ENVELOPE_CHANNELS):
            raise ValueError(f"inputs must be (n, 4), got shape {x.shape}")
        with np.errstate(invalid="ignore"):
            return np.any((x < self.low_) | (x > self.high_), axis=1)

    def init_state(self) -> EnvelopeState:
        """A fresh state: no average yet, no detection."""
        flag = np.zeros(1, dtype=np.bool_)
        return EnvelopeState(np.zeros(4), flag, flag.copy(), flag.copy())

    def check_state(self, state: Any) -> None:
        """Raise a `ValueError` naming the field unless ``state`` is an envelope state."""
        check_state(state, self.init_state(), "envelope state")

    def run(
        self, inputs: Any, detected: Any, state: EnvelopeState | None = None
    ) -> tuple[np.ndarray, EnvelopeState]:
        """Per second: whether the current detection began while the inputs were outside the
        envelope (False while DD is off).

        Parameters
        ----------
        inputs
            ``(n, 4)`` CV, P1, P2, T1 of consecutive seconds of one run.
        detected
            ``(n,)`` the detection decision DD.
        state
            The state after the preceding second (default: a fresh one); not changed.

        Returns
        -------
        novel_onset : numpy.ndarray
            ``(n,)`` bool.
        state : EnvelopeState
            The state after the last second.
        """
        self._check_fitted()
        x = np.ascontiguousarray(np.asarray(inputs, dtype=np.float64))
        dd = np.ascontiguousarray(np.asarray(detected, dtype=np.bool_))
        if x.ndim != 2 or x.shape[1] != 4 or dd.shape != (x.shape[0],):
            raise ValueError(f"inputs must be (n, 4) and detected (n,), got {x.shape}, {dd.shape}")
        state = working_state(self, state)
        out = np.zeros(dd.size, dtype=np.bool_)
        low, high = np.ascontiguousarray(self.low_), np.ascontiguousarray(self.high_)
        _onset_kernel(dd, x, low, high, 1.0 / self.reference_seconds, state, out)
        return out, state

    def update(
        self, inputs: Any, detected: bool, state: EnvelopeState | None = None
    ) -> tuple[bool, EnvelopeState]:
        """`run` on one second (``inputs`` ``(4,)``): a bool and the new state."""
        row = np.asarray(inputs, dtype=np.float64).reshape(1, -1)
        out, state = self.run(row, np.array([bool(detected)]), state)
        return bool(out[0]), state

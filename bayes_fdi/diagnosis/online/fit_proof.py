"""The fit proof of the online diagnoser: a model must see a valve fit before it names its faults.

A fault is a *change*: a valve that fitted the normal models departs from them. A model that
never fitted the valve it watches (the simulator-trained default model on a real valve, or on a
plant whose parameters differ from the simulated one) raises an alarm within its first seconds
and keeps it, and its signature is the misfit, not a fault. `FitProof` tells the two apart by
what the stream has seen: a detection counts as a fault only once the normal models have fitted
the valve, without detection, for ``seconds`` consecutive counted seconds before the
detection's estimated change point (`bayes_fdi.diagnosis.online.change_point.change_ages`).
Before that, a detection is *unproven*: the diagnoser answers ``"mismatch"`` ("model mismatch:
commission this valve", DAZZLED) and names no fault. Once proven, the proof holds for the rest
of the stream (its state carries it from chunk to chunk and across a saved state).

A second is counted when it has no detection, every channel is measured and the inputs lie
inside the normal models' envelope (`bayes_fdi.diagnosis.online.envelope.InputEnvelope`); a
second that is not counted neither extends the quiet stretch nor breaks it. ``seconds = 0``
(models fitted on the valve's own data: a commissioned valve, ``bayes-fdi fit --normal``; model
files saved before the proof existed) proves every detection.

An online component like the others (`bayes_fdi.diagnosis.component_state`): ``run``,
``run_stacked`` and ``update`` over a `FitProofState`, never changed in place.

Written by hand: a compiled counter of quiet seconds, which no library offers.
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

__all__ = ["FitProof", "FitProofState"]


class FitProofState(NamedTuple):
    """The state of a `FitProof`."""

    quiet: np.ndarray  #: ``(1,)`` int64: counted seconds without detection since the last one
    proven: np.ndarray  #: ``(1,)`` bool: a quiet stretch before an earlier change proved the fit
    unproven_at_onset: np.ndarray  #: ``(1,)`` bool: the current detection came before the proof
    detected: np.ndarray  #: ``(1,)`` bool: DD of the last second

    @classmethod
    def proven_state(cls, runs: tuple[int, ...] = ()) -> FitProofState:
        """A state whose fit is proven (for a stream saved before the proof existed), with a
        leading ``runs`` shape."""
        return cls(
            np.zeros((*runs, 1), dtype=np.int64),
            np.ones((*runs, 1), dtype=np.bool_),
            np.zeros((*runs, 1), dtype=np.bool_),
            np.zeros((*runs, 1), dtype=np.bool_),
        )


@njit(cache=True, error_model="numpy")
def _proof_kernel(dd, counted, ages, seconds, state, out):  # pragma: no cover - compiled
    """Whether each second's detection came before the fit was proven; ``state`` in place."""
    for t in range(dd.size):
        if not dd[t]:
            if counted[t]:
                state.quiet[0] += 1
            state.detected[0] = False
            state.unproven_at_onset[0] = False
            out[t] = False
            continue
        if not state.detected[0]:  # a new detection: quiet seconds before its change point
            before = state.quiet[0] - max(ages[t] - 1, 0)
            if max(before, 0) >= seconds:
                state.proven[0] = True
            state.unproven_at_onset[0] = not state.proven[0]
            state.quiet[0] = 0
        state.detected[0] = True
        out[t] = state.unproven_at_onset[0]


@njit(cache=True, error_model="numpy")
def _proof_runs(dd, counted, ages, seconds, state, out):  # pragma: no cover - compiled
    """`_proof_kernel` over each run (row) of ``dd``; ``state`` stacks the runs' states."""
    for r in range(dd.shape[0]):
        run_state = FitProofState(
            state.quiet[r], state.proven[r], state.unproven_at_onset[r], state.detected[r]
        )
        _proof_kernel(dd[r], counted[r], ages[r], seconds, run_state, out[r])


class FitProof:
    """Whether each detection came after the normal models were seen to fit the valve.

    Parameters
    ----------
    seconds
        Counted seconds without detection that must precede a detection's estimated change
        point, once in the stream, before detections are read as faults (0: every detection
        is).
    """

    def __init__(self, seconds: int = 0) -> None:
        self.seconds = seconds

    def _check_params(self) -> int:
        s = self.seconds
        if isinstance(s, bool) or not isinstance(s, int | np.integer) or s < 0:
            raise ValueError(f"fit_proof_seconds must be an int >= 0, got {s!r}")
        return int(s)

    def init_state(self) -> FitProofState:
        """A fresh state: no quiet second yet, not proven (with ``seconds = 0`` the first
        detection proves the fit)."""
        self._check_params()
        flag = np.zeros(1, dtype=np.bool_)
        return FitProofState(np.zeros(1, dtype=np.int64), flag, flag.copy(), flag.copy())

    def check_state(self, state: Any) -> None:
        """Raise a `ValueError` naming the field unless ``state`` is a fit-proof state."""
        check_state(state, self.init_state(), "fit proof state")

    @staticmethod
    def _arrays(detected: Any, counted: Any, change_age: Any, ndim: int) -> tuple:
        dd = np.ascontiguousarray(np.asarray(detected, dtype=np.bool_))
        ok = np.ascontiguousarray(np.asarray(counted, dtype=np.bool_))
        ages = np.zeros(dd.shape, np.int64) if change_age is None else np.asarray(change_age)
        if dd.ndim != ndim or ok.shape != dd.shape or ages.shape != dd.shape:
            raise ValueError(
                f"detected, counted and change_age must share one {ndim}-D shape, got "
                f"{dd.shape}, {ok.shape}, {ages.shape}"
            )
        if not np.issubdtype(ages.dtype, np.integer):
            raise ValueError(f"change_age must hold integers (seconds), got {ages.dtype}")
        return dd, ok, np.ascontiguousarray(ages, dtype=np.int64)

    def run(
        self,
        detected: Any,
        counted: Any,
        state: FitProofState | None = None,
        change_age: Any = None,
    ) -> tuple[np.ndarray, FitProofState]:
        """Per second, whether the current detection came before the fit was proven (False
        while DD is off).

        Parameters
        ----------
        detected
            ``(n,)`` the detection decision DD of consecutive seconds of one run.
        counted
            ``(n,)`` whether a second without detection counts towards the proof (every
            channel measured, the inputs inside the envelope).
        state
            The state after the preceding second (default: a fresh one); not changed.
        change_age
            ``(n,)`` seconds since the detector's estimated change point (`change_ages`;
            default 0). Read at DD's rising edges.

        Returns
        -------
        unproven : numpy.ndarray
            ``(n,)`` bool.
        state : FitProofState
            The state after the last second.
        """
        seconds = self._check_params()
        dd, ok, ages = self._arrays(detected, counted, change_age, 1)
        state = working_state(self, state)
        out = np.zeros(dd.size, dtype=np.bool_)
        _proof_kernel(dd, ok, ages, seconds, state, out)
        return out, state

    def run_stacked(
        self, detected: Any, counted: Any, state: FitProofState, change_age: Any = None
    ) -> tuple[np.ndarray, FitProofState]:
        """`run` of many runs at once: ``(runs, n)`` arrays and their states stacked along a
        leading run axis; each run's flags and state equal `run`'s."""
        seconds = self._check_params()
        dd, ok, ages = self._arrays(detected, counted, change_age, 2)
        check_stacked_state(state, self.init_state(), dd.shape[0], "fit proof state")
        state = writable_copy(state)
        out = np.zeros(dd.shape, dtype=np.bool_)
        _proof_runs(dd, ok, ages, seconds, state, out)
        return out, state

    def update(
        self,
        detected: bool,
        counted: bool,
        state: FitProofState | None = None,
        change_age: int = 0,
    ) -> tuple[bool, FitProofState]:
        """`run` on one second: a bool and the new state."""
        out, state = self.run(
            np.array([bool(detected)]), np.array([bool(counted)]), state, np.array([change_age])
        )
        return bool(out[0]), state

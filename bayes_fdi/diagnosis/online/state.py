"""The stream state of the online diagnoser: what one second needs of the seconds before it.

`OnlineDiagnoser` processes a run second by second through compiled kernels that each keep a
small state: the normal models' input history (for the CV and pressure-drop increments), the AR
whitening memory of each output, the sequential detectors' statistics, the hysteresis of the
detection decision, and the running sums of the isolation window. `StreamState` holds all of
them for every run of a recording as plain arrays with a leading ``run`` axis (read-only), so

- ``run(chunk, return_state=True)`` returns it after the chunk's last second and
  ``run(next_chunk, state=...)`` continues exactly where the first call stopped;
- ``update(sample)`` works on the same state for one run (``stream_state()`` /
  ``reset(state=...)`` read and restore it);
- it can be stored with `bayes_fdi.model_files.format` (a named tuple of arrays).

The kernels update their state in place; `run_state` hands out writable copies of one run's
arrays and `pack_states` freezes the per-run results into a new `StreamState`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from bayes_fdi.diagnosis.isolation.isolator import INPUT_REFERENCE_SECONDS, new_feature_state

__all__ = [
    "StreamState",
    "check_state",
    "new_run_state",
    "onset_inputs_novel",
    "pack_states",
    "run_state",
]

#: The fields of `StreamState` that hold one array per run (each with a leading run axis).
_ARRAY_FIELDS = (
    "model_history",
    "model_seen",
    "whiten_X",
    "whiten_X_valid",
    "whiten_F",
    "whiten_F_valid",
    "decision",
    "held",
    "features",
    "input_reference",
    "seconds",
)


class StreamState(NamedTuple):
    """The stream state of an `~bayes_fdi.diagnosis.OnlineDiagnoser` after some seconds.

    Every array has a leading ``run`` axis (one row per run of the recording it came from) and
    is read-only; a new state is made for every call, never changed in place.
    """

    model_history: np.ndarray  #: ``(runs, 2, n_differences)`` last CV and pressure-drop root
    model_seen: np.ndarray  #: ``(runs, 1)`` samples the normal models have seen (capped)
    whiten_X: np.ndarray  #: ``(runs, order)`` last centred residuals of the X whitening
    whiten_X_valid: np.ndarray  #: ``(runs, 1)`` valid history length of the X whitening
    whiten_F: np.ndarray  #: ``(runs, order)`` of the F whitening
    whiten_F_valid: np.ndarray  #: ``(runs, 1)``
    detect_X: tuple[np.ndarray, ...]  #: the X detector's state arrays, each ``(runs, ...)``
    detect_F: tuple[np.ndarray, ...]  #: the F detector's state arrays
    decision: np.ndarray  #: ``(runs, 1)`` 1.0 while the detection decision DD is on
    held: np.ndarray  #: ``(runs, 2)`` last finite detector statistic of X and F
    features: np.ndarray  #: ``(runs, 22)`` isolation window sums and input reference
    #: ``(runs, 7)`` average of CV, P1, P2, T1 before the detection, whether it is set, whether
    #: the current detection began outside the input envelope, DD of the last second
    input_reference: np.ndarray
    seconds: np.ndarray  #: ``(runs,)`` seconds processed so far (int64)

    @property
    def n_runs(self) -> int:
        """Number of runs the state is of."""
        return int(self.seconds.shape[0])


def new_run_state(diag: Any) -> dict[str, Any]:
    """A fresh state of one run of a fitted `OnlineDiagnoser` (writable arrays)."""
    return {
        "models": diag.normal_models_.new_state(),
        "whiten": {c: diag.whiteners_[c].new_state() for c in ("X", "F")},
        "detect": {c: diag.detector_.new_state() for c in ("X", "F")},
        "dd": np.zeros(1),
        "held": np.zeros(2),
        "features": new_feature_state(),
        "reference": np.zeros(7),
        "seconds": 0,
    }


def run_state(diag: Any, state: StreamState | None, i: int) -> dict[str, Any]:
    """Writable copies of run ``i``'s arrays of ``state`` (a fresh state when None)."""
    if state is None:
        return new_run_state(diag)
    return {
        "models": (state.model_history[i].copy(), state.model_seen[i].copy()),
        "whiten": {
            "X": (state.whiten_X[i].copy(), state.whiten_X_valid[i].copy()),
            "F": (state.whiten_F[i].copy(), state.whiten_F_valid[i].copy()),
        },
        "detect": {
            "X": tuple(a[i].copy() for a in state.detect_X),
            "F": tuple(a[i].copy() for a in state.detect_F),
        },
        "dd": state.decision[i].copy(),
        "held": state.held[i].copy(),
        "features": state.features[i].copy(),
        "reference": state.input_reference[i].copy(),
        "seconds": int(state.seconds[i]),
    }


def _frozen(parts: Sequence[np.ndarray]) -> np.ndarray:
    a = np.stack([np.asarray(p) for p in parts])
    a.flags.writeable = False
    return a


def pack_states(states: Sequence[dict[str, Any]]) -> StreamState:
    """One read-only `StreamState` of the per-run states (as `new_run_state` makes them)."""
    if not states:
        raise ValueError("no run states to pack")
    n_detect = len(states[0]["detect"]["X"])
    return StreamState(
        model_history=_frozen([s["models"][0] for s in states]),
        model_seen=_frozen([s["models"][1] for s in states]),
        whiten_X=_frozen([s["whiten"]["X"][0] for s in states]),
        whiten_X_valid=_frozen([s["whiten"]["X"][1] for s in states]),
        whiten_F=_frozen([s["whiten"]["F"][0] for s in states]),
        whiten_F_valid=_frozen([s["whiten"]["F"][1] for s in states]),
        detect_X=tuple(_frozen([s["detect"]["X"][k] for s in states]) for k in range(n_detect)),
        detect_F=tuple(_frozen([s["detect"]["F"][k] for s in states]) for k in range(n_detect)),
        decision=_frozen([s["dd"] for s in states]),
        held=_frozen([s["held"] for s in states]),
        features=_frozen([s["features"] for s in states]),
        input_reference=_frozen([s["reference"] for s in states]),
        seconds=_frozen([np.int64(s["seconds"]) for s in states]),
    )


def check_state(diag: Any, state: StreamState, n_runs: int) -> None:
    """Raise a `ValueError` unless ``state`` fits ``n_runs`` runs of this fitted diagnoser."""
    if not isinstance(state, StreamState):
        raise ValueError(
            f"state must be the StreamState returned by run(..., return_state=True), got "
            f"{type(state).__name__}"
        )
    if state.n_runs != n_runs:
        raise ValueError(f"state is of {state.n_runs} run(s), the recording has {n_runs}")
    fresh = pack_states([new_run_state(diag)])
    for name in (*_ARRAY_FIELDS, "detect_X", "detect_F"):
        want, got = getattr(fresh, name), getattr(state, name)
        if isinstance(want, tuple):
            ok = len(want) == len(got) and all(
                w.shape[1:] == g.shape[1:] for w, g in zip(want, got, strict=False)
            )
        else:
            ok = want.shape[1:] == np.shape(got)[1:]
        if not ok:
            raise ValueError(f"state does not fit this diagnoser ({name}: another model's state?)")


@njit(cache=True, error_model="numpy")
def _onset_kernel(dd, inputs, low, high, alpha, st, out):  # pragma: no cover - compiled
    """st: [average of the 4 inputs, set, novel at onset, DD before]."""
    for t in range(dd.size):
        if not dd[t]:
            ok = True
            for j in range(4):
                if not np.isfinite(inputs[t, j]):
                    ok = False
            if ok:
                for j in range(4):
                    if st[4] < 0.5:
                        st[j] = inputs[t, j]
                    else:
                        st[j] += alpha * (inputs[t, j] - st[j])
                st[4] = 1.0
            st[5] = 0.0
            st[6] = 0.0
            out[t] = False
            continue
        if st[6] < 0.5:  # a new detection: were the inputs before it inside the envelope?
            novel = False
            if st[4] > 0.5:
                for j in range(4):
                    if st[j] < low[j] or st[j] > high[j]:
                        novel = True
            st[5] = 1.0 if novel else 0.0
        st[6] = 1.0
        out[t] = st[5] > 0.5


def onset_inputs_novel(
    dd: np.ndarray, inputs: np.ndarray, low: np.ndarray, high: np.ndarray, state: np.ndarray
) -> np.ndarray:
    """Per second: whether the current detection began while the inputs were outside the
    training envelope ``[low, high]`` (False while DD is off).

    The inputs (``(n, 4)``: CV, P1, P2, T1) are averaged over the seconds without detection
    (exponential average, time constant `INPUT_REFERENCE_SECONDS`, as the isolation features'
    input reference); at each rising edge of DD that average is checked against the envelope
    and the answer held until DD falls. The average of the seconds *before* the detection is
    what counts: a fault that itself moves an input (f7 makes T1 jump) is detected within
    seconds, before the average has moved, while a plant running outside the training range
    (another temperature, another pressure) is caught. ``state`` (7,) is updated in place.
    """
    out = np.zeros(dd.size, dtype=np.bool_)
    _onset_kernel(np.ascontiguousarray(dd, dtype=np.bool_), np.ascontiguousarray(inputs),
                  np.ascontiguousarray(low), np.ascontiguousarray(high),
                  1.0 / INPUT_REFERENCE_SECONDS, state, out)  # fmt: skip
    return out

"""The stream state of the online diagnoser: what one second needs of the seconds before it.

`~bayes_fdi.diagnosis.online.diagnoser.OnlineDiagnoser` chains online components, each of which
owns a small state (a named tuple of arrays that it creates, checks and returns anew from every
step): the normal models' input history (`NormalModelsState`), the AR whitening memory of each
output (`WhitenState`), the sequential detector of each output (`CUSUMState` or `GLRState`), the
hysteresis of the detection decision (`DecisionState`), the running sums of the isolation window
(`SignatureState`), the input average of the envelope's onset check (`EnvelopeState`) and the
quiet seconds of the fit proof (`FitProofState`).

- `RunState` nests them for one run (what ``update`` carries from second to second);
- `StreamState` nests the same states for every run of a recording, each array with a leading
  ``run`` axis (read-only), so ``run(chunk, return_state=True)`` returns it after the chunk's
  last second and ``run(next_chunk, state=...)`` continues exactly where the first call
  stopped; ``stream_state()`` / ``reset(state=...)`` read and restore a one-run state for
  ``update``; `StreamState.select_runs` and `StreamState.with_runs` take some runs out and put
  them back (to advance only those). Both can be stored with `bayes_fdi.model_files`.

Files of bayes_fdi 0.1.0 hold these states flat (one array per component, the run state as a
dict); `bayes_fdi.diagnosis.online.legacy` rebuilds today's layout from them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np

from bayes_fdi.diagnosis.component_state import stack_states, state_of_run
from bayes_fdi.diagnosis.detection.decision import DecisionState
from bayes_fdi.diagnosis.detection.detectors import CUSUMState, GLRState
from bayes_fdi.diagnosis.detection.whitening import WhitenState
from bayes_fdi.diagnosis.isolation.signatures import SignatureState
from bayes_fdi.diagnosis.normal_models.dynamic_kernel import NormalModelsState
from bayes_fdi.diagnosis.online.envelope import EnvelopeState
from bayes_fdi.diagnosis.online.fit_proof import FitProofState

__all__ = ["PerOutput", "RunState", "StreamState"]


class PerOutput(NamedTuple):
    """One component's states for the two outputs X and F."""

    X: Any
    F: Any


class RunState(NamedTuple):
    """The stream state of one run (one actuator) after some seconds."""

    models: NormalModelsState  #: the normal models' input history
    whiten: PerOutput  #: `WhitenState` of X and F
    detect: PerOutput  #: `CUSUMState` or `GLRState` of X and F
    decision: DecisionState  #: the detection decision's hysteresis
    signature: SignatureState  #: the isolation window
    onset: EnvelopeState  #: the input envelope's onset check
    proof: FitProofState  #: the fit proof's quiet seconds
    seconds: int  #: seconds processed so far

    @classmethod
    def upgrade_model_file(cls, fields: dict, format_version: int) -> dict:
        """The fields of a run state saved before the fit proof (model-file format <= 13): its
        fit counts as proven, as its model's detections all were."""
        fields = dict(fields)
        fields.setdefault("proof", FitProofState.proven_state())
        return fields


class StreamState(NamedTuple):
    """The stream state of an `~bayes_fdi.diagnosis.OnlineDiagnoser` after some seconds.

    The fields of `RunState`, every array with a leading ``run`` axis (one row per run of the
    recording it came from) and read-only: a new state is made for every call, never changed
    in place.
    """

    models: NormalModelsState
    whiten: PerOutput
    detect: PerOutput
    decision: DecisionState
    signature: SignatureState
    onset: EnvelopeState
    proof: FitProofState
    seconds: np.ndarray  #: ``(runs,)`` int64

    @property
    def n_runs(self) -> int:
        """Number of runs the state is of."""
        return int(np.shape(self.seconds)[0])

    @classmethod
    def of_runs(cls, runs: Sequence[RunState]) -> StreamState:
        """One read-only state of the states of ``runs``, stacked along a leading axis."""
        if not runs:
            raise ValueError("no run states to stack")
        return cls(*stack_states(list(runs)))

    def run(self, i: int) -> RunState:
        """The state of run ``i`` (read-only views)."""
        one = state_of_run(RunState(*self), i)
        return one._replace(seconds=int(one.seconds))

    def select_runs(self, runs: Sequence[int]) -> StreamState:
        """The state of the runs ``runs`` (indices, in that order; read-only copies)."""
        index = np.asarray(runs, dtype=np.int64)
        return StreamState.from_arrays({p: a[index] for p, a in self.arrays().items()})

    def with_runs(self, runs: Sequence[int], part: StreamState) -> StreamState:
        """This state with runs ``runs`` (indices) replaced by the runs of ``part`` (a state
        of ``len(runs)`` runs of the same layout, e.g. `select_runs`' advanced)."""
        index = np.asarray(runs, dtype=np.int64)
        if part.n_runs != index.size:
            raise ValueError(f"part is of {part.n_runs} run(s), not of {index.size}")
        arrays, replacing = self.arrays(), part.arrays()
        if arrays.keys() != replacing.keys():
            raise ValueError("part has another layout than this state")
        out = {}
        for path, a in arrays.items():
            out[path] = a.copy()
            out[path][index] = replacing[path]
        return StreamState.from_arrays(out)

    def check_layout(self) -> None:
        """Raise a `ValueError` unless every field is an array with the leading run axis."""
        if not isinstance(self.seconds, np.ndarray) or self.seconds.ndim != 1:
            raise ValueError("state.seconds must be a (runs,) array")
        n = self.n_runs

        def walk(value: Any, where: str) -> None:
            if isinstance(value, tuple) and hasattr(value, "_fields"):
                for name, item in zip(value._fields, value, strict=True):
                    walk(item, f"{where}.{name}")
            elif not isinstance(value, np.ndarray) or value.ndim < 1 or value.shape[0] != n:
                raise ValueError(f"{where} must be an array with a leading axis of {n} run(s)")

        walk(self, "state")

    def arrays(self) -> dict[str, np.ndarray]:
        """Every array of the state by its dotted path (``"models.history"``,
        ``"detect.X.sums"``, ..., ``"seconds"``); `from_arrays` rebuilds the state."""
        out: dict[str, np.ndarray] = {}

        def walk(value: Any, where: str) -> None:
            if isinstance(value, tuple):
                for name, item in zip(value._fields, value, strict=True):
                    walk(item, f"{where}.{name}" if where else name)
            else:
                out[where] = value

        walk(self, "")
        return out

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray]) -> StreamState:
        """The state of `arrays`' output (read-only); a `ValueError` names a missing or
        unknown path."""
        used: set[str] = set()
        arrays = dict(arrays)
        if "decision.on" in arrays and "decision.quiet" not in arrays:  # saved before the hold
            arrays["decision.quiet"] = np.zeros(np.shape(arrays["decision.on"]), dtype=np.int64)
        if "seconds" in arrays and "proof.quiet" not in arrays:  # saved before the fit proof
            runs = np.shape(arrays["seconds"])
            for name, value in FitProofState.proven_state(runs)._asdict().items():
                arrays[f"proof.{name}"] = value

        def build(options: tuple[type, ...], where: str) -> Any:
            for option in options:
                paths = [f"{where}.{name}" for name in option._fields]
                if all(p in arrays for p in paths):
                    used.update(paths)
                    return option(*(np.asarray(arrays[p]) for p in paths))
            raise ValueError(
                f"the arrays hold no {' or '.join(o.__name__ for o in options)} at {where!r}"
            )

        fields: dict[str, Any] = {}
        for name, options in _COMPONENT_STATES.items():
            if name in ("whiten", "detect"):
                fields[name] = PerOutput(build(options, f"{name}.X"), build(options, f"{name}.F"))
            else:
                fields[name] = build(options, name)
        if "seconds" not in arrays:
            raise ValueError("the arrays hold no 'seconds'")
        fields["seconds"] = np.asarray(arrays["seconds"])
        unknown = sorted(set(arrays) - used - {"seconds"})
        if unknown:
            raise ValueError(f"unknown stream state arrays {unknown}")
        state = cls(**fields)
        state.check_layout()
        for value in state.arrays().values():
            value.flags.writeable = False
        return state

    @classmethod
    def upgrade_model_file(cls, data: dict, format_version: int) -> dict:
        """A saved `StreamState`'s fields in today's layout
        (`bayes_fdi.diagnosis.online.legacy.upgrade_stream_state`)."""
        from bayes_fdi.diagnosis.online.legacy import upgrade_stream_state

        return upgrade_stream_state(data)


#: The classes each component state of a `StreamState` may be of.
_COMPONENT_STATES: dict[str, tuple[type, ...]] = {
    "models": (NormalModelsState,),
    "whiten": (WhitenState,),
    "detect": (CUSUMState, GLRState),
    "decision": (DecisionState,),
    "signature": (SignatureState,),
    "onset": (EnvelopeState,),
    "proof": (FitProofState,),
}

"""The online diagnoser's model files of bayes_fdi 0.1.0, translated to today's layout.

bayes_fdi 0.1.0 saved an `~bayes_fdi.diagnosis.online.diagnoser.OnlineDiagnoser` with its input
envelope as two arrays (``input_low_``, ``input_high_``), without the detection decision and
signature window components, and with the `update` stream's state as a flat dict; a
`~bayes_fdi.diagnosis.online.state.StreamState` had one flat field per component array. The
model-file loader (`bayes_fdi.model_files`) calls the classes' ``upgrade_model_file`` hooks on
such files, which call `upgrade_diagnoser` and `upgrade_stream_state` here; `upgrade_run_state`
rebuilds one run's state. The translation moves numbers only, so a loaded model continues its
saved stream exactly.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from bayes_fdi.diagnosis.detection.decision import DecisionState, DetectionDecision
from bayes_fdi.diagnosis.detection.detectors import CUSUMState, GLRState
from bayes_fdi.diagnosis.detection.whitening import WhitenState
from bayes_fdi.diagnosis.isolation.signatures import SignatureState, SignatureWindow
from bayes_fdi.diagnosis.normal_models.dynamic_kernel import NormalModelsState
from bayes_fdi.diagnosis.online.envelope import EnvelopeState, InputEnvelope
from bayes_fdi.diagnosis.online.fit_proof import FitProofState
from bayes_fdi.diagnosis.online.state import PerOutput, RunState, StreamState

__all__ = ["upgrade_diagnoser", "upgrade_run_state", "upgrade_stream_state"]


def upgrade_diagnoser(data: dict[str, Any]) -> dict[str, Any]:
    """An `OnlineDiagnoser`'s saved attributes in today's layout (today's returned unchanged; a
    file saved before the fit proof gets ``fit_proof_seconds = 0``, the stream it gave; one
    saved before the diagnoser chose its ``group_rule``, its isolator's rule, or the pairwise
    rule that fitted every other)."""
    data = dict(data)
    data.setdefault("fit_proof_seconds", 0)  # saved before the fit proof: every detection a fault
    data.setdefault("group_rule", getattr(data.get("isolator_"), "group_rule", "pairwise"))
    if "input_low_" in data:
        low, high = data.pop("input_low_"), data.pop("input_high_")
        margin = data.get("input_margin", 0.1)
        data["envelope_"] = InputEnvelope.from_bounds(
            low, high, margin=margin, change_lookback=0, command_check=False
        )
    if "threshold_" in data and "decision_" not in data:
        data["decision_"] = DetectionDecision(data["threshold_"], data["clear_level_"], 2, hold=0)
    if "normal_models_" in data and "signature_" not in data:
        data["signature_"] = SignatureWindow()
    if isinstance(data.get("_stream"), dict):
        data["_stream"] = upgrade_run_state(data["_stream"])
    return data


def _part(a: Any, start: int, stop: int, dtype: Any = np.float64) -> np.ndarray:
    """Columns ``start:stop`` of the last axis of ``a``, a contiguous copy."""
    return np.ascontiguousarray(np.asarray(a)[..., start:stop]).astype(dtype)


def _flag(a: Any, start: int) -> np.ndarray:
    """Column ``start`` of the last axis of a 0/1 float array as a bool array (``(..., 1)``)."""
    return np.ascontiguousarray(np.asarray(a)[..., start : start + 1] > 0.5)


def _detector_state(arrays: Sequence[Any]) -> CUSUMState | GLRState:
    """0.1.0 kept a CUSUM's state as ``([S+, S-, n+, n-],)`` and a GLR's as
    ``(ring, [stored, slot])``, floats."""
    if len(arrays) == 1:
        return CUSUMState(_part(arrays[0], 0, 2), _part(arrays[0], 2, 4))
    if len(arrays) == 2:
        ring = np.ascontiguousarray(arrays[0], dtype=np.float64)
        return GLRState(ring, _part(arrays[1], 0, 1, np.int64), _part(arrays[1], 1, 2, np.int64))
    raise ValueError(f"a detector state of {len(arrays)} arrays is of no known detector")


def _nested(
    models: tuple, whiten: dict, detect: dict, decision: Any, held: Any, features: Any, onset: Any
) -> dict[str, Any]:
    """Today's nested fields from 0.1.0's flat arrays (with or without a leading run axis).

    ``features`` was ``[n, 16 sums, reference of P1 P2 T1, reference set, DD before]`` and
    ``onset`` ``[average of CV P1 P2 T1, set, novel at onset, DD before]``.
    """
    return {
        "models": NormalModelsState(
            np.ascontiguousarray(models[0], dtype=np.float64), _part(models[1], 0, 1, np.int64)
        ),
        "whiten": PerOutput(
            *(
                WhitenState(np.ascontiguousarray(h, dtype=np.float64), _part(v, 0, 1, np.int64))
                for h, v in (whiten["X"], whiten["F"])
            )
        ),
        "detect": PerOutput(_detector_state(detect["X"]), _detector_state(detect["F"])),
        "decision": DecisionState(
            _flag(decision, 0),
            np.ascontiguousarray(held, np.float64),
            np.zeros(_flag(decision, 0).shape, dtype=np.int64),
        ),
        "signature": SignatureState(
            _part(features, 0, 1),
            _part(features, 1, 17),
            _part(features, 17, 20),
            _flag(features, 20),
            _flag(features, 21),
        ),
        "onset": EnvelopeState(  # 0.1.0 had no rates: no last second, rates 0
            _part(onset, 0, 4),
            _flag(onset, 4),
            _flag(onset, 5),
            _flag(onset, 6),
            np.full((*np.shape(onset)[:-1], 2), np.nan),
            np.zeros((*np.shape(onset)[:-1], 2)),
            np.zeros((*np.shape(onset)[:-1], 0, 4)),  # no ring: judged before the detection
            np.zeros((*np.shape(onset)[:-1], 1), dtype=np.int64),
            np.zeros((*np.shape(onset)[:-1], 1), dtype=np.int64),
            np.zeros((*np.shape(onset)[:-1], 2), dtype=np.int64),
        ),
        "proof": FitProofState.proven_state(np.shape(onset)[:-1]),  # 0.1.0 had no fit proof
    }


def upgrade_run_state(old: dict[str, Any]) -> RunState:
    """The `RunState` of a run state saved by bayes_fdi 0.1.0 (the diagnoser's ``_stream``: a
    dict of ``models``, ``whiten``, ``detect``, ``dd``, ``held``, ``features``, ``reference``,
    ``seconds``)."""
    fields = _nested(
        old["models"],
        old["whiten"],
        old["detect"],
        old["dd"],
        old["held"],
        old["features"],
        old["reference"],
    )
    return RunState(**fields, seconds=int(old["seconds"]))


def upgrade_stream_state(fields: dict[str, Any]) -> dict[str, Any]:
    """A `StreamState`'s fields in today's layout; fields saved by bayes_fdi 0.1.0 (flat:
    ``model_history``, ``whiten_X``, ``detect_X``, ``features``, ...) are nested, today's are
    returned as they are."""
    if "model_history" not in fields:
        if "proof" not in fields and "seconds" in fields:  # saved before the fit proof
            fields = {**fields, "proof": FitProofState.proven_state(np.shape(fields["seconds"]))}
        return fields
    nested = _nested(
        (fields["model_history"], fields["model_seen"]),
        {c: (fields[f"whiten_{c}"], fields[f"whiten_{c}_valid"]) for c in ("X", "F")},
        {c: tuple(fields[f"detect_{c}"]) for c in ("X", "F")},
        fields["decision"],
        fields["held"],
        fields["features"],
        fields["input_reference"],
    )
    state = StreamState(**nested, seconds=np.array(fields["seconds"], dtype=np.int64))
    state.check_layout()
    _freeze(state)
    return state._asdict()


def _freeze(value: Any) -> None:
    if isinstance(value, np.ndarray):
        value.flags.writeable = False
    else:
        for item in value:
            _freeze(item)

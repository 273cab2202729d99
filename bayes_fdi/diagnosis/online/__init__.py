"""The online self-validating diagnoser: every second, detect, isolate and say how far to
trust X and F.

- `bayes_fdi.diagnosis.online.diagnoser`: `OnlineDiagnoser` (``fit``, ``run`` over a recording,
  ``update`` one second at a time; both give the same stream).
- `bayes_fdi.diagnosis.online.state`: `StreamState` and `RunState`, what one second needs of
  the seconds before it (the online components' states, nested).
- `bayes_fdi.diagnosis.online.envelope`: `InputEnvelope`, the inputs' training range and the
  check of a detection's onset against it.
- `bayes_fdi.diagnosis.online.fit_proof`: `FitProof`, whether the normal models were seen to
  fit the valve before a detection, so that it may be read as a fault.
- `bayes_fdi.diagnosis.online.change_point`: `change_ages`, the detector's estimated change
  point behind a detection, which that check looks up.
- `bayes_fdi.diagnosis.online.stream`: the per-second decisions and the stream dataset.
- `bayes_fdi.diagnosis.online.records`: the SEVA record of one second and its reasons.
- `bayes_fdi.diagnosis.online.training`: the training data of the fit (stacked runs, split
  fault runs, isolation signatures).
- `bayes_fdi.diagnosis.online.timeline`: the timeline figure of a recording's stream.

May import the other concepts of `bayes_fdi.diagnosis`, `bayes_fdi.model_files`,
`bayes_fdi.datasets` and the foundation.
"""

from bayes_fdi.diagnosis.online.diagnoser import OnlineDiagnoser
from bayes_fdi.diagnosis.online.envelope import EnvelopeState, InputEnvelope
from bayes_fdi.diagnosis.online.fit_proof import FitProof, FitProofState
from bayes_fdi.diagnosis.online.state import PerOutput, RunState, StreamState
from bayes_fdi.diagnosis.online.stream import FAULTS

__all__ = [
    "FAULTS",
    "EnvelopeState",
    "FitProof",
    "FitProofState",
    "InputEnvelope",
    "OnlineDiagnoser",
    "PerOutput",
    "RunState",
    "StreamState",
]

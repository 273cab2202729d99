"""The online self-validating diagnoser: every second, detect, isolate and say how far to
trust X and F.

- `bayes_fdi.diagnosis.online.diagnoser`: `OnlineDiagnoser` (``fit``, ``run`` over a recording,
  ``update`` one second at a time; both give the same stream).
- `bayes_fdi.diagnosis.online.state`: `StreamState`, what one second needs of the seconds
  before it.
- `bayes_fdi.diagnosis.online.fitting`: the fit (detection from fault-free runs, isolation from
  fault runs).
- `bayes_fdi.diagnosis.online.timeline`: the timeline figure of a recording's stream.

May import the other concepts of `bayes_fdi.diagnosis`, `bayes_fdi.model_files`,
`bayes_fdi.datasets` and the foundation.
"""

from bayes_fdi.diagnosis.online.diagnoser import FAULTS, OnlineDiagnoser
from bayes_fdi.diagnosis.online.state import StreamState

__all__ = ["FAULTS", "OnlineDiagnoser", "StreamState"]

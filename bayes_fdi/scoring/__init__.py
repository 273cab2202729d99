"""Scoring a 1 Hz decision stream against the truth: the DAMADICS benchmark's indices (PICalc).

- `bayes_fdi.scoring.picalc`: the performance indices of DABLib's PICalc block.
- `bayes_fdi.scoring.decision_signals`: the decision signals PICalc reads (DD, FFID, the
  indicated faults) from an online diagnoser's stream, and their rising edges.

Library code: may import the foundation and `bayes_fdi.datasets`; used by the DAMADICS
benchmark and by ``bayes-fdi diagnose`` (recordings with known fault events).
"""

from bayes_fdi.scoring.picalc import PICALC_KEYS, UNDETERMINED, picalc

__all__ = ["PICALC_KEYS", "UNDETERMINED", "picalc"]

"""Experiments: studies composed from the library.

- `bayes_fdi.experiments.campaigns`: declarative campaign files (``sim/*.toml``) and their
  simulation (the ``bayes-fdi simulate`` command).
- `bayes_fdi.experiments.reproduce`: the paper's experiment (``bayes-fdi reproduce``) and
  `bayes_fdi.experiments.reproduce_report`, its Markdown report.
- `bayes_fdi.experiments.performance_indices`: the DAMADICS benchmark's performance indices
  (PICalc), exported as ``from bayes_fdi.experiments import picalc``.
- `bayes_fdi.experiments.scenarios`: the benchmark's 44 Step-I scenarios and fault-free hours.
- `bayes_fdi.experiments.benchmark`: the online diagnoser scored on them (``bayes-fdi
  benchmark``), with `bayes_fdi.experiments.benchmark_report` and
  `bayes_fdi.experiments.timeline` (the per-recording timeline figure).
"""

from bayes_fdi.experiments.performance_indices import PICALC_KEYS, UNDETERMINED, picalc

__all__ = ["PICALC_KEYS", "UNDETERMINED", "picalc"]

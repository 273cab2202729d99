"""Experiments: studies composed from the library.

- `bayes_fdi.experiments.campaigns`: declarative campaign files (``sim/*.toml``) and their
  simulation (the ``bayes-fdi simulate`` command).
- `bayes_fdi.experiments.reproduce`: the paper's experiment (``bayes-fdi reproduce``), built from
  `campaign_cache` (simulated datasets and their cache), `paper_setup` (states, kernel widths,
  node classifiers), `paper_pipeline` (the protocol on one dataset), `classification_scores`,
  `separability` (which states two features can split) and `calibration_headlines`;
  `bayes_fdi.experiments.reproduce_report` renders its Markdown report from `report_tables`,
  `report_figures`, `report_sections` and `results_json`.
- `bayes_fdi.experiments.performance_indices`: the DAMADICS benchmark's performance indices
  (PICalc), exported as ``from bayes_fdi.experiments import picalc``.
- `bayes_fdi.experiments.scenarios`: the benchmark's 44 Step-I scenarios and fault-free hours.
- `bayes_fdi.experiments.benchmark`: the online diagnoser scored on them (``bayes-fdi
  benchmark``), with `bayes_fdi.experiments.benchmark_report` and
  `bayes_fdi.experiments.timeline` (the per-recording timeline figure).
"""

from bayes_fdi.experiments.performance_indices import PICALC_KEYS, UNDETERMINED, picalc

__all__ = ["PICALC_KEYS", "UNDETERMINED", "picalc"]

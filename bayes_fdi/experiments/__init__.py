"""Experiments: studies composed from the library.

- `bayes_fdi.experiments.campaigns`: declarative campaign files (``sim/*.toml``) and their
  simulation (the ``bayes-fdi simulate`` command).
- `bayes_fdi.experiments.reproduce`: the paper's experiment (``bayes-fdi reproduce``) and
  `bayes_fdi.experiments.reproduce_report`, its Markdown report.
"""

"""Experiments: the DAMADICS benchmark's performance indices, scenarios and runner.

>>> from bayes_fdi.experiments import picalc
"""

from bayes_fdi.experiments.performance_indices import PICALC_KEYS, UNDETERMINED, picalc

__all__ = ["PICALC_KEYS", "UNDETERMINED", "picalc"]

"""Bayesian digital twin of an actuator, calibrated on its healthy data, and fault transplant.

>>> from bayes_fdi.datasets import load_lublin_example
>>> from bayes_fdi.twin import ActuatorTwin
>>> hour = load_lublin_example()
>>> twin = ActuatorTwin().fit(hour.isel(time=slice(0, 1800)))  # doctest: +SKIP
>>> twin.check(hour.isel(time=slice(1800, 3600))).coverage  # doctest: +SKIP

See ``docs/twin.md`` for the model, the method and what the real hour identifies.
"""

from bayes_fdi.twin.checks import TwinCheck, predictive_check
from bayes_fdi.twin.inference import ParameterIdentification, identification
from bayes_fdi.twin.priors import DEFAULT_PRIORS, NOISE_PRIOR, NoisePrior, ParameterPrior
from bayes_fdi.twin.transplant import (
    MEASUREMENT_BIAS_SCALE,
    STRENGTH_DRAWS,
    MeasurementFault,
    transplant,
    transplant_library,
)
from bayes_fdi.twin.twin import ActuatorTwin

__all__ = [
    "DEFAULT_PRIORS",
    "MEASUREMENT_BIAS_SCALE",
    "NOISE_PRIOR",
    "STRENGTH_DRAWS",
    "ActuatorTwin",
    "MeasurementFault",
    "NoisePrior",
    "ParameterIdentification",
    "ParameterPrior",
    "TwinCheck",
    "identification",
    "predictive_check",
    "transplant",
    "transplant_library",
]

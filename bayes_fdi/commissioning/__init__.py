"""Commissioning a valve on its own healthy data: a Bayesian digital twin, a fault library
transplanted onto the data, and an online diagnoser that isolates on the plant's own terms.

- `bayes_fdi.commissioning.commission`: `commission`, the whole procedure, and its result.
- `bayes_fdi.commissioning.healthy`: the checks of the healthy data and the operating range
  they cover.
- `bayes_fdi.commissioning.expectations`: what to expect of the commissioned diagnoser,
  measured on held-out transplants.

Library code above the diagnosis and calibration: may import `bayes_fdi.twin`,
`bayes_fdi.diagnosis`, `bayes_fdi.calibration`, `bayes_fdi.datasets` and the foundation; the
deployment commands (``bayes-fdi commission``, ``diagnose --commission-seconds``) and the
benchmark build on it.
"""

from bayes_fdi.commissioning.commission import (
    DETECT_RATE,
    INPUT_MARGIN,
    LIBRARY_FAULTS,
    Commissioning,
    commission,
)
from bayes_fdi.commissioning.healthy import check_healthy, operating_range

__all__ = [
    "DETECT_RATE",
    "INPUT_MARGIN",
    "LIBRARY_FAULTS",
    "Commissioning",
    "check_healthy",
    "commission",
    "operating_range",
]

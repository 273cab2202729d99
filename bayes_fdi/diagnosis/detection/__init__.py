"""Fault detection on the normal models' residuals: whitening, sequential tests, thresholds.

- `bayes_fdi.diagnosis.detection.whitening`: `ARWhitener`, an AR prediction-error filter that
  turns standardised residuals into about white innovations.
- `bayes_fdi.diagnosis.detection.detectors`: the sequential tests `CUSUM` and `GLR` and the
  detection decision DD with hysteresis.
- `bayes_fdi.diagnosis.detection.thresholds`: thresholds for a false-alarm budget.

May import `bayes_fdi.datasets` and the foundation.
"""

from bayes_fdi.diagnosis.detection.detectors import CUSUM, GLR, detection_decision
from bayes_fdi.diagnosis.detection.thresholds import calibrate_threshold, cusum_threshold
from bayes_fdi.diagnosis.detection.whitening import ARWhitener

__all__ = [
    "CUSUM",
    "GLR",
    "ARWhitener",
    "calibrate_threshold",
    "cusum_threshold",
    "detection_decision",
]

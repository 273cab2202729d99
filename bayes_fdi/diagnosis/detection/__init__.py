"""Fault detection on the normal models' residuals: whitening, sequential tests, thresholds.

- `bayes_fdi.diagnosis.detection.whitening`: `ARWhitener`, an AR prediction-error filter that
  turns standardised residuals into about white innovations.
- `bayes_fdi.diagnosis.detection.detectors`: the sequential tests `CUSUM` and `GLR`.
- `bayes_fdi.diagnosis.detection.two_speed`: `TwoSpeedCUSUM`, the CUSUM with a slow branch
  for lasting small shifts of the innovations (commissioned diagnosers use it).
- `bayes_fdi.diagnosis.detection.variance_hold`: `VarianceHoldCUSUM`, the CUSUM whose alarm
  holds while the innovations' variance stays above its in-control level (the default online
  diagnoser uses it).
- `bayes_fdi.diagnosis.detection.decision`: `DetectionDecision`, the detection decision DD
  with hysteresis and a hold (`CLEAR_HOLD`: the online diagnoser's).
- `bayes_fdi.diagnosis.detection.thresholds`: thresholds for a false-alarm budget.

Each online component here owns its state, a named tuple of arrays (`WhitenState`,
`CUSUMState`, `GLRState`, `TwoSpeedCUSUMState`, `VarianceHoldCUSUMState`,
`DecisionState`), with ``update`` for one
sample and ``run`` over a chunk through the same compiled kernel.

May import `bayes_fdi.diagnosis.component_state`, `bayes_fdi.datasets` and the foundation.
"""

from bayes_fdi.diagnosis.detection.decision import (
    CLEAR_HOLD,
    DecisionState,
    DetectionDecision,
    detection_decision,
)
from bayes_fdi.diagnosis.detection.detectors import (
    CUSUM,
    GLR,
    CUSUMState,
    DetectorOutput,
    GLRState,
)
from bayes_fdi.diagnosis.detection.thresholds import (
    calibrate_threshold,
    cusum_threshold,
    fit_threshold,
)
from bayes_fdi.diagnosis.detection.two_speed import TwoSpeedCUSUM, TwoSpeedCUSUMState
from bayes_fdi.diagnosis.detection.variance_hold import (
    VarianceHoldCUSUM,
    VarianceHoldCUSUMState,
    variance_reference,
)
from bayes_fdi.diagnosis.detection.whitening import ARWhitener, WhitenState

__all__ = [
    "CLEAR_HOLD",
    "CUSUM",
    "GLR",
    "ARWhitener",
    "CUSUMState",
    "DecisionState",
    "DetectionDecision",
    "DetectorOutput",
    "GLRState",
    "TwoSpeedCUSUM",
    "TwoSpeedCUSUMState",
    "VarianceHoldCUSUM",
    "VarianceHoldCUSUMState",
    "WhitenState",
    "calibrate_threshold",
    "cusum_threshold",
    "detection_decision",
    "fit_threshold",
    "variance_reference",
]

"""The self-validating (SEVA) output: records, statuses and the rules that set them.

- `bayes_fdi.diagnosis.seva.record`: the immutable `SevaRecord`, `SevaStatus` (CLEAR, BLURRED,
  DAZZLED, BLIND), `ClassDistribution` and their conversions (data frame, xarray, JSON).
- `bayes_fdi.diagnosis.seva.rules`: thresholds, measurement screening and the status rules.
- `bayes_fdi.diagnosis.seva.novelty`: whether the inputs are novel (nearest-neighbour ratio).
- `bayes_fdi.diagnosis.seva.names`: what a diagnosed state and a status mean, in words.
- `bayes_fdi.diagnosis.seva.windows`: the records of the offline diagnoser's runs or windows.
- `bayes_fdi.diagnosis.seva.empty_windows`: diagnosing runs of which a window holds no complete
  sample.

May import `bayes_fdi.datasets`, `bayes_fdi.actuator` (the fault table),
`bayes_fdi.diagnosis.isolation` (features) and the foundation.
"""

from bayes_fdi.diagnosis.seva.names import STATUS_MEANINGS, describe_state
from bayes_fdi.diagnosis.seva.novelty import NoveltyReference
from bayes_fdi.diagnosis.seva.record import (
    ClassDistribution,
    SevaRecord,
    SevaStatus,
    to_frame,
    to_json,
    to_xarray,
)
from bayes_fdi.diagnosis.seva.rules import SevaThresholds
from bayes_fdi.diagnosis.seva.windows import records_from_diagnosis, seva_records

__all__ = [
    "STATUS_MEANINGS",
    "ClassDistribution",
    "NoveltyReference",
    "SevaRecord",
    "SevaStatus",
    "SevaThresholds",
    "describe_state",
    "records_from_diagnosis",
    "seva_records",
    "to_frame",
    "to_json",
    "to_xarray",
]

"""Calibration of probabilistic diagnoses and of the normal models' predictive intervals.

A diagnoser is *calibrated* when its stated probabilities are frequencies: among the runs it
diagnoses as ``f2`` with probability 0.8, about 80 % really are ``f2``. A normal model is
calibrated when its 95 % predictive intervals contain about 95 % of fault-free measurements.

- `bayes_fdi.calibration.metrics`: ECE (top-label, classwise, bootstrap intervals, noise floor),
  log loss, Brier score, reliability diagrams, and `probability_rows`, the check of a
  probability matrix they and the recalibrators share.
- `bayes_fdi.calibration.temperature`: temperature scaling (`TemperatureScaler`, and
  `check_temperature_bounds` for its search interval).
- `bayes_fdi.calibration.age_temperature`: one temperature per age bin of the evidence
  (`AgeTemperatureScaler`), for probabilities that grow more reliable as a signature settles.
- `bayes_fdi.calibration.top_label`: a temperature and a beta map of the top class
  (`TopLabelScaler`), which bends the reliability curve.
- `bayes_fdi.calibration.dirichlet`: Dirichlet calibration and vector scaling (`DirichletScaler`).
- `bayes_fdi.calibration.recalibration`: the cross-validated log loss that chooses between
  recalibrators, and what they share.
- `bayes_fdi.calibration.nodes`: binary calibration of each node of a hierarchical classifier.
- `bayes_fdi.calibration.intervals`: coverage, PIT and CRPS of Gaussian predictive distributions
  (and `StdScaler`, which recalibrates them).
- `bayes_fdi.calibration.report`: the calibration report (``bayes-fdi calibration-report``),
  built from `bayes_fdi.calibration.summaries` (its numbers), `.recalibrator_selection`
  (cross-fitted recalibration and the choice of recalibrator) and `.report_markdown` (its text).
"""

from bayes_fdi.calibration.age_temperature import AgeTemperatureScaler
from bayes_fdi.calibration.dirichlet import DEFAULT_REG_GRID, DirichletScaler
from bayes_fdi.calibration.intervals import (
    DEFAULT_LEVELS,
    CoverageResult,
    crps_gaussian,
    interval_coverage,
    pit_histogram,
    pit_values,
    plot_pit_histogram,
)
from bayes_fdi.calibration.metrics import (
    PROBABILITY_ROUNDING,
    ECEResult,
    brier,
    expected_calibration_error,
    log_loss,
    probability_rows,
    reliability_diagram,
)
from bayes_fdi.calibration.nodes import NodeCalibration, node_calibration
from bayes_fdi.calibration.recalibration import cross_val_log_loss
from bayes_fdi.calibration.temperature import TemperatureScaler, check_temperature_bounds
from bayes_fdi.calibration.top_label import TopLabelScaler
from bayes_fdi.diagnosis.normal_models.std_scaler import StdScaler

__all__ = [
    "DEFAULT_LEVELS",
    "DEFAULT_REG_GRID",
    "PROBABILITY_ROUNDING",
    "AgeTemperatureScaler",
    "CoverageResult",
    "DirichletScaler",
    "ECEResult",
    "NodeCalibration",
    "StdScaler",
    "TemperatureScaler",
    "TopLabelScaler",
    "brier",
    "check_temperature_bounds",
    "cross_val_log_loss",
    "crps_gaussian",
    "expected_calibration_error",
    "interval_coverage",
    "log_loss",
    "node_calibration",
    "pit_histogram",
    "pit_values",
    "plot_pit_histogram",
    "probability_rows",
    "reliability_diagram",
]

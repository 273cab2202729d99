"""The small dynamic normal models and healthy runs that the online diagnoser's quick tests fit
(seconds, not minutes): one RBF width per output, 300 training samples, two folds."""

from __future__ import annotations

from bayes_fdi.actuator import benchmark_inputs, simulate
from bayes_fdi.diagnosis.normal_models.dynamic import DynamicNormalModels


def small_normal_models() -> DynamicNormalModels:
    """Unfitted normal models, seeded."""
    return DynamicNormalModels(
        x_widths=(8.0,), f_widths=(0.1,), evidence_max_samples=200, max_train_samples=300,
        calibration_folds=2, random_state=0,
    )  # fmt: skip


def small_normal_runs():
    """Four healthy 400-s runs under varied DGen sines (seed 1)."""
    return simulate(benchmark_inputs(4, 400, seed=1, vary=True), seed=1)

"""A small online diagnoser's training data for tests: light normal models and short simulated
runs of three faults (f1, f7, f18) for training, validation and calibration."""

from __future__ import annotations

from typing import NamedTuple

import xarray as xr

from bayes_fdi.actuator import Fault, benchmark_inputs, simulate
from bayes_fdi.diagnosis.normal_models.dynamic import DynamicNormalModels

KINDS = ("f1", "f7", "f18")


class SmallRuns(NamedTuple):
    normal: xr.Dataset  #: 4 fault-free runs of 400 s
    faults: xr.Dataset  #: 15 fault runs of 300 s (5 strengths per fault, onset 100 s)
    validation: xr.Dataset  #: 6 fault runs of 300 s (onset 80 s)
    calibration: xr.Dataset  #: 6 fault runs of 300 s (onset 80 s), another seed


def small_normal_models() -> DynamicNormalModels:
    """Normal models light enough for a test's fit (one width each, few samples)."""
    return DynamicNormalModels(
        x_widths=(8.0,), f_widths=(0.1,), evidence_max_samples=200, max_train_samples=300,
        calibration_folds=2, random_state=0,
    )  # fmt: skip


def small_normal_runs() -> xr.Dataset:
    """`SmallRuns.normal` alone (seed 1), for a test that needs no fault runs."""
    return simulate(benchmark_inputs(4, 400, seed=1, vary=True), seed=1)


def small_fault_runs() -> xr.Dataset:
    """`SmallRuns.faults` alone (seed 2)."""
    specs = [Fault(f, s, 100.0) for f in KINDS for s in (0.4, 0.6, 0.8, 1.0, 0.5)]
    return simulate(benchmark_inputs(len(specs), 300, seed=2, vary=True), specs, seed=2)


def small_runs() -> SmallRuns:
    """The seeded runs (seeds 1, 2, 4, 5)."""
    normal, faults = small_normal_runs(), small_fault_runs()
    held = [Fault(f, s, 80.0) for f in KINDS for s in (0.5, 0.9)]
    validation = simulate(benchmark_inputs(len(held), 300, seed=4, vary=True), held, seed=4)
    calibration = simulate(benchmark_inputs(len(held), 300, seed=5, vary=True), held, seed=5)
    return SmallRuns(normal, faults, validation, calibration)


def small_calibrated_diagnoser(runs: SmallRuns):
    """An `OnlineDiagnoser` with the small normal models fitted on ``runs``, its group
    probabilities recalibrated by one temperature on their calibration runs."""
    from bayes_fdi.calibration import TemperatureScaler
    from bayes_fdi.diagnosis import OnlineDiagnoser

    return OnlineDiagnoser(
        small_normal_models(), calibrator=TemperatureScaler(), max_signatures_per_fault=20,
        random_state=0,
    ).fit(runs.normal, runs.faults, validation_runs=runs.validation,
          calibration_runs=runs.calibration)  # fmt: skip

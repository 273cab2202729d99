"""The refit of ``benchmarks/isolation_classifiers.py``: the isolation as the fit fits it."""

from __future__ import annotations

import numpy as np
import pytest
from benchmark_scripts import load_benchmark
from small_online import small_normal_models, small_runs

from bayes_fdi.calibration import TemperatureScaler
from bayes_fdi.diagnosis import OnlineDiagnoser
from bayes_fdi.diagnosis.isolation import ForestClassifier
from bayes_fdi.diagnosis.online.training import detection_components, training_signatures

tool = load_benchmark("isolation_classifiers")


@pytest.fixture(scope="module")
def fitted():
    runs = small_runs()
    diag = OnlineDiagnoser(
        small_normal_models(), calibrator=TemperatureScaler(), max_signatures_per_fault=20,
        random_state=0,
    ).fit(runs.normal, runs.faults, validation_runs=runs.validation,
          calibration_runs=runs.calibration)  # fmt: skip
    faults, validation, calibration = runs.faults, runs.validation, runs.calibration
    components = detection_components(diag)
    X, y, _, _ = training_signatures(components, faults)
    Xv, yv, av, _ = training_signatures(components, validation)
    Xc, yc, _, _ = training_signatures(components, calibration, per_second=True)
    return diag, ((X, y), (Xv, yv, av), (Xc, yc)), calibration


def test_the_tree_at_the_fits_seed_is_the_fits_own_isolation(fitted):
    diag, signatures, calibration = fitted
    again = tool.refit_isolation(diag, signatures, "tree@0")
    assert again is not diag and again.isolator_ is not diag.isolator_
    assert again.groups_ == diag.groups_
    assert again.isolator_.temperature() == diag.isolator_.temperature()
    # the same decisions of every RVC; their weights may differ in the last bits between two
    # fits (the BLAS's rounding can follow the arrays' memory alignment), not more
    rows = signatures[2][0][:50]
    want = diag.isolator_.run(rows).group_proba
    np.testing.assert_allclose(again.isolator_.run(rows).group_proba, want, rtol=1e-10, atol=0)
    # the detection is the model's own: the same stream but for the isolation
    runs = calibration[["CV", "P1", "P2", "T1", "X", "F"]]
    np.testing.assert_array_equal(again.run(runs)["DD"].values, diag.run(runs)["DD"].values)


def test_a_forest_variant_and_an_unknown_one(fitted):
    diag, signatures, _ = fitted
    forest = tool.refit_isolation(diag, signatures, "forest@1")
    assert isinstance(forest.isolator_.classifier_, ForestClassifier)
    # a forest refitted at the same seed is the same forest, bit for bit
    twice = tool.refit_isolation(diag, signatures, "forest@1")
    rows = signatures[2][0][:50]
    np.testing.assert_array_equal(twice.isolator_.run(rows).group_proba,
                                  forest.isolator_.run(rows).group_proba)  # fmt: skip
    assert forest.isolator_.classifier_.random_state == 1
    assert not isinstance(diag.isolator_.classifier_, ForestClassifier)  # a copy was refitted
    with pytest.raises(SystemExit, match="unknown classifier 'svm' in 'svm@0'"):
        tool.refit_isolation(diag, signatures, "svm@0")

"""The refit of ``benchmarks/isolation_classifiers.py``: the isolation as the fit fits it."""

from __future__ import annotations

import numpy as np
import pytest
from benchmark_scripts import load_benchmark
from small_online import small_calibrated_diagnoser, small_runs

from bayes_fdi.diagnosis.isolation import ForestClassifier
from bayes_fdi.diagnosis.online.training import detection_components, training_signatures

tool = load_benchmark("isolation_classifiers")


@pytest.fixture(scope="module")
def fitted():
    runs = small_runs()
    diag = small_calibrated_diagnoser(runs)
    # signatures the stream gives on the calibration runs: rows to compare the isolations on
    rows = training_signatures(detection_components(diag), runs.calibration, per_second=True)[0]
    return diag, (runs.faults, runs.validation, runs.calibration), rows[:50], runs.calibration


def test_the_tree_at_the_fits_seed_is_the_fits_own_isolation(fitted):
    diag, fault_runs, rows, calibration = fitted
    again = tool.refit_isolation(diag, fault_runs, "tree@0")
    assert again is not diag and again.isolator_ is not diag.isolator_
    assert again.groups_ == diag.groups_ and again.undetectable_ == diag.undetectable_
    assert again.isolator_.temperature() == diag.isolator_.temperature()
    # the same decisions of every RVC; their weights may differ in the last bits between two
    # fits (the BLAS's rounding can follow the arrays' memory alignment), not more
    want = diag.isolator_.run(rows).group_proba
    np.testing.assert_allclose(again.isolator_.run(rows).group_proba, want, rtol=1e-10, atol=0)
    # the detection is the model's own: the same stream but for the isolation
    runs = calibration[["CV", "P1", "P2", "T1", "X", "F"]]
    np.testing.assert_array_equal(again.run(runs)["DD"].values, diag.run(runs)["DD"].values)


def test_a_forest_variant_and_an_unknown_one(fitted):
    diag, fault_runs, rows, _ = fitted
    forest = tool.refit_isolation(diag, fault_runs, "forest@1")
    assert isinstance(forest.isolator_.classifier_, ForestClassifier)
    # a forest refitted at the same seed is the same forest, bit for bit
    twice = tool.refit_isolation(diag, fault_runs, "forest@1")
    np.testing.assert_array_equal(twice.isolator_.run(rows).group_proba,
                                  forest.isolator_.run(rows).group_proba)  # fmt: skip
    assert forest.isolator_.classifier_.random_state == 1
    assert not isinstance(diag.isolator_.classifier_, ForestClassifier)  # a copy was refitted
    # forest-t1: the same forest, its temperature never below 1 (it only softens)
    held = tool.refit_isolation(diag, fault_runs, "forest-t1@1")
    free = forest.isolator_.temperature()
    assert held.isolator_.temperature() == pytest.approx(max(1.0, free), rel=1e-6)
    with pytest.raises(SystemExit, match="unknown classifier 'svm' in 'svm@0'"):
        tool.refit_isolation(diag, fault_runs, "svm@0")

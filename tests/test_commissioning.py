"""Commissioning a valve on its healthy data (bayes_fdi.commissioning)."""

from __future__ import annotations

import numpy as np
import pytest

from bayes_fdi import model_files
from bayes_fdi.actuator import simulate
from bayes_fdi.actuator.excitation import level_loop_inputs
from bayes_fdi.commissioning import check_healthy, commission, operating_range
from bayes_fdi.commissioning.report import render_report
from bayes_fdi.diagnosis import DynamicNormalModels, OnlineDiagnoser


@pytest.fixture(scope="module")
def healthy():
    """A simulated valve in a level loop: 1500 s of healthy data."""
    return simulate(level_loop_inputs(1, 1500, seed=4), seed=4)


def _small_commissioning() -> dict:
    """Keywords of a quick commissioning: three faults, small libraries and normal models."""
    models = DynamicNormalModels(
        x_widths=(8.0,),
        f_widths=(0.1,),
        evidence_max_samples=200,
        max_train_samples=400,
        calibration_folds=2,
        random_state=0,
    )
    return dict(
        faults=("f1", "f18", "bias_X"),
        runs_per_fault=4,
        duration=400,
        sizes=(0.75,),
        evaluation_runs=1,
        normal_models=models,
        progress=False,
    )


@pytest.fixture(scope="module")
def commissioned(healthy):
    return commission(healthy, **_small_commissioning())


def test_bad_healthy_data_is_refused_naming_the_problem(healthy):
    stuck = healthy.copy()
    stuck["X"] = stuck["X"] * 0 + 0.6
    with pytest.raises(ValueError, match=r"X hardly moves .* stuck stem"):
        check_healthy(stuck)
    with pytest.raises(ValueError, match="only 600 complete seconds"):
        check_healthy(healthy.isel(time=slice(0, 600)))
    faulty = healthy.assign_coords(state=("run", ["f1"]))
    with pytest.raises(ValueError, match="must be fault-free"):
        check_healthy(faulty)


def test_operating_range_reports_percentiles(healthy):
    covered = operating_range(healthy)
    assert covered["seconds"] == 1500
    x = healthy["X"].values.ravel()
    assert covered["X"]["p50"] == pytest.approx(float(np.median(x)))
    assert covered["CV"]["p01"] <= covered["CV"]["p50"] <= covered["CV"]["p99"]


def test_commissioning_gives_a_diagnoser_of_this_valve_with_its_report(commissioned, healthy):
    diag, _, report = commissioned
    assert isinstance(diag, OnlineDiagnoser) and diag.commissioning_ is report
    faults = {f for g in diag.groups_ for f in g} | set(diag.undetectable_)
    assert faults == {"f1", "f18", "bias_X"}
    # the healthy data it was fitted on raise no alarm
    stream = diag.run(healthy[["CV", "P1", "P2", "T1", "X", "F"]])
    assert not stream["DD"].values.any()
    assert set(report) >= {"healthy", "twin", "library", "groups", "expected", "seconds"}
    assert {row["fault"] for row in report["expected"]} == {"f1", "f18", "bias_X"}
    f18 = next(r for r in report["expected"] if r["fault"] == "f18")
    assert f18["detected_share"] == 1.0  # a big bypass opening is seen at once
    assert report["twin"]["heldout"]["n_samples"] > 0
    names = [p["name"] for p in report["twin"]["parameters"]]
    assert "kv" in names
    # the normal models' training samples are reported (here a fixed subset of 400)
    sizes = {k: report["normal_models"][k] for k in ("rows", "available", "curve", "text")}
    assert sizes == {
        "rows": 400,
        "available": 1500,
        "curve": [],
        "text": "fitted on 400 of 1500 healthy samples (a fixed subset)",
    }
    assert "The normal models of X and F were fitted on 400 of 1500" in render_report(report)
    # the input envelope: the healthy data's range, widened by the sensors' noise alone
    levels = report["envelope"]["levels"]
    cv = healthy["CV"].values
    assert levels["CV"] == pytest.approx([np.nanmin(cv) - 0.02, np.nanmax(cv) + 0.02], rel=1e-12)
    np.testing.assert_array_equal(diag.envelope_.high_, [hi for _, hi in levels.values()])
    assert f"CV {levels['CV'][0]:.3f}-{levels['CV'][1]:.3f}" in render_report(report)
    older = {k: v for k, v in report.items() if k != "envelope"}
    assert "The input envelope" not in render_report(older)


def test_the_commissioning_report_travels_with_the_model_file(commissioned, tmp_path):
    diag = commissioned.diagnoser
    diag.save(tmp_path / "plant.npz")
    back = OnlineDiagnoser.load(tmp_path / "plant.npz")
    assert back.commissioning_ == diag.commissioning_
    assert model_files.read_metadata(tmp_path / "plant.npz")["root_class"] == "OnlineDiagnoser"


def test_commissioned_diagnosers_detect_with_the_two_speed_cusum(commissioned, tmp_path):
    from bayes_fdi.diagnosis.detection import TwoSpeedCUSUM

    diag, _, report = commissioned
    assert isinstance(diag.detector_, TwoSpeedCUSUM)
    assert report["detection"]["detector"] == "TwoSpeedCUSUM"
    assert report["detection"]["k_slow"] == diag.detector_.k_slow == 0.1
    diag.save(tmp_path / "plant.npz")
    back = OnlineDiagnoser.load(tmp_path / "plant.npz")
    assert repr(back.detector_) == repr(diag.detector_)


def test_the_report_says_what_the_undetectable_rule_measured(commissioned, healthy):
    from bayes_fdi.commissioning import DETECT_RATE
    from bayes_fdi.commissioning.report import render_report

    diag, _, report = commissioned
    # the rule, recorded: a fault detected in fewer than half of its training transplants (or
    # with fewer than 5 signatures) is not classified
    assert report["detect_rate"] == diag.detect_rate == DETECT_RATE == 0.5
    for fault, rate in report["detection_rates"].items():
        if rate < DETECT_RATE:
            assert fault in report["undetectable"]
    classified = {f for g in diag.groups_ for f in g}
    assert all(report["detection_rates"][f] >= DETECT_RATE for f in classified)
    report = dict(report, undetectable=["bias_X"])
    report["detection_rates"] = dict(report["detection_rates"], bias_X=0.25)
    text = render_report(report)
    assert "fewer than half of their training transplants" in text
    assert "bias_X (1 of 4)" in text  # 4 training runs per fault in this commissioning
    # reports written before the rate was recorded had the same half
    older = {k: v for k, v in report.items() if k != "detect_rate"}
    assert render_report(older) == text
    assert "fewer than 25% of their" in render_report(dict(report, detect_rate=0.25))
    assert "fewer than 30% of their" in render_report(dict(report, detect_rate=0.3))
    # a bad rate is refused before anything is fitted
    for rate, match in [(-0.1, "is out of range"), (1.5, "is out of range"),
                        (float("nan"), "is out of range"), (True, "must be a real number"),
                        ("0.3", "must be a real number")]:  # fmt: skip
        with pytest.raises(ValueError, match=f"detect_rate {match}"):
            commission(healthy, detect_rate=rate, progress=False)


def test_a_lower_detect_rate_classifies_more_of_the_same_faults(commissioned, healthy):
    # the same seed draws the same libraries and fits the same detection, so the detection
    # rates are the same; at rate 0 only the signature count (at least 5) can leave a fault
    # unclassified, so its undetectable faults are among those of the rate 0.5
    diag, _, report = commission(healthy, **_small_commissioning(), detect_rate=0.0)
    assert report["detect_rate"] == diag.detect_rate == 0.0
    assert report["detection_rates"] == commissioned.report["detection_rates"]
    assert set(report["undetectable"]) <= set(commissioned.report["undetectable"])
    assert {f for g in diag.groups_ for f in g} | set(report["undetectable"]) == {
        "f1", "f18", "bias_X"
    }  # fmt: skip


def test_the_report_separates_its_paragraphs_by_one_blank_line(commissioned):
    text = render_report(commissioned.report)
    assert "\n\n\n" not in text
    # the healthy data's table, one blank line, the normal models, one blank line, the twin
    assert "| F |" in text and "\n\nThe normal models of X and F were" in text
    older = {k: v for k, v in commissioned.report.items() if k != "normal_models"}
    assert "\n\n\n" not in render_report(older)


def test_the_report_gives_the_normal_models_predictive_stds(commissioned, healthy):
    from bayes_fdi.commissioning.report import STD_FACTOR_WARNING

    diag, _, report = commissioned
    models = diag.normal_models_
    got = report["normal_models"]
    # the median over the healthy data of the models' own predictions, and their cross-fit
    predicted = models.predict(healthy)
    for c in ("X", "F"):
        assert got["median_std"][c] == float(np.nanmedian(predicted[f"{c}_hat_std"].values))
        assert got["std_factor"][c] == models.std_scale_all_[c]
    text = render_report(report)
    x, f = got["median_std"]["X"], got["median_std"]["F"]
    assert f"predictive standard deviations are {x:.4f} (X) and {f:.4f} (F) of full scale" in text
    fx, ff = got["std_factor"]["X"], got["std_factor"]["F"]
    assert f"widened {fx:.2f} and {ff:.2f} times" in text
    assert ("**Wide intervals.**" in text) is (max(fx, ff) > STD_FACTOR_WARNING)
    # a cross-fit that needed wide intervals for F is said in words, naming the factor
    wide = dict(got, std_factor={"X": 1.2, "F": 8.16})
    text = render_report(dict(report, normal_models=wide))
    assert "much worse than the models' posteriors allow for F (8.2 times)" in text
    assert "X (1.2 times)" not in text
    at = dict(got, std_factor={"X": STD_FACTOR_WARNING, "F": 1.0})
    assert "**Wide intervals.**" not in render_report(dict(report, normal_models=at))
    # reports written before the deviations were recorded render without them
    old = {k: v for k, v in got.items() if k not in ("median_std", "std_factor")}
    text = render_report(dict(report, normal_models=old))
    assert f"The normal models of X and F were {got['text']}." in text
    assert "predictive standard deviations" not in text


@pytest.mark.parametrize(("pareto_k", "warned"), [(1.05, True), (0.7, False), (0.3, False)])
def test_the_report_says_when_the_laplace_check_failed(commissioned, pareto_k, warned):
    # Vehtari et al.'s rule: above k = 0.7 the Gaussian is not a usable proposal, and the report
    # must say so in words rather than leave the reader to compare k with the threshold
    report = dict(commissioned.report, twin=dict(commissioned.report["twin"], pareto_k=pareto_k))
    text = render_report(report)
    assert f"k = {pareto_k:.2f}; up to 0.7 the approximation is reliable" in text
    assert ("**The check failed here (k = 1.05 > 0.7):**" in text) is warned
    assert ("as indicative only" in text) is warned


def test_the_group_probabilities_are_softened_never_sharpened(commissioned, healthy):
    diag, _, report = commissioned
    scaler = diag.isolator_.calibrator_
    assert report["calibration"] == {
        "temperature": scaler.temperature_,
        "bounds": [1.0, 50.0],
        "at_bound": scaler.at_bound_,
    }
    assert scaler.bounds == (1.0, 50.0) and scaler.temperature_ >= 1.0
    text = render_report(report)
    assert f"with temperature {scaler.temperature_:.3g} (bounds 1 to 50" in text
    # a fit that stopped at the lower bound says why the probabilities were left as they are
    at_one = dict(report, calibration={"temperature": 1.0, "bounds": [1.0, 50.0], "at_bound": True})
    assert "stopped at its lower bound" in render_report(at_one)
    assert "stopped at its lower bound" not in text or scaler.at_bound_
    # reports written before the calibration was recorded render without the line
    older = {k: v for k, v in report.items() if k != "calibration"}
    assert "calibrated on held-out transplants with temperature" not in render_report(older)
    # bad bounds are refused before anything is fitted
    for bounds in [(2.0, 1.0), (0.0, 50.0), (1.0, float("inf"))]:
        with pytest.raises(ValueError, match="temperature_bounds must satisfy"):
            commission(healthy, temperature_bounds=bounds, progress=False)


def test_commissioned_groups_come_from_the_one_way_confusion_of_detected_seconds(
    commissioned, healthy
):
    # the second library (seed 10 seed + 2), diagnosed second by second: its detected seconds
    # at least GROUP_MIN_AGE after their detection, named by the classifier, give the groups
    from bayes_fdi.diagnosis.isolation.isolator import isolability_groups, naming_confusion
    from bayes_fdi.diagnosis.online.training import (
        GROUP_MIN_AGE,
        detection_components,
        training_signatures,
    )
    from bayes_fdi.twin import transplant_library

    diag, twin, report = commissioned
    assert report["group_rule"] == "naming" and diag.isolator_.group_rule == "naming"
    assert "named as the other in at least 15% of its detected seconds" in render_report(report)
    library = transplant_library(
        healthy, twin, faults=("f1", "f18", "bias_X"), runs_per_fault=4, duration=400, seed=2
    )
    rows, labels, ages, _ = training_signatures(
        detection_components(diag), library, per_second=True
    )
    iso = diag.isolator_
    keep = np.isin(labels, iso.faults_) & (ages >= GROUP_MIN_AGE)
    named = iso.faults_[np.argmax(iso.fault_proba(rows[keep]), axis=1)]
    faults = [f for f in ("bias_X", "f1", "f18") if f in iso.faults_]  # the natural order
    confusion = naming_confusion(labels[keep], named, faults)
    groups = isolability_groups(faults, confusion, threshold=diag.group_threshold)
    assert [list(g) for g in diag.groups_] == groups


def test_a_forest_can_name_the_faults_and_travels_with_the_model_file(healthy, tmp_path):
    from bayes_fdi.commissioning.report import render_report
    from bayes_fdi.diagnosis.isolation import ForestClassifier

    options = _small_commissioning()
    with pytest.raises(ValueError, match="isolation must be one of tree, forest"):
        commission(healthy, isolation="svm", **options)
    diag, _, report = commission(healthy, isolation="forest", **options)
    assert isinstance(diag.isolator_.classifier_, ForestClassifier)
    assert report["isolation_classifier"] == "forest"
    assert report["calibration"]["temperature"] >= 1.0  # a forest's shares are never sharpened
    assert "random forest" in render_report(report)
    f18 = next(r for r in report["expected"] if r["fault"] == "f18")
    assert f18["detected_share"] == 1.0 and f18["named_share"] > 0.5
    # the model file holds the forest as arrays; the reloaded model gives the same stream
    diag.save(tmp_path / "forest.npz")
    back = OnlineDiagnoser.load(tmp_path / "forest.npz")
    bypass = healthy.copy()
    bypass["F"] = bypass["F"] + 0.1 * (bypass["time"] >= 900)
    channels = ["CV", "P1", "P2", "T1", "X", "F"]
    a, b = diag.run(bypass[channels]), back.run(bypass[channels])
    assert a["DD"].values[0, 900:].any()
    np.testing.assert_array_equal(a["group_proba"].values, b["group_proba"].values)
    np.testing.assert_array_equal(a["state"].values, b["state"].values)

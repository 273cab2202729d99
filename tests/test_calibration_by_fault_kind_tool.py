"""``benchmarks/calibration_by_fault_kind.py``: the benchmark's calibration sample, split."""

from __future__ import annotations

import json

import numpy as np
import pytest
from benchmark_scripts import load_benchmark
from small_online import small_calibrated_diagnoser, small_runs

from bayes_fdi.benchmark.harness import run_benchmark
from bayes_fdi.benchmark.scenarios import SCENARIOS, benchmark_seeds

tool = load_benchmark("calibration_by_fault_kind")


@pytest.fixture(scope="module")
def case():
    diag = small_calibrated_diagnoser(small_runs())
    by_name = {s.name: s for s in SCENARIOS}
    # the small model's faults (f1, f7, f18), abrupt and incipient, cut short
    names = ("f18 abrupt big", "f7 abrupt big", "f18 incipient")
    scenarios = [by_name[n].truncated(1500.0) for n in names]
    return diag, scenarios


def test_the_pooled_sample_is_the_benchmarks_own(case, tmp_path):
    """The split's "all" sample is the one `run_benchmark` scores: same seconds, same ECE."""
    diag, scenarios = case
    seeds = benchmark_seeds(1)
    collectors, per_run = tool.collect(diag, scenarios, seeds)
    run_benchmark(
        diag, tmp_path, n_seeds=1, scenarios=scenarios, hours=0.05, real_hour=False,
        figures=False, n_bootstrap=0, progress=False,
    )  # fmt: skip
    results = json.loads((tmp_path / "benchmark.json").read_text())
    want = results["calibration"]
    got = tool._summary(collectors["all"], 0)
    assert got["n_seconds"] == want["n_seconds"] > 0
    assert got["ece"] == pytest.approx(want["ece"], abs=1e-12)
    assert got["accuracy"] == pytest.approx(want["accuracy"], abs=1e-12)
    # the two kinds partition the pooled sample, in the scenarios' order
    split = collectors["abrupt"].proba + collectors["incipient"].proba
    assert sum(p.shape[0] for p in split) == got["n_seconds"]
    abrupt = np.concatenate(collectors["abrupt"].proba)
    np.testing.assert_array_equal(np.concatenate(collectors["all"].proba)[: len(abrupt)], abrupt)
    # one row per run with seconds; its accuracy is that of its own seconds
    assert len(per_run) == len(collectors["all"].proba)
    for row, proba, true in zip(
        per_run, collectors["all"].proba, collectors["all"].true, strict=True
    ):
        assert row["seconds"] == proba.shape[0]
        assert row["accuracy"] == pytest.approx(np.mean(proba.argmax(axis=1) == true))
    # the confident wrong count is the benchmark's, and its scenarios add up to it
    cw = tool.confident_wrong_summary(collectors["all"])
    assert cw["seconds"] == results["confident_wrong"]["seconds"]
    assert cw["faulty_seconds"] == results["confident_wrong"]["faulty_seconds"] > 0
    assert sum(cw["scenarios"].values()) == cw["seconds"]
    by_hand = sum(r["confident_wrong_seconds"] for r in collectors["all"].rows)
    assert cw["seconds"] == by_hand
    # the age bins partition the sample: their seconds add up, their accuracies average to it
    bins = tool.by_age(collectors["all"])
    assert sum(b["seconds"] for b in bins) == got["n_seconds"]
    pooled = sum(b["seconds"] * b["accuracy"] for b in bins) / got["n_seconds"]
    assert pooled == pytest.approx(got["accuracy"], abs=1e-12)
    ages = np.concatenate(collectors["all"].age)
    assert ages.size == got["n_seconds"] and np.isfinite(ages).all() and ages.min() >= 0


def test_the_signature_age_counts_from_the_last_rising_edge_by_hand():
    from bayes_fdi.benchmark.collection import seconds_since_detection

    t = np.arange(10.0, 20.0)
    dd = np.array([1, 1, 0, 0, 1, 1, 1, 0, 1, 1], dtype=bool)
    want = [0, 1, np.nan, np.nan, 0, 1, 2, np.nan, 0, 1]
    np.testing.assert_array_equal(seconds_since_detection(t, dd), want)
    assert np.isnan(seconds_since_detection(t, np.zeros(10, bool))).all()
    # irregular time: the age is in seconds, not samples
    np.testing.assert_array_equal(
        seconds_since_detection(np.array([0.0, 2.0, 5.0]), np.ones(3, bool)), [0, 2, 5]
    )


def test_the_age_table_by_hand():
    """Two bins by hand: ages 5 and 8 (one right, one wrong) and 40 (right)."""
    from types import SimpleNamespace

    proba = np.array([[0.8, 0.2], [0.6, 0.4], [0.3, 0.7]])
    collector = SimpleNamespace(
        proba=[proba], true=[np.array([0, 1, 1])], age=[np.array([5.0, 8.0, 40.0])]
    )
    bins = tool.by_age(collector, edges=(0.0, 10.0, 30.0, 100.0))
    assert bins == [
        {"low": 0.0, "high": 10.0, "seconds": 2, "accuracy": 0.5, "mean_confidence": 0.7},
        {"low": 30.0, "high": 100.0, "seconds": 1, "accuracy": 1.0, "mean_confidence": 0.7},
    ]
    assert tool.by_age(SimpleNamespace(proba=[], true=[], age=[])) == []


def test_confident_wrong_seconds_are_summed_per_scenario_by_hand():
    """The scenarios' counts add the runs of one scenario, most first, scenarios without any
    left out; the totals are the collector's."""
    from types import SimpleNamespace

    def row(fault, mode, size, seconds):
        return {"fault": fault, "mode": mode, "size": size, "confident_wrong_seconds": seconds}

    collector = SimpleNamespace(
        rows=[
            row("f4", "incipient", None, 30),
            row("f13", "abrupt", "small", 40),
            row("f4", "incipient", None, 25),
            row("f1", "abrupt", "big", 0),
        ],
        confident_wrong=95,
        faulty_seconds=2000,
    )
    cw = tool.confident_wrong_summary(collector)
    assert cw["scenarios"] == {"f4 incipient": 55, "f13 abrupt small": 40}
    assert list(cw["scenarios"]) == ["f4 incipient", "f13 abrupt small"]
    assert (cw["seconds"], cw["faulty_seconds"]) == (95, 2000)
    assert cw["share"] == pytest.approx(95 / 2000)


def test_the_detection_summary_by_hand():
    """Big abrupt scenarios detected in every seed, kept on, first-detection medians; r_fd over
    every run."""
    from types import SimpleNamespace

    def row(fault, mode, size, first, kept, r_fd):
        return {"fault": fault, "mode": mode, "size": size, "indices": {"r_fd": r_fd},
                "first_detection": {"t_dt_first": first, "dd_permanent": kept}}  # fmt: skip

    collector = SimpleNamespace(
        rows=[
            row("f1", "abrupt", "big", 1.0, True, 0.0),
            row("f1", "abrupt", "big", 3.0, False, 0.0),
            row("f12", "abrupt", "big", -1.0, False, 0.02),
            row("f12", "abrupt", "big", 40.0, True, 0.0),
            row("f4", "incipient", None, 900.0, True, 0.5),
        ]
    )
    det = tool.detection_summary(collector)
    assert det["big_abrupt"]["f1 abrupt big"] == {
        "seeds": 2, "detected": 2, "kept": 1, "t_dt_first_median": 2.0
    }  # fmt: skip
    assert det["big_abrupt"]["f12 abrupt big"]["t_dt_first_median"] == 40.0
    assert (det["detected_every_seed"], det["detected_runs"], det["kept"]) == (1, 3, 2)
    assert det["median_r_fd"] == 0.0 and det["runs_r_fd_above"] == 2


def test_fault_free_alarms_are_the_rising_edges_of_the_streams_dd():
    """Counted on a faulty run, so that there are edges to count."""
    diag = small_calibrated_diagnoser(small_runs())
    runs = small_runs().faults.isel(run=[0])
    stream = diag.run(runs).isel(run=0)
    dd = stream["DD"].values.astype(bool)
    t = stream["time"].values
    got = tool.fault_free_alarms(diag, runs, warmup=10.0)
    counted = np.flatnonzero(t >= 10.0)  # an alarm on at the first counted second counts one
    edges = [i for i in counted if dd[i] and (i == counted[0] or not dd[i - 1])]
    assert got["alarms"] == len(edges) >= 1
    assert got["dd_on"] == pytest.approx(dd[t >= 10.0].mean())


def test_an_alarm_on_when_the_warmup_ends_counts_one():
    """The benchmarks' count: the rising edges of DD after the warm-up, an alarm still on at
    its end counting one (`alarms_after`, which `fault_free_alarms` applies to a stream)."""
    t = np.arange(8.0)
    dd = np.array([0, 1, 1, 1, 1, 0, 1, 0], dtype=bool)
    # after the warm-up (t >= 3): [1, 1, 0, 1, 0] -> on at its start (1) and one edge (1)
    got = tool.alarms_after(t, dd, warmup=3.0)
    assert got == {"alarms": 2, "dd_on": pytest.approx(3 / 5)}
    # a DD off at the end of the warm-up: only the edges after it
    assert tool.alarms_after(t, dd, warmup=5.0) == {"alarms": 1, "dd_on": pytest.approx(1 / 3)}
    # NaN (no decision) is off, as the benchmarks read it
    nan_dd = np.array([np.nan, 1.0, np.nan, 1.0])
    assert tool.alarms_after(np.arange(4.0), nan_dd, warmup=0.0)["alarms"] == 2

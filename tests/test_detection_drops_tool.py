"""``benchmarks/detection_drops.py``: where DD falls during a fault, and what the fault showed."""

from __future__ import annotations

import numpy as np
from benchmark_scripts import load_benchmark

tool = load_benchmark("detection_drops")


def test_quiet_before_counts_the_seconds_since_the_last_one_at_or_above_the_level():
    effect = np.array([5.0, 0.2, 3.0, 0.5, 0.5, 0.9, 2.0])
    assert tool.quiet_before(effect, 6, 1.0) == 3  # seconds 3, 4, 5
    assert tool.quiet_before(effect, 6, 3.0) == 3  # 3.0 itself is not below 3
    assert tool.quiet_before(effect, 2, 1.0) == 1
    assert tool.quiet_before(effect, 2, 10.0) == 2  # never reached: all seconds before
    assert tool.quiet_before(effect, 0, 1.0) == 0


def test_falls_are_the_falling_edges_after_the_first_detection_in_the_faulty_part():
    dd = np.array([1, 1, 0, 0, 1, 1, 0, 1, 0, 1], dtype=bool)
    # an alarm before the fault (index < 3) and its fall at 2 do not count
    np.testing.assert_array_equal(tool.falls(dd, 3), [6, 8])
    np.testing.assert_array_equal(tool.falls(dd, 0), [2, 6, 8])
    assert tool.falls(np.zeros(5, dtype=bool), 0).size == 0
    # on to the end: no fall
    assert tool.falls(np.array([0, 0, 1, 1, 1], dtype=bool), 1).size == 0


def test_a_run_whose_fault_stopped_showing_for_longer_than_the_hold():
    t_from, hold = 10, 5
    n = 40
    dd = np.zeros(n, dtype=bool)
    dd[12:30] = True  # detected 2 s after the fault, falls at 30
    effect = np.zeros(n)
    effect[10:20] = 8.0  # the fault shows for 10 s, then nothing until 35
    effect[35:] = 4.0
    res = tool.analyse_run(dd, effect, t_from, hold)
    assert res["first_detection"] == 2 and not res["kept_on"]
    (fall,) = res["falls"]
    assert fall["fall"] == 20
    assert fall["quiet_1sigma"] == fall["quiet_3sigma"] == 10  # seconds 20..29
    assert fall["longer_than_hold"]
    assert fall["effect_above_3sigma_after"] == 5 / 10  # seconds 30..39: 35..39 above
    # kept on to the end: no fall; never detected in the faulty part: None
    dd_on = np.zeros(n, dtype=bool)
    dd_on[11:] = True
    assert tool.analyse_run(dd_on, effect, t_from, hold) == {
        "first_detection": 1,
        "kept_on": True,
        "falls": [],
    }
    early = np.zeros(n, dtype=bool)
    early[:5] = True
    assert tool.analyse_run(early, effect, t_from, hold) is None


def test_kept_on_is_the_benchmarks_own_reading(tmp_path):
    """`measure` streams the runs the nominal benchmark streams: the same runs detected and kept
    on as `run_benchmark`'s ``dd_permanent``."""
    import json

    from small_online import small_normal_models, small_runs

    from bayes_fdi.benchmark.harness import run_benchmark
    from bayes_fdi.benchmark.scenarios import SCENARIOS, benchmark_seeds
    from bayes_fdi.diagnosis import OnlineDiagnoser

    runs = small_runs()
    diag = OnlineDiagnoser(small_normal_models(), max_signatures_per_fault=20, random_state=0)
    diag.fit(runs.normal, runs.faults, validation_runs=runs.validation)
    by_name = {s.name: s for s in SCENARIOS}
    scenarios = [by_name[n].truncated(1300.0) for n in ("f18 abrupt big", "f7 abrupt big")]
    seeds = benchmark_seeds(2)
    rows = tool.measure(diag, "nominal", scenarios, seeds)
    run_benchmark(
        diag, tmp_path, n_seeds=2, scenarios=scenarios, hours=0.05, real_hour=False,
        figures=False, n_bootstrap=0, progress=False,
    )  # fmt: skip
    bench = json.loads((tmp_path / "benchmark.json").read_text())["scenarios"]
    want = {
        (f"{r['fault']} {r['mode']} {r['size']}", r["seed"]): r["first_detection"]
        for r in bench
        if r["first_detection"]["t_dt_first"] >= 0
    }
    got = {(r["scenario"], r["seed"]): r for r in rows}
    assert set(got) == set(want) and got
    for key, first in want.items():
        assert got[key]["kept_on"] == (first["dd_permanent"] == 1.0)
        assert got[key]["first_detection"] == first["t_dt_first"]
        assert got[key]["physical"]["first_detection"] == first["t_dt_first"]

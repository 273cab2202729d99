"""The benchmark's count of confidently wrong seconds, against a stream decided by hand.

The stream's answers come from the diagnoser's own decision rule (`decide`), fed per-second
quantities chosen so that each second exercises one case: not detected, right, wrong and
confident, wrong but not confident, wrong probabilities behind an "unknown" answer (a novel
signature) and behind a "mismatch" (a change that began outside the envelope), undefined.
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from bayes_fdi.benchmark.collection import CONFIDENT, confident_wrong
from bayes_fdi.benchmark.commissioning_summary import confident_wrong_share
from bayes_fdi.benchmark.report_wrong import (
    WRONG_SCENARIOS_SHOWN,
    calibration_lines,
    wrong_by_scenario,
)
from bayes_fdi.datasets import CHANNELS
from bayes_fdi.diagnosis.online.stream import decide

GROUPS = ("f1", "f6|f18")
NAN = np.nan
#: Per second: DD, group probabilities, novelty ratio, change began outside the envelope.
SECONDS = [
    (False, (NAN, NAN), 0.0, False),  # not detected
    (True, (0.95, 0.05), 0.0, False),  # right group, confident
    (True, (0.05, 0.95), 0.0, False),  # wrong group, confident: a wrong answer
    (True, (0.2, 0.8), 0.0, False),  # wrong group below CONFIDENT
    (True, (0.02, 0.98), 9.0, False),  # novel signature: answered "unknown"
    (True, (0.03, 0.97), 0.0, True),  # began outside the envelope: answered "mismatch"
    (True, (NAN, NAN), 0.0, False),  # no signature yet
]


def _stream() -> xr.Dataset:
    n = len(SECONDS)
    dd = np.array([s[0] for s in SECONDS])
    proba = np.array([s[1] for s in SECONDS], dtype=np.float64)
    out = {
        "DD": dd,
        "group_proba": proba,
        "novelty": np.array([s[2] for s in SECONDS]),
        "novel_inputs": np.zeros(n, dtype=bool),
        "novel_onset": np.array([s[3] for s in SECONDS]),
        "unproven_onset": np.zeros(n, dtype=bool),
        "stat_X": np.ones(n),
        "stat_F": np.zeros(n),
        "features": np.zeros((n, 2)),
        "r_X": np.ones(n),
        "r_F": np.zeros(n),
    }
    channels = {c: np.full(n, 0.5) for c in CHANNELS}
    d = decide(
        channels,
        out,
        threshold=1.0,
        group_labels=GROUPS,
        novelty_ratio=1.0,
        p_fault=0.5,
        coverage=0.95,
    )
    return xr.Dataset(
        {
            "group_proba": (("time", "group"), proba),
            "indicated": (("time", "group"), d["indicated"]),
            "probability": ("time", d["probability"]),
            "state": ("time", d["state"]),
        },
        coords={"time": np.arange(n, dtype=np.float64), "group": list(GROUPS)},
    )


def test_the_rule_answers_each_second_as_the_cases_intend():
    states = list(_stream()["state"].values)
    assert states == ["fn", "f1", "f6|f18", "f6|f18", "unknown", "mismatch", "unknown"]
    assert 0.8 < CONFIDENT < 0.95  # the confident and unconfident seconds straddle it


def test_answers_count_the_named_wrong_group_and_probabilities_every_confident_wrong_one():
    answers, probabilities = confident_wrong(_stream(), true_group=0)
    assert answers.tolist() == [False, False, True, False, False, False, False]
    assert probabilities.tolist() == [False, False, True, False, True, True, False]


def test_a_fault_in_no_group_makes_every_confident_answer_wrong():
    answers, probabilities = confident_wrong(_stream(), true_group=None)
    assert answers.tolist() == [False, True, True, False, False, False, False]
    assert probabilities.tolist() == [False, True, True, False, True, True, False]


def test_a_detection_only_stream_is_never_confidently_wrong():
    one = _stream().isel(group=slice(0, 0))
    answers, probabilities = confident_wrong(one, true_group=None)
    assert not answers.any() and not probabilities.any()
    assert answers.size == len(SECONDS)


def test_the_reports_give_the_probabilities_count_only_where_it_differs():
    rows = [
        {
            "confident_wrong_seconds": 1,
            "confident_wrong_probabilities_seconds": 3,
            "faulty_seconds": 6,
        },
        {
            "confident_wrong_seconds": 0,
            "confident_wrong_probabilities_seconds": 0,
            "faulty_seconds": 4,
        },
    ]
    share = confident_wrong_share(rows)
    assert share == {
        "seconds": 1,
        "faulty_seconds": 10,
        "share": 0.1,
        "probabilities_seconds": 3,
        "probabilities_share": 0.3,
    }
    from bayes_fdi.benchmark.commissioning_summary import _wrong_text

    assert _wrong_text(share) == (
        "10.00%; counting the seconds answered unknown or mismatch by their most probable "
        "group, 30.00 %"
    )
    assert _wrong_text({**share, "probabilities_seconds": 1}) == "10.00%"
    cal = {
        "n_seconds": 10,
        "n_runs": 2,
        "ece": 0.1,
        "ci_low": 0.05,
        "ci_high": 0.15,
        "noise_floor": 0.01,
        "mce": 0.2,
        "accuracy": 0.8,
        "mean_confidence": 0.7,
        "n_bootstrap": 20,
    }
    differs = " ".join(
        calibration_lines({"calibration": cal, "confident_wrong": share, "scenarios": []})
    )
    assert "wrong group: 10.00 % of all faulty seconds; counting" in differs
    assert "unknown or mismatch by their most probable group, 30.00 %." in differs
    same = {**share, "probabilities_seconds": 1, "probabilities_share": 0.1}
    text = " ".join(
        calibration_lines({"calibration": cal, "confident_wrong": same, "scenarios": []})
    )
    assert "wrong group: 10.00 % of all faulty seconds." in text and "counting" not in text
    old = {k: share[k] for k in ("seconds", "faulty_seconds", "share")}  # an older results file
    text = " ".join(
        calibration_lines({"calibration": cal, "confident_wrong": old, "scenarios": []})
    )
    assert "wrong group: 10.00 % of all faulty seconds." in text


def _row(fault, mode, size, seconds, named):
    return {
        "fault": fault,
        "mode": mode,
        "size": size,
        "confident_wrong_seconds": seconds,
        "confident_wrong_named": named,
    }


def test_the_report_says_in_which_scenarios_the_confident_wrong_seconds_lie():
    f18_1 = _row("f18", "incipient", None, 600, {"f13": 600})  # seed 1
    f18_2 = _row("f18", "incipient", None, 300, {"f13": 200, "f10|f16": 100})  # seed 2
    f2 = _row("f2", "incipient", None, 50, {"f11|f15": 50})
    f1 = _row("f1", "abrupt", "big", 40, {"f10|f16": 40})
    f7 = _row("f7", "abrupt", "big", 10, {"f13": 10})
    f9 = _row("f9", "incipient", None, 1, {"f13": 1})
    f4 = _row("f4", "abrupt", "big", 0, {})
    assert WRONG_SCENARIOS_SHOWN == 3  # f7 and f9 are left out of the first sentence
    assert wrong_by_scenario([f18_1, f18_2, f2, f1, f7, f9, f4]) == (  # 1001 s in all
        " Where they lie, most first: f18 incipient 90 % (named f13 800 s, f10|f16 100 s); "
        "f2 incipient 5 % (named f11|f15 50 s); f1 abrupt big 4 % (named f10|f16 40 s)."
    )
    assert wrong_by_scenario([f9, f7]) == (
        " Where they lie, most first: f7 abrupt big 91 % (named f13 10 s); "
        "f9 incipient 9 % (named f13 1 s)."
    )
    assert wrong_by_scenario([f18_1, f9]).endswith("; f9 incipient under 1 % (named f13 1 s).")
    assert wrong_by_scenario([f4]) == ""  # no confident wrong second
    old = [{k: v for k, v in r.items() if not k.startswith("confident")} for r in (f18_1, f2)]
    assert wrong_by_scenario(old) == ""  # results written before the per-run counts

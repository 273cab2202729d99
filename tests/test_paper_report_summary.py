"""The opening of the reproduction's report: its summary is the results' figures, its glossary
defines the indices the tables print, every state code it uses is named."""

from __future__ import annotations

from bayes_fdi.actuator import FAULT_TABLE
from bayes_fdi.paper.report_summary import (
    GLOSSARY,
    fault_codes_section,
    summary_section,
)


def _results() -> dict:
    method = {
        "accuracy": 0.85,
        "confusion": {"classes": ["f1", "f17", "fn"], "matrix": [[9, 1, 0], [3, 7, 0], [0, 0, 10]]},
    }
    dataset = {
        "rvm": method,
        "svm": {**method, "accuracy": 0.8},
        "paired": {"a_only": 4, "b_only": 2, "p_value": 0.6875},
        "all_states": {"states": ["fn", "f1", "f17", "f2"], "groups": [["fn"], ["f1", "f17"]]},
        "dynamic": {"rvm": {"accuracy": 0.9}, "svm": {"accuracy": 0.875}},
    }
    return {"small": True, "datasets": {"paper-simulated": dataset}}


def test_the_summary_states_the_results_figures():
    lines = summary_section(_results())
    (line,) = [x for x in lines if x.startswith("- **paper-simulated**")]
    # 30 test runs (the confusion's sum); the paper's ratios are its Table 2 / 4 figures
    assert (
        "of 30 test runs, the RVM tree names the state of 85.00% right (the paper: 99.60%)" in line
    )
    assert "the SVM tree 80.00% (the paper: 98.53%)" in line
    assert "differ on 6 of the same runs (McNemar p = 0.69)" in line
    # misread runs: f1 -> f17 (1), f17 -> f1 (3); both inside the group f1|f17
    assert "4 of the RVM's 4 misread runs went to a state of their own group" in line
    assert "(over all 4 states: f1|f17)" in line
    # the largest off-diagonal count: 3 runs of f17 read as f1, of 10
    assert "f17 read as f1 in 3 of 10 runs" in line
    assert "the RVM tree names 90.00%, the SVM tree 87.50%" in line
    assert any("one test run is 3.33% of a ratio" in x for x in lines)  # 1 / 30


def test_a_confusion_outside_the_groups_is_not_blamed_on_them():
    results = _results()
    results["datasets"]["paper-simulated"]["all_states"]["groups"] = [["fn", "f17"], ["f1"]]
    (line,) = [x for x in summary_section(results) if x.startswith("- **paper-simulated**")]
    assert "0 of the RVM's 4 misread runs went to a state of their own group" in line


def test_every_state_code_is_named_and_the_indices_defined():
    # codes in any order, repeated, in tables and words; f18x and xf1 are not codes
    text = "| f17 | fn |\nf2|f17 read as f1; f1 again, f18x xf1"
    lines = fault_codes_section(text)
    assert lines[2:] == [
        "- fn fault-free",
        f"- f1 {FAULT_TABLE['f1'].description}",
        f"- f2 {FAULT_TABLE['f2'].description}",
        f"- f17 {FAULT_TABLE['f17'].description}",
        "",
    ]
    for index in ("identification ratio", "log loss", "Brier score", "ECE", "McNemar p"):
        assert index in GLOSSARY

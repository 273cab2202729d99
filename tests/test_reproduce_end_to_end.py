"""``bayes-fdi reproduce`` end to end on a small simulated campaign (simulator + RVMs)."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from tiny_campaign import CAMPAIGN, STATES

from bayes_fdi.actuator import FAULT_TABLE
from bayes_fdi.cli import main
from bayes_fdi.paper.report_tables import confusion_table


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    from bayes_fdi.paper.reproduce import reproduce

    tmp = tmp_path_factory.mktemp("reproduce")
    toml = tmp / "tiny.toml"
    toml.write_text(CAMPAIGN.format(states=json.dumps(STATES)))
    kwargs = dict(seed=3, cache_dir=tmp / "cache", states=STATES, progress=False)
    first = reproduce(tmp / "out1", datasets=[toml], **kwargs)
    return tmp, toml, first, kwargs


def test_outputs_written_and_consistent(run):
    tmp, _, results, _ = run
    out = tmp / "out1"
    on_disk = json.loads((out / "results.json").read_text())
    assert on_disk == results  # the returned dict is exactly what was written
    d = results["datasets"]["tiny"]
    for method in ("rvm", "svm"):
        m = d[method]
        cm = np.array(m["confusion"]["matrix"])
        assert m["confusion"]["classes"] == ["f1", "f2", "f17", "f18", "fn"]
        assert cm.sum() == 5 * 4  # 4 test runs per state (24 - 20)
        assert m["accuracy"] == pytest.approx(np.trace(cm) / cm.sum())
        assert len(m["nodes"]) == 4  # binary tree over 5 classes
        assert m["nodes"][0]["samples"] == 100  # root: 20 training runs x 5 states
        for node in m["nodes"]:
            assert 0 < node["vectors"] <= node["samples"]
        assert 0.0 <= m["ece"] <= 1.0 and 0.0 <= m["brier"] <= 2.0 and m["log_loss"] >= 0.0
        assert m["fit_seconds"] > 0 and m["predict_seconds"] > 0
    # faults with large flow effects are told from the fault-free state
    assert d["rvm"]["accuracy"] >= 0.8
    assert d["split"]["normal_model_runs"] == 20
    assert {s: v["runs"] for s, v in d["strength"].items()} == {s: 24 for s in STATES}
    assert all(
        0.5 <= abs(v["min"]) <= abs(v["max"]) <= 1.0 for s, v in d["strength"].items() if s != "fn"
    )
    report = (out / "report.md").read_text()
    assert (
        confusion_table(d["rvm"]["confusion"]["matrix"], d["rvm"]["confusion"]["classes"]) in report
    )
    for fig in results["figures"]["tiny"].values():
        assert (out / fig).stat().st_size > 1000
        assert f"]({fig})" in report


def test_calibration_headlines_match_the_full_report(run):
    tmp, _, results, _ = run
    out = tmp / "out1"
    cal = results["datasets"]["tiny"]["calibration"]
    full = json.loads((out / "tiny-calibration" / "calibration.json").read_text())
    assert (out / cal["report"]).is_file()
    for when in ("before", "after"):
        # the headlines are copied from the full report's numbers: identical by construction
        mine, theirs = cal[when], full["whole_tree"][when]
        assert mine["ece"]["value"] == theirs["ece"]["value"]
        assert mine["accuracy"] == theirs["accuracy"] and mine["log_loss"] == theirs["log_loss"]
        assert 0.0 <= mine["ece"]["value"] <= 1.0
    # before recalibration the numbers are the main table's (same runs, same bins), computed
    # again from the diagnoser's own predictions: equal up to rounding (about 1e-15 relative),
    # inside pytest.approx's default 1e-6 relative
    rvm = results["datasets"]["tiny"]["rvm"]
    assert cal["before"]["accuracy"] == pytest.approx(rvm["accuracy"])
    assert cal["before"]["ece"]["value"] == pytest.approx(rvm["ece"])
    for name in ("X", "F"):
        c95 = cal["coverage"][name]["95%"]
        assert c95 == full["normal_models"][name]["coverage"]["95%"]
        assert 0.5 <= c95["coverage"] <= 1.0 and c95["mean_width"] > 0
    assert "real_record_coverage" not in cal  # simulated inputs: no real record to split
    report = (out / "report.md").read_text()
    assert "## Calibration of the RVM pipeline" in report and f"]({cal['report']})" in report


def test_dynamic_normal_models_beyond_the_paper(run):
    tmp, _, results, _ = run
    d = results["datasets"]["tiny"]
    dyn = d["dynamic"]
    assert results["dynamic_lags"] == [1.0, 2.0]
    assert dyn["normal_models"]["input_lags"] == [1.0, 2.0]
    assert d["normal_models"]["input_lags"] == []  # the paper's static models stay the main result
    for method in ("rvm", "svm"):
        m = dyn[method]
        cm = np.array(m["confusion"]["matrix"])
        assert cm.sum() == 5 * 4 and m["accuracy"] == pytest.approx(np.trace(cm) / cm.sum())
    # the same test runs: the confusion rows hold the same number of runs per state
    assert np.array_equal(
        np.sum(dyn["rvm"]["confusion"]["matrix"], axis=1),
        np.sum(d["rvm"]["confusion"]["matrix"], axis=1),
    )
    cal = dyn["calibration"]
    assert (tmp / "out1" / cal["report"]).is_file() and cal["report"].startswith("tiny-dynamic")
    report = (tmp / "out1" / "report.md").read_text()
    assert "## Beyond the paper: dynamic normal models" in report
    assert f"]({cal['report']})" in report


def test_single_threaded_limits_and_restores():
    import torch
    from threadpoolctl import threadpool_info

    from bayes_fdi.paper.setup import single_threaded

    before = torch.get_num_threads()
    with single_threaded():
        assert torch.get_num_threads() == 1
        assert all(lib["num_threads"] == 1 for lib in threadpool_info())
    assert torch.get_num_threads() == before


def test_cli_same_seed_same_numbers_from_the_cache(tmp_path, capsys, run):
    tmp, toml, first, _ = run
    cached = list((tmp / "cache").glob("tiny-*-seed3.nc"))
    assert len(cached) == 1
    argv = ["reproduce", "--out", str(tmp_path / "o"), "--seed", "3", "--no-progress"]
    argv += ["--dynamic-lags", ""]  # skip the dynamic part here (tested above)
    argv += ["--cache-dir", str(tmp / "cache"), "--campaign", str(toml)]
    assert main([*argv, "--states", ",".join(STATES)]) == 0
    second = json.loads((tmp_path / "o" / "results.json").read_text())
    a, b = first["datasets"]["tiny"], second["datasets"]["tiny"]
    assert b["campaign"]["cached"] and not a["campaign"]["cached"]
    assert "dynamic" in a and "dynamic" not in b
    for method in ("rvm", "svm"):
        # counts and ratios of counts: the same decisions give the same values exactly
        for key in ("accuracy", "per_class", "confusion", "nodes"):
            assert a[method][key] == b[method][key]
        # Scores of the probabilities: MKL's products can differ in their last bits between
        # two calls in one process (they depend on memory alignment), and these scores are
        # smooth in the probabilities, so the two runs agree to about 1e-15 relative; 1e-9
        # is still five orders below the 4 decimals the report prints.
        for key in ("log_loss", "brier", "ece"):
            assert b[method][key] == pytest.approx(a[method][key], rel=1e-9, abs=1e-12)
    assert a["all_states"]["groups"] == b["all_states"]["groups"]
    assert a["normal_models"]["width"] == b["normal_models"]["width"]
    assert "tiny: RVM" in capsys.readouterr().out
    # usage errors: exit status 2 and a one-line message (the CLI's convention)
    assert main([*argv, "--states", "fn,f42"]) == 2
    assert "unknown state" in capsys.readouterr().err
    assert main([*argv[:-2], "--states", ",".join(STATES), "--dynamic-lags", "1,two"]) == 2
    assert "--dynamic-lags" in capsys.readouterr().err


def test_the_report_opens_in_words_with_the_results_figures(run):
    tmp, _, results, _ = run
    report = (tmp / "out1" / "report.md").read_text()
    d = results["datasets"]["tiny"]
    short = report[report.index("## In short") : report.index("## Glossary")]
    (line,) = [x for x in short.splitlines() if x.startswith("- **tiny**")]
    rvm = np.array(d["rvm"]["confusion"]["matrix"])
    svm = np.array(d["svm"]["confusion"]["matrix"])
    # the ratios from the confusions' counts, formatted by hand (two decimals, percent)
    assert f"of {rvm.sum()} test runs, the RVM tree names the state of " in line
    assert f"{100 * np.trace(rvm) / rvm.sum():.2f}% right, " in line  # no paper figure: tiny
    assert f"the SVM tree {100 * np.trace(svm) / svm.sum():.2f}%." in line
    dyn = np.array(d["dynamic"]["rvm"]["confusion"]["matrix"])
    assert f"the RVM tree names {100 * np.trace(dyn) / dyn.sum():.2f}%" in line
    # the most frequent confusion: the largest off-diagonal count of the RVM's confusion
    classes = d["rvm"]["confusion"]["classes"]
    off = [(rvm[i, j], i, j) for i in range(len(classes)) for j in range(len(classes)) if i != j]
    if max(off)[0]:
        a, b, n, m = re.search(r"(f\d+|fn) read as (f\d+|fn) in (\d+) of (\d+) runs", line).groups()
        i, j = classes.index(a), classes.index(b)
        assert (int(n), int(m)) == (rvm[i, j], rvm[i].sum()) and int(n) == max(off)[0]
    # the glossary defines the indices and terms the tables and sentences print
    body = report[report.index("## Overall identification ratio") :]
    glossary = report[report.index("## Glossary") : report.index("## State codes")]
    always = (
        ("identification ratio", "Identification ratio"),
        ("log loss", "Log loss"),
        ("Brier score", "Brier"),
        ("ECE", "ECE"),
        ("McNemar p", "McNemar p"),
        ("relevance / support vectors", "Vectors per node"),
        ("noise floor", "noise floor"),
        ("coverage", "coverage"),
        ("fault strength", "Strength"),
    )
    for term, printed in always:
        assert f"- **{term}**: " in glossary and printed in body, term
    # printed only when the all-states analysis finds groups
    for term in ("pairwise k-NN error", "group level, P(true group)"):
        assert f"- **{term}**: " in glossary, term
    # every state code the report mentions is named once, with the actuator table's description
    codes = set(re.findall(r"\b(f\d{1,2}|fn)\b", report))
    named = report[report.index("## State codes") : report.index("## Overall")]
    assert codes >= set(STATES)
    for code in codes:
        meaning = "fault-free" if code == "fn" else FAULT_TABLE[code].description
        assert named.count(f"- {code} {meaning}\n") == 1, code

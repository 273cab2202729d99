"""The benchmark harness: decision signals, the runner end to end (with a test double of the
online diagnoser's contract), the report and the timeline figure."""

import json
import re

import numpy as np
import pytest
import xarray as xr
from online_double import OnlineDouble

from bayes_fdi.actuator import FAULT_TABLE, benchmark_inputs, simulate
from bayes_fdi.benchmark.harness import run_benchmark
from bayes_fdi.benchmark.scenarios import SCENARIOS, simulate_scenario
from bayes_fdi.diagnosis.online.timeline import plot_timeline
from bayes_fdi.scoring import picalc
from bayes_fdi.scoring.decision_signals import decision_signals, rising_edges
from bayes_fdi.scoring.picalc import PICALC_KEYS, first_detection

BY_NAME = {s.name: s for s in SCENARIOS}


def hand_stream(indicated, dd, groups, undetectable=()):
    """A one-run decision stream holding what decision_signals reads."""
    indicated = np.asarray(indicated, dtype=bool)
    labels = list(groups)
    return xr.Dataset(
        {"DD": ("time", np.asarray(dd, dtype=bool)), "indicated": (("time", "group"), indicated)},
        coords={"time": np.arange(indicated.shape[0], dtype=float), "group": labels},
        attrs={"groups": json.dumps(groups), "undetectable": json.dumps(list(undetectable))},
    )


GROUPS = {"f1": ["f1"], "f2|f3": ["f2", "f3"], "f7|f8|f9": ["f7", "f8", "f9"]}
DD = [0, 1, 1, 1, 1]
IND = [[0, 0, 0], [0, 1, 1], [1, 1, 0], [1, 0, 0], [1, 0, 0]]


def test_decision_signals_follow_the_contract():
    sig = decision_signals(hand_stream(IND, DD, GROUPS, ["f14"]), "f1")
    np.testing.assert_array_equal(sig.pid, [0, 0, 1, 1, 1])  # column of f1's group
    np.testing.assert_array_equal(sig.cid, [0, 2, 1, 0, 0])  # the others indicated
    np.testing.assert_array_equal(sig.group_sizes, [1, 2, 3])
    assert sig.true_group == 0
    sig = decision_signals(hand_stream(IND, DD, GROUPS, ["f14"]), "f3")
    np.testing.assert_array_equal(sig.pid, [0, 1, 1, 0, 0])
    np.testing.assert_array_equal(sig.cid, [0, 1, 1, 1, 1])


def test_a_dgn0_fault_is_isolated_by_not_detecting_it():
    sig = decision_signals(hand_stream(IND, DD, GROUPS, ["f14", "f5"]), "f14")
    np.testing.assert_array_equal(sig.pid, [1, 0, 0, 0, 0])  # PID = not DD
    np.testing.assert_array_equal(sig.cid, [0, 2, 2, 1, 1])  # every stream group is "other"
    np.testing.assert_array_equal(sig.group_sizes, [1, 2, 3, 3])  # DGN0: f14, f5 and OK
    np.testing.assert_array_equal(sig.indicated[:, -1], [1, 0, 0, 0, 0])
    assert sig.true_group is None
    sig = decision_signals(hand_stream(IND, DD, GROUPS), "f19")  # in no group: never isolated
    assert not sig.pid.any() and sig.true_group is None
    with pytest.raises(ValueError, match="one run"):
        decision_signals(hand_stream(IND, DD, GROUPS).expand_dims(run=[0]), "f1")


def test_rising_edges():
    assert rising_edges([0, 1, 1, 0, 1, 0]) == 2
    assert rising_edges([1, 1, 0, 1]) == 2  # high at the first sample counts
    assert rising_edges([]) == 0


@pytest.fixture(scope="module")
def double():
    normal = simulate(benchmark_inputs(n_runs=3, duration=1200, vary=True, seed=1), seed=1)
    return OnlineDouble().fit(normal)


@pytest.fixture(scope="module")
def tiny_run(double, tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    scenarios = [BY_NAME["f1 abrupt big"], BY_NAME["f14 abrupt big"]]
    results = run_benchmark(
        double, out, n_seeds=1, scenarios=scenarios, hours=0.1, n_bootstrap=20, progress=False
    )
    return out, results


def test_runner_writes_the_contracts_json_and_the_report(tiny_run):
    out, _ = tiny_run
    data = json.loads((out / "benchmark.json").read_text())
    assert [(r["fault"], r["mode"], r["size"], r["seed"]) for r in data["scenarios"]] == [
        ("f1", "abrupt", "big", 10_000),
        ("f14", "abrupt", "big", 10_000),
    ]
    for row in data["scenarios"]:
        assert set(row["indices"]) == {
            "t_dt",
            "r_fd",
            "r_td",
            "fs_d",
            "t_it",
            "r_fi",
            "r_ti",
            "r_mi",
            "fs_i",
            "dacc",
        }
    assert set(data["real_hour"]) >= {"seconds", "alarms", "clear_share"}
    assert data["real_hour"]["seconds"] == 1800  # the second half of the shipped hour
    assert data["fault_free"]["seconds"] == 360  # 0.1 h after the warm-up
    report = (out / "benchmark.md").read_text()
    assert "Not the benchmark's numbers" in report and "## Targets" in report
    assert "f14 abrupt big" in report and "Published DAMADICS results" in report
    rms = data["innovation_rms"]
    assert f"innovations have an RMS of {rms['X']:.2f} (X) and {rms['F']:.2f} (F)" in report
    for name in ("f1-abrupt-big", "f14-abrupt-big"):
        assert (out / "timelines" / f"{name}.png").stat().st_size > 10_000
    assert (out / "reliability.png").exists()


def test_runner_indices_equal_picalc_on_the_diagnosers_own_stream(tiny_run, double):
    # an independent replay: simulate the scenario, run the double, derive PID/CID by hand
    _, results = tiny_run
    s = BY_NAME["f1 abrupt big"]
    stream = double.run(simulate_scenario(s, [10_000])[["CV", "P1", "P2", "T1", "X", "F"]])
    one = stream.isel(run=0)
    dd = one.DD.values
    pid = one.indicated.values[:, 0]  # f1 is in the double's first group
    cid = one.indicated.values[:, 1].astype(int)
    t = one.time.values
    want = picalc(
        t,
        dd,
        pid,
        cid,
        t_on=300,
        t_from=900,
        t_hor=1500,
        strength=np.where(t >= 900, 0.75, 0.0),
        indicated=one.indicated.values,
        group_sizes=[10, 8],
    )
    assert results["scenarios"][0]["indices"] == want
    assert want["t_dt"] != -1  # f1 big clogs the valve: the double sees it
    first = first_detection(t, dd, t_on=300, t_from=900, t_hor=1500)
    assert results["scenarios"][0]["first_detection"] == first
    assert first["dd_permanent"] in (0.0, 1.0)
    assert (first["t_dt_first"] == want["t_dt"]) == (first["dd_permanent"] == 1.0)


def test_rows_count_the_confident_wrong_seconds_of_the_diagnosers_own_stream(tiny_run, double):
    from bayes_fdi.benchmark.collection import confident_wrong

    _, results = tiny_run
    total, rms = 0, {"X": [], "F": []}
    for row in results["scenarios"]:
        s = BY_NAME[f"{row['fault']} {row['mode']} {row['size']}"]
        run = simulate_scenario(s, [row["seed"]])[["CV", "P1", "P2", "T1", "X", "F"]]
        one = double.run(run).isel(run=0)
        t = one.time.values
        faulty = (t >= s.t_from) & (t < s.t_hor)
        answers, _ = confident_wrong(one, decision_signals(one, s.fault).true_group)
        named = one.state.values.astype(str)[answers & faulty]
        assert row["faulty_seconds"] == faulty.sum() == s.t_hor - s.t_from
        assert row["confident_wrong_seconds"] == named.size
        assert sum(row["confident_wrong_named"].values()) == named.size
        assert set(row["confident_wrong_named"]) == set(named.tolist())
        dd = one.DD.values.astype(bool)
        states, counts = np.unique(one.state.values.astype(str)[faulty & dd], return_counts=True)
        want = dict(zip(states.tolist(), counts.tolist(), strict=True))
        assert row["states"] == {**want, "not detected": int((faulty & ~dd).sum())}
        assert sum(row["states"].values()) == row["faulty_seconds"]
        total += named.size
        fault_free = (t >= s.t_on) & (t < s.t_from)
        for c in ("X", "F"):
            rms[c].append(np.sqrt(np.mean(one[f"r_{c}"].values[fault_free] ** 2)))
    assert results["confident_wrong"]["seconds"] == total
    for c in ("X", "F"):  # the median over the runs of the innovations' RMS before the fault
        assert results["innovation_rms"][c] == pytest.approx(np.median(rms[c]), rel=1e-12)


def test_dgn0_scenario_indices_obey_pid_equals_not_dd(tiny_run):
    _, results = tiny_run
    ind = results["scenarios"][1]["indices"]  # f14: the double declares it undetectable
    # PID = not DD, so over the fault-free part r_fi = 1 - r_fd and over the faulty part
    # r_ti = 1 - r_td (each sample is either detected or "isolated" as DGN0)
    assert ind["r_fi"] == pytest.approx(1.0 - ind["r_fd"])
    assert ind["r_ti"] == pytest.approx(1.0 - ind["r_td"])


def test_effects_show_f14_leaves_the_measurements_untouched(tiny_run):
    _, results = tiny_run
    effects = {e["scenario"]: e for e in results["effects"]}
    # f14 changes only the positioner's chamber-pressure reading: X, F, P1, P2, T1 bit-identical
    assert effects["f14 abrupt big"]["deflection"] == 0.0
    assert effects["f14 abrupt big"]["oracle_time"] is None
    assert effects["f1 abrupt big"]["deflection"] > 100.0


def test_timeline_from_a_stream_alone(double, tmp_path):
    rec = simulate(benchmark_inputs(n_runs=1, duration=300), seed=3)
    stream = double.run(rec)
    fig = plot_timeline(stream, rec)  # no truth: e.g. a user's own recording
    assert len(fig.axes) >= 7
    path = plot_timeline(
        stream, rec, truth={"fault": "f1", "onset": 100.0}, path=tmp_path / "t.png"
    )
    assert path.exists() and not list(tmp_path.glob(".*tmp*"))
    # faults by code and name: the title, and each group of the probability panel's legend
    fig = plot_timeline(stream, rec, truth={"fault": "f18"})
    assert fig._suptitle.get_text() == f"f18 {FAULT_TABLE['f18'].description}"
    legend = fig.axes[6].get_legend()
    assert legend is not None and legend.get_texts()
    for text in (t.get_text() for t in legend.get_texts()):
        codes = text.split(":")[0].split()[0].split("|")
        for code in codes:
            assert code in FAULT_TABLE or code in ("fn", "unknown")
            if code in FAULT_TABLE:
                assert FAULT_TABLE[code].description in text
    with pytest.raises(ValueError, match="one run"):
        two = simulate(benchmark_inputs(n_runs=2, duration=300), seed=3)
        plot_timeline(double.run(two), two)
    with pytest.raises(ValueError, match="unknown truth key"):
        plot_timeline(stream, rec, truth={"fualt": "f1"})


def test_the_benchmark_command_is_registered(capsys):
    from bayes_fdi.cli import main

    assert main(["benchmark", "--help"]) == 0  # main returns the exit status
    out = capsys.readouterr().out
    for option in ("--out", "--seeds", "--small", "--quiet"):
        assert option in out


def test_results_do_not_depend_on_the_batching(double, tmp_path):
    scenarios = [BY_NAME["f18 abrupt big"], BY_NAME["f13 incipient"].truncated(1600)]
    kw = {
        "n_seeds": 2,
        "scenarios": scenarios,
        "hours": 0.05,
        "real_hour": False,
        "figures": False,
        "n_bootstrap": 0,
        "progress": False,
    }
    one_run_each = run_benchmark(double, tmp_path / "a", max_batch_samples=1, **kw)
    all_at_once = run_benchmark(double, tmp_path / "b", max_batch_samples=10**7, **kw)
    assert one_run_each["scenarios"] == all_at_once["scenarios"]
    assert len(all_at_once["scenarios"]) == 4


def test_nan_decisions_are_low():
    dd = np.array([np.nan, 1.0, np.nan, 0.0])  # a float DD with BLIND seconds
    ind = np.array([[np.nan, 0.0], [1.0, 0.0], [np.nan, np.nan], [0.0, 0.0]])
    stream = xr.Dataset(
        {"DD": ("time", dd), "indicated": (("time", "group"), ind)},
        coords={"time": np.arange(4.0), "group": ["f1", "f2"]},
        attrs={"groups": json.dumps({"f1": ["f1"], "f2": ["f2"]}), "undetectable": "[]"},
    )
    sig = decision_signals(stream, "f1")
    np.testing.assert_array_equal(sig.dd, [0, 1, 0, 0])
    np.testing.assert_array_equal(sig.pid, [0, 1, 0, 0])


def test_timeline_axes_use_the_recordings_own_ranges(double):
    """A Lublin Actuator-1 record is drawn in its own ranges, anything else in DABLib's."""
    from bayes_fdi.datasets.lublin import ACTUATOR_RANGES

    rec = simulate(benchmark_inputs(n_runs=1, duration=120), seed=3)
    stream = double.run(rec)
    fig = plot_timeline(stream, rec)
    assert fig.axes[0].get_ylabel() == "X [%]" and fig.axes[1].get_ylabel() == "F [t/h]"
    line = fig.axes[1].get_lines()[0]  # the measured flow: F' x 40 t/h
    np.testing.assert_allclose(line.get_ydata(), rec["F"].values[0] * 40.0)
    rec1 = rec.assign_attrs(actuator=1)
    fig1 = plot_timeline(stream, rec1)
    factor, unit = ACTUATOR_RANGES[1]["F"]
    assert fig1.axes[1].get_ylabel() == f"F [{unit.replace('m3/h', 'm³/h')}]"
    np.testing.assert_allclose(fig1.axes[1].get_lines()[0].get_ydata(), rec["F"].values[0] * factor)


def test_the_report_opens_with_its_targets_in_short_a_glossary_and_the_fault_names(tiny_run):
    out, _ = tiny_run
    report = (out / "benchmark.md").read_text()
    data = json.loads((out / "benchmark.json").read_text())
    head = report[: report.index("## Targets")]
    short = head[head.index("## In short") : head.index("## Glossary")]
    targets = report[report.index("## Targets") : report.index("## Indices per scenario")]
    judged = [line for line in targets.splitlines() if line.endswith(("| yes |", "| **no** |"))]
    met = sum(line.endswith("| yes |") for line in judged)
    assert f"{met} of {len(judged)} targets met." in short
    # detected / isolated: scenarios whose t_dt / t_it is determined (not -1) in >= half the seeds
    seeds: dict[str, list[dict]] = {}
    for row in data["scenarios"]:
        seeds.setdefault(f"{row['fault']} {row['mode']} {row['size']}", []).append(row["indices"])

    def in_half(key):
        return sum(2 * sum(r[key] != -1 for r in rs) >= len(rs) for rs in seeds.values())

    assert (
        f"Of the {len(seeds)} scenarios, {in_half('t_dt')} are detected and {in_half('t_it')} "
        "isolated" in short
    )
    # f14 leaves X, F, P1, P2, T1 bit-identical: the summary says no method can detect it
    assert "No method can detect f14 abrupt big from the measurements" in short
    # every column of the indices table, and every abbreviation the report prints, is defined
    table = report[report.index("| scenario | t_dt") :].splitlines()[0]
    columns = [c.strip() for c in table.strip("|").split("|")][1:-1]
    assert columns == list(PICALC_KEYS)
    first = report[report.index("## First detection and permanence") :]
    assert "| scenario | t_dt [s] | t_dt_first [s] | kept on |" in first
    glossary = head[head.index("## Glossary") :]
    defined = {line[4 : line.index("**:")] for line in glossary.splitlines() if "**:" in line}
    terms = {t.strip() for entry in defined for t in entry.replace("/", ",").split(",")}
    printed = ("DD", "PID", "t_from", "DGN", "dacc_t", "dacc_tm", "σ", "ECE", "MCE")
    for term in (*PICALC_KEYS, *printed, "deflection", "oracle time", "CLEAR", "t_dt_first"):
        assert term in terms, term
        assert term in report[report.index("## Targets") :] or term in PICALC_KEYS, term
    assert "kept on" in terms
    # every fault code the report mentions is named, with the actuator table's description
    codes = set(re.findall(r"\bf(\d{1,2})\b", report))
    assert codes >= {"1", "14"}
    for number in codes:
        fault = f"f{number}"
        assert f"- {fault} {FAULT_TABLE[fault].description}\n" in head, fault
    # DGN0 is the OK state alone when the diagnoser declares no fault undetectable
    assert re.search(r"\| DGN0 \| OK(, f\d+)* \|", report)


def test_an_alarm_left_on_through_the_fault_free_hours_fails_their_target():
    """One rising edge whose alarm then stays on is one alarm, but not a quiet 8 hours: the
    fault-free target also bounds the share of seconds with DD on (r_fd <= 0.01)."""
    from bayes_fdi.benchmark.report_detection import fault_free_target

    def target(alarms: int, on: float) -> tuple[str, str, bool]:
        ff = {"hours": 8.0, "alarms": alarms, "alarms_per_8h": float(alarms), "r_fd": on}
        return fault_free_target(ff)

    _, measured, met = target(1, 0.999)
    assert not met and measured == "1 alarm(s) = 1.00 per 8 h, DD on 99.90 %"
    assert target(1, 0.004)[2] and not target(2, 0.0)[2]


def test_declared_false_detections_leave_out_the_model_mismatch_answers(double):
    """``declared_r_fd`` counts the fault-free seconds with DD on that the diagnoser does not
    answer "mismatch"; PICalc's r_fd counts them all."""
    from bayes_fdi.benchmark.collection import RunCollector
    from bayes_fdi.benchmark.report_detection import declared_r_fd_median

    s = BY_NAME["f1 abrupt big"]
    one = double.run(simulate_scenario(s, [10_000])[["CV", "P1", "P2", "T1", "X", "F"]])
    one = one.isel(run=0)
    t = one.time.values
    fault_free = (t >= s.t_on) & (t < s.t_from)
    # an alarm in the fault-free part, answered "mismatch" in its first 40 seconds only
    dd = one.DD.values.astype(bool).copy()
    dd[(t >= 500) & (t < 600)] = True
    state = one.state.values.astype(str).copy()
    state[dd] = "f1"
    state[(t >= 500) & (t < 540)] = "mismatch"
    one = one.assign(DD=("time", dd), state=("time", state.astype(object)))
    col = RunCollector(seed=0)
    row = col.add(s, 10_000, one)
    want_all = dd[fault_free].mean()
    want = (dd & (state != "mismatch"))[fault_free].mean()
    assert row["indices"]["r_fd"] == pytest.approx(want_all, abs=1e-12)
    assert row["declared_r_fd"] == pytest.approx(want, abs=1e-12)
    assert want == pytest.approx(want_all - 40 / fault_free.sum(), abs=1e-12)
    assert declared_r_fd_median({"scenarios": [row, {**row, "declared_r_fd": 1.0}]}) == (
        pytest.approx((want + 1.0) / 2)
    )
    assert declared_r_fd_median({"scenarios": [{"indices": row["indices"]}]}) is None


def test_the_calibration_over_the_seconds_not_answered_mismatch(double):
    """``calibration["answered"]``: the ECE over the sampled seconds whose answer is not
    "mismatch", the same figure as the whole sample's computed on those seconds alone."""
    from bayes_fdi.benchmark.collection import RunCollector, group_calibration
    from bayes_fdi.calibration import expected_calibration_error

    s = BY_NAME["f1 abrupt big"]
    one = double.run(simulate_scenario(s, [10_000])[["CV", "P1", "P2", "T1", "X", "F"]])
    one = one.isel(run=0)
    t = one.time.values
    col = RunCollector(seed=0)
    col.add(s, 10_000, one)
    assert "answered" not in group_calibration(col, 0, 0, None)  # no "mismatch" answer
    state = one.state.values.astype(str).copy()
    early = (t >= s.t_from) & (t < s.t_from + 100)
    state[early] = "mismatch"
    marked = RunCollector(seed=0)
    marked.add(s, 10_000, one.assign(state=("time", state.astype(object))))
    cal = group_calibration(marked, 0, 0, None)
    proba, true = marked.proba[0], marked.true[0]
    kept = marked.answered[0]
    assert 0 < kept.sum() < kept.size  # the sample holds seconds of both kinds
    labels = np.asarray(marked.labels)
    want = expected_calibration_error(
        labels[true[kept]], proba[kept], classes=labels, n_bins=15
    ).value
    assert cal["answered"]["n_seconds"] == int(kept.sum())
    assert cal["answered"]["ece"] == pytest.approx(want, abs=1e-12)
    assert cal["ece"] == pytest.approx(group_calibration(col, 0, 0, None)["ece"], abs=1e-12)

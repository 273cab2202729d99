"""The commissioning benchmark (bayes_fdi.benchmark.commissioning and its parts)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bayes_fdi.actuator import NOMINAL, PARAMETER_INFO, benchmark_inputs, simulate
from bayes_fdi.benchmark.cases import innovation_effect, score_case
from bayes_fdi.benchmark.commissioning import run_commissioning_benchmark
from bayes_fdi.benchmark.plants import (
    FACTOR_BANDS,
    MAX_AT_RANGE_END,
    PERTURBED_FIELDS,
    draw_plant,
    healthy_run,
    scenario_run,
    scenario_seed,
)
from bayes_fdi.benchmark.scenarios import SCENARIOS
from bayes_fdi.diagnosis import DynamicNormalModels, OnlineDiagnoser
from bayes_fdi.twin import DEFAULT_PRIORS, ActuatorTwin

TINY_MODELS = dict(
    x_widths=(8.0,),
    f_widths=(0.1,),
    evidence_max_samples=200,
    max_train_samples=400,
    calibration_folds=2,
    random_state=0,
)


#: A twin of two parameters (the flow law's scale and zero), a short mode search
QUICK_TWIN = ActuatorTwin(
    priors={k: DEFAULT_PRIORS[k] for k in ("kv", "f_offset")}, n_draws=20, max_iter=8
)


def _by_name(name):
    return next(s for s in SCENARIOS if s.name == name)


def test_a_plant_lies_20_to_30_percent_from_nominal_and_is_reproducible():
    plant = draw_plant(3)
    assert plant == draw_plant(3)
    assert set(plant.factors) == set(PERTURBED_FIELDS)
    assert {PARAMETER_INFO[f].group for f in PERTURBED_FIELDS} == {
        "valve",
        "servomotor",
        "positioner",
    }
    for name, factor in plant.factors.items():
        assert any(lo <= factor <= hi for lo, hi in FACTOR_BANDS), name
        assert getattr(plant.parameters, name) == pytest.approx(getattr(NOMINAL, name) * factor)
    for name in ("x_gain", "f_offset", "p1_gain"):  # the transmitters stay nominal
        assert getattr(plant.parameters, name) == getattr(NOMINAL, name)
    assert plant.parameters == plant.parameters.validated()
    # the loop's flow law is this valve's, and its operating point is fixed
    assert plant.loop.characteristic == plant.parameters.characteristic
    assert plant.loop.kv_ratio == pytest.approx(plant.parameters.kv / NOMINAL.kv)
    assert plant.operating.dp[0] == plant.operating.dp[1]
    assert draw_plant(4).parameters != plant.parameters


def test_a_plants_runs_are_seeded_apart_and_its_healthy_hour_stays_in_range():
    plant = draw_plant(0)
    healthy = healthy_run(plant, 3600)
    ends = np.zeros(3600, dtype=bool)
    for c in ("CV", "X", "F"):
        v = healthy[c].values[0]
        ends |= (v <= 0.005) | (v >= 0.995)
    assert ends.mean() < MAX_AT_RANGE_END
    assert not np.array_equal(
        healthy_run(plant, 600, heldout=True)["X"].values, healthy["X"].values[:, :600]
    )
    s = _by_name("f18 abrupt big").truncated(1000)
    faulty = scenario_run(plant, s, 0, SCENARIOS.index(_by_name("f18 abrupt big")))
    clean = scenario_run(plant, s, 0, SCENARIOS.index(_by_name("f18 abrupt big")), faulty=False)
    # same inputs and noise: identical before the fault, different after
    np.testing.assert_array_equal(faulty["X"].values[:, :900], clean["X"].values[:, :900])
    np.testing.assert_array_equal(faulty["CV"].values, clean["CV"].values)
    assert np.abs(faulty["F"].values[:, 905:] - clean["F"].values[:, 905:]).max() > 0.01
    assert scenario_seed(1, 2, 3) == 51_203
    with pytest.raises(ValueError, match="plant seed"):
        scenario_seed(0, 10, 0)


@pytest.fixture(scope="module")
def detection_only():
    """A real, cheap diagnoser: normal models of the nominal simulator, no fault library."""
    normal = simulate(benchmark_inputs(n_runs=1, duration=900, vary=True), seed=3)
    return OnlineDiagnoser(DynamicNormalModels(**TINY_MODELS), random_state=0).fit(normal)


@pytest.fixture(scope="module")
def tiny_run(detection_only, tmp_path_factory):
    out = tmp_path_factory.mktemp("commissioning")
    scenarios = [_by_name("f18 abrupt big").truncated(1200), _by_name("f1 abrupt small")]
    scenarios[1] = scenarios[1].truncated(1100)
    results = run_commissioning_benchmark(
        detection_only,
        out,
        n_plants=1,
        n_seeds=1,
        scenarios=scenarios,
        real_hour=False,
        commission_seconds=900,
        commission_options={
            "faults": ("f1", "f18", "bias_X"),
            "runs_per_fault": 2,
            "duration": 300,
            "sizes": (0.75,),
            "evaluation_runs": 1,
            "normal_models": DynamicNormalModels(**TINY_MODELS),
            "twin": QUICK_TWIN,
        },
        progress=False,
    )
    return results, out, scenarios


def test_the_tiny_run_writes_its_report(tiny_run):
    _, out, _ = tiny_run
    written = json.loads((out / "benchmark.json").read_text())
    assert set(written) >= {"plants", "targets", "settings", "timing", "load"}
    (plant,) = written["plants"]
    assert set(plant) >= {"plant", "commissioning", "twin_check", "clean", "cases", "groups"}
    assert plant["commissioning"]["healthy_seconds"] == 900
    # two scenarios, one seed, both models
    assert len(plant["cases"]) == 4
    assert {r["model"] for r in plant["cases"]} == {"commissioned", "default"}
    f18 = next(r for r in plant["cases"] if r["model"] == "commissioned" and r["fault"] == "f18")
    assert f18["effect"]["deflection"] > 5  # a big bypass opening moves the residuals
    assert f18["indices"]["t_dt"] != -1  # and is detected
    md = (out / "benchmark.md").read_text()
    for heading in ("## In short", "## Targets", "## Glossary", "## Perturbed plants",
                    "## Fault codes"):  # fmt: skip
        assert heading in md
    assert "f18 fully or partly opened bypass valve" in md
    assert "A reduced run" in md


def _hand_indices(dd, t_on, t_from, t_hor):
    """PICalc's detection indices of a DD stream, by hand (the last rising edge, kept)."""
    zone = dd[int(t_on) : int(t_hor)]
    before, after = zone[: int(t_from - t_on)], zone[int(t_from - t_on) :]
    t_dt = -1.0
    if after[-1]:
        k = len(zone) - 1
        while k > 0 and zone[k - 1]:
            k -= 1
        t_dt = max(k + t_on - t_from, 0.0)
    return {"r_fd": before.mean(), "r_td": after.mean(), "t_dt": t_dt}


def test_an_index_of_the_report_checks_by_hand(tiny_run, detection_only):
    results, _, scenarios = tiny_run
    plant = draw_plant(0)
    s = scenarios[0]
    run = scenario_run(plant, s, 0, SCENARIOS.index(_by_name("f18 abrupt big")))
    stream = detection_only.run(run[["CV", "P1", "P2", "T1", "X", "F"]]).isel(run=0)
    hand = _hand_indices(np.asarray(stream["DD"].values, bool), s.t_on, s.t_from, s.t_hor)
    row = next(
        r for r in results["plants"][0]["cases"] if r["model"] == "default" and r["fault"] == "f18"
    )
    for key, value in hand.items():
        assert row["indices"][key] == pytest.approx(value)
    assert row["faulty_seconds"] == s.t_hor - s.t_from


def test_score_case_counts_the_named_seconds_and_confident_wrong_ones(detection_only):
    run = simulate(benchmark_inputs(n_runs=1, duration=700), seed=5)
    one = detection_only.run(run[["CV", "P1", "P2", "T1", "X", "F"]]).isel(run=0)
    t = one["time"].values
    out = score_case(
        one, "f1", t_on=100, t_from=400, t_hor=700, strength=np.where(t >= 400, 0.5, 0.0)
    )
    assert out["faulty_seconds"] == 300
    assert sum(out["states"].values()) == 300  # every faulty second named once
    assert out["confident_wrong_seconds"] == 0  # a detection-only model never names a group
    assert out["true_group"] is None  # f1 is unknown to it
    effect = innovation_effect(one, one, t_from=400, noise={"r_X": 1.0, "r_F": 1.0})
    assert effect["deflection"] == 0.0 and effect["oracle_time"] is None


@pytest.mark.slow
def test_the_real_hour_part(detection_only, tmp_path):
    """Commissioned on the first half of the real hour; the second half clean and with every
    library fault transplanted (one twin draw, the quick commissioning)."""
    from bayes_fdi.benchmark.commissioning import small_commission_options
    from bayes_fdi.benchmark.commissioning_report import write_commissioning_report
    from bayes_fdi.benchmark.commissioning_summary import targets
    from bayes_fdi.benchmark.real_hour import real_hour_benchmark
    from bayes_fdi.commissioning import LIBRARY_FAULTS
    from bayes_fdi.datasets import load_lublin_example

    real = real_hour_benchmark(
        detection_only, draws=1, commission_options=small_commission_options(), progress=False
    )
    assert real["zones"] == {"t_on": 0.0, "t_from": 300.0, "t_hor": 1800.0}
    assert len(real["cases"]) == len(LIBRARY_FAULTS) * 3 * 2
    assert all(r["faulty_seconds"] == 1500 for r in real["cases"])
    assert real["parameter_seeds"] == [10_000]
    # the default model's clean-half alarms, counted by hand
    second = load_lublin_example().isel(time=slice(1800, None))
    dd = detection_only.run(second[["CV", "P1", "P2", "T1", "X", "F"]]).isel(run=0)["DD"].values
    dd = np.asarray(dd, dtype=bool)
    assert real["clean"]["default"]["alarms"] == int(dd[0] + np.sum(dd[1:] & ~dd[:-1]))
    com = {(r["fault"], r["size"]): r for r in real["cases"] if r["model"] == "commissioned"}
    # a bias of the stem reading moves the X residual up and leaves F's exactly (F is
    # predicted from the command, not from the X reading)
    shift = com[("bias_X", "big")]["effect"]["residual_shift"]
    assert shift["X"] > 1.0 and shift["F"] == 0.0
    # a big bypass opening is seen in F and detected
    assert com[("f18", "big")]["effect"]["deflection"] > 5
    assert com[("f18", "big")]["indices"]["t_dt"] != -1
    results = {
        "real_hour": real,
        "plants": [],
        "settings": {"n_plants": 0, "n_seeds": 1, "draws": 1, "n_scenarios": 0},
        "timing": {"wall_s": 1.0, "cpu_s": 1.0},
    }
    results["targets"] = targets(results)
    _, md = write_commissioning_report(results, tmp_path)
    text = md.read_text()
    assert "## The real hour" in text and "Group-level confusion" in text


def test_the_isolation_option_belongs_to_the_commissioning_benchmark(tmp_path, capsys):
    from bayes_fdi.cli import build_parser, main
    from bayes_fdi.commissioning.commission import ISOLATION_CLASSIFIERS

    out = str(tmp_path / "b")
    for name in ISOLATION_CLASSIFIERS:
        args = build_parser("benchmark").parse_args(
            ["benchmark", "--out", out, "--commissioning", "--isolation", name]
        )
        assert args.isolation == name
    assert main(["benchmark", "--out", out, "--isolation", "forest"]) == 2
    assert "--isolation belongs to --commissioning" in capsys.readouterr().err


def test_score_case_declares_faults_only_outside_model_mismatch(detection_only):
    """``declared_r_fd``: the fault-free seconds with DD on and an answer other than
    "mismatch"; PICalc's r_fd counts every second with DD on."""
    run = simulate(benchmark_inputs(n_runs=1, duration=700), seed=5)
    one = detection_only.run(run[["CV", "P1", "P2", "T1", "X", "F"]]).isel(run=0)
    t = one["time"].values
    dd = (t >= 150) & (t < 250)  # a false alarm of 100 s in the fault-free part [100, 400)
    state = np.where(dd, "unknown", "fn").astype(object)
    state[(t >= 150) & (t < 190)] = "mismatch"  # its first 40 s answered "model mismatch"
    one = one.assign(DD=("time", dd), state=("time", state))
    out = score_case(
        one, "f1", t_on=100, t_from=400, t_hor=700, strength=np.where(t >= 400, 0.5, 0.0)
    )
    assert out["indices"]["r_fd"] == pytest.approx(100 / 300)
    assert out["declared_r_fd"] == pytest.approx(60 / 300)

"""The shift benchmark (``bayes-fdi benchmark --shift``): its families are held out of every
training campaign, its runs are the Step-I scenarios under a family's inputs with the
evaluation seeds, and it writes the nominal report per family plus a summary."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from online_double import OnlineDouble

from bayes_fdi.actuator import NOISE_STD, benchmark_inputs, simulate
from bayes_fdi.benchmark.scenarios import SCENARIOS, simulate_scenario
from bayes_fdi.benchmark.shift import (
    SHIFT_INPUT_SEED,
    ShiftInputs,
    run_shift_benchmark,
    shift_families,
)
from bayes_fdi.benchmark.shift_report import family_figures
from bayes_fdi.campaigns import load_campaign
from bayes_fdi.campaigns.excitation import excitation_inputs
from bayes_fdi.cli import main

SIM = Path(__file__).parents[1] / "sim"
BY_NAME = {s.name: s for s in SCENARIOS}
CHANNELS = ["CV", "P1", "P2", "T1", "X", "F"]


def test_at_least_three_shift_families_none_used_by_a_training_campaign():
    families = shift_families()
    assert len(families) >= 3
    assert len({f.family for f in families}) == len(families)  # different generators
    shift = {f.family for f in families}
    training = sorted(SIM.glob("online-*.toml"))
    assert training  # the default diagnoser's training campaigns
    for path in training:
        campaign = load_campaign(path)
        if campaign.source == "excitation":
            used = campaign.excitation["family"]
            assert used not in shift, f"{path.name} trains on the shift family {used}"
    for f in families:
        text = Path(f.path).read_text()
        assert "Fixed before any result" in text and "used by no training campaign" in text


@pytest.fixture(scope="module")
def chirp():
    (family,) = [f for f in shift_families() if f.family == "chirp"]
    return family


def test_a_seeds_scenarios_share_its_family_inputs_and_differ_in_their_noise(chirp):
    inputs = ShiftInputs(chirp, [10_000, 10_002], 2400)
    # seed 10 000 + k reads run k of the family's draw with the shift input seed
    drawn = excitation_inputs(chirp.excitation, 3, 2400, seed=SHIFT_INPUT_SEED)
    np.testing.assert_array_equal(inputs.inputs["CV"].values, drawn["CV"].values[[0, 2]])
    big = inputs.simulate(BY_NAME["f1 abrupt big"], [10_000, 10_002])
    ramp = inputs.simulate(BY_NAME["f13 incipient"], [10_002])
    assert list(big["run"].values) == [10_000, 10_002] and big.sizes["time"] == 1500
    assert ramp.sizes["time"] == 2400 and big.attrs["excitation"] == "chirp"
    # the same CV for both scenarios of seed 10 002 (the first 1500 s), not DGen's sine
    np.testing.assert_array_equal(big["CV"].values[1], ramp["CV"].values[0, :1500])
    dgen = benchmark_inputs(n_runs=1, duration=1500)["CV"].values[0]
    assert np.abs(big["CV"].values[1] - dgen).max() > 0.1
    # before the fault the two runs differ by their measurement noise only
    before = slice(100, 900)
    dx = big["X"].values[1, before] - ramp["X"].values[0, before]
    assert 0.0 < dx.std() < 2.0 * NOISE_STD
    # the fault acts after t_from: f1 (valve clogging) moves X far beyond the noise
    clean = simulate(inputs.inputs.sel(run=[10_000]).isel(time=slice(0, 1500)), noise=False)
    assert np.abs(big["X"].values[0, 1000:] - clean["X"].values[0, 1000:]).max() > 20 * NOISE_STD
    with pytest.raises(ValueError, match="seeds must be >= 10000"):
        ShiftInputs(chirp, [5], 100)
    with pytest.raises(ValueError, match="needs 2400 s, 1500 s were drawn"):
        ShiftInputs(chirp, [10_000], 1500).simulate(BY_NAME["f13 incipient"], [10_000])


def test_a_study_draws_the_same_way_with_seeds_of_its_own(chirp):
    """Seed ``first_seed + k`` reads run k of the draw with ``input_seed``; a scenario's noise
    is ``noise_seed`` plus its position in the table; fault-free hours take their own seed:
    each checked against the generator and the simulator called directly."""
    study = ShiftInputs(chirp, [5000, 5002], 1500, first_seed=5000, input_seed=77, noise_seed=5000)
    drawn = excitation_inputs(chirp.excitation, 3, 1500, seed=77)
    np.testing.assert_array_equal(study.inputs["CV"].values, drawn["CV"].values[[0, 2]])
    scenario = BY_NAME["f1 abrupt big"]
    position = [s.name for s in SCENARIOS].index(scenario.name)
    runs = study.simulate(scenario, [5002])
    direct = simulate(study.inputs.sel(run=[5002]), [scenario.fault_spec()], seed=5000 + position)
    np.testing.assert_array_equal(runs["X"].values, direct["X"].values)
    assert list(runs["run"].values) == [5002]
    free = study.fault_free(0.05, seed=5003)
    alone = excitation_inputs(chirp.excitation, 1, 300 + 180, seed=5003)
    np.testing.assert_array_equal(free["CV"].values, alone["CV"].values)
    assert list(free["run"].values) == [5003]
    with pytest.raises(ValueError, match="seeds must be >= 5000"):
        ShiftInputs(chirp, [4999], 100, first_seed=5000)


def test_fault_free_hours_under_a_family(chirp):
    ds = ShiftInputs(chirp, [10_000], 100).fault_free(0.1)
    assert ds.sizes["time"] == 300 + 360 and list(ds["run"].values) == [20_000]
    assert ds.attrs["warmup"] == 300.0 and ds.attrs["hours"] == 0.1
    nominal = simulate_scenario(BY_NAME["f1 abrupt big"], [10_000])
    assert not np.allclose(ds["CV"].values[0, :100], nominal["CV"].values[0, :100])


@pytest.fixture(scope="module")
def double():
    normal = simulate(benchmark_inputs(n_runs=3, duration=1200, vary=True, seed=1), seed=1)
    return OnlineDouble().fit(normal)


def test_shift_run_writes_a_report_per_family_and_a_summary(double, tmp_path):
    scenarios = [BY_NAME["f1 abrupt big"], BY_NAME["f18 abrupt big"]]
    families = shift_families()
    results = run_shift_benchmark(
        double, tmp_path, families=families, n_seeds=1, scenarios=scenarios, hours=0.05,
        figures=False, n_bootstrap=0, progress=False, settings={"fit_wall_s": 1.0},
    )  # fmt: skip
    data = json.loads((tmp_path / "benchmark.json").read_text())
    assert [f["name"] for f in data["families"]] == [f.name for f in families]
    summary = (tmp_path / "benchmark.md").read_text()
    assert "under excitation shift" in summary and "Not the benchmark's numbers" in summary
    for entry, family in zip(data["families"], families, strict=True):
        report = (tmp_path / family.name / "benchmark.md").read_text()
        assert f"shift family **{family.name}**" in report and "## Targets" in report
        assert f"## {family.name}" in summary and f"({family.name}/benchmark.md)" in summary
        one = json.loads((tmp_path / family.name / "benchmark.json").read_text())
        assert [r["seed"] for r in one["scenarios"]] == [10_000, 10_000]
        assert one["real_hour"] is None and one["fault_free"]["seconds"] == 180
        assert "fit_wall_s" not in one["settings"]  # the training time is the summary's
        # the summary's figures are those of the family's own results
        r_fd = np.median([r["indices"]["r_fd"] for r in one["scenarios"]])
        assert entry["figures"]["r_fd_median"] == pytest.approx(r_fd)
        assert entry["figures"]["alarms"] == one["fault_free"]["alarms"]
        always = np.mean([r["indices"]["r_fd"] == 1.0 for r in one["scenarios"]])
        assert entry["figures"]["alarmed_before"] == pytest.approx(always)
        assert entry["figures"]["dd_share"] == one["fault_free"]["r_fd"]
        if always > 0:
            assert f"{family.name} ({100 * always:.0f} %)" in summary
        assert entry["figures"] == pytest.approx(family_figures(one))
        rms = one["innovation_rms"]
        assert entry["figures"]["innovation_rms_X"] == rms["X"] > 0
        row = next(line for line in summary.splitlines() if line.startswith(f"| [{family.name}]"))
        assert f"| {rms['X']:.2f} / {rms['F']:.2f} |" in row
    # the indices are the double's on the family's runs, replayed independently
    inputs = ShiftInputs(families[0], [10_000], 1500)
    stream = double.run(inputs.simulate(BY_NAME["f1 abrupt big"], [10_000])[CHANNELS])
    first = json.loads((tmp_path / families[0].name / "benchmark.json").read_text())
    detected = bool(stream["DD"].values[0, 900:].any())
    assert (first["scenarios"][0]["indices"]["t_dt"] != -1) == detected
    assert results["settings"]["n_seeds"] == 1


def test_shift_and_commissioning_are_refused_together(tmp_path, capsys):
    assert main(["benchmark", "--help"]) == 0
    assert "--shift" in capsys.readouterr().out
    argv = ["benchmark", "--shift", "--commissioning", "--out", str(tmp_path / "b")]
    assert main(argv) == 2
    assert "--shift and --commissioning" in capsys.readouterr().err


@pytest.mark.slow
def test_shift_small_end_to_end(tmp_path):
    """``bayes-fdi benchmark --shift --small`` with the default diagnoser's small training."""
    out = tmp_path / "shift"
    argv = ["benchmark", "--shift", "--small", "--seeds", "1", "--quiet", "--out", str(out)]
    assert main(argv) == 0
    data = json.loads((out / "benchmark.json").read_text())
    assert len(data["families"]) >= 3 and data["settings"]["small"] is True
    for entry in data["families"]:
        one = json.loads((out / entry["name"] / "benchmark.json").read_text())
        assert len(one["scenarios"]) == 44
        assert (out / entry["name"] / "timelines" / "f1-abrupt-big.png").exists()

"""Campaign TOML files: schema validation, run labels, and (with the model) simulated datasets."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from bayes_fdi.campaigns.parsing import load_campaign, parse_campaign
from bayes_fdi.campaigns.spec import Campaign, CampaignError

SIM = Path(__file__).parents[1] / "sim"
ALL_STATES = ["fn", *(f"f{i}" for i in range(1, 20))]


def _minimal(**campaign):
    table = {
        "campaign": {
            "name": "unit",
            "seed": 3,
            "duration": 40,
            "source": "benchmark-inputs",
            "runs_per_state": 2,
            "states": ["fn", "f1", "f19"],
            **campaign,
        },
        "faults": {"strength": [0.5, 1.0]},
    }
    return table


def test_paper_simulated_file_shapes_and_labels():
    c = load_campaign(SIM / "paper-simulated.toml")
    assert (c.name, c.duration, c.source, c.runs_per_state) == (
        "paper-simulated", 350, "benchmark-inputs", 190,
    )  # fmt: skip
    assert list(c.states) == ALL_STATES and c.n_runs == 20 * 190
    spec = c.run_specs()
    assert len(spec.state) == 3800
    for s in ALL_STATES:
        assert (spec.state == s).sum() == 190
    fn = spec.state == "fn"
    assert (spec.strength[fn] == 0).all()
    magnitude = np.abs(spec.strength[~fn])
    assert magnitude.min() >= 0.5 and magnitude.max() <= 1.0
    # uniform on [0.5, 1]: mean 0.75, sd 0.144 -> a 3800-draw mean is within 0.01 w.h.p.
    assert abs(magnitude.mean() - 0.75) < 0.01
    negative = sorted(set(spec.state[spec.strength < 0]))
    assert negative == ["f12", "f14", "f19"]  # the benchmark's directions
    assert (spec.onset == 0).all() and set(spec.profile) == {"abrupt"} and (spec.ramp == 0).all()


def test_paper_lublin_file_shapes_and_labels():
    c = load_campaign(SIM / "paper-lublin.toml")
    assert (c.source, c.duration, c.runs_per_state, c.n_runs) == ("lublin-example", 350, 90, 1800)
    assert c.inputs["window"] == "random"
    spec = c.run_specs()
    assert [int((spec.state == s).sum()) for s in ALL_STATES] == [90] * 20


def test_damadics_benchmark_file_lists_the_44_scenarios():
    c = load_campaign(SIM / "damadics-benchmark.toml")
    assert c.n_runs == 45 and c.duration == 2400 and c.inputs["vary"] is False
    faulty = [s for s in c.scenarios if s.state != "fn"]
    assert len(faulty) == 44
    assert all(s.onset == 900.0 for s in faulty)
    abrupt = {(s.state, abs(s.strength)) for s in faulty if s.profile == "abrupt"}
    for f in ("f1", "f7", "f8", "f10", "f12", "f13", "f14", "f16", "f18", "f19"):
        assert {(f, 0.25), (f, 0.5), (f, 0.75)} <= abrupt
    assert {s for s, _ in abrupt} - {"f2", "f11", "f15", "f17"} == {
        "f1", "f7", "f8", "f10", "f12", "f13", "f14", "f16", "f18", "f19",
    }  # fmt: skip
    ramps = {s.state + "@" + str(int(s.ramp)) for s in faulty if s.profile == "incipient"}
    assert ramps == {
        *(f"{f}@84000" for f in ("f2", "f3", "f5", "f6", "f9", "f11", "f18")),
        "f4@3600", "f17@3600", "f13@900",
    }  # fmt: skip
    assert all(s.strength < 0 for s in faulty if s.state in ("f12", "f14", "f19"))
    spec = c.run_specs()
    assert list(spec.state) == [s.state for s in c.scenarios]


def test_runs_are_seeded_and_overridable(tmp_path):
    c = parse_campaign(_minimal())
    a, b = c.run_specs(), c.run_specs()
    np.testing.assert_array_equal(a.strength, b.strength)
    assert not np.array_equal(a.strength, c.run_specs(seed=4).strength)
    small = load_campaign(SIM / "paper-simulated.toml", runs_per_state=3, duration=30)
    assert small.n_runs == 60 and small.duration == 30
    again = small.replace(**{"faults.strength": [0.6, 0.6]})
    assert set(np.abs(again.run_specs().strength[again.run_specs().state != "fn"])) == {0.6}
    assert small.faults["f1"].strength == (0.5, 1.0)  # the original is unchanged


def test_campaign_is_immutable():
    c = parse_campaign(_minimal())
    assert isinstance(c, Campaign)
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.duration = 10
    with pytest.raises(TypeError):
        c.faults["f1"] = None
    with pytest.raises(TypeError):
        c.inputs["vary"] = False


def test_per_fault_overrides_and_directions():
    table = _minimal(states=["f4", "f17", "f2"])
    table["faults"]["f4"] = {"strength": [0.1, 0.2], "direction": -1}
    table["faults"]["f2"] = {"profile": "incipient", "ramp": 20.0, "onset": 5.0}
    c = parse_campaign(table)
    spec = c.run_specs()
    f4 = spec.strength[spec.state == "f4"]
    assert (f4 <= -0.1).all() and (f4 >= -0.2).all()
    assert (spec.strength[spec.state == "f17"] > 0).all()
    f2 = spec.state == "f2"
    assert set(spec.profile[f2]) == {"incipient"} and (spec.ramp[f2] == 20).all()
    assert (spec.onset[f2] == 5).all() and (spec.onset[~f2] == 0).all()


def test_stratified_strengths_take_one_magnitude_in_each_slice_of_the_range():
    """With ``draw = "stratified"`` the n runs of a fault fall one in each of n equal slices of
    its range (counted here independently of the draw), and the pooled magnitudes over many
    seeds are uniform on the range (a Kolmogorov-Smirnov test; a stratified draw has exactly the
    uniform marginal, so only a broken draw is rejected at this level)."""
    from scipy import stats

    table = _minimal(states=["f1", "f19", "f4"], runs_per_state=5)
    table["faults"] = {"strength": [0.2, 0.9], "draw": "stratified"}
    table["faults"]["f4"] = {"strength": [0.4, 0.4]}
    pooled = []
    for seed in range(400):
        spec = parse_campaign(table).run_specs(seed)
        for fault in ("f1", "f19"):
            m = np.abs(spec.strength[spec.state == fault])
            assert m.min() >= 0.2 and m.max() <= 0.9
            slices = np.floor((m - 0.2) / 0.7 * 5).astype(int)
            assert sorted(slices) == [0, 1, 2, 3, 4]
            pooled.append(m)
        assert (spec.strength[spec.state == "f4"] == 0.4).all()  # one value: that value
        assert (spec.strength[spec.state == "f19"] < 0).all()  # direction kept
    p = stats.kstest(np.concatenate(pooled), stats.uniform(0.2, 0.7).cdf).pvalue
    assert p > 1e-3
    # the slices are taken in a random order: not always the weakest run first
    firsts = [parse_campaign(table).run_specs(s).strength[0] for s in range(20)]
    assert np.ptp(firsts) > 0.35


def test_uniform_strengths_are_the_default_and_a_fault_may_override_the_draw():
    table = _minimal(states=["f1", "f2"], runs_per_state=4)
    default = parse_campaign(table)
    assert {s.draw for s in default.faults.values()} == {"uniform"}
    explicit = _minimal(states=["f1", "f2"], runs_per_state=4)
    explicit["faults"]["draw"] = "uniform"
    np.testing.assert_array_equal(
        parse_campaign(explicit).run_specs().strength, default.run_specs().strength
    )
    table["faults"]["f2"] = {"draw": "stratified"}
    c = parse_campaign(table)
    assert c.faults["f1"].draw == "uniform" and c.faults["f2"].draw == "stratified"
    f2 = c.run_specs(11).strength[c.run_specs(11).state == "f2"]
    assert sorted(np.floor((f2 - 0.5) / 0.5 * 4).astype(int)) == [0, 1, 2, 3]


_DROP = object()


def _set(table, dotted, value):
    *parents, last = dotted.split(".")
    node = table
    for part in parents:
        node = node.setdefault(part, {})
    if value is _DROP:
        node.pop(last)
    else:
        node[last] = value


BAD_CONFIGS = [
    ("campaign.duration", -5, "campaign.duration must be > 0, got -5"),
    ("campaign.duration", 0, "campaign.duration must be > 0"),
    ("campaign.duration", 3.5, "campaign.duration must be an integer"),
    ("campaign.seed", _DROP, "campaign.seed is missing"),
    ("campaign.seed", -1, "campaign.seed must be >= 0"),
    ("campaign.source", "dgen", "campaign.source must be one of"),
    ("campaign.runs_per_state", 0, "campaign.runs_per_state must be > 0"),
    ("campaign.states", ["fn", "f20"], "campaign.states: unknown state 'f20'"),
    ("campaign.colour", "red", "campaign.colour: unknown key"),
    ("faults.f42", {"strength": 0.5}, "faults.f42: unknown fault"),
    (
        "faults.f2",
        {"strength": [0.5, 1.5]},
        r"faults.f2.strength: \[0.5, 1.5\] not within \[0, 1\]",
    ),
    ("faults.f2", {"strength": [0.9, 0.5]}, "faults.f2.strength: .*low <= high"),
    ("faults.strength", [0.0, 0.5], "faults.strength: .*0 < low"),
    ("faults.strength", "big", "faults.strength must be a magnitude range"),
    ("faults.f1", {"direction": -1}, "faults.f1.direction: f1 only takes positive"),
    ("faults.f3", {"speed": 1}, "faults.f3.speed: unknown key"),
    ("faults.draw", "latin", "faults.draw must be one of uniform, stratified, got 'latin'"),
    ("faults.f3", {"draw": 2}, "faults.f3.draw must be one of uniform, stratified"),
    ("faults.onset", 40.0, r"faults.onset must lie in \[0, campaign.duration=40\)"),
    ("faults.profile", "incipient", "faults.ramp must be > 0 s for an incipient"),
    ("faults.f6", {"ramp": 3.0}, "faults.f6.ramp must be 0 for an abrupt"),
    ("faults.profile", "sudden", "faults.profile must be 'abrupt' or 'incipient'"),
    ("inputs.vary", "yes", "inputs.vary must be true or false"),
    ("inputs.window", "random", "inputs.window: unknown key"),
    ("extra", {}, "extra: unknown key"),
    ("campaign", _DROP, "campaign is missing"),
]


@pytest.mark.parametrize(("key", "value", "message"), BAD_CONFIGS)
def test_bad_configs_name_the_key(key, value, message):
    table = _minimal()
    _set(table, key, value)
    with pytest.raises(CampaignError, match=message):
        parse_campaign(table)


def test_bad_scenarios_name_the_key():
    base = {"campaign": {"name": "s", "seed": 0, "duration": 100, "source": "benchmark-inputs"}}
    cases = [
        ([{"state": "f99", "strength": 0.5}], r"scenarios\[0\].state: unknown state 'f99'"),
        ([{"state": "f1"}], r"scenarios\[0\].strength is missing"),
        ([{"state": "fn"}, {"state": "f1", "strength": 1.2}], r"scenarios\[1\].strength: 1.2 not"),
        ([{"state": "f1", "strength": 0.5, "onset": 100}], r"scenarios\[0\].onset must lie in"),
        ([{"state": "f1", "strength": 0.5, "runs": 0}], r"scenarios\[0\].runs must be > 0"),
        ([{"state": "fn", "strength": 0.5}], r"scenarios\[0\].strength does not apply"),
    ]
    for scenarios, message in cases:
        with pytest.raises(CampaignError, match=message):
            parse_campaign({**base, "scenarios": scenarios})
    both = {**base, "scenarios": [{"state": "fn"}]}
    both["campaign"] = {**base["campaign"], "runs_per_state": 3}
    with pytest.raises(CampaignError, match=r"campaign.runs_per_state must be omitted"):
        parse_campaign(both)


def test_lublin_duration_is_bounded_by_the_hour():
    table = _minimal(source="lublin-example", duration=4000)
    with pytest.raises(CampaignError, match=r"campaign.duration must be <= 3600"):
        parse_campaign(table)


def test_file_errors_name_the_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[campaign]\nname = "x"\nseed = 1\nduration = -1\nsource = "benchmark-inputs"\n')
    with pytest.raises(CampaignError, match=r"bad.toml: campaign.duration must be > 0"):
        load_campaign(bad)
    bad.write_text("[campaign\n")
    with pytest.raises(CampaignError, match="not valid TOML"):
        load_campaign(bad)


def test_label_tables_agree_with_the_model_and_the_dataset_format():
    # campaigns keeps its own copies (it imports neither xarray nor the numba model at import
    # time); they must not drift from the tables they copy
    from bayes_fdi.actuator import FAULT_NAMES, SIGNED_FAULTS
    from bayes_fdi.campaigns import spec as campaigns
    from bayes_fdi.datasets.format import PROFILES, STATES

    assert campaigns.STATES == STATES
    assert campaigns.FAULTS == FAULT_NAMES
    assert campaigns.PROFILES == PROFILES
    assert campaigns.SIGNED_FAULTS == SIGNED_FAULTS
    assert {f for f, d in campaigns.FAULT_DIRECTION.items() if d < 0} <= SIGNED_FAULTS

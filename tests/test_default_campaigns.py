"""The default diagnoser's training campaigns (`sim/online-*.toml`, `bayes_fdi.default_diagnoser`).

The default training "excitation-mix" spans the DGen sines and the three training excitation
families over the DABLib operating ranges, never a family of the shift benchmark; the training
"dgen" is the DGen sines alone. Seeds are below 1000 and no two simulations share one.
"""

from __future__ import annotations

import numpy as np
import pytest

from bayes_fdi.campaigns.simulation import simulate_campaign
from bayes_fdi.default_diagnoser import (
    CALIBRATION_AFTER_ONSET,
    CAMPAIGNS,
    DEFAULT_GROUP_RULES,
    DEFAULT_PHYSICS_INPUTS,
    DEFAULT_TRAINING,
    SET_SEED_OFFSETS,
    TRAININGS,
    fit_online_diagnoser,
    online_campaigns,
    simulate_online_campaigns,
    simulation_plan,
)

MIX = "excitation-mix"

TRAINING_FAMILIES = {"sine-sum", "step-ramp", "level-loop"}
SHIFT_FAMILIES = {"telegraph", "chirp", "flow-loop"}


def _family(campaign) -> str:
    return "dgen" if campaign.source == "benchmark-inputs" else campaign.excitation["family"]


@pytest.mark.parametrize("small", [False, True])
def test_every_set_of_the_mix_spans_dgen_and_the_training_families(small):
    campaigns = online_campaigns(small=small, training=MIX)
    assert set(campaigns) == {"normal", "abrupt", "incipient"}
    for key, files in campaigns.items():
        families = [_family(c) for c in files]
        assert families[0] == "dgen"  # the benchmark's excitation first
        assert not set(families) & SHIFT_FAMILIES
        assert len(set(families)) == len(families)
        if key != "incipient":
            assert set(families) == {"dgen"} | TRAINING_FAMILIES
        for c in files:
            if c.source == "excitation":  # over the DABLib ranges: the generators' defaults
                assert not c.excitation["operating"]
    normal = campaigns["normal"]
    assert all(set(c.run_specs(c.seed).state) == {"fn"} for c in normal)
    for key in ("abrupt", "incipient"):
        for c in campaigns[key]:
            assert set(c.run_specs(c.seed).state) == {f"f{i}" for i in range(1, 20)}
    if not small:  # 12 h of fault-free training, as before the families were added
        assert sum(c.n_runs * c.duration for c in normal) == 48 * 900
        dgen = normal[0].n_runs * normal[0].duration
        assert 0.3 < dgen / (48 * 900) < 0.5


def test_the_default_training_is_the_mix_and_the_dgen_training_the_sines_as_declared():
    assert DEFAULT_TRAINING == MIX and DEFAULT_PHYSICS_INPUTS[MIX] == ("command_lag",)
    assert online_campaigns() == online_campaigns(training=MIX)
    assert simulation_plan() == simulation_plan(training=MIX)
    campaigns = online_campaigns(training="dgen")
    assert {k: tuple(c.name for c in v) for k, v in campaigns.items()} == CAMPAIGNS
    assert [(c.n_runs, c.duration) for cs in campaigns.values() for c in cs] == [
        (48, 900),
        (190, 600),
        (76, 900),
    ]
    assert all(c.source == "benchmark-inputs" for cs in campaigns.values() for c in cs)


def test_the_seeds_are_below_1000_and_distinct():
    campaigns = online_campaigns(training=MIX)
    seeds = []
    for key, files in campaigns.items():
        offsets = [0] if key == "normal" else SET_SEED_OFFSETS.values()
        seeds += [c.seed + o for c in files for o in offsets]
    assert len(set(seeds)) == len(seeds) == 4 + 3 * (4 + 3)
    assert max(seeds) < 1000 and min(seeds) >= 0
    assert [c.name for cs in campaigns.values() for c in cs] == [
        name for files in TRAININGS[MIX].values() for name, _ in files
    ]


def test_a_training_family_campaign_simulates_its_generator_inputs():
    from bayes_fdi.actuator.excitation import step_ramp_inputs

    normal = online_campaigns(small=True, training=MIX)["normal"]
    (campaign,) = [c for c in normal if _family(c) == "step-ramp"]
    ds = simulate_campaign(campaign, seed=campaign.seed, progress=False)
    seed = ds.attrs["inputs_seed"]
    inputs = step_ramp_inputs(campaign.n_runs, campaign.duration, seed=seed)
    np.testing.assert_array_equal(ds["CV"].values, inputs["CV"].values)
    assert (ds["P1"].values > ds["P2"].values).all()


def test_a_seed_beyond_the_last_allowed_or_an_unknown_training_is_refused_by_name():
    with pytest.raises(ValueError, match=r"seed must be an integer in \[0, 529\)"):
        simulate_online_campaigns(seed=529, small=True, progress=False)
    with pytest.raises(ValueError, match=r"seed must be an integer in \[0, 549\)"):
        simulate_online_campaigns(seed=549, small=True, progress=False, training="dgen")
    with pytest.raises(ValueError, match="training must be one of dgen, excitation-mix"):
        online_campaigns(training="chirp")
    # checked before anything is simulated
    with pytest.raises(ValueError, match="isolation must be one of tree, forest, got 'svm'"):
        fit_online_diagnoser(isolation="svm", small=True, progress=False)


def test_the_long_calibration_sees_settled_abrupt_faults_and_slow_incipient_ones():
    # by default the calibration parts are the fault files' own runs; with "top-label-long" the
    # abrupt calibration runs last CALIBRATION_AFTER_ONSET s after the onset and the slow
    # incipient file gives the calibration set alone, with the calibration offset
    # (the DGen training: one file per set)
    default = [
        (part, c.name, c.duration, s) for part, c, s in simulation_plan(seed=3, training="dgen")
    ]
    assert default == [
        ("normal", "online-normal", 900, 104),
        ("train", "online-faults-abrupt", 600, 204),
        ("validation", "online-faults-abrupt", 600, 304),
        ("calibration", "online-faults-abrupt", 600, 404),
        ("train", "online-faults-incipient", 900, 254),
        ("validation", "online-faults-incipient", 900, 354),
        ("calibration", "online-faults-incipient", 900, 454),
    ]
    long = simulation_plan(seed=3, training="dgen", calibration="top-label-long")
    assert [(part, c.name, c.duration, s) for part, c, s in long] == [
        *default[:3],
        ("calibration", "online-faults-abrupt", 120 + CALIBRATION_AFTER_ONSET, 404),
        *default[4:],
        ("calibration", "online-calibration-incipient-slow", 3720, 444),
    ]
    slow = long[-1][1]
    assert slow.n_runs == 76 and set(slow.run_specs(slow.seed).state) == {
        f"f{i}" for i in range(1, 20)
    }
    small = simulation_plan(small=True, calibration="top-label-long")
    assert [(part, c.duration) for part, c, _ in small] == [
        (part, c.duration) for part, c, _ in simulation_plan(small=True)
    ]
    with pytest.raises(
        ValueError, match="calibration must be one of age-temperature, temperature, top-label"
    ):
        simulation_plan(calibration="isotonic")
    # the seeds of the long calibration stay below 1000 with the largest allowed seed
    top = simulation_plan(seed=548, training="dgen", calibration="top-label-long")
    assert max(s for _, _, s in top) < 1000


def test_the_forest_option_names_the_faults_with_a_seeded_forest():
    from bayes_fdi.diagnosis.isolation import ForestClassifier

    diag = fit_online_diagnoser(seed=3, small=True, progress=False, isolation="forest")
    forest = diag.isolator_.classifier_
    assert isinstance(forest, ForestClassifier) and forest.random_state == 3
    assert diag.isolator_.rows_independent  # its compiled per-second pass
    # the default recalibration: one temperature per age bin of the signature
    from bayes_fdi.calibration import AgeTemperatureScaler

    assert isinstance(diag.isolator_.calibrator_, AgeTemperatureScaler) and diag.isolator_.uses_ages
    assert diag.normal_models_.physics_inputs == DEFAULT_PHYSICS_INPUTS[DEFAULT_TRAINING]
    # the groups from how the validation runs' seconds are named, as commissioning finds them
    assert diag.group_rule == DEFAULT_GROUP_RULES[DEFAULT_TRAINING] == "naming"
    assert diag.isolator_.group_rule == "naming"
    # a stream in two chunks is the stream in one, probabilities included
    from bayes_fdi.actuator import Fault, benchmark_inputs, simulate

    run = simulate(benchmark_inputs(1, 400, seed=7), [Fault("f18", 0.8, 150.0)], seed=7)
    run = run[["CV", "P1", "P2", "T1", "X", "F"]].isel(run=0)
    whole = diag.run(run)
    first, state = diag.run(run.isel(time=slice(0, 230)), return_state=True)
    second = diag.run(run.isel(time=slice(230, None)), state=state)
    assert whole["DD"].values[230:].any()
    joined = np.concatenate([first["group_proba"].values, second["group_proba"].values])
    np.testing.assert_array_equal(joined, whole["group_proba"].values)

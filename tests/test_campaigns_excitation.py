"""Campaigns driven by an excitation family (``source = "excitation"``, the ``[excitation]``
table): every family simulates, the inputs are the generator's own draw, the same seed gives the
same data, and every bad key is refused with its name."""

from __future__ import annotations

import numpy as np
import pytest

from bayes_fdi.actuator import NOISE_STD
from bayes_fdi.actuator.excitation import LevelLoop, OperatingRange, level_loop_inputs
from bayes_fdi.campaigns import CampaignError, load_campaign, parse_campaign, simulate_campaign
from bayes_fdi.campaigns.excitation import EXCITATION_FAMILIES, excitation_inputs

FAMILIES = tuple(EXCITATION_FAMILIES)


def _table(excitation, **campaign):
    head = {"name": "excited", "seed": 5, "duration": 120, "source": "excitation",
            "runs_per_state": 2, "states": ["fn", "f1"], "batch_size": 4, **campaign}  # fmt: skip
    return {"campaign": head, "excitation": excitation, "faults": {"onset": 40.0}}


@pytest.mark.parametrize("family", FAMILIES)
def test_each_family_simulates_with_its_generators_inputs_and_is_reproducible(family):
    campaign = parse_campaign(_table({"family": family}))
    ds = simulate_campaign(campaign, progress=False)
    assert ds.sizes == {"run": 4, "time": 120}
    assert list(ds["state"].values) == ["fn", "fn", "f1", "f1"]
    # the inputs are the generator's draw with the recorded inputs seed (f1 leaves them alone):
    # CV exactly, the measured P1, P2, T1 within the sensors' noise (std NOISE_STD)
    drawn = excitation_inputs(campaign.excitation, 4, 120, seed=ds.attrs["inputs_seed"])
    assert drawn.attrs["generator"] == family
    np.testing.assert_array_equal(ds["CV"].values, drawn["CV"].values)
    for channel in ("P1", "P2", "T1"):
        error = ds[channel].values - drawn[channel].values
        assert np.abs(error).max() < 6 * NOISE_STD
        assert 0.5 * NOISE_STD < error.std() < 2 * NOISE_STD
    # same seed, any batch size: the same data; another seed: other data
    again = simulate_campaign(campaign.replace(batch_size=1), progress=False)
    assert ds.equals(again)
    other = simulate_campaign(campaign, seed=6, progress=False)
    assert not np.array_equal(ds["CV"].values, other["CV"].values)
    # the fault acts from its onset: before it, the faulty runs see a fault-free valve
    assert ds.attrs["source"] == "excitation"
    assert f'"family": "{family}"' in ds.attrs["campaign_config"]


def test_parameters_and_operating_range_reach_the_generator():
    table = _table({"family": "level-loop", "kp": [1.0, 1.0], "ti": [100, 100],
                    "operating": {"p1": [3.0e6, 3.0e6], "t1": [50.0, 50.0]}})  # fmt: skip
    campaign = parse_campaign(table)
    loop = LevelLoop(kp=(1.0, 1.0), ti=(100.0, 100.0))
    op = OperatingRange(p1=(3.0e6, 3.0e6), t1=(50.0, 50.0))
    direct = level_loop_inputs(3, 80, seed=11, loop=loop, operating=op)
    drawn = excitation_inputs(campaign.excitation, 3, 80, seed=11)
    np.testing.assert_array_equal(drawn["CV"].values, direct["CV"].values)
    np.testing.assert_array_equal(drawn["P1"].values, direct["P1"].values)


def test_a_campaign_file_with_an_excitation_table_loads_and_takes_overrides(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text(
        '[campaign]\nname = "c"\nseed = 1\nduration = 60\nsource = "excitation"\n'
        'runs_per_state = 1\nstates = ["fn"]\n\n[excitation]\nfamily = "sine-sum"\n'
        "frequencies = [0.01, 0.02]\n"
    )
    campaign = load_campaign(path, **{"excitation.n_sines": 2})
    assert campaign.excitation["parameters"] == {"frequencies": (0.01, 0.02), "n_sines": 2}
    with pytest.raises(CampaignError, match=r"c\.toml: excitation\.n_sines must be an integer"):
        load_campaign(path, **{"excitation.n_sines": 2.5})


@pytest.mark.parametrize(
    ("excitation", "message"),
    [
        ({}, r"excitation\.family is missing"),
        ({"family": "square"}, r"excitation\.family must be one of sine-sum, .*got 'square'"),
        ({"family": "sine-sum", "n_sine": 2}, r"excitation\.n_sine: unknown key \(allowed: "),
        ({"family": "sine-sum", "n_sines": 2.0}, r"excitation\.n_sines must be an integer"),
        ({"family": "sine-sum", "frequencies": 0.01}, r"excitation\.frequencies must be a pair"),
        ({"family": "sine-sum", "frequencies": [0.02, 0.01]}, r"\.frequencies must have low <="),
        ({"family": "sine-sum", "frequencies": [0.01, 0.9]}, r"excitation: sine_sum_inputs: "),
        ({"family": "level-loop", "kp": ["a", 1]}, r"excitation\.kp must be a number"),
        ({"family": "chirp", "p1_frequency": float("nan")}, r"\.p1_frequency must be finite"),
        ({"family": "telegraph", "operating": {"p3": [1, 2]}}, r"\.operating\.p3: unknown key"),
        ({"family": "telegraph", "operating": 3}, r"excitation\.operating must be a table"),
        ("sine-sum", r"excitation must be a table"),
    ],
)
def test_bad_excitation_tables_are_refused_naming_the_key(excitation, message):
    with pytest.raises(CampaignError, match=message):
        parse_campaign(_table(excitation))


def test_the_excitation_table_belongs_to_the_excitation_source_only():
    with pytest.raises(CampaignError, match=r"excitation is missing"):
        parse_campaign({"campaign": _table({})["campaign"]})
    table = _table({"family": "sine-sum"}, source="benchmark-inputs")
    with pytest.raises(CampaignError, match=r"excitation is only for campaign\.source"):
        parse_campaign(table)
    table = _table({"family": "sine-sum"})
    table["inputs"] = {"vary": True}
    with pytest.raises(CampaignError, match=r"inputs\.vary is not used with source"):
        parse_campaign(table)

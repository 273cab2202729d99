"""The 44 Step-I scenarios against the benchmark's definition, and their simulation."""

from collections import Counter

import numpy as np
import pytest

from bayes_fdi.actuator import NOISE_STD, benchmark_inputs, simulate
from bayes_fdi.benchmark.scenarios import (
    BENCHMARK_SEED,
    FAULT_FREE_SEED,
    SCENARIOS,
    benchmark_seeds,
    fault_free_hours,
    iter_scenarios,
    simulate_scenario,
)

BY_NAME = {s.name: s for s in SCENARIOS}


def test_the_table_holds_the_benchmarks_44_scenarios():
    assert len(SCENARIOS) == 44 and len(BY_NAME) == 44  # names are unique
    modes = Counter((s.mode, s.size) for s in SCENARIOS)
    # 10 faults x S/M/B, 14 big abrupt (10 + f2, f11, f15, f17), 10 incipient
    assert modes == {("abrupt", "small"): 10, ("abrupt", "medium"): 10, ("abrupt", "big"): 14,
                     ("incipient", None): 10}  # fmt: skip
    strengths = {s.size: s.strength for s in SCENARIOS}
    assert strengths == {"small": 0.25, "medium": 0.5, "big": 0.75, None: 1.0}
    big_only = {s.fault for s in SCENARIOS if s.mode == "abrupt"} - {
        s.fault for s in SCENARIOS if s.size == "small"
    }
    assert big_only == {"f2", "f11", "f15", "f17"}


@pytest.mark.parametrize(
    ("faults", "t_fd", "t_hor"),
    [
        (("f2", "f3", "f5", "f6", "f9", "f11", "f18"), 84_000.0, 85_500.0),
        (("f4", "f17"), 3_600.0, 5_100.0),
        (("f13",), 900.0, 2_400.0),
    ],
)
def test_incipient_horizons_are_the_picalc_masks(faults, t_fd, t_hor):
    got = {s.fault: (s.t_fd, s.t_hor) for s in SCENARIOS if s.mode == "incipient"}
    for f in faults:
        assert got[f] == (t_fd, t_hor)  # t_hor = 900 + t_fd + 600


def test_abrupt_horizons_zones_and_directions():
    for s in SCENARIOS:
        assert (s.t_on, s.t_from) == (300.0, 900.0)
        assert s.t_hor == s.t_from + s.t_fd + 600.0
        if s.mode == "abrupt":
            assert (s.t_fd, s.t_hor) == (0.0, 1500.0)
        negative = s.fault in ("f12", "f14", "f19")
        assert s.direction == (-1 if negative else 1)
        assert np.sign(s.fault_spec().strength) == s.direction
        assert s.fault_spec().validated() == s.fault_spec()


def test_seeds_are_disjoint_from_training_and_from_the_fault_free_hours():
    seeds = benchmark_seeds(10)
    assert seeds == tuple(range(10_000, 10_010)) and BENCHMARK_SEED == 10_000
    assert min(seeds) >= 1000 and FAULT_FREE_SEED not in seeds  # training seeds are < 1000
    with pytest.raises(ValueError, match="n_seeds"):
        benchmark_seeds(0)


def test_no_training_campaign_draws_the_benchmarks_noise_streams():
    # simulate_campaign(seed=s) draws its noise from a seed derived from s (a 32-bit hash), not
    # from s itself: none of the derived noise seeds of the training seeds 0..999 may be a
    # benchmark or fault-free seed, or a training run could share a benchmark run's noise
    from bayes_fdi.campaigns.simulation import _derived_seeds

    reserved = set(benchmark_seeds(1000)) | {FAULT_FREE_SEED}
    derived = {_derived_seeds(s)[1] for s in range(1000)}
    assert not derived & reserved


def test_an_incipient_ramp_reaches_its_strength_at_its_time():
    # f18 incipient: the bypass valve's Kv = 19.75 f(t) with f(t) = (t - 900) / 84000, so the
    # true flow of the faulty run exceeds the nominal one by the bypass law 100 Kv sqrt(dp / rho)
    # (dp in MPa, rho = 1000): f = 0 at 900 s, 0.5 at 42 900 s, 1.0 from 84 900 s on.
    s = BY_NAME["f18 incipient"]
    inputs = benchmark_inputs(n_runs=2, duration=round(s.t_hor))
    _, states = simulate(inputs, [s.fault_spec(), None], noise=False, return_states=True)
    t = np.array([899, 900, 42_900, 84_900, 85_499])
    fs = s.strength_at(t)
    np.testing.assert_allclose(fs, [0.0, 0.0, 0.5, 1.0, 1.0], rtol=0, atol=1e-12)
    dp = (inputs.P1.values[0, t] - inputs.P2.values[0, t]) * 4.0  # MPa
    bypass = 100.0 * 19.75 * fs * np.sqrt(dp / 1000.0)
    extra = states.F_true.values[0, t] - states.F_true.values[1, t]
    # the bypass does not move the stem, so the flow difference is the bypass flow itself
    # (the kernel's double-precision arithmetic: agreement to round-off)
    np.testing.assert_allclose(extra, bypass, rtol=1e-9, atol=1e-12)


def test_simulate_scenario_runs_to_the_horizon_with_its_own_noise_per_seed():
    big_f1 = BY_NAME["f1 abrupt big"]
    runs = simulate_scenario(big_f1, [10_000, 10_001])
    assert runs.sizes == {"run": 2, "time": 1500} and runs.run.values.tolist() == [10_000, 10_001]
    assert set(runs.state.values) == {"f1"} and set(runs.strength.values) == {0.75}
    # before the onset the fault does nothing: the run equals a fault-free simulation with the
    # same noise stream (seed, run id = the scenario's position in the table)
    position = SCENARIOS.index(big_f1)
    inputs = benchmark_inputs(n_runs=1, duration=1500).assign_coords(run=[position])
    nominal = simulate(inputs, None, seed=10_001)
    np.testing.assert_array_equal(runs.X.values[1, :900], nominal.X.values[0, :900])
    # another scenario with the same seed draws other noise: the difference of the fault-free
    # parts is the difference of two independent noises, std sqrt(2) * NOISE_STD
    other = simulate_scenario(BY_NAME["f7 abrupt big"], [10_001])
    diff = runs.X.values[1, :900] - other.X.values[0, :900]
    # 900 samples: the sample std lies within 10 % of sqrt(2) NOISE_STD (its relative standard
    # error is 1 / sqrt(2 * 900) = 2.4 %, so 10 % is over 4 standard errors)
    assert np.std(diff) == pytest.approx(np.sqrt(2) * NOISE_STD, rel=0.10)


def test_truncated_scenarios_and_batches():
    s = BY_NAME["f2 incipient"].truncated(2000)
    assert (s.t_fd, s.t_hor) == (84_000.0, 2000.0)
    batches = list(iter_scenarios([s], [10_000, 10_001, 10_002], batch=2))
    assert [b.sizes["run"] for _, b in batches] == [2, 1]
    assert all(b.sizes["time"] == 2000 for _, b in batches)
    with pytest.raises(ValueError, match="exceed t_from"):
        s.truncated(900)


def test_fault_free_hours_cover_warmup_plus_the_budget():
    ds = fault_free_hours(0.1, warmup=300)
    assert ds.sizes == {"run": 1, "time": 300 + 360}
    assert ds.state.values.tolist() == ["fn"] and ds.run.values.tolist() == [FAULT_FREE_SEED]
    assert ds.attrs["hours"] == 0.1 and ds.attrs["warmup"] == 300.0


def test_the_campaign_file_lists_the_same_scenarios():
    from pathlib import Path

    from bayes_fdi.campaigns.parsing import load_campaign

    c = load_campaign(Path(__file__).parents[1] / "sim" / "damadics-benchmark.toml")
    faulty = [s for s in c.scenarios if s.state != "fn"]
    got = {(s.state, s.profile, abs(s.strength), s.ramp) for s in faulty}
    assert len(faulty) == 44
    assert got == {(s.fault, s.mode, s.strength, s.t_fd) for s in SCENARIOS}
    assert all(np.sign(s.strength) == BY_NAME[f"{s.state} {s.profile}"].direction
               for s in faulty if s.profile == "incipient")  # fmt: skip

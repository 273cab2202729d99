"""``benchmarks/excitation_temperature.py``: the benchmark's calibration sample, recalibrated."""

from __future__ import annotations

import numpy as np
import pytest
from benchmark_scripts import load_benchmark
from small_online import small_calibrated_diagnoser, small_runs

from bayes_fdi.benchmark.collection import RunCollector
from bayes_fdi.benchmark.scenarios import SCENARIOS, simulate_scenario, strip_truth
from bayes_fdi.calibration import TemperatureScaler

tool = load_benchmark("excitation_temperature")


def test_the_sample_is_the_benchmarks_and_the_model_calibrates_the_classifiers_own():
    """The seconds the tool scores are those `RunCollector` keeps for the benchmark's ECE (a
    collector of its own over the same stream agrees), and the classifier's own probabilities
    of those seconds (the stream with the calibrator set aside) are the ones the model's
    temperature turned into its probabilities: softmax(log p / T), second by second."""
    runs_fit = small_runs()
    model = small_calibrated_diagnoser(runs_fit)
    raw = small_calibrated_diagnoser(runs_fit)
    raw.isolator_.calibrator_ = None
    by_name = {s.name: s for s in SCENARIOS}
    scenario = by_name["f7 abrupt big"].truncated(1500.0)
    seeds = (5000, 5001)
    runs = simulate_scenario(scenario, seeds, position=7)
    x = strip_truth(runs)
    stream = model.run(x)
    raw_stream = raw.run(x)
    rows = tool.benchmark_sample(stream, raw_stream, runs, scenario, 120)
    collector = RunCollector(seed=0)
    for i, seed in enumerate(seeds):
        collector.add(scenario, seed, stream.isel(run=i))
    assert len(rows) == len(collector.proba) == 2
    for (proba, own, cov, true), want, want_true in zip(
        rows, collector.proba, collector.true, strict=True
    ):
        np.testing.assert_array_equal(proba, want)
        np.testing.assert_array_equal(true, want_true)
        assert proba.shape[0] > 0 and cov.shape == (proba.shape[0], 3)
        t = model.isolator_.calibrator_.temperature_
        by_hand = np.exp(np.log(np.maximum(own, 1e-300)) / t)
        by_hand /= by_hand.sum(axis=1, keepdims=True)
        np.testing.assert_allclose(proba, by_hand, rtol=1e-9, atol=1e-12)
    # the signature's strength instead of the inputs: the same seconds, the stream's covariates
    strength = tool.families.covariates_of(runs, raw_stream, 120, "strength")
    rows_s = tool.benchmark_sample(stream, raw_stream, runs, scenario, 120, "strength")
    for i, (row, row_s) in enumerate(zip(rows, rows_s, strict=True)):
        np.testing.assert_array_equal(row[0], row_s[0])
        np.testing.assert_array_equal(row_s[2], strength[i][collector.index[i]])
        assert row_s[2].shape == (row[0].shape[0], 2) and np.isfinite(row_s[2]).all()


def test_a_constant_excitation_temperature_is_one_temperature():
    """With weights ``[log T, 0, 0, 0]`` the excitation's temperature is temperature scaling
    by ``T``, whatever the covariates."""
    rng = np.random.default_rng(0)
    proba = rng.dirichlet(np.ones(4), size=50)
    cov = rng.uniform(0.01, 1.0, size=(50, 3))
    scaler = TemperatureScaler(classes=[0, 1, 2, 3]).fit(proba, rng.integers(0, 4, 50))
    t = scaler.temperature_
    weights = np.array([np.log(t), 0.0, 0.0, 0.0])
    got = tool.families.scaled(np.log(proba), tool.design(cov) @ weights)
    np.testing.assert_allclose(got, scaler.transform(proba), rtol=1e-9, atol=1e-12)


def test_the_covariates_are_trailing_standard_deviations_by_hand():
    import xarray as xr

    cv = np.array([0.5, 0.5, 0.7, 0.1, 0.4])
    p1 = np.full(5, 3.0e6)
    p2 = np.array([2.0e6, 2.1e6, 2.0e6, 2.0e6, 2.2e6])
    runs = xr.Dataset(
        {k: (("run", "time"), v[None]) for k, v in {"CV": cv, "P1": p1, "P2": p2}.items()}
    )
    cov = tool.families.covariates_of(runs, None, 3, "inputs")[0]
    dcv = np.diff(cv, prepend=cv[0])
    for t in range(5):
        lo = max(0, t - 2)
        want = [np.std(v[lo : t + 1]) for v in (cv, dcv, p1 - p2)]
        np.testing.assert_allclose(cov[t], want, rtol=1e-12, atol=1e-9)
    assert cov[0] == pytest.approx([0.0, 0.0, 0.0])

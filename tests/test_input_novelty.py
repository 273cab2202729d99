"""The input novelty of the dynamic normal models (``std_bins="novelty"``): the distance of a
second's standardised inputs to the nearest of a sample of training inputs, binning the
predictive standard deviations' factors.

Checked against a brute-force search over every pair (the compiled distance and scikit-learn's
k-d tree alike), against
the inputs the fit standardises, against the out-of-fold residuals the factors calibrate, whole
against second by second, through a model file, and against files saved before the option."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from second_by_second import second_by_second

from bayes_fdi import model_files
from bayes_fdi.actuator import benchmark_inputs, simulate
from bayes_fdi.actuator.excitation import step_ramp_inputs
from bayes_fdi.diagnosis.normal_models.dynamic import DynamicNormalModels
from bayes_fdi.diagnosis.normal_models.dynamic_kernel import NormalModelsParams, dynamic_inputs
from bayes_fdi.diagnosis.normal_models.input_novelty import (
    NOVELTY_LEVELS,
    NOVELTY_REFERENCE_ROWS,
    input_novelty,
    nearest_distance,
    novelty_columns,
    novelty_reference,
)

SMALL = dict(
    x_widths=(8.0,), f_widths=(0.1,), evidence_max_samples=200, max_train_samples=300,
    calibration_folds=3, std_coverage=0.9, random_state=0,
)  # fmt: skip


@pytest.fixture(scope="module")
def normal():
    """Fault-free runs under DGen sines and under command steps and ramps."""
    sines = simulate(benchmark_inputs(3, 600, seed=61, vary=True), seed=61)
    steps = simulate(step_ramp_inputs(3, 600, seed=62), seed=62)
    return xr.concat([sines, steps], dim="run")


@pytest.fixture(scope="module")
def models(normal):
    return DynamicNormalModels(std_bins="novelty", **SMALL).fit(normal)


def brute_force(Z: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """The distance of each row of ``Z`` to its nearest row of ``reference``, every pair
    computed."""
    return np.sqrt(((Z[:, None, :] - reference[None, :, :]) ** 2).sum(axis=-1).min(axis=1))


def test_the_compiled_and_the_k_d_tree_distances_are_the_brute_force_ones():
    rng = np.random.default_rng(63)
    reference, Z = rng.normal(size=(300, 6)), rng.normal(size=(50, 6)) * 2
    Z[3, 2] = np.nan
    finite = np.arange(50) != 3
    want = brute_force(Z[finite], reference)
    got = input_novelty(Z, reference)  # scikit-learn's k-d tree
    assert np.isnan(got[3])
    np.testing.assert_allclose(got[finite], want, rtol=1e-12)
    everything = np.arange(6)
    compiled = [nearest_distance(Z[i], reference, everything) for i in np.flatnonzero(finite)]
    np.testing.assert_allclose(compiled, want, rtol=1e-12)
    # over a subset of the columns: the distance to the reference restricted to them
    some = np.array([0, 4])
    want = brute_force(Z[:2][:, some], reference[:, some])
    sub = np.ascontiguousarray(reference[:, some])
    got = [nearest_distance(Z[i], sub, some) for i in (0, 1)]
    np.testing.assert_allclose(got, want, rtol=1e-12)
    np.testing.assert_allclose(input_novelty(Z[:2], sub, some), want, rtol=1e-12)
    # the reference: distinct training rows in row order, all of them when fewer
    rows = novelty_reference(Z, np.arange(10), rng, everything)
    np.testing.assert_array_equal(rows, Z[:10])
    big = rng.normal(size=(2000, 2))
    ref = novelty_reference(big, np.arange(2000), np.random.default_rng(0), np.arange(2))
    assert ref.shape == (NOVELTY_REFERENCE_ROWS, 2) and len(np.unique(ref[:, 0])) == ref.shape[0]


def test_the_commands_novelty_leaves_out_the_process_inputs():
    # u = (CV, s, dCV_0, dCV_1, ds_0, ds_1, lag): the command's columns are its level, its
    # increments and its lag
    np.testing.assert_array_equal(novelty_columns("command-novelty", 2, True), [0, 2, 3, 6])
    np.testing.assert_array_equal(novelty_columns("command-novelty", 2, False), [0, 2, 3])
    np.testing.assert_array_equal(novelty_columns("novelty", 2, True), np.arange(7))


def test_the_kernel_bins_by_the_distance_to_the_reference(models):
    nm = models
    ref = nm.params_.novelty_reference
    assert ref.shape == (NOVELTY_REFERENCE_ROWS, nm.input_mean_.size)
    assert nm.std_scale_edges_.size == len(NOVELTY_LEVELS)
    test = simulate(step_ramp_inputs(1, 300, seed=64), seed=64)
    out, _ = nm.run({c: test[c].values[0] for c in ("CV", "P1", "P2")})
    Z = (dynamic_inputs(test, nm.n_differences)[0] - nm.input_mean_) / nm.input_scale_
    np.testing.assert_allclose(out[:, 4], input_novelty(Z, ref), rtol=1e-12)
    bins = np.searchsorted(nm.std_scale_edges_, out[:, 4], side="right")
    raw = nm.regressors_["X"].predict(Z, return_std=True)[1]
    np.testing.assert_allclose(out[:, 1], raw * nm.std_scale_["X"][bins], rtol=1e-9)


def test_the_farthest_seconds_get_the_largest_factors(models):
    # out of fold, the seconds far from the training rows (the steps' transients) spread more
    # than the nearest half, whose bin has the smallest factor (the top bin, 0.1 % of the
    # seconds, holds too few of them to rank reliably)
    for c in ("X", "F"):
        scale = models.std_scale_[c]
        assert scale.argmin() == 0 and scale[1:].max() > 1.5 * scale[0]


def test_stream_and_file_round_trip(models, tmp_path):
    test = simulate(step_ramp_inputs(1, 120, seed=65), seed=65)
    channels = {c: test[c].values[0] for c in ("CV", "P1", "P2")}
    whole, _ = models.run(channels)
    np.testing.assert_array_equal(second_by_second(models, channels)[0], whole)
    again = model_files.load(model_files.save(models, tmp_path / "novelty.model"))
    assert again.std_bins == "novelty"
    np.testing.assert_array_equal(again.run(channels)[0], whole)


def test_std_bins_is_checked():
    normal = simulate(benchmark_inputs(2, 60, seed=66), seed=66)
    with pytest.raises(ValueError, match="std_bins must be one of"):
        DynamicNormalModels(std_bins="distance").fit(normal)


def test_files_saved_before_the_option_bin_by_speed():
    new = NormalModelsParams.upgrade_model_file({"valve_law": np.empty(0)}, 11)
    assert new["novelty_reference"].shape == (0, 0)


def test_a_pressure_step_moves_the_novelty_not_the_commands(normal, models):
    command = DynamicNormalModels(std_bins="command-novelty", **SMALL).fit(normal)
    assert command.params_.novelty_reference.shape == (NOVELTY_REFERENCE_ROWS, 3)
    test = simulate(step_ramp_inputs(1, 200, seed=67), seed=67)
    channels = {c: test[c].values[0] for c in ("CV", "P1", "P2")}
    dropped = dict(channels, P2=channels["P2"] - np.where(np.arange(200) >= 100, 0.1, 0.0))
    for nm, moved in ((command, False), (models, True)):
        before, after = nm.run(channels)[0][:, 4], nm.run(dropped)[0][:, 4]
        np.testing.assert_array_equal(before[:100], after[:100])
        assert bool(np.any(before[100:] != after[100:])) is moved

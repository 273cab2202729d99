"""Tests of the residual feature registry and extraction."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from bayes_fdi.diagnosis.isolation.features import (
    DEFAULT_FEATURES,
    FEATURES,
    extract_features,
    register_feature,
    window_bounds,
)


def residual_ds(rng: np.random.Generator, n_runs: int = 4, n_times: int = 50) -> xr.Dataset:
    shape = (n_runs, n_times)
    data = {k: (("run", "time"), rng.normal(size=shape)) for k in ("r1", "r2", "z1", "z2")}
    return xr.Dataset(
        data, coords={"run": np.arange(n_runs), "time": np.arange(n_times, dtype=float)}
    )


def test_default_features_are_the_papers_mean_residuals(rng):
    res = residual_ds(rng)
    feats, names = extract_features(res)
    assert names == DEFAULT_FEATURES == ("mean_r1", "mean_r2")
    assert feats.shape == (4, 2)
    for i in range(4):  # independent: plain Python means
        assert feats[i, 0] == pytest.approx(sum(res["r1"].values[i]) / 50, rel=1e-12)
        assert feats[i, 1] == pytest.approx(sum(res["r2"].values[i]) / 50, rel=1e-12)


def test_builtin_statistics_match_numpy(rng):
    res = residual_ds(rng)
    names = ("std_r1", "rms_r2", "mean_z1", "max_abs_z2")
    feats, got = extract_features(res, names)
    assert got == names
    r1, r2 = res["r1"].values, res["r2"].values
    z1, z2 = res["z1"].values, res["z2"].values
    np.testing.assert_allclose(feats[:, 0], r1.std(axis=1))
    np.testing.assert_allclose(feats[:, 1], np.sqrt((r2**2).mean(axis=1)))
    np.testing.assert_allclose(feats[:, 2], z1.mean(axis=1))
    np.testing.assert_allclose(feats[:, 3], np.abs(z2).max(axis=1))


def test_windows_and_steps(rng):
    res = residual_ds(rng, n_runs=2, n_times=10)
    np.testing.assert_array_equal(window_bounds(10, 4, 3), [[0, 4], [3, 7], [6, 10]])
    np.testing.assert_array_equal(window_bounds(10, 4), [[0, 4], [4, 8]])
    feats, _ = extract_features(res, ("mean_r1",), window=4, step=3)
    assert feats.shape == (2, 3, 1)
    r1 = res["r1"].values
    for w, start in enumerate((0, 3, 6)):
        np.testing.assert_allclose(feats[:, w, 0], r1[:, start : start + 4].mean(axis=1))


def test_nan_residuals_are_ignored_and_empty_window_is_nan(rng):
    res = residual_ds(rng, n_runs=2, n_times=6)
    r1 = res["r1"].values.copy()
    r1[0, :2] = np.nan
    r1[1, :3] = np.nan
    res["r1"] = (("run", "time"), r1)
    feats, _ = extract_features(res, ("mean_r1",), window=3)
    assert feats[0, 0, 0] == pytest.approx(r1[0, 2])
    assert np.isnan(feats[1, 0, 0])
    np.testing.assert_allclose(feats[:, 1, 0], r1[:, 3:].mean(axis=1))


def test_register_custom_feature(rng):
    res = residual_ds(rng)

    @register_feature("test_p90_abs_r2", overwrite=True)
    def p90(window_res):
        return np.nanpercentile(np.abs(window_res["r2"].values), 90, axis=1)

    try:
        feats, names = extract_features(res, ("mean_r1", "test_p90_abs_r2"))
        assert names[1] == "test_p90_abs_r2"
        np.testing.assert_allclose(feats[:, 1], np.percentile(np.abs(res["r2"].values), 90, axis=1))
        with pytest.raises(ValueError, match="already registered"):
            register_feature("test_p90_abs_r2", lambda r: r["r1"].values.mean(axis=1))
    finally:
        FEATURES.pop("test_p90_abs_r2", None)


def test_bad_requests_raise(rng):
    res = residual_ds(rng)
    with pytest.raises(ValueError, match="unknown feature"):
        extract_features(res, ("mean_r9",))
    with pytest.raises(ValueError, match="longer than the runs"):
        extract_features(res, window=51)
    with pytest.raises(ValueError, match="lacks 'r2'"):
        extract_features(res.drop_vars("r2"))
    register_feature("test_bad_shape", lambda r: np.zeros(3), overwrite=True)
    try:
        with pytest.raises(ValueError, match="returned shape"):
            extract_features(res, ("test_bad_shape",))
    finally:
        FEATURES.pop("test_bad_shape", None)

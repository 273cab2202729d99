"""Dynamic normal models of the online diagnoser (bayes_fdi.diagnosis.normal_models.dynamic)."""

from __future__ import annotations

import numpy as np
import pytest
from second_by_second import second_by_second

from bayes_fdi.actuator import Fault, benchmark_inputs, simulate
from bayes_fdi.diagnosis.normal_models.dynamic import (
    RAIL_TOL,
    DynamicNormalModels,
    standardised_residuals,
)
from bayes_fdi.diagnosis.normal_models.dynamic_kernel import dynamic_inputs, signed_root


@pytest.fixture(scope="module")
def models():
    normal = simulate(benchmark_inputs(4, 300, seed=11, vary=True), seed=11)
    nm = DynamicNormalModels(
        x_widths=(8.0,), f_widths=(0.1,), evidence_max_samples=200, max_train_samples=300,
        calibration_folds=2, random_state=0,
    ).fit(normal)  # fmt: skip
    return nm, normal


def test_inputs_are_held_increments_with_nan_propagation():
    import xarray as xr

    cv = np.array([[0.5, 0.6, np.nan, 0.7, 0.9, 1.0]])
    p1, p2 = np.full_like(cv, 0.8), np.array([[0.6, 0.7, 0.6, 0.9, 0.6, 0.6]])
    ds = xr.Dataset({"CV": (("run", "time"), cv), "P1": (("run", "time"), p1),
                     "P2": (("run", "time"), p2)})  # fmt: skip
    U = dynamic_inputs(ds, 2)[0]
    s = signed_root(p1, p2)[0]
    assert s[3] == -np.sqrt(0.9 - 0.8)  # P1 < P2: the signed root, kept (same operations)
    # dCV_0 = CV(t) - CV(t-1), dCV_1 = CV(t-1) - CV(t-2); held at the first value before t = 0
    np.testing.assert_allclose(U[:, 2], [0.0, 0.1, np.nan, np.nan, 0.2, 0.1], equal_nan=True)
    np.testing.assert_allclose(U[:, 3], [0.0, 0.0, 0.1, np.nan, np.nan, 0.2], equal_nan=True)
    np.testing.assert_allclose(U[:, 4], [0.0, s[1] - s[0], s[2] - s[1], s[3] - s[2],
                                         s[4] - s[3], s[5] - s[4]])  # fmt: skip


def test_stream_equals_the_regressions_on_the_vectorised_inputs(models):
    nm, _normal = models
    test = simulate(benchmark_inputs(1, 200, seed=12, vary=True), seed=12)
    got = nm.predict(test)
    U = dynamic_inputs(test, nm.n_differences)[0]
    Z = (U - nm.input_mean_) / nm.input_scale_
    x_mean, x_std = nm.regressors_["X"].predict(Z, return_std=True)
    x_hat = np.clip(x_mean, 0.0, 1.0)
    f_mean, f_std = nm.regressors_["F"].predict(np.column_stack([x_hat, U[:, 1]]),
                                                return_std=True)  # fmt: skip
    speed = np.abs(U[:, 2])
    b = np.searchsorted(nm.std_scale_edges_, speed, side="right")
    # compiled sequential sums against torch matrix products: agreement to rounding
    np.testing.assert_allclose(got["X_hat"].values[0], x_hat, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(got["X_hat_std"].values[0], x_std * nm.std_scale_["X"][b],
                               rtol=1e-10)  # fmt: skip
    np.testing.assert_allclose(got["F_hat"].values[0], np.clip(f_mean, 0, 1), rtol=1e-10,
                               atol=1e-12)  # fmt: skip
    np.testing.assert_allclose(got["F_hat_std"].values[0], f_std * nm.std_scale_["F"][b],
                               rtol=1e-10)  # fmt: skip


def test_stream_state_carries_across_calls(models):
    nm, _ = models
    test = simulate(benchmark_inputs(1, 120, seed=13, vary=True), seed=13)
    channels = {c: test[c].values[0] for c in ("CV", "P1", "P2")}
    whole, end = nm.run(channels)
    rows, state = second_by_second(nm, channels)
    # the same compiled kernel on the same state, one second at a time: identical
    np.testing.assert_array_equal(rows, whole)
    np.testing.assert_array_equal(state.history, end.history)
    # the history holds the last two values of CV and of the signed root of the pressure drop
    np.testing.assert_array_equal(end.history[0], channels["CV"][[-1, -2]])
    np.testing.assert_array_equal(
        end.history[1], signed_root(channels["P1"], channels["P2"])[[-1, -2]]
    )
    # the state passed in is not changed; a state of other models is refused, naming the field
    kept = end.history.copy()
    nm.run(channels, end)
    np.testing.assert_array_equal(end.history, kept)
    assert state.seen[0] == 1
    with pytest.raises(ValueError, match=r"history must be a float64 array of shape \(2, 2\)"):
        nm.run(channels, end._replace(history=np.zeros((2, 3))))


def test_out_of_fold_residuals_are_standardised(models):
    nm, normal = models
    z = nm.oof_z_
    assert z.shape == (normal.sizes["run"], normal.sizes["time"], 2)
    # calibrated per bin by maximum likelihood on these very residuals: unit RMS overall
    # (censored samples, z = 0 by construction, pull it slightly below)
    for j in range(2):
        rms = np.sqrt(np.nanmean(z[..., j] ** 2))
        assert 0.8 < rms <= 1.0 + 1e-9


def test_censored_residuals():
    y = np.array([1.0, 1.0, 0.5, 0.0, 1.0 - RAIL_TOL / 2])
    y_hat = np.array([0.999, 0.9, 0.5, 0.001, 1.0])
    r, z = standardised_residuals(y, y_hat, np.full(5, 0.01))
    np.testing.assert_allclose(r, y - y_hat)
    # at the same rail: no information (z = 0); off the rail: the usual z
    np.testing.assert_allclose(z, [0.0, 10.0, 0.0, 0.0, 0.0], atol=1e-12)


def test_fit_refuses_faulty_runs():
    bad = simulate(benchmark_inputs(2, 60, seed=1), [None, Fault("f1", 0.5)], seed=1)
    with pytest.raises(ValueError, match="fault-free"):
        DynamicNormalModels().fit(bad)


@pytest.mark.parametrize("coverage", [0.9, None])
def test_each_speed_bin_is_calibrated_to_its_rule(coverage):
    # a step of the command puts a heavy tail into the out-of-fold residuals
    drive = benchmark_inputs(4, 300, seed=21, vary=True)
    cv = drive["CV"].values.copy()
    cv[:, 150:] -= 0.15  # CV stays in [0.05, 0.65]: X never at a rail
    normal = simulate(drive.assign(CV=(("run", "time"), cv)), seed=21)
    nm = DynamicNormalModels(
        x_widths=(8.0,), f_widths=(0.1,), evidence_max_samples=200, max_train_samples=300,
        calibration_folds=2, std_coverage=coverage, random_state=0,
    ).fit(normal)  # fmt: skip
    speed = np.abs(np.diff(cv, axis=1, prepend=cv[:, :1]))
    bins = np.searchsorted(nm.std_scale_edges_, speed, side="right")
    z = nm.oof_z_[..., 0]
    for b in range(nm.std_scale_edges_.size + 1):
        zb = np.abs(z[(bins == b) & np.isfinite(z)])
        if coverage is None:  # maximum likelihood: unit mean square in every bin
            assert np.sqrt(np.mean(zb**2)) == pytest.approx(1.0, rel=1e-9)
        else:  # the central 90 % interval, +-1.645, covers 90 % of the bin's residuals
            assert np.quantile(zb, 0.9) == pytest.approx(1.6448536269514722, rel=1e-9)

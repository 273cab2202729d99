"""Tests of the normal models and residual generation (paper eqs. 16-20)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from conftest import sine_inputs
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

from bayes_fdi.datasets import make_dataset
from bayes_fdi.diagnosis import (
    KernelRidgeRegressor,
    NegativePressureDropWarning,
    NormalModels,
    genetic_width_search,
    model_inputs,
)

NOISE = 0.005


def synthetic_runs(n_runs, rng, offsets=(0.0, 0.0), T=100):
    """Smooth actuator-like maps of (CV, sqrt(P1-P2), T1) plus noise; faults as offsets."""
    ch = sine_inputs(n_runs, rng, T)
    CV, P1, P2, T1 = ch["CV"], ch["P1"], ch["P2"], ch["T1"]
    X = 0.9 * CV + 0.05 * CV**2 + NOISE * rng.standard_normal((n_runs, T)) + offsets[0]
    F = (
        0.7 * (1 - 0.8 * (0.9 * CV + 0.05 * CV**2)) * np.sqrt(P1 - P2) * (1 + 0.1 * T1)
        + NOISE * rng.standard_normal((n_runs, T))
        + offsets[1]
    )
    return dict(ch, X=X, F=F)


def test_model_inputs_signed_root_and_count():
    ch = {
        "CV": np.array([[0.1, 0.2, 0.3]]),
        "P1": np.array([[0.9, 0.5, 0.2]]),
        "P2": np.array([[0.5, 0.5, 0.6]]),
        "T1": np.array([[0.3, 0.3, 0.4]]),
    }
    ds = make_dataset(ch)
    with pytest.warns(NegativePressureDropWarning, match="1 of 3 samples have P1 < P2"):
        U, n_neg = model_inputs(ds)
    assert n_neg == 1
    np.testing.assert_allclose(U[:, 0], [0.1, 0.2, 0.3])
    np.testing.assert_allclose(U[:, 1], [np.sqrt(0.4), 0.0, -np.sqrt(0.4)])
    np.testing.assert_allclose(U[:, 2], [0.3, 0.3, 0.4])


def test_model_inputs_missing_channel():
    ds = make_dataset({"CV": np.zeros((1, 3)), "P1": np.ones((1, 3)), "T1": np.ones((1, 3))})
    with pytest.raises(ValueError, match="P2"):
        model_inputs(ds)


def gp():
    kernel = ConstantKernel(1.0) * RBF(
        length_scale=[0.3, 0.3, 0.3], length_scale_bounds=(0.05, 1e3)
    ) + WhiteKernel(noise_level=1e-4, noise_level_bounds=(1e-8, 1.0))
    return GaussianProcessRegressor(kernel=kernel, normalize_y=True, random_state=0)


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")  # T1 irrelevant
def test_residuals_of_fault_free_runs_are_noise_and_calibrated(rng):
    normal = make_dataset(synthetic_runs(4, rng))
    test = make_dataset(synthetic_runs(3, rng))
    nm = NormalModels(gp(), max_train_samples=300, random_state=0).fit(normal)
    assert nm.n_train_samples_ == 300
    res = nm.residuals(test)
    for r, z in (("r1", "z1"), ("r2", "z2")):
        rms = float(np.sqrt(np.mean(res[r].values ** 2)))
        # the true noise level: the RMS of 300 noise samples has relative sd 1/sqrt(600) = 4 %,
        # so 0.8 is 5 sd below; above, the GP's own error adds in quadrature (up to 0.83 NOISE)
        assert 0.8 * NOISE < rms < 1.3 * NOISE
        # calibrated predictive std: the sd of 300 standardised residuals is 1 within 4 % (sd),
        # and the GP's std estimate from 300 samples adds a few % more either way
        assert 0.8 < float(np.std(res[z].values)) < 1.25
    np.testing.assert_allclose(res["r1"].values, test["X"].values - res["X_hat"].values)
    np.testing.assert_allclose(res["z2"].values, res["r2"].values / res["F_hat_std"].values)
    assert res.attrs["n_negative_pressure_drop"] == 0


def test_offset_faults_show_as_residual_means(rng):
    normal = make_dataset(synthetic_runs(4, rng))
    nm = NormalModels(KernelRidgeRegressor(width=0.3), max_train_samples=400).fit(normal)
    faulty = make_dataset(synthetic_runs(3, rng, offsets=(0.04, -0.03)))
    res = nm.residuals(faulty)
    # the mean of 300 residuals: noise sd NOISE / sqrt(300) = 0.0003, plus the model's own
    # bias (ridge shrinkage, well under 0.002 at this width): 0.003 covers both
    assert float(res["r1"].mean()) == pytest.approx(0.04, abs=0.003)
    assert float(res["r2"].mean()) == pytest.approx(-0.03, abs=0.003)


def test_nan_inputs_give_nan_predictions_and_are_counted(rng):
    normal = make_dataset(synthetic_runs(3, rng))
    normal["X"].values[0, 5] = np.nan  # a gap, as in plant records
    with pytest.warns(UserWarning, match="1 fault-free sample"):
        nm = NormalModels(KernelRidgeRegressor(width=0.3)).fit(normal)
    assert nm.n_dropped_nan_ == 1 and nm.n_train_samples_ == 3 * 100 - 1
    test = make_dataset(synthetic_runs(1, rng))
    test["P1"].values[0, 10] = np.nan
    res = nm.residuals(test)
    assert res.attrs["n_nan_inputs"] == 1
    assert np.isnan(res["r1"].values[0, 10]) and np.isnan(res["F_hat_std"].values[0, 10])
    assert np.isfinite(np.delete(res["r1"].values[0], 10)).all()


def test_normal_models_refuse_faulty_runs_and_missing_outputs(rng):
    ds = make_dataset(synthetic_runs(2, rng), state=["fn", "f1"])
    with pytest.raises(ValueError, match="fault-free"):
        NormalModels(KernelRidgeRegressor()).fit(ds)
    ds = make_dataset({k: v for k, v in synthetic_runs(2, rng).items() if k != "F"})
    with pytest.raises(ValueError, match="F"):
        NormalModels(KernelRidgeRegressor()).fit(ds)
    with pytest.raises(ValueError, match="not fitted"):
        NormalModels(KernelRidgeRegressor()).predict(ds)


class QuadraticInLogWidth(RegressorMixin, BaseEstimator):
    """Predicts y + (log10(width) - log10(0.03)): validation MSE is a known parabola."""

    def __init__(self, width=1.0):
        self.width = width

    def fit(self, X, y):
        self.fitted_ = True
        return self

    def predict(self, X, return_std=False):
        mean = X[:, 0] + (np.log10(self.width) - np.log10(0.03))
        return (mean, np.ones_like(mean)) if return_std else mean


def test_genetic_search_finds_known_optimum():
    X = np.linspace(0, 1, 20)[:, None]
    y = X[:, 0]
    res = genetic_width_search(
        lambda w: QuadraticInLogWidth(width=w), X, y, X, y, population=10, generations=15
    )
    assert res.width == pytest.approx(0.03, rel=0.05)
    assert res.mse == pytest.approx((np.log10(res.width) - np.log10(0.03)) ** 2)
    assert res.history.shape == (16, 2)
    assert np.all(np.diff(res.history[:, 1]) <= 0)  # elitism: best never gets worse
    again = genetic_width_search(
        lambda w: QuadraticInLogWidth(width=w), X, y, X, y, population=10, generations=15
    )
    assert again.width == res.width  # seeded


def test_ga_width_search_in_normal_models(rng):
    normal = make_dataset(synthetic_runs(4, rng))
    nm = NormalModels(
        KernelRidgeRegressor(width=5.0, alphas=(1e-2,)),
        width_search="ga",
        ga_population=6,
        ga_generations=3,
        ga_max_samples=200,
        max_train_samples=300,
    ).fit(normal)
    for name in ("X", "F"):
        ga = nm.ga_results_[name]
        assert nm.regressors_[name].width == ga.width
    # The GA's choice beats the (over-smooth) starting width on new fault-free runs.
    test = make_dataset(synthetic_runs(2, rng))
    fixed = NormalModels(
        KernelRidgeRegressor(width=5.0, alphas=(1e-2,)), max_train_samples=300
    ).fit(normal)
    for r in ("r1", "r2"):
        mse_ga = float((nm.residuals(test)[r] ** 2).mean())
        mse_fixed = float((fixed.residuals(test)[r] ** 2).mean())
        assert mse_ga < mse_fixed
        # close to the noise floor: the MSE of 200 noise samples has relative sd
        # sqrt(2/200) = 10 %; the model's error adds a few % of NOISE**2
        assert mse_ga < 1.2 * NOISE**2
    with pytest.raises(ValueError, match="no parameter 'width'"):
        NormalModels(gp(), width_search="ga").fit(normal)
    with pytest.raises(ValueError, match="at least 2 fault-free runs"):
        NormalModels(KernelRidgeRegressor(), width_search="ga").fit(normal.isel(run=[0]))


def test_negative_pressure_drop_runs_are_kept(rng):
    normal = make_dataset(synthetic_runs(2, rng))
    nm = NormalModels(KernelRidgeRegressor(width=0.3)).fit(normal)
    ch = synthetic_runs(1, rng)
    ch["P2"][0, :7] = ch["P1"][0, :7] + 0.01
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = nm.residuals(make_dataset(ch))
    assert any(issubclass(w.category, NegativePressureDropWarning) for w in caught)
    assert res.attrs["n_negative_pressure_drop"] == 7
    assert np.isfinite(res["r2"].values).all() and res.sizes["time"] == 100


def test_evidence_width_search_on_a_subsample(rng):
    """``width_search="evidence"``: the RVR's own evidence search on a seeded subsample (checked
    by repeating it independently on the same samples), then a fit on every sample at that
    width."""
    from bayes_fdi.rvm import RVR

    normal = make_dataset(synthetic_runs(4, rng))
    nm = NormalModels(
        RVR(width="auto"), width_search="evidence", evidence_max_samples=150, random_state=3
    ).fit(normal)
    U, _ = model_inputs(normal)
    idx = np.sort(np.random.default_rng(3).choice(U.shape[0], size=150, replace=False))
    for name in ("X", "F"):
        y = normal[name].values.ravel()
        expected = RVR(width="auto").fit(U[idx], y[idx]).width_
        assert nm.widths_[name] == pytest.approx(expected)
        assert nm.regressors_[name].get_params()["width"] == pytest.approx(expected)
    assert nm.n_train_samples_ == U.shape[0]
    # a fixed width is left alone
    fixed = NormalModels(RVR(width=0.4), random_state=3).fit(normal)
    assert fixed.widths_ == {} and fixed.regressors_["X"].width_ == 0.4

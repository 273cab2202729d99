"""Tests of the cross-fitted interval calibration of the normal models."""

from __future__ import annotations

import warnings
from typing import ClassVar

import numpy as np
import pytest
from scipy import stats
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.linear_model import BayesianRidge

from bayes_fdi.datasets import make_dataset
from bayes_fdi.diagnosis import FaultDiagnoser, NormalModels

LEVELS = np.array([0.5, 0.8, 0.9, 0.95])


def hetero_runs(n_runs, rng, T=200, base=0.002, gain=0.4, heavy=False):
    """Linear maps of CV with noise whose std grows with |dCV/dt| (known truth).

    CV is a sine with a per-run period, so runs differ in speed. The noise of X and F has
    standard deviation ``base + gain * |dCV/dt|`` (Gaussian, or Student-t with 5 degrees of
    freedom rescaled to that std when ``heavy``).
    """
    t = np.arange(T, dtype=float)
    period = rng.uniform(15, 150, (n_runs, 1))
    ph = rng.uniform(0, 2 * np.pi, (n_runs, 1))
    CV = 0.5 + 0.3 * np.sin(2 * np.pi * t / period + ph)
    speed = np.abs(np.gradient(CV, t, axis=1))
    sd = base + gain * speed

    def noise():
        if heavy:
            return sd * rng.standard_t(5, CV.shape) / np.sqrt(5 / 3)
        return sd * rng.standard_normal(CV.shape)

    ch = {
        "CV": CV,
        "P1": np.full(CV.shape, 0.8),
        "P2": np.full(CV.shape, 0.3),
        "T1": 0.3 + 0.01 * rng.standard_normal(CV.shape),
        "X": 0.9 * CV + 0.05 + noise(),
        "F": 0.6 - 0.4 * CV + noise(),
    }
    return make_dataset(ch), speed.ravel()


def coverage(res, runs, name):
    y = runs[name].values.ravel()
    m = res[f"{name}_hat"].values.ravel()
    s = res[f"{name}_hat_std"].values.ravel()
    a = np.abs(y - m) / s
    return a, np.array([np.mean(a <= stats.norm.ppf(0.5 + lv / 2)) for lv in LEVELS])


def binomial_tol(p, n, k=4.0):
    return k * np.sqrt(p * (1 - p) / n)


@pytest.mark.parametrize("heavy", [False, True])
@pytest.mark.parametrize("seed", [0, 1])
def test_calibrated_intervals_reach_nominal_coverage(heavy, seed):
    rng = np.random.default_rng(seed)
    train, _ = hetero_runs(24, rng, heavy=heavy)
    test, speed = hetero_runs(30, rng, heavy=heavy)
    raw = NormalModels(BayesianRidge(), interval_calibration=None).fit(train)
    cal = NormalModels(BayesianRidge(), calibration_bins=5, random_state=1).fit(train)
    slow = speed <= np.quantile(speed, 0.2)
    fast = speed >= np.quantile(speed, 0.8)
    z95 = stats.norm.ppf(0.975)
    for name in ("X", "F"):
        a_raw, cov_raw = coverage(raw.predict(test), test, name)
        a_cal, cov_cal = coverage(cal.predict(test), test, name)
        # 95 % coverage of the held-out runs within a binomial tolerance (independent noise;
        # 4 se) plus 0.01 for the factors fitted on 24 training runs (their own se ~0.5 %)
        assert abs(cov_cal[-1] - 0.95) < binomial_tol(0.95, a_cal.size) + 0.01
        # the constant-variance intervals are far off at some level, the calibrated are not
        assert np.max(np.abs(cov_raw - LEVELS)) > 0.12
        # conditional on the speed: raw misses in the slow or fast fifth, calibrated is closer
        off_raw = [abs(np.mean(a_raw[p] <= z95) - 0.95) for p in (slow, fast)]
        off_cal = [abs(np.mean(a_cal[p] <= z95) - 0.95) for p in (slow, fast)]
        assert max(off_cal) < max(off_raw) - 0.01
        if not heavy:  # Gaussian within a bin: every level and both fifths are close
            # left: the variation of the noise sd within each of the 5 speed bins (a fifth of
            # the range each), which moves coverage by ~0.02-0.03; both bounds leave a margin
            # over that and the binomial se of a fifth (1200 samples: 0.006)
            assert np.max(np.abs(cov_cal - LEVELS)) < 0.05
            assert max(off_cal) < 0.035 < max(off_raw)
        # heavy (Student-t) noise: a Gaussian interval matched in variance is too wide at 50 %


class ConstantRegressor(RegressorMixin, BaseEstimator):
    """Predicts mean 0 and std 1 everywhere; logs which runs (T1 = run id) it saw."""

    log: ClassVar[list[tuple[frozenset, frozenset]]] = []

    def fit(self, X, y):
        self.seen_ = frozenset(np.round(X[:, 2]).astype(int).tolist())
        return self

    def predict(self, X, return_std=False):
        ConstantRegressor.log.append((self.seen_, frozenset(np.round(X[:, 2]).astype(int))))
        mean = np.zeros(X.shape[0])
        return (mean, np.ones(X.shape[0])) if return_std else mean


def hand_runs(y_slow, y_fast, n_runs=8, T=40):
    """CV still in the first half of every run and ramping in the second; T1 = run id."""
    CV = np.concatenate([np.full(T // 2, 0.2), 0.2 + 0.02 * np.arange(1, T // 2 + 1)])
    CV = np.tile(CV, (n_runs, 1))
    y = np.concatenate([np.resize(y_slow, T // 2), np.resize(y_fast, T // 2)])
    y = np.tile(y, (n_runs, 1))
    ch = {
        "CV": CV,
        "P1": np.full(CV.shape, 0.8),
        "P2": np.full(CV.shape, 0.3),
        "T1": np.repeat(np.arange(n_runs, dtype=float)[:, None], T, axis=1),
        "X": y,
        "F": 2 * y,
    }
    return make_dataset(ch)


def test_scale_factors_equal_the_closed_form():
    # slow half: |z| = 0.1 or 0.3; fast half: |z| = 2 (the ramp's central differences are
    # 0.02 except at its start, 0.01, which lies in the slow bin with the still part)
    ds = hand_runs([0.1, -0.3], [2.0, -2.0])
    y = ds["X"].values.ravel()
    speed = np.abs(np.gradient(ds["CV"].values, axis=1)).ravel()
    nm = NormalModels(ConstantRegressor(), width_search=None, calibration_bins=1).fit(ds)
    assert nm.std_scale_["X"] == pytest.approx([np.sqrt(np.mean(y**2))])
    assert nm.std_scale_["F"] == pytest.approx([2 * np.sqrt(np.mean(y**2))])
    nm2 = NormalModels(ConstantRegressor(), width_search=None, calibration_bins=2).fit(ds)
    edge = np.quantile(speed, 0.5)
    assert nm2.std_scale_edges_ == pytest.approx([edge])
    in_fast = speed >= edge
    assert nm2.std_scale_["X"] == pytest.approx(
        [np.sqrt(np.mean(y[~in_fast] ** 2)), np.sqrt(np.mean(y[in_fast] ** 2))]
    )
    assert nm2.std_scale_all_["X"] == pytest.approx(np.sqrt(np.mean(y**2)))
    nm3 = NormalModels(
        ConstantRegressor(), width_search=None, calibration_bins=1, calibration_method="coverage"
    ).fit(ds)
    assert nm3.std_scale_["X"] == pytest.approx([np.quantile(np.abs(y), 0.95) / 1.959964])
    # predict multiplies the regressor's std (1) by the factor of each sample's bin
    pred = nm2.predict(ds)
    expect = np.where(in_fast, nm2.std_scale_["X"][1], nm2.std_scale_["X"][0])
    np.testing.assert_allclose(pred["X_hat_std"].values.ravel(), expect)


def test_folds_are_by_run_and_never_calibrate_a_run_with_itself():
    ds = hand_runs([0.1, -0.3], [2.0, -2.0], n_runs=9)
    ConstantRegressor.log.clear()
    nm = NormalModels(ConstantRegressor(), width_search=None, calibration_folds=4).fit(ds)
    fold = nm.calibration_fold_
    assert fold.shape == (9, 40)
    assert np.all(fold == fold[:, :1])  # one fold per run
    assert sorted(np.bincount(fold[:, 0])) == [2, 2, 2, 3]
    assert len(ConstantRegressor.log) == 2 * 4  # two outputs x four folds
    for seen, predicted in ConstantRegressor.log:
        assert seen and predicted and not (seen & predicted)
        assert len(seen | predicted) == 9


def test_single_run_is_cut_into_contiguous_blocks():
    ds = hand_runs([0.1, -0.3], [2.0, -2.0], n_runs=1, T=40)
    nm = NormalModels(ConstantRegressor(), width_search=None, calibration_folds=4).fit(ds)
    fold = nm.calibration_fold_[0]
    assert sorted(set(fold.tolist())) == [0, 1, 2, 3]
    for block in range(4):  # blocks of 10 samples, each one fold
        assert np.unique(fold[10 * block : 10 * (block + 1)]).size == 1


def test_no_calibration_keeps_the_regressor_std_and_default_is_cross_fit(rng):
    assert NormalModels().interval_calibration == "cross-fit"
    assert FaultDiagnoser().interval_calibration == "cross-fit"
    train, _ = hetero_runs(6, rng, T=60)
    raw = NormalModels(BayesianRidge(), interval_calibration=None).fit(train)
    assert raw.interval_calibration_ is None and "calibration" not in raw.fit_seconds_
    assert not hasattr(raw, "calibration_fold_")
    from bayes_fdi.diagnosis import model_inputs

    U, _ = model_inputs(train)
    _, std = raw.regressors_["X"].predict(U, return_std=True)
    np.testing.assert_allclose(raw.predict(train)["X_hat_std"].values.ravel(), std)


def test_too_few_samples_warn_and_leave_the_std_uncalibrated():
    ds = hand_runs([0.1], [2.0], n_runs=1, T=6)
    with pytest.warns(UserWarning, match="too few"):
        nm = NormalModels(ConstantRegressor(), width_search=None, calibration_folds=4).fit(ds)
    assert nm.interval_calibration_ is None
    np.testing.assert_allclose(nm.predict(ds)["F_hat_std"].values, 1.0)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"interval_calibration": "conformal"}, "interval_calibration"),
        ({"calibration_folds": 1}, "calibration_folds"),
        ({"calibration_folds": 2.5}, "calibration_folds"),
        ({"calibration_bins": 0}, "calibration_bins"),
        ({"calibration_method": "iso"}, "calibration_method"),
        ({"calibration_max_samples": 1}, "calibration_max_samples"),
    ],
)
def test_bad_calibration_options_raise(kwargs, match):
    ds = hand_runs([0.1], [2.0], n_runs=2, T=10)
    with warnings.catch_warnings(), pytest.raises(ValueError, match=match):
        NormalModels(ConstantRegressor(), width_search=None, **kwargs).fit(ds)


def test_fault_diagnoser_passes_the_option_on(rng):
    train, _ = hetero_runs(6, rng, T=60)
    faulty, _ = hetero_runs(6, rng, T=60)
    faulty = faulty.assign(X=faulty["X"] + 0.05)
    runs = make_dataset(
        {k: np.concatenate([train[k].values, faulty[k].values]) for k in train.data_vars},
        state=["fn"] * 6 + ["f1"] * 6,
    )
    for option in (None, "cross-fit"):
        d = FaultDiagnoser(BayesianRidge(), interval_calibration=option).fit(train, runs)
        assert d.normal_models_.interval_calibration_ == option

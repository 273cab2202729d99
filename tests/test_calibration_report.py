"""Tests of the calibration report with a contract-conforming stand-in diagnoser."""

from __future__ import annotations

import argparse
import json
from types import SimpleNamespace

import numpy as np
import pytest
import xarray as xr

from bayes_fdi.calibration import recalibrator_selection, summaries
from bayes_fdi.calibration import report as cr
from bayes_fdi.calibration.recalibration import LOG_LOSS_RTOL
from bayes_fdi.commands import calibration_report as cr_command
from bayes_fdi.datasets import make_dataset, save_dataset

CLASSES = ["fn", "f1", "f2"]
MU = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
S = 0.5
T = 60


def _posterior(feats):
    """Exact posterior of the Gaussian class model with equal priors."""
    logit = -((feats[:, None, :] - MU[None]) ** 2).sum(-1) / (2 * S**2)
    logit -= logit.max(axis=1, keepdims=True)
    p = np.exp(logit)
    return p / p.sum(axis=1, keepdims=True)


def _make_runs(rng, n_per_class):
    states = np.repeat(CLASSES, n_per_class)
    n = states.size
    cv = 0.5 + 0.2 * np.sin(np.arange(T) / 7.0 + rng.uniform(0, 6, size=(n, 1)))
    ch = {
        "CV": cv,
        "P1": np.full((n, T), 0.8),
        "P2": np.full((n, T), 0.6),
        "T1": np.full((n, T), 0.5),
        "X": cv.copy(),
        "F": 0.3 + 0.3 * cv,
    }
    runs = make_dataset(ch, state=states)
    feats = MU[[CLASSES.index(s) for s in states]] + S * rng.normal(size=(n, 2))
    return runs, feats


class _Node:
    def __init__(self, left, right):
        self.left, self.right = left, right
        self.estimator = SimpleNamespace(classes_=np.array([0, 1]), predict_proba=self._proba)

    def _proba(self, X):
        p = _posterior(X)
        idx_l = [CLASSES.index(c) for c in self.left]
        idx_r = [CLASSES.index(c) for c in self.right]
        pr = p[:, idx_r].sum(1) / (p[:, idx_l].sum(1) + p[:, idx_r].sum(1))
        return np.column_stack([1 - pr, pr])


class FakeDiagnoser:
    """Reports softmax(sharpness * log posterior) and Gaussian normal-model predictions.

    sharpness 2 is over-confident by a known temperature of 2; measured X, F are drawn
    around the predictions with exactly the stated std, so intervals are calibrated.
    """

    def __init__(self, features_by_run, sharpness=2.0, x_std=0.01, f_std=0.02, seed=0):
        self.features_by_run = features_by_run
        self.sharpness = sharpness
        self.x_std, self.f_std = x_std, f_std
        self.seed = seed
        self.classes_ = CLASSES
        self.classifier_ = SimpleNamespace(
            nodes_=[_Node(("fn",), ("f1", "f2")), _Node(("f1",), ("f2",))]
        )

    def diagnose(self, runs):
        feats = self.features_by_run[runs.attrs["key"]]
        logp = np.log(_posterior(feats)) * self.sharpness
        p = np.exp(logp - logp.max(axis=1, keepdims=True))
        p /= p.sum(axis=1, keepdims=True)
        rng = np.random.default_rng(self.seed)
        n = runs.sizes["run"]
        x_hat = runs["X"].values - self.x_std * rng.normal(size=(n, T))
        f_hat = runs["F"].values - self.f_std * rng.normal(size=(n, T))
        return xr.Dataset(
            {
                "state": ("run", np.array(CLASSES)[p.argmax(1)]),
                "proba": (("run", "class"), p),
                "confidence": ("run", p.max(1)),
                "X_hat": (("run", "time"), x_hat),
                "X_hat_std": (("run", "time"), np.full((n, T), self.x_std)),
                "F_hat": (("run", "time"), f_hat),
                "F_hat_std": (("run", "time"), np.full((n, T), self.f_std)),
                "features": (("run", "feature"), feats),
            },
            coords={"run": runs["run"].values, "class": CLASSES, "time": runs["time"].values},
        )


@pytest.fixture
def setup(rng):
    test, f_test = _make_runs(rng, 400)
    cal, f_cal = _make_runs(rng, 400)
    test.attrs["key"], cal.attrs["key"] = "test", "cal"
    return test, cal, {"test": f_test, "cal": f_cal}


def test_report_before_after_nodes_and_coverage(setup, tmp_path):
    test, cal, feats = setup
    diag = FakeDiagnoser(feats)
    path = cr.write_calibration_report(
        diag, test, tmp_path, calibration_runs=cal, n_bootstrap=100, seed=3
    )
    assert path == tmp_path / "report.md"
    res = json.loads((tmp_path / "calibration.json").read_text())
    before, after = res["whole_tree"]["before"], res["whole_tree"]["after"]
    # the fake is over-confident by exactly T = 2: recalibration finds it and fixes the ECE.
    # T is fitted on 1200 calibration runs (se of 1/T about 3 %: 15 % is 5 se); a calibrated
    # ECE on 1200 runs with 15 bins is at most sqrt(2/pi) sqrt(15 / 4 / 1200) = 0.045 and
    # typically half that, the over-confident one several times more
    assert res["recalibration"]["temperature"] == pytest.approx(2.0, rel=0.15)
    assert after["ece"]["value"] < 0.04 < before["ece"]["value"]
    assert after["log_loss"] < before["log_loss"]
    temp = res["whole_tree"]["temperature"]
    assert temp["accuracy"] == before["accuracy"]  # one temperature never changes the argmax
    # the distortion is a pure temperature: every recalibrator fixes it, none beats the truth
    for m in ("temperature", "vector", "dirichlet"):
        assert res["whole_tree"][m]["ece"]["value"] < 0.04
    fit = res["recalibration"]["fits"][0]
    assert res["recalibration"]["selected"] == [fit["selected"]]
    # the first method (simplest first) within LOG_LOSS_RTOL of the lowest log loss
    scores = fit["cv_log_loss"]
    best = min(scores.values())
    tied = [m for m in scores if scores[m] <= best + LOG_LOSS_RTOL * abs(best)]
    assert fit["selected"] == tied[0]
    assert after == res["whole_tree"][fit["selected"]]
    assert {(b["strategy"], b["n_bins"]) for b in res["ece_binning"]} == {
        (s, nb) for s in ("uniform", "quantile") for nb in (15, 10, 5)
    }
    assert sum(before["ece"]["bin_counts"]) == 1200
    # nodes evaluate the exact posterior -> calibrated; node 0 sees all runs, node 1 the faults
    assert [n["n"] for n in res["nodes"]] == [1200, 800]
    # binary, 10 bins, 800-1200 runs: a calibrated ECE of at most sqrt(2/pi) sqrt(10/4/800)
    # = 0.045, typically less
    assert all(n["ece"] < 0.06 for n in res["nodes"])
    # fault-free runs: predictions within exactly-stated Gaussian noise -> nominal coverage
    for name in ("X", "F"):
        d = res["normal_models"][name]
        assert d["n"] == 400 * T
        for lv, c in d["coverage"].items():
            # 24 000 samples: binomial se at most sqrt(0.25 / 24 000) = 0.0032; 0.012 = 3.7 se
            assert c["coverage"] == pytest.approx(c["nominal"], abs=0.012), (name, lv)
        std = 0.01 if name == "X" else 0.02
        # expected CRPS of a calibrated Gaussian: E[z(2Phi-1)] = E[2 phi] = 1/sqrt(pi),
        # so E[CRPS] = std / sqrt(pi); the mean of 24 000 CRPS values (relative sd about 0.8
        # each) has relative sd 0.005: 0.02 is 4 sd
        assert d["crps"] == pytest.approx(std / np.sqrt(np.pi), rel=0.02)
    text = path.read_text()
    for needle in ("top-label ECE", "classwise ECE", "| X | 95% |", "reliability_whole_tree.png"):
        assert needle in text
    assert (tmp_path / "figures" / "reliability_whole_tree.png").stat().st_size > 1000
    assert (tmp_path / "figures" / "pit_normal_models.png").stat().st_size > 1000


def test_report_cross_fits_without_calibration_runs(setup, tmp_path):
    test, _, feats = setup
    test2 = test.assign_coords(state=("run", np.where(np.arange(1200) < 10, "f9", test["state"])))
    test2.attrs["key"] = "test"
    cr.write_calibration_report(FakeDiagnoser(feats), test2, tmp_path, n_bootstrap=0, n_folds=2)
    res = json.loads((tmp_path / "calibration.json").read_text())
    t = res["recalibration"]["temperature"]
    # each T fitted on 595 runs: se about 4.5 %, 25 % is over 5 se
    assert len(t) == 2 and all(v == pytest.approx(2.0, rel=0.25) for v in t)
    assert [f["scored"] for f in res["recalibration"]["fits"]] == [595, 595]
    assert [f["n_fit"] for f in res["recalibration"]["fits"]] == [595, 595]
    assert res["n_excluded_unknown_state"] == 10 and res["excluded_states"] == ["f9"]
    assert res["whole_tree"]["after"]["ece"]["value"] < res["whole_tree"]["before"]["ece"]["value"]
    assert "10 excluded" in (tmp_path / "report.md").read_text()
    # the default cross-fits in five folds (each fit on 4/5 of the runs)
    cr.write_calibration_report(FakeDiagnoser(feats), test2, tmp_path / "k5", n_bootstrap=0)
    fits = json.loads((tmp_path / "k5" / "calibration.json").read_text())["recalibration"]["fits"]
    assert len(fits) == 5 and sum(f["scored"] for f in fits) == 1190
    assert all(f["n_fit"] == 1190 - f["scored"] for f in fits)


def test_cli_fits_on_train_and_reports(setup, tmp_path, monkeypatch):
    test, _cal, feats = setup
    train = test.copy()
    train.attrs["key"] = "test"
    save_dataset(train, tmp_path / "train.nc")
    save_dataset(test, tmp_path / "test.nc")
    fitted = {}

    class Fittable(FakeDiagnoser):
        def fit(self, normal, labelled):
            fitted["normal_states"] = set(normal["state"].values.tolist())
            fitted["n_labelled"] = labelled.sizes["run"]
            return self

        def diagnose(self, runs):
            runs = runs.copy()
            runs.attrs["key"] = "test"
            return super().diagnose(runs)

    monkeypatch.setattr(cr_command, "_build_diagnoser", lambda method, seed: Fittable(feats))
    parser = argparse.ArgumentParser()
    cr_command.configure_parser(parser)
    args = parser.parse_args(
        ["--train", str(tmp_path / "train.nc"), "--test", str(tmp_path / "test.nc"),
         "--out", str(tmp_path / "out"), "--n-bootstrap", "10", "--seed", "1"]
    )  # fmt: skip
    assert cr_command.run_from_cli(args) == 0
    assert fitted == {"normal_states": {"fn"}, "n_labelled": 1200}
    assert (tmp_path / "out" / "report.md").exists()


def test_report_rejects_unlabelled_runs(setup, tmp_path):
    test, _, feats = setup
    with pytest.raises(ValueError, match="state"):
        cr.write_calibration_report(FakeDiagnoser(feats), test.drop_vars("state"), tmp_path)


def test_nodes_see_standardised_features(setup, tmp_path):
    test, _, feats = setup

    class Scaled(FakeDiagnoser):
        """Reports unscaled features 3x + 2; the tree works on x (scaler_ maps back)."""

        scaler_ = SimpleNamespace(transform=lambda f: (np.asarray(f) - 2.0) / 3.0)

        def diagnose(self, runs):
            d = super().diagnose(runs)
            d["features"] = 3.0 * d["features"] + 2.0
            return d

    cr.write_calibration_report(Scaled(feats), test, tmp_path, n_bootstrap=0)
    res = json.loads((tmp_path / "calibration.json").read_text())
    assert all(n["ece"] < 0.06 for n in res["nodes"])
    assert res["nodes"][1]["accuracy"] > 0.85  # f1 vs f2 at distance 1.41 / 0.5: ~0.92


def test_window_labels_follow_onset():
    runs = make_dataset({"X": np.zeros((2, 300))}, state=["f1", "fn"], onset=[150.0, 0.0])
    diag = xr.Dataset(
        {"proba": (("run", "window", "class"), np.full((2, 3, 3), 1 / 3))},
        coords={
            "class": CLASSES,
            "window_start": ("window", [0.0, 100.0, 200.0]),
            "window_end": ("window", [100.0, 200.0, 300.0]),
        },
    )
    y, p, f = summaries.labelled_rows(diag, runs)
    # run 0 (f1, onset 150): window ending at 99 is fn, at 199 and 299 is f1
    assert y.tolist() == ["fn", "f1", "f1", "fn", "fn", "fn"]
    assert p.shape == (6, 3) and f is None


class _GaussianNormalModel:
    """Normal model with a known answer: X ~ N(a CV + b, s^2), fitted by least squares."""

    def fit(self, runs):
        self.coef_ = {}
        for name in ("X", "F"):
            cv = runs["CV"].values.ravel()
            y = runs[name].values.ravel()
            A = np.column_stack([cv, np.ones_like(cv)])
            beta, *_ = np.linalg.lstsq(A, y, rcond=None)
            self.coef_[name] = (beta, np.std(y - A @ beta, ddof=2))
        return self

    def predict(self, runs):
        out = {}
        for name, (beta, s) in self.coef_.items():
            m = beta[0] * runs["CV"].values + beta[1]
            out[f"{name}_hat"] = (("run", "time"), m)
            out[f"{name}_hat_std"] = (("run", "time"), np.full(m.shape, s))
        return xr.Dataset(out, coords={"time": runs["time"].values})


def test_time_split_summary_of_a_correct_gaussian_model(rng):
    n_t = 20_000
    cv = rng.uniform(0.2, 0.8, size=(1, n_t))
    runs = make_dataset(
        {
            "CV": cv,
            "X": 0.9 * cv + 0.05 + 0.01 * rng.normal(size=cv.shape),
            "F": 0.5 * cv + 0.2 + 0.03 * rng.normal(size=cv.shape),
        }
    )
    first, second = summaries.split_in_time(runs, 0.5)
    assert first.sizes["time"] == second.sizes["time"] == n_t // 2
    assert second["time"].values[0] == n_t // 2
    res = summaries.time_split_summary(_GaussianNormalModel(), runs)
    assert res["split_time"] == n_t // 2 and res["n_fit_samples"] == n_t // 2
    for name, s in (("X", 0.01), ("F", 0.03)):
        for c in res[name]["coverage"].values():
            se = np.sqrt(c["nominal"] * (1 - c["nominal"]) / (n_t // 2))
            assert abs(c["coverage"] - c["nominal"]) < 4 * se
        # 10 000 CRPS values of relative sd ~0.8: the mean's relative sd 0.008; 0.03 = 3.7 sd
        assert res[name]["crps"] == pytest.approx(s / np.sqrt(np.pi), rel=0.03)
    with pytest.raises(ValueError, match="fraction"):
        summaries.split_in_time(runs, 1.0)


def test_recalibrate_cross_fits_every_run_out_of_fold(rng):
    """Each fold's temperature column equals a TemperatureScaler fitted on the other folds."""
    from bayes_fdi.calibration import TemperatureScaler
    from bayes_fdi.calibration.recalibration import fold_indices

    n, k = 900, 3
    p_true = rng.dirichlet(np.ones(k), size=n)
    y = np.array(CLASSES)[(rng.random(n)[:, None] > np.cumsum(p_true, 1)).sum(1).clip(max=k - 1)]
    hot = np.exp(np.log(p_true) / 0.5)
    hot /= hot.sum(axis=1, keepdims=True)
    out, info = recalibrator_selection.recalibrate(
        y, hot, CLASSES, n_folds=3, methods=("temperature",), seed=4
    )
    y_idx = np.array([CLASSES.index(v) for v in y])
    folds = fold_indices(y_idx, 3, 4)
    assert sorted(np.concatenate(folds).tolist()) == list(range(n))
    for fold, fit in zip(folds, info["fits"], strict=True):
        rest = np.setdiff1d(np.arange(n), fold)
        ts = TemperatureScaler(classes=CLASSES).fit(hot[rest], y[rest])
        # the same fit on the same runs, repeated: equal to rounding
        np.testing.assert_allclose(out["temperature"][fold], ts.transform(hot[fold]))
        assert fit["temperature"]["temperature"] == pytest.approx(ts.temperature_)
        assert fit["selected"] == "temperature" and fit["scored"] == fold.size
    np.testing.assert_array_equal(out["after"], out["temperature"])
    with pytest.raises(ValueError, match="n_folds"):
        recalibrator_selection.recalibrate(y, hot, CLASSES, n_folds=1)
    with pytest.raises(ValueError, match="unknown recalibrator"):
        recalibrator_selection.recalibrate(y, hot, CLASSES, methods=("platt",))


def test_recalibrate_selects_dirichlet_for_a_dirichlet_distortion(rng):
    """Classes 0 and 1 swapped by the distortion: only the full map can undo it."""
    n, k = 1500, 3
    p_true = rng.dirichlet(np.full(k, 0.5), size=n)
    y = np.array(CLASSES)[(rng.random(n)[:, None] > np.cumsum(p_true, 1)).sum(1).clip(max=k - 1)]
    p_obs = p_true[:, [1, 0, 2]]
    out, info = recalibrator_selection.recalibrate(y, p_obs, CLASSES, n_folds=2, seed=0)
    assert [f["selected"] for f in info["fits"]] == ["dirichlet", "dirichlet"]
    acc = {m: np.mean(np.array(CLASSES)[q.argmax(1)] == y) for m, q in out.items()}
    acc_true = np.mean(np.array(CLASSES)[p_true.argmax(1)] == y)
    # maps fitted on 750 runs each move the argmax of some runs near a class boundary: the
    # accuracy of the true posterior is reached within 2.5 % (sd of an accuracy on 1500 runs
    # is 1.2 %)
    assert acc["after"] == pytest.approx(acc_true, abs=0.025)
    # a temperature never changes the argmax: exactly the distorted model's accuracy
    assert acc["temperature"] == pytest.approx(np.mean(np.array(CLASSES)[p_obs.argmax(1)] == y))
    assert acc["after"] > acc["temperature"] + 0.2


def test_recalibrate_ties_go_to_the_simplest_method(rng, monkeypatch):
    """Cross-validated log losses within LOG_LOSS_RTOL are a tie: the first method wins, so
    a difference in the last digits (another BLAS code path) cannot change the choice."""
    from bayes_fdi.calibration import recalibrator_selection as rs

    n, k = 300, 3
    p = rng.dirichlet(np.ones(k), size=n)
    y = np.array(CLASSES)[(rng.random(n)[:, None] > np.cumsum(p, 1)).sum(1).clip(max=k - 1)]
    base = 0.5
    for delta, want in ((-0.1 * LOG_LOSS_RTOL, "temperature"), (-10 * LOG_LOSS_RTOL, "vector")):
        scores = {"temperature": base, "vector": base * (1 + delta), "dirichlet": base}
        monkeypatch.setattr(rs, "cross_val_log_loss", lambda est, *a, s=scores, **kw: s[_name(est)])
        _, info = recalibrator_selection.recalibrate(y, p, CLASSES, n_folds=2, seed=0)
        assert [f["selected"] for f in info["fits"]] == [want, want]


def _name(est):
    from bayes_fdi.calibration import TemperatureScaler

    if isinstance(est, TemperatureScaler):
        return "temperature"
    return "vector" if est.parametrization == "diagonal" else "dirichlet"

"""End-to-end tests of FaultDiagnoser on small synthetic campaigns (stand-in estimators)."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from conftest import sine_inputs
from sklearn.linear_model import LogisticRegression

from bayes_fdi.datasets import make_dataset
from bayes_fdi.diagnosis import (
    FaultDiagnoser,
    KernelRidgeRegressor,
    svm_classifier,
    svm_fault_diagnoser,
)
from bayes_fdi.diagnosis.isolation.tree import HierarchicalClassifier

NOISE = 0.005
# Fault signatures as (X offset, F offset) after onset: distinct residual means.
OFFSETS = {"fn": (0, 0), "f1": (0.04, 0), "f2": (0, -0.04), "f3": (0.03, 0.03), "f6": (-0.04, 0)}


def campaign(states, n_per, rng, T=100, onset=0.0):
    sts = [s for s in states for _ in range(n_per)]
    n, t = len(sts), np.arange(T)
    ch = sine_inputs(n, rng, T)
    CV = ch["CV"]
    X = 0.9 * CV + 0.05 * CV**2 + NOISE * rng.standard_normal((n, T))
    F = 0.7 * (1 - 0.8 * X) * np.sqrt(ch["P1"] - ch["P2"]) + NOISE * rng.standard_normal((n, T))
    on = (t >= onset)[None, :]
    for i, s in enumerate(sts):
        X[i] += OFFSETS[s][0] * on[0]
        F[i] += OFFSETS[s][1] * on[0]
    return make_dataset(
        dict(ch, X=X, F=F),
        state=sts,
        onset=onset,
        campaign="synthetic-test",
    )


@pytest.fixture
def data(rng):
    states = list(OFFSETS)
    return campaign(["fn"], 4, rng), campaign(states, 8, rng), campaign(states, 6, rng)


def stand_in(**kw):
    return FaultDiagnoser(
        KernelRidgeRegressor(width=0.3),
        HierarchicalClassifier(svm_classifier(sigma=2.0)),
        max_train_samples=400,
        **kw,
    )


def test_end_to_end_small_campaign(data):
    normal, labelled, test = data
    diag = stand_in().fit(normal, labelled)
    assert set(diag.fit_seconds_) == {"normal_models", "residuals", "classifier", "total"}
    assert list(diag.classes_) == sorted(OFFSETS)
    out = diag.diagnose(test)
    assert out.sizes["run"] == 30 and out.sizes["class"] == 5 and out.sizes["feature"] == 2
    # offsets >= 0.03 apart against run means of noise sd 0.005 / sqrt(100) = 0.0005: the
    # states are separable; 0.95 still allows one of the 30 runs to fall to a model error
    accuracy = float((out["state"].values == out["true_state"].values).mean())
    assert accuracy >= 0.95
    proba = out["proba"].values
    np.testing.assert_allclose(proba.sum(axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(out["confidence"].values, proba.max(axis=1))
    np.testing.assert_array_equal(out["state"].values, out["class"].values[proba.argmax(1)])
    # The features are the paper's: mean residuals over the run, recomputed independently.
    r1 = test["X"].values - out["X_hat"].values
    np.testing.assert_allclose(out["features"].sel(feature="mean_r1").values, r1.mean(axis=1))
    np.testing.assert_allclose(out["r2"].values, test["F"].values - out["F_hat"].values)
    for var in ("X_hat_std", "F_hat_std"):
        assert (out[var].values > 0).all()
    # Fault-free runs' mean residuals are near 0; f1's mean r1 is near its +0.04 offset.
    feats = out["features"].values
    is_f1 = out["true_state"].values == "f1"
    # run means: noise sd 0.0005, plus the kernel ridge model's error of a few 1e-3 at most
    assert np.abs(feats[is_f1, 0] - 0.04).max() < 0.005


def test_svm_baseline_and_flat_classifier_plug_in(data):
    normal, labelled, test = data
    out = svm_fault_diagnoser(max_train_samples=300).fit(normal, labelled).diagnose(test)
    assert float((out["state"].values == out["true_state"].values).mean()) >= 0.95
    flat = FaultDiagnoser(
        KernelRidgeRegressor(width=0.3), LogisticRegression(), max_train_samples=300
    ).fit(normal, labelled)
    out = flat.diagnose(test)
    np.testing.assert_allclose(out["proba"].values.sum(axis=1), 1.0)
    # a linear classifier on these (separable, not linearly separable in one step for all five
    # states) features: at most 3 of the 30 runs wrong
    assert float((out["state"].values == out["true_state"].values).mean()) >= 0.9


def test_windowed_diagnosis_labels_pre_onset_windows_fn(rng):
    states = list(OFFSETS)
    normal = campaign(["fn"], 3, rng)
    labelled = campaign(states, 6, rng, onset=50.0)
    diag = stand_in(window=25, features=("mean_r1", "mean_r2", "std_r1")).fit(normal, labelled)
    labels = diag.training_labels_.reshape(30, 4)
    assert (labels[:, :2] == "fn").all()  # windows [0,25) and [25,50) end before the onset
    np.testing.assert_array_equal(labels[:, 2], labelled["state"].values)
    # Boundary: with the onset at t = 49 the window [25, 50) holds one faulty sample.
    early = labelled.assign_coords(onset=("run", np.full(30, 49.0)))
    labels = stand_in(window=25).fit(normal, early).training_labels_.reshape(30, 4)
    assert (labels[:, 0] == "fn").all()
    np.testing.assert_array_equal(labels[:, 1], labelled["state"].values)
    test = campaign(states, 3, rng, onset=50.0)
    out = diag.diagnose(test)
    assert out["proba"].dims == ("run", "window", "class")
    np.testing.assert_array_equal(out["window_start"].values, [0, 25, 50, 75])
    np.testing.assert_array_equal(out["window_end"].values, [25, 50, 75, 100])
    pred = out["state"].values
    # windows of 25 samples: run-mean noise 0.005 / 5 = 0.001 against offsets >= 0.03; 0.9
    # allows 3 of the 30 windows on either side of the onset to fall to a model error
    assert (pred[:, :2] == "fn").mean() >= 0.9
    assert (pred[:, 2:] == test["state"].values[:, None]).mean() >= 0.9
    np.testing.assert_allclose(out["proba"].values.sum(axis=-1), 1.0)


def test_bad_inputs_raise(data):
    normal, labelled, test = data
    with pytest.raises(ValueError, match="no 'state' coordinate"):
        stand_in().fit(normal, labelled.drop_vars("state"))
    with pytest.raises(ValueError, match="one class only"):
        stand_in().fit(normal, labelled.isel(run=labelled["state"] == "f1"))
    with pytest.raises(ValueError, match="lack"):
        stand_in().fit(normal, labelled.drop_vars("F"))
    with pytest.raises(ValueError, match="not fitted"):
        stand_in().diagnose(test)
    diag = stand_in().fit(normal, labelled)
    broken = test.copy(deep=True)
    broken["CV"].values[3, :] = np.nan
    with pytest.raises(ValueError, match=r"run\(s\) \[3\]"):
        diag.diagnose(broken)


def test_seva_output_statuses(data, rng):
    """The diagnoser's SEVA records: confident fn -> CLEAR, confident fault -> BLURRED,
    missing signals -> BLIND, inputs far outside training -> DAZZLED; VMV/VU from the
    normal models at the stated coverage."""
    from bayes_fdi.diagnosis.seva.record import SevaStatus, to_frame

    normal, labelled, _ = data
    # A tree of logistic regressions: confident on these well-separated residual offsets.
    diag = FaultDiagnoser(
        KernelRidgeRegressor(width=0.3),
        HierarchicalClassifier(LogisticRegression(C=100.0)),
        max_train_samples=400,
    ).fit(normal, labelled)
    test = campaign(["fn", "f1"], 2, rng)
    # Run 4: a copy of run 0 with a dead X sensor (all NaN) -> BLIND.
    blind = test.isel(run=[0]).assign(X=test["X"].isel(run=[0]) * np.nan)
    # Run 5: a copy of run 2 (f1) driven far outside the training inputs -> DAZZLED.
    novel = test.isel(run=[2])
    novel = novel.assign(P2=novel["P2"] * 0 + 0.7, T1=novel["T1"] + 0.5)
    runs = test.assign_coords(run=np.arange(4))
    runs = xr.concat([runs, blind.assign_coords(run=[4]), novel.assign_coords(run=[5])], dim="run")
    records = diag.seva(runs)
    status = [r.status for r in records]
    assert status[:2] == [SevaStatus.CLEAR, SevaStatus.CLEAR]
    assert status[2:4] == [SevaStatus.BLURRED, SevaStatus.BLURRED]
    assert status[4] == SevaStatus.BLIND
    assert status[5] == SevaStatus.DAZZLED
    assert all(r.state == "f1" for r in records[2:4])
    # VMV is the normal model's mean prediction; VU is 1.96 predictive std at 95 %.
    out = diag.diagnose(runs.isel(run=[0]))
    rec = records[0]
    assert rec.coverage == 0.95
    np.testing.assert_allclose(rec.x_vmv, float(out["X_hat"].mean()), rtol=1e-9)
    np.testing.assert_allclose(rec.x_measured, float(runs["X"].isel(run=0).mean()), rtol=1e-12)
    assert rec.x_vu > 0 and rec.f_vu > 0
    frame = to_frame(records)
    assert list(frame["status"].astype(str)) == [str(s) for s in status]

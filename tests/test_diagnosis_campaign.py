"""End-to-end diagnosis of a small simulated DAMADICS campaign (actuator model + RVMs)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bayes_fdi.campaigns.parsing import load_campaign
from bayes_fdi.campaigns.simulation import simulate_campaign
from bayes_fdi.diagnosis import FaultDiagnoser, svm_fault_diagnoser
from bayes_fdi.rvm import RVR

# States whose mean residuals the paper's two features separate well in the simulator.
STATES = ["fn", "f1", "f2", "f15", "f17", "f18"]
RUNS = 12  # per state: 6 to train, 6 to test


@pytest.fixture(scope="module")
def campaign():
    c = load_campaign(Path(__file__).parents[1] / "sim" / "paper-simulated.toml").replace(
        runs_per_state=RUNS, states=STATES, duration=200, seed=11
    )
    ds = simulate_campaign(c, progress=False)
    k = np.concatenate([np.arange(RUNS)] * len(STATES))
    order = np.concatenate([np.flatnonzero(ds["state"].values == s) for s in STATES])
    ds = ds.isel(run=order)
    train, test = ds.isel(run=k < RUNS // 2), ds.isel(run=k >= RUNS // 2)
    normal = train.isel(run=np.flatnonzero(train["state"].values == "fn"))
    return normal, train, test


def check_output(diag, out, test):
    np.testing.assert_allclose(out["proba"].values.sum(axis=1), 1.0, atol=1e-9)
    np.testing.assert_array_equal(out["true_state"].values, test["state"].values)
    # Residuals are measured minus predicted outputs, recomputed here from the data.
    np.testing.assert_allclose(out["r1"].values, test["X"].values - out["X_hat"].values)
    np.testing.assert_allclose(
        out["features"].sel(feature="mean_r2").values, out["r2"].values.mean(axis=1)
    )
    assert (out["X_hat_std"].values > 0).all() and (out["F_hat_std"].values > 0).all()
    for node in diag.classifier_.nodes_:
        assert node.n_vectors is not None and 0 < node.n_vectors <= node.n_samples
    return float((out["state"].values == out["true_state"].values).mean())


def test_rvm_pipeline_on_simulated_campaign(campaign):
    normal, train, test = campaign
    # The paper's method with the default tree of RVCs (sigma = 2); the RVR width is fixed
    # here (0.3, near this simulator's evidence optimum) to keep the test fast.
    diag = FaultDiagnoser(RVR(kernel="rbf", width=0.3), random_state=0).fit(normal, train)
    out = diag.diagnose(test)
    accuracy = check_output(diag, out, test)
    # these six states are the ones the two features separate (see docs/reproduce.md), but
    # with 6 training runs of 200 s per state the tree is rough: at most 3 of 36 runs wrong
    assert accuracy >= 0.9
    # Fault-free residuals are small against the predictive std (the model fits normal data):
    # a calibrated model gives an RMS of 1; 3 allows for the width fixed away from the optimum
    fn = out.isel(run=np.flatnonzero(out["true_state"].values == "fn"))
    assert float(np.sqrt(np.mean(fn["z1"].values ** 2))) < 3.0
    assert diag.classifier_.export_text().startswith("RVM1: ")


def test_svm_baseline_on_simulated_campaign(campaign):
    normal, train, test = campaign
    diag = svm_fault_diagnoser(max_train_samples=600).fit(normal, train)
    accuracy = check_output(diag, diag.diagnose(test), test)
    assert accuracy >= 0.9  # as for the RVM pipeline above

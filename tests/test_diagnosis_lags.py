"""FaultDiagnoser passes ``input_lags`` to its normal models."""

from __future__ import annotations

import numpy as np

from bayes_fdi.datasets import make_dataset
from bayes_fdi.diagnosis import FaultDiagnoser, KernelRidgeRegressor, NormalModels

OFFSETS = {"fn": (0.0, 0.0), "f1": (0.04, 0.0), "f2": (0.0, -0.04)}


def campaign(states, n_per, rng, T=60):
    """Static synthetic actuator, fault signatures as (X, F) offsets."""
    sts = [s for s in states for _ in range(n_per)]
    n, t = len(sts), np.arange(T)
    ph = rng.uniform(0, 2 * np.pi, (n, 1))
    CV = 0.5 + 0.3 * np.sin(2 * np.pi * t / 30 + ph)
    P1 = np.full((n, T), 0.9)
    P2 = 0.3 + 0.05 * np.sin(2 * np.pi * t / 23 + 3 * ph)
    T1 = np.full((n, T), 0.3)
    X = 0.9 * CV + 0.005 * rng.standard_normal((n, T))
    F = 0.7 * (1 - 0.8 * X) * np.sqrt(P1 - P2) + 0.005 * rng.standard_normal((n, T))
    X += np.array([OFFSETS[s][0] for s in sts])[:, None]
    F += np.array([OFFSETS[s][1] for s in sts])[:, None]
    return make_dataset(dict(CV=CV, P1=P1, P2=P2, T1=T1, X=X, F=F), state=sts)


def test_fault_diagnoser_forwards_input_lags():
    rng = np.random.default_rng(21)
    states = list(OFFSETS)
    normal, labelled = campaign(["fn"], 3, rng), campaign(states, 4, rng)
    assert FaultDiagnoser().get_params()["input_lags"] == ()
    diag = FaultDiagnoser(
        KernelRidgeRegressor(width=0.5, alphas=(1e-3,)),
        max_train_samples=200,
        input_lags=(1, 3),
    )
    assert diag.get_params()["input_lags"] == (1, 3)
    diag.fit(normal, labelled)
    nm = diag.normal_models_
    assert nm.input_lags == (1, 3)
    assert nm.input_names_ == ("CV", "sqrt_dP", "T1", "CV_lag1s", "CV_lag3s")
    # its residuals are those of NormalModels fitted alone with the same settings
    alone = NormalModels(
        KernelRidgeRegressor(width=0.5, alphas=(1e-3,)),
        max_train_samples=200,
        random_state=0,
        input_lags=(1, 3),
    ).fit(normal)
    out = diag.diagnose(labelled)
    np.testing.assert_allclose(out["r1"].values, alone.residuals(labelled)["r1"].values)
    static = FaultDiagnoser(KernelRidgeRegressor(width=0.5, alphas=(1e-3,)), max_train_samples=200)
    assert static.fit(normal, labelled).normal_models_.input_names_ == ("CV", "sqrt_dP", "T1")


def test_seva_records_with_dynamic_normal_models():
    """The SEVA output works unchanged on a diagnoser with lagged inputs."""
    rng = np.random.default_rng(22)
    states = list(OFFSETS)
    normal, labelled = campaign(["fn"], 3, rng), campaign(states, 4, rng)
    test = campaign(states, 2, rng)
    diag = FaultDiagnoser(
        KernelRidgeRegressor(width=0.5, alphas=(1e-3,)), max_train_samples=200, input_lags=(1, 2)
    ).fit(normal, labelled)
    records = diag.seva(test)
    assert len(records) == test.sizes["run"]
    truth = np.asarray(test["state"].values).astype(str)
    # offsets of 0.04 against noise 0.005: every run is diagnosed right, with its distribution
    assert [r.state for r in records] == truth.tolist()
    for r in records:
        assert abs(sum(r.distribution[c] for c in r.distribution) - 1.0) < 1e-9
        assert r.probability == max(r.distribution[c] for c in r.distribution)
        assert np.isfinite(r.x_vu) and r.x_vu > 0

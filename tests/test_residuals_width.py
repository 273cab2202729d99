"""Tests of the ``"evidence-grid"`` width search of the normal models (the default)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import sine_inputs
from sklearn.linear_model import Ridge

from bayes_fdi.datasets import make_dataset
from bayes_fdi.diagnosis import (
    WIDTH_GRID,
    FaultDiagnoser,
    NormalModels,
    evidence_grid_search,
    model_inputs,
)
from bayes_fdi.rvm import RVR

GRID = (0.05, 0.1, 0.2, 0.4, 0.8)


def trajectory_runs(n_runs, rng, T=100, noise=0.005):
    """Sine-driven runs (thin trajectories of the input space) with smooth outputs."""
    ch = sine_inputs(n_runs, rng, T)
    CV, P1, P2 = ch["CV"], ch["P1"], ch["P2"]
    X = 0.9 * CV + 0.05 * CV**2 + noise * rng.standard_normal((n_runs, T))
    F = 0.7 * (1 - 0.8 * X) * np.sqrt(P1 - P2) + noise * rng.standard_normal((n_runs, T))
    return make_dataset(dict(ch, X=X, F=F))


def independent_evidence(U, ys, widths):
    """Log evidence of ``RVR(kernel="rbf", width=w)`` fitted on ``(U, y)``, per output."""
    return {
        name: {w: RVR(kernel="rbf", width=w).fit(U, y).log_evidence_ for w in widths}
        for name, y in ys.items()
    }


def test_defaults_are_the_evidence_grid():
    assert NormalModels().width_search == "evidence-grid"
    assert NormalModels().width_grid == GRID == WIDTH_GRID
    assert NormalModels().evidence_max_samples == 600
    assert FaultDiagnoser().width_search == "evidence-grid"


def test_grid_search_is_the_argmax_of_independent_evidences(rng):
    """Width = argmax over the grid of the X + F log evidences of RVRs fitted independently on
    the same seeded subsample; both final models use it and every sample."""
    normal = trajectory_runs(4, rng)
    nm = NormalModels(evidence_max_samples=150, random_state=3, interval_calibration=None)
    nm.fit(normal)
    U, _ = model_inputs(normal)
    idx = np.sort(np.random.default_rng(3).choice(U.shape[0], size=150, replace=False))
    ys = {name: normal[name].values.ravel()[idx] for name in ("X", "F")}
    ev = independent_evidence(U[idx], ys, GRID)
    total = {w: ev["X"][w] + ev["F"][w] for w in GRID}
    best = max(total, key=total.get)
    assert nm.widths_ == {"X": best, "F": best}
    assert set(nm.width_log_evidence_) == set(GRID)
    for w in GRID:
        assert nm.width_log_evidence_[w] == pytest.approx(total[w], rel=1e-9)
        for name in ("X", "F"):
            assert nm.width_log_evidence_by_output_[name][w] == pytest.approx(ev[name][w], rel=1e-9)
    for est in nm.regressors_.values():
        assert est.get_params()["width"] == best and est.width_ == best
    assert nm.n_train_samples_ == U.shape[0] == 400
    assert nm.fit_seconds_["evidence-grid"] > 0  # the search ran and was timed


def test_grid_search_on_every_sample_when_there_are_few():
    """No more samples than ``evidence_max_samples``: the grid is fitted on all of them."""
    normal = trajectory_runs(2, np.random.default_rng(5), T=40)
    nm = NormalModels(evidence_max_samples=600, interval_calibration=None).fit(normal)
    U, _ = model_inputs(normal)
    ys = {name: normal[name].values.ravel() for name in ("X", "F")}
    ev = independent_evidence(U, ys, GRID)
    for w in GRID:
        assert nm.width_log_evidence_[w] == pytest.approx(ev["X"][w] + ev["F"][w], rel=1e-9)


def rbf_basis_runs(true_width, rng, n_runs=4, T=100, noise=0.01, n_centres=12):
    """Inputs spread over [0, 1]^3; X and F sums of Gaussian bumps of width ``true_width``."""
    shape = (n_runs, T)
    CV, dP, T1 = rng.uniform(0, 1, shape), rng.uniform(0.05, 1, shape), rng.uniform(0, 1, shape)
    P2 = rng.uniform(0.1, 0.3, shape)
    U = np.stack([CV, np.sqrt(dP), T1], axis=-1)
    out = {}
    for name in ("X", "F"):
        centres = rng.uniform(0, 1, (n_centres, 3))
        weights = rng.normal(0, 1, n_centres)
        d2 = ((U[..., None, :] - centres) ** 2).sum(-1)
        out[name] = np.exp(-d2 / (2 * true_width**2)) @ weights + noise * rng.standard_normal(shape)
    return make_dataset(dict(CV=CV, P1=P2 + dP, P2=P2, T1=T1, **out))


@pytest.mark.parametrize("true_width", [0.1, 0.4])
def test_grid_search_finds_a_known_width(true_width):
    """Outputs built from Gaussian bumps of a known width: the search picks it or a grid
    neighbour."""
    normal = rbf_basis_runs(true_width, np.random.default_rng(11))
    nm = NormalModels(evidence_max_samples=300, random_state=0, interval_calibration=None)
    nm.fit(normal)
    k = GRID.index(true_width)
    assert nm.widths_["X"] in GRID[max(k - 1, 0) : k + 2]


def test_grid_search_uses_the_lagged_inputs():
    """With ``input_lags`` the evidences are those of RVRs on hand-built lagged inputs."""
    normal = trajectory_runs(2, np.random.default_rng(8), T=40)
    nm = NormalModels(input_lags=(2,), interval_calibration=None, width_grid=(0.1, 0.4))
    nm.fit(normal)
    cv = normal["CV"].values
    lag2 = np.concatenate([cv[:, :1], cv[:, :1], cv[:, :-2]], axis=1)
    U = np.column_stack(
        [
            cv.ravel(),
            np.sqrt((normal["P1"] - normal["P2"]).values.ravel()),
            normal["T1"].values.ravel(),
            lag2.ravel(),
        ]
    )
    ys = {name: normal[name].values.ravel() for name in ("X", "F")}
    ev = independent_evidence(U, ys, (0.1, 0.4))
    for w in (0.1, 0.4):
        assert nm.width_log_evidence_[w] == pytest.approx(ev["X"][w] + ev["F"][w], rel=1e-9)
    assert all(est.n_features_in_ == 4 for est in nm.regressors_.values())


def test_select_regression_width_is_the_same_search(rng):
    """`select_regression_width` and the default `NormalModels` search agree exactly."""
    from bayes_fdi.paper.setup import select_regression_width

    normal = trajectory_runs(4, rng)
    width, evidence = select_regression_width(normal, seed=3, max_samples=150)
    nm = NormalModels(evidence_max_samples=150, random_state=3, interval_calibration=None)
    nm.fit(normal)
    assert nm.widths_ == {"X": width, "F": width}
    assert nm.width_log_evidence_ == evidence


def test_explicit_width_and_grid_kept_as_given(rng):
    normal = trajectory_runs(2, rng, T=50)
    grid = [0.4, 0.1]
    nm = NormalModels(RVR(kernel="rbf", width=0.3), width_grid=grid, interval_calibration=None)
    assert nm.get_params()["width_grid"] is grid
    nm.fit(normal)
    assert nm.widths_ == {} and nm.width_log_evidence_ == {}
    assert nm.width_log_evidence_by_output_ == {}
    assert all(est.width_ == 0.3 for est in nm.regressors_.values())
    assert nm.width_grid is grid and grid == [0.4, 0.1]
    # the grid's own order is kept in the recorded evidences
    searched = NormalModels(width_grid=grid, interval_calibration=None).fit(normal)
    assert list(searched.width_log_evidence_) == [0.4, 0.1]


@pytest.mark.parametrize(
    "grid", [(), [], (0.1, -0.2), (0.1, 0.0), (0.1, np.nan), (np.inf,), (0.1, 0.1), 0.1, "ab",
             (True,), (0.1, None)]
)  # fmt: skip
def test_bad_width_grid_raises(grid):
    normal = trajectory_runs(1, np.random.default_rng(0), T=20)
    with pytest.raises(ValueError, match="width_grid"):
        NormalModels(width_grid=grid, interval_calibration=None).fit(normal)


@pytest.mark.parametrize("m", [0, 1, 2.5, True, None])
def test_bad_evidence_max_samples_raises(m):
    normal = trajectory_runs(1, np.random.default_rng(0), T=20)
    with pytest.raises(ValueError, match="evidence_max_samples"):
        NormalModels(evidence_max_samples=m, interval_calibration=None).fit(normal)


def test_bad_width_search_raises():
    normal = trajectory_runs(1, np.random.default_rng(0), T=20)
    with pytest.raises(ValueError, match="evidence-grid"):
        NormalModels(width_search="grid").fit(normal)


def test_evidence_grid_search_needs_a_log_evidence():
    U = np.random.default_rng(1).uniform(size=(20, 3))
    with pytest.raises(ValueError, match="log_evidence_"):
        evidence_grid_search(lambda w: Ridge(alpha=w), U, {"X": U[:, 0]}, (0.1, 1.0))
    with pytest.raises(ValueError, match="empty"):
        evidence_grid_search(lambda w: RVR(width=w), U, {"X": U[:, 0]}, ())

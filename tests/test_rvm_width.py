"""width="auto" against a brute-force evidence grid, and the search helper on a known curve."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from bayes_fdi.rvm import RVC, RVR
from bayes_fdi.rvm.width import (
    NN_FACTOR,
    data_scale,
    nearest_neighbour_scale,
    search_width,
    width_bounds,
)


def test_search_width_finds_known_maximum():
    calls = []

    def curve(width: float) -> float:
        calls.append(width)
        return -((math.log(width) - math.log(0.37)) ** 2)

    res = search_width(curve, scale=1.0)
    assert res.width == pytest.approx(0.37, rel=0.03)
    assert res.log_evidence == max(res.evidences)
    np.testing.assert_allclose(res.widths, calls)


def test_data_scale_is_median_distance():
    X = torch.tensor([[0.0], [1.0], [3.0]], dtype=torch.float64)
    assert data_scale(X) == pytest.approx(2.0)  # distances 1, 2, 3


def test_rvr_auto_width_near_grid_maximum():
    rng = np.random.default_rng(3)
    X = rng.uniform(-10, 10, (200, 1))
    y = np.sinc(X[:, 0] / np.pi) + 0.1 * rng.standard_normal(200)
    auto = RVR(width="auto").fit(X, y)
    grid = np.geomspace(0.3, 10.0, 25)
    evidences = np.array([RVR(width=w).fit(X, y).log_evidence_ for w in grid])
    best = evidences.max()
    # the evidence over sigma is rugged (local optima of the sequential algorithm):
    # the search must land within a nat of the brute-force maximum, at a similar width
    assert auto.log_evidence_ >= best - 1.0
    assert abs(math.log(auto.width_ / grid[evidences.argmax()])) < math.log(2.0)
    assert auto.log_evidence_ == pytest.approx(RVR(width=auto.width_).fit(X, y).log_evidence_)
    assert auto.width_search_.log_evidence == pytest.approx(auto.log_evidence_)


def test_rvc_auto_width_beats_poor_widths():
    rng = np.random.default_rng(9)
    y = np.repeat([0, 1], 50)
    X = rng.standard_normal((100, 2)) + 1.2 * y[:, None]
    auto = RVC(width="auto").fit(X, y)
    for w in (0.5, 2.0, 8.0):
        assert auto.log_evidence_ >= RVC(width=w).fit(X, y).log_evidence_ - 0.5


def test_nearest_neighbour_scale_and_bounds_by_brute_force():
    rng = np.random.default_rng(4)
    X = torch.tensor(rng.standard_normal((60, 3)))
    X = torch.cat([X, X[:5]])  # duplicated rows must not shrink the scale to zero
    U = np.unique(X.numpy(), axis=0)
    d = np.linalg.norm(U[:, None] - U[None], axis=-1)
    np.fill_diagonal(d, np.inf)
    nn = np.median(d.min(1))
    assert nearest_neighbour_scale(X, block=7) == pytest.approx(nn)
    lo, hi = width_bounds(X)
    assert lo == pytest.approx(NN_FACTOR * nn)
    assert hi == pytest.approx(d[np.isfinite(d)].max())


def test_rvr_auto_width_does_not_interpolate_real_plant_data():
    """The real Lublin hour: tiny widths have the highest evidence but interpolate.

    Train on a seeded subsample of samples 12 s apart, test on the samples half-way in
    between (interleaved).  The auto width must give a sparse model whose noise level
    matches the residual spread of a plain smooth (cubic least-squares) fit and whose
    90 % predictive intervals cover the held-out samples.
    """
    from bayes_fdi.datasets import load_lublin_example

    ds = load_lublin_example()
    X = np.stack([ds[c].values[0] for c in ("CV", "P1", "P2", "T1")], 1)
    y = ds["X"].values[0]
    rng = np.random.default_rng(0)
    tr = np.sort(rng.choice(np.arange(0, 3594, 12), 150, replace=False))
    te = tr + 6
    model = RVR(width="auto").fit(X[tr], y[tr])

    # independent reference: residual std of a cubic polynomial least-squares fit
    def cubic(A):
        return np.column_stack([A**k for k in (1, 2, 3)] + [np.ones(len(A))])

    w, *_ = np.linalg.lstsq(cubic(X[tr]), y[tr], rcond=None)
    ref_std = np.std(y[tr] - cubic(X[tr]) @ w)

    assert 1 <= len(model.relevance_indices_) <= 30
    assert 0.5 * ref_std < model.noise_std_ < 2.0 * ref_std
    mean, std = model.predict(X[te], return_std=True)
    coverage = np.mean(np.abs(y[te] - mean) <= 1.6448536 * std)
    assert 0.75 <= coverage <= 0.98
    search = model.width_search_
    lo, hi = search.bounds
    assert lo <= model.width_ <= hi
    assert lo > 0.0021  # the unbounded evidence maximum (an interpolating fit) is excluded
    assert search.log_evidence == pytest.approx(model.log_evidence_)
    assert np.all(search.evidences <= search.log_evidence)


def test_rvc_auto_width_within_data_bounds_and_sparse():
    rng = np.random.default_rng(11)
    y = np.repeat([0, 1], 60)
    X = rng.standard_normal((120, 2)) + 1.5 * y[:, None]
    clf = RVC(width="auto").fit(X, y)
    lo, hi = clf.width_search_.bounds
    assert (lo, hi) == pytest.approx(width_bounds(torch.tensor(X)))
    assert lo <= clf.width_ <= hi
    assert len(clf.relevance_indices_) < 20
    # Bayes-optimal rule for two unit-variance Gaussians: threshold on x1 + x2
    Xt = rng.standard_normal((400, 2)) + 1.5 * np.repeat([0, 1], 200)[:, None]
    yt = np.repeat([0, 1], 200)
    bayes_acc = np.mean((Xt.sum(1) > 1.5) == yt)
    assert clf.score(Xt, yt) >= bayes_acc - 0.05

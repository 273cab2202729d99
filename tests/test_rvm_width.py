"""width="auto" against a brute-force evidence grid, and the search helper on a known curve."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from bayes_fdi.rvm import RVC, RVR
from bayes_fdi.rvm.width import data_scale, search_width


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
    grid = np.geomspace(0.3, 10.0, 40)
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
    y = np.repeat([0, 1], 80)
    X = rng.standard_normal((160, 2)) + 1.2 * y[:, None]
    auto = RVC(width="auto").fit(X, y)
    for w in (0.3, 1.0, 3.0, 10.0):
        assert auto.log_evidence_ >= RVC(width=w).fit(X, y).log_evidence_ - 0.5

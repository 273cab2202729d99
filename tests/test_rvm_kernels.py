"""Kernels against scikit-learn's pairwise kernels, and their algebra and serialisation."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from sklearn.metrics.pairwise import linear_kernel, polynomial_kernel, rbf_kernel

from bayes_fdi.rvm import RBF, Linear, Polynomial
from bayes_fdi.rvm.kernels import kernel_from_dict


@pytest.fixture(scope="module")
def points():
    rng = np.random.default_rng(2)
    return rng.normal(size=(30, 3)) * 5 + 100, rng.normal(size=(20, 3)) * 5 + 100


def test_against_sklearn(points):
    X, Z = points
    Xt, Zt = torch.tensor(X), torch.tensor(Z)
    sigma = 3.0
    np.testing.assert_allclose(
        RBF(sigma)(Xt, Zt).numpy(), rbf_kernel(X, Z, gamma=1 / (2 * sigma**2)), rtol=1e-10
    )
    np.testing.assert_allclose(Linear(2.0)(Xt, Zt).numpy(), linear_kernel(X, Z) + 2.0, rtol=1e-12)
    np.testing.assert_allclose(
        Polynomial(3, 0.001, 1.0)(Xt, Zt).numpy(),
        polynomial_kernel(X, Z, degree=3, gamma=0.001, coef0=1.0),
        rtol=1e-12,
    )
    assert torch.all(RBF(sigma)(Xt).diagonal() == 1.0)  # exact on a Gram matrix
    np.testing.assert_allclose(RBF(sigma)(Xt, Xt[:5].clone()).diagonal().numpy(), 1.0, rtol=1e-12)


def test_algebra_dtype_and_round_trip(points):
    X, Z = points
    Xt, Zt = torch.tensor(X, dtype=torch.float32), torch.tensor(Z, dtype=torch.float32)
    k = RBF(2.0) + 0.5 * RBF(8.0) * Linear(1.0)
    K = k(Xt, Zt)
    assert K.dtype == torch.float32 and K.shape == (30, 20)
    expect = RBF(2.0)(Xt, Zt) + 0.5 * (RBF(8.0)(Xt, Zt) * Linear(1.0)(Xt, Zt))
    torch.testing.assert_close(K, expect)
    back = kernel_from_dict(k.to_dict())
    assert back == k
    torch.testing.assert_close(back(Xt, Zt), K)


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: RBF(0.0), "width"),
        (lambda: RBF(float("nan")), "width"),
        (lambda: Polynomial(0), "degree"),
        (lambda: Linear(-1.0), "offset"),
        (lambda: kernel_from_dict({"type": "matern"}), "unknown kernel"),
        (lambda: kernel_from_dict({"type": "rbf"}), "malformed"),
        (lambda: RBF(1.0)(torch.zeros(3, 2), torch.zeros(3, 3)), "features"),
    ],
)
def test_invalid(make, match):
    with pytest.raises(ValueError, match=match):
        make()


# ---------------------------------------------------------------- extreme widths and inputs
def _rbf_closed_form(x: np.ndarray, z: np.ndarray, width: float) -> np.ndarray:
    """exp(-||x - z||^2 / (2 width^2)) by direct differences, the distance scaled by the
    width before squaring (so that neither width^2 nor ||x - z||^2 is ever formed)."""
    d = np.sqrt(((x[:, None, :] - z[None, :, :]) ** 2).sum(-1))
    with np.errstate(over="ignore"):  # (d / width)^2 = inf: the kernel is 0
        return np.exp(-0.5 * (d / width) ** 2)


@pytest.mark.parametrize("width", [1e-160, 1e-300, 5e291, 1e300])
def test_rbf_extreme_widths_are_finite_and_exact(width):
    # 1e-160 and 5e291 square to below / above the float64 range: a zero distance must
    # still give exactly 1, a positive one exp(-d^2 / (2 w^2)) (0 or 1 at these widths)
    Z = torch.tensor([[0.0], [1.0]], dtype=torch.float64)
    X = torch.tensor([[0.0], [1.0], [3.0]] + [[float(k)] for k in range(20)], dtype=torch.float64)
    for A, B in ((Z, Z), (X, X), (X, Z)):
        K = RBF(width)(A, B).numpy()
        assert np.isfinite(K).all()
        np.testing.assert_array_equal(K, _rbf_closed_form(A.numpy(), B.numpy(), width))


def test_rbf_far_from_the_mean_does_not_cancel():
    # |x|^2 + |z|^2 - 2 x.z cancels catastrophically for points 1e8 away from the data's
    # mean; k(0, 1) = exp(-1/2) in closed form (direct differences are exact here: the
    # inputs and their differences are integers)
    X = torch.tensor([[0.0], [1e8], [2e8]], dtype=torch.float64)
    Z = torch.tensor([[0.0], [1.0]], dtype=torch.float64)
    K = RBF(1.0)(X, Z).numpy()
    assert K[0, 1] == pytest.approx(np.exp(-0.5), rel=1e-15)
    # the same in a set large enough for the expansion path (> 16 entries of Z), as a Gram
    # matrix and across sets, integer inputs up to 2e8 with unit differences among the small
    big = np.concatenate([[0.0, 1e8, 2e8], np.arange(1.0, 30.0)])[:, None]
    Bt = torch.tensor(big)
    expect = _rbf_closed_form(big, big, 1.0)
    np.testing.assert_allclose(RBF(1.0)(Bt).numpy(), expect, rtol=1e-14, atol=0)
    np.testing.assert_allclose(RBF(1.0)(Bt, Bt[3:].clone()).numpy(), expect[:, 3:], rtol=1e-14)
    # 3 features, points offset by +-1e7 with distances ~1: every near pair lies below the
    # cancellation bound and is recomputed by direct differences (exact for points within a
    # factor 2 of each other), the far pairs' kernel underflows to 0: the result is the
    # closed form up to the last bits of exp and sqrt
    rng = np.random.default_rng(4)
    P = rng.normal(size=(40, 3)) + 1e7
    P[20:] -= 2e7  # the mean lies far from every point
    np.testing.assert_allclose(
        RBF(2.0)(torch.tensor(P)).numpy(), _rbf_closed_form(P, P, 2.0), rtol=1e-13, atol=0
    )

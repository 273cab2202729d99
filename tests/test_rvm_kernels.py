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

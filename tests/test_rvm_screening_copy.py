"""The kernel matrix's screening copy (upper triangle, float32 + bfloat16 entries, float64
products) against numpy's float64 kernel matrix, and the fits it serves against the fits of the
float64 matrix held in memory."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from blas_paths import EVERYTHING_ELSE, REFERENCE, run_python

from bayes_fdi.rvm import RBF, RVC, RVR, Linear
from bayes_fdi.rvm.sbl import ENTRY_BYTES, Design, TriangleCopy, fast_gaussian, triangle_bytes


def rbf(X: np.ndarray, width: float) -> np.ndarray:
    d2 = ((X[:, None, :] - X[None, :, :]) ** 2).sum(-1)
    return np.exp(-d2 / (2 * width**2))


@pytest.fixture(scope="module")
def problem() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(31)
    X = rng.uniform(-1, 1, (500, 3))
    y = np.sin(np.pi * X[:, 0]) * np.cos(np.pi * X[:, 1] / 2) + X[:, 2] ** 2 / 2
    return X, y + 0.1 * rng.standard_normal(500)


def test_storage_by_hand():
    """Blocks of 3 rows of a 10 x 10 matrix keep 3x10, 3x7, 3x4 and 1x1 entries: 64."""
    assert triangle_bytes(10, 3) == ENTRY_BYTES * 64 == 384
    X = torch.linspace(0, 1, 10, dtype=torch.float64)[:, None]
    copy = TriangleCopy(RBF(0.5), X, rows=3)
    assert [tuple(b.shape) for b in copy.his] == [(3, 10), (3, 7), (3, 4), (1, 1)]
    assert copy.nbytes == 384
    assert TriangleCopy.rows_for(20_000) == 25  # 25 x 20 000 float64 = 4 MB


@pytest.mark.parametrize("rows", [1, 7, 64, 500])
def test_entries_products_norms_against_numpy(problem, rows):
    X, y = problem
    K = rbf(X, 0.5)
    copy = TriangleCopy(RBF(0.5), torch.tensor(X), rows=rows, rhs=torch.tensor(y))
    # each stored entry hi + lo within 2^-33 |K| (+ the subnormal floor) of K
    s = 0
    for hi, lo in zip(copy.his, copy.los, strict=True):
        r = hi.shape[0]
        stored = hi.double().numpy() + lo.double().numpy()
        exact = K[s : s + r, s:]
        assert (np.abs(stored - exact) <= 2.0**-33 * np.abs(exact) + 2.0**-133).all()
        s += r
    norms = np.linalg.norm(K, axis=0)
    np.testing.assert_allclose(copy.norms.numpy(), norms, rtol=1e-14)
    np.testing.assert_allclose(copy.rhs_product[:, 0].numpy(), K @ y, rtol=0, atol=1e-11)
    bound = copy.error(float(norms.min()))
    assert 2 * 2.0**-33 < bound < 3 * 2.0**-33  # the stored entries' error dominates
    V = np.random.default_rng(2).standard_normal((500, 3))
    got = copy.matmul(torch.tensor(V)).numpy()
    limit = bound * norms[:, None] * np.linalg.norm(V, axis=0)[None, :]
    assert (np.abs(got - K @ V) <= limit).all()
    w = np.random.default_rng(3).uniform(0, 2, 500)
    got_sq = copy.square_matmul(torch.tensor(w)[:, None])[:, 0].numpy()
    assert (np.abs(got_sq - (K * K) @ w) <= bound * norms**2 * w.max()).all()


def test_float32_overflow_is_refused_and_the_design_falls_back():
    """A linear kernel on inputs near 1e20 has entries beyond float32: no copy is kept."""
    X = torch.tensor([[1e20], [2e20], [3e20]], dtype=torch.float64)
    with pytest.raises(OverflowError, match="float32 range"):
        TriangleCopy(Linear(), X, rows=2)
    design = Design(kernel=Linear(), X=X, bias=False, screen=True)
    assert design.screen_copy is None and design.F is not None


def test_float32_designs_get_no_copy():
    X = torch.rand(50, 2, dtype=torch.float32)
    with pytest.raises(TypeError, match="float64"):
        TriangleCopy(RBF(1.0), X, rows=8)
    assert Design(kernel=RBF(1.0), X=X, screen=True).screen_copy is None


def test_budget_selects_the_copy_and_the_fit_is_the_same(problem):
    """With a budget below the float64 matrix (2 MB here) but above the copy, a CPU design keeps
    the copy by default; the fit takes the float64 matrix's path of actions."""
    X, y = problem
    Xt, t = torch.tensor(X), torch.tensor(y)
    n = 500
    budget = 8 * n * n - 1
    assert triangle_bytes(n, TriangleCopy.rows_for(n)) < budget
    held = Design(kernel=RBF(0.5), X=Xt, rhs=t)
    copied = Design(kernel=RBF(0.5), X=Xt, rhs=t, max_bytes=budget)
    rows = Design(kernel=RBF(0.5), X=Xt, rhs=t, max_bytes=budget, screen=False)
    assert held.F is not None and held.screen_copy is None
    assert copied.F is None and copied.screen_copy is not None and copied.materialised
    assert rows.F is None and rows.screen_copy is None and not rows.materialised
    r_held, r_copied = fast_gaussian(held, t), fast_gaussian(copied, t)
    assert r_copied.active.tolist() == r_held.active.tolist()
    assert r_copied.n_iter == r_held.n_iter
    assert r_copied.log_evidence == pytest.approx(r_held.log_evidence, abs=1e-9)
    # through the estimator, which passes its budget on
    m_held = RVR(width=0.5).fit(X, y)
    m_copied = RVR(width=0.5, max_kernel_bytes=budget).fit(X, y)
    np.testing.assert_array_equal(m_copied.relevance_indices_, m_held.relevance_indices_)
    np.testing.assert_allclose(m_copied.predict(X[:50]), m_held.predict(X[:50]), atol=1e-8)


def test_classifier_on_the_copy_is_the_same(problem):
    """The Bernoulli solver screens with the copy's products and squared products."""
    X, _ = problem
    labels = (X[:, 0] + 0.3 * np.sin(4 * X[:, 1]) > 0).astype(int)
    budget = 8 * 500 * 500 - 1
    held = RVC(width=0.5).fit(X, labels)
    copied = RVC(width=0.5, max_kernel_bytes=budget).fit(X, labels)
    np.testing.assert_array_equal(copied.relevance_indices_, held.relevance_indices_)
    np.testing.assert_allclose(
        copied.predict_proba(X[:50]), held.predict_proba(X[:50]), rtol=0, atol=1e-8
    )


def test_screening_error_covers_tiny_columns():
    """The bound grows where a column's norm is tiny (the stored entries' absolute floor)."""
    X = torch.tensor([[0.0], [1.0]], dtype=torch.float64)
    copy = TriangleCopy(RBF(1.0), X, rows=1)
    assert copy.error(1.0) < 1e-9
    assert copy.error(1e-40) > 1e-9
    assert copy.error(0.0) == math.inf


_SCRIPT = """
import numpy as np
from bayes_fdi.rvm import RVR
rng = np.random.default_rng(5)
X = rng.uniform(-10, 10, (300, 3))
y = (np.sinc(X / np.pi)).sum(1) + 0.1 * rng.standard_normal(300)
for budget in (8 * 300 * 300 - 1, 2 * 10**9):  # the copy; the float64 matrix (dsymv products)
    m = RVR(width=5 ** 0.5, max_kernel_bytes=budget).fit(X, y)
    print(m.relevance_indices_.tolist(), m.n_iter_, repr(m.log_evidence_))
"""


def test_fit_on_the_copy_is_the_same_on_another_blas_code_path_and_thread_count():
    """A sinc-sum fit (many relevance vectors) screened with the copy, and with the float64
    matrix in memory: the same basis and iteration count under MKL's AVX2 path, OpenBLAS's
    Haswell kernels and two threads as on the default path with one (the evidence to rounding),
    and the same with either storage."""
    outs = [
        line.rsplit(" ", 2)
        for env in (REFERENCE, EVERYTHING_ELSE)
        for line in run_python(_SCRIPT, env).strip().splitlines()
    ]
    assert len(outs) == 4
    for a in outs[1:]:
        assert a[:2] == outs[0][:2]  # basis and iteration count
        assert float(a[2]) == pytest.approx(float(outs[0][2]), abs=1e-9)


def test_tiny_matrices_and_more_rows_than_samples():
    """One sample, and blocks asked larger than the matrix: the products are still K v."""
    X = torch.tensor([[0.3]], dtype=torch.float64)
    one = TriangleCopy(RBF(1.0), X, rows=10**6)
    assert one.rows == 1 and one.nbytes == ENTRY_BYTES
    v = torch.tensor([[2.5]], dtype=torch.float64)
    assert one.matmul(v).item() == 2.5  # K = [[1]]
    X3 = torch.tensor([[0.0], [1.0], [3.0]], dtype=torch.float64)
    K = torch.tensor(rbf(X3.numpy(), 1.0))
    copy = TriangleCopy(RBF(1.0), X3, rows=50)
    V = torch.tensor([[1.0, -1.0], [2.0, 0.5], [-3.0, 4.0]], dtype=torch.float64)
    norms = torch.linalg.vector_norm(K, dim=0)
    bound = copy.error(float(norms.min())) * norms[:, None] * torch.linalg.vector_norm(V, dim=0)
    assert bool(((copy.matmul(V) - K @ V).abs() <= bound).all())

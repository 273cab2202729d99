"""The fast Bernoulli solver where a wide RBF basis separates the classes.

The fixture holds the 400 training signatures (10 standardised features, two classes) of one
node of a commissioned isolation tree: one class a tight cluster, the other spread around it
with outliers. At width 5.5153 the fast solver's third addition predicts every target to within
rounding (all weights ``y (1 - y)`` underflow), and the next addition's precision underflows to
0: the solver used to add it and fail in the next Laplace mode ("Hessian ... not positive
definite"), which also broke ``width="auto"``, whose search passes that width. It now stops at
the best model seen. Checked against a Laplace evidence computed here in numpy by a Newton
iteration of its own.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bayes_fdi.rvm import RVC

DATA = Path(__file__).parent / "data" / "rvc_separating_basis.npz"
WIDTH = 5.5153


def _data() -> tuple[np.ndarray, np.ndarray]:
    with np.load(DATA, allow_pickle=False) as d:
        return d["X"], d["y"]


def _laplace_evidence(model: RVC, X: np.ndarray, y: np.ndarray) -> tuple[float, np.ndarray]:
    """Laplace log evidence and weight mode of ``model``'s basis and precisions (Tipping
    2001, eqs. 26-28), by a damped Newton iteration in numpy."""
    z = model.relevance_vectors_
    d2 = ((X[:, None, :] - z[None, :, :]) ** 2).sum(-1)
    Phi = np.exp(-d2 / (2.0 * model.width_**2))
    if len(model.mean_) == Phi.shape[1] + 1:  # the bias column comes first
        Phi = np.column_stack([np.ones(len(X)), Phi])
    alpha = np.asarray(model.alpha_, dtype=np.float64)

    def objective(m):
        a = Phi @ m
        log_lik = np.sum(y * -np.logaddexp(0, -a) + (1 - y) * -np.logaddexp(0, a))
        return float(log_lik) - 0.5 * float(alpha @ (m * m))

    m = np.zeros(Phi.shape[1])
    for _ in range(200):
        p = 1.0 / (1.0 + np.exp(-(Phi @ m)))
        H = (Phi.T * (p * (1 - p))) @ Phi + np.diag(alpha)
        step = np.linalg.solve(H, Phi.T @ (y - p) - alpha * m)
        lr = 1.0
        while objective(m + lr * step) < objective(m) and lr > 1e-6:
            lr /= 2
        m = m + lr * step
        if float(np.abs(step).max()) < 1e-12 * (1 + float(np.abs(m).max())):
            break
    p = 1.0 / (1.0 + np.exp(-(Phi @ m)))
    H = (Phi.T * (p * (1 - p))) @ Phi + np.diag(alpha)
    logdet = np.linalg.slogdet(H)[1] - np.sum(np.log(alpha))
    return objective(m) - 0.5 * logdet, m


def test_the_solver_stops_before_a_basis_that_separates_the_classes():
    X, y = _data()
    model = RVC(kernel="rbf", width=WIDTH).fit(X, y)
    assert model.converged_
    assert np.all(np.isfinite(model.mean_)) and np.all(np.asarray(model.alpha_) > 0)
    # the model returned is one whose Laplace approximation holds: no target predicted to
    # within rounding, and its evidence and mode are those computed afresh
    p = model.predict_proba(X)[:, 1]
    assert 1e-6 < p.min() and p.max() < 1 - 1e-6
    evidence, mode = _laplace_evidence(model, X, y)
    # both modes are found to rounding on a 400-sample problem with a handful of weights;
    # 1e-6 relative bounds the conditioning of H times the rounding of two Newton solvers
    assert model.log_evidence_ == pytest.approx(evidence, rel=1e-6)
    np.testing.assert_allclose(model.mean_, mode, rtol=1e-6, atol=1e-8)
    assert model.log_evidence_ == pytest.approx(float(np.max(model.evidence_trace_)), abs=1e-4)


def test_the_width_search_passes_such_a_width():
    X, y = _data()
    model = RVC(kernel="rbf", width="auto").fit(X, y)
    assert np.isfinite(model.log_evidence_)
    fixed = RVC(kernel="rbf", width=WIDTH).fit(X, y)
    assert model.log_evidence_ > fixed.log_evidence_  # the search did not stop at it

"""RVC against the analytic Bayes classifier, closed forms and the EM solver."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.special import expit
from scipy.stats import multivariate_normal
from sklearn.exceptions import NotFittedError

from bayes_fdi.rvm import RVC

MEANS = (np.array([-1.0, 0.0]), np.array([1.0, 0.5]))
COV = np.array([[1.0, 0.3], [0.3, 1.0]])


def two_gaussians(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    y = rng.integers(0, 2, n)
    X = np.where(
        y[:, None] == 1,
        rng.multivariate_normal(MEANS[1], COV, n),
        rng.multivariate_normal(MEANS[0], COV, n),
    )
    return X, y


def metrics(p1: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Accuracy, Brier score and log-loss of P(y = 1) = p1."""
    p1 = np.clip(p1, 1e-15, 1 - 1e-15)
    acc = np.mean((p1 > 0.5) == y)
    brier = np.mean((p1 - y) ** 2)
    logloss = -np.mean(y * np.log(p1) + (1 - y) * np.log(1 - p1))
    return float(acc), float(brier), float(logloss)


@pytest.fixture(scope="module")
def data():
    X, y = two_gaussians(400, seed=11)
    X_test, y_test = two_gaussians(20000, seed=12)
    return X, y, X_test, y_test


@pytest.fixture(scope="module")
def clf(data) -> RVC:
    X, y, _, _ = data
    return RVC(width=1.0).fit(X, y)


def test_near_bayes_optimal(data, clf):
    _, _, X_test, y_test = data
    # the true posterior from the generating densities (equal priors)
    d1 = multivariate_normal(MEANS[1], COV).pdf(X_test)
    d0 = multivariate_normal(MEANS[0], COV).pdf(X_test)
    acc_b, brier_b, ll_b = metrics(d1 / (d0 + d1), y_test)
    acc, brier, ll = metrics(clf.predict_proba(X_test)[:, 1], y_test)
    assert acc >= acc_b - 0.01
    assert brier <= brier_b + 0.01
    assert ll <= ll_b + 0.025
    assert len(clf.relevance_indices_) <= 0.05 * 400
    assert clf.score(X_test, y_test) == pytest.approx(acc)


def test_moderated_output_closed_form(data, clf):
    X, _, X_test, _ = data
    Xn = X_test[:200]
    Phi = clf.design_matrix(Xn).numpy()
    mean = Phi @ clf.mean_
    var = np.einsum("ij,jk,ik->i", Phi, clf.covariance_, Phi)
    kappa = 1.0 / np.sqrt(1.0 + np.pi * var / 8.0)
    np.testing.assert_allclose(clf.predict_proba(Xn)[:, 1], expit(kappa * mean), rtol=1e-10)
    np.testing.assert_allclose(clf.decision_function(Xn), kappa * mean, rtol=1e-10, atol=1e-12)
    plain = RVC(width=1.0, moderated=False).fit(X, data[1])
    np.testing.assert_allclose(plain.predict_proba(Xn)[:, 1], expit(mean), rtol=1e-10)
    m_lat, s_lat = clf.predict_latent(Xn)
    np.testing.assert_allclose(m_lat, mean, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(s_lat, np.sqrt(var), rtol=1e-10)


def test_laplace_posterior_is_the_mode(data, clf):
    """At the mode the gradient of the log posterior vanishes and Sigma = H^-1 (eqs. 26-28)."""
    X, y, _, _ = data
    Phi = clf.design_matrix(X).numpy()
    p = expit(Phi @ clf.mean_)
    grad = Phi.T @ (y - p) - clf.alpha_ * clf.mean_
    assert np.abs(grad).max() < 1e-6 * max(1.0, np.abs(Phi.T @ y).max())
    H = Phi.T @ (Phi * (p * (1 - p))[:, None]) + np.diag(clf.alpha_)
    np.testing.assert_allclose(clf.covariance_, np.linalg.inv(H), rtol=1e-6, atol=1e-10)
    # Laplace evidence, by hand
    ll = np.sum(y * np.log(p) + (1 - y) * np.log(1 - p))
    _, logdet = np.linalg.slogdet(H)
    ev = ll - 0.5 * clf.alpha_ @ clf.mean_**2 + 0.5 * np.log(clf.alpha_).sum() - 0.5 * logdet
    assert clf.log_evidence_ == pytest.approx(ev, abs=1e-6)


def test_fast_and_em_agree(data, clf):
    X, y, X_test, _ = data
    em = RVC(width=1.0, method="em").fit(X, y)
    assert abs(em.log_evidence_ - clf.log_evidence_) < 1.0  # nats, out of ~136
    agree = np.mean(em.predict(X_test) == clf.predict(X_test))
    assert agree > 0.98
    p_em, p_fast = em.predict_proba(X_test)[:, 1], clf.predict_proba(X_test)[:, 1]
    assert np.mean(np.abs(p_em - p_fast)) < 0.02


def test_labels_and_multiclass(data):
    X, y, X_test, _ = data
    names = np.array(["closed", "open"])[y]
    clf = RVC(width=1.0).fit(X, names)
    np.testing.assert_array_equal(clf.classes_, ["closed", "open"])
    assert set(clf.predict(X_test[:50])) <= {"closed", "open"}
    # three well separated classes, one-vs-rest
    rng = np.random.default_rng(5)
    centres = np.array([[0.0, 3.0], [-3.0, -2.0], [3.0, -2.0]])
    y3 = np.repeat([0, 1, 2], 60)
    X3 = centres[y3] + rng.standard_normal((180, 2))
    m3 = RVC(width=1.5).fit(X3, y3)
    proba = m3.predict_proba(X3)
    assert proba.shape == (180, 3)
    np.testing.assert_allclose(proba.sum(1), 1.0, atol=1e-12)
    assert m3.score(X3, y3) > 0.95
    assert len(m3.estimators_) == 3 and len(m3.mean_) == 3
    assert m3.decision_function(X3).shape == (180, 3)
    np.testing.assert_array_equal(m3.predict(X3), proba.argmax(1))
    assert m3.log_evidence_ == pytest.approx(sum(e.log_evidence_ for e in m3.estimators_))


def test_torch_in_torch_out(data, clf):
    X, y, X_test, _ = data
    m = RVC(width=1.0).fit(torch.tensor(X), torch.tensor(y))
    proba = m.predict_proba(torch.tensor(X_test[:100]))
    assert isinstance(proba, torch.Tensor)
    np.testing.assert_allclose(proba.numpy(), clf.predict_proba(X_test[:100]), atol=1e-10)
    pred = m.predict(torch.tensor(X_test[:100]))
    assert isinstance(pred, torch.Tensor)
    np.testing.assert_array_equal(pred.numpy(), clf.predict(X_test[:100]))


def test_errors(data, clf):
    X, y, _, _ = data
    with pytest.raises(ValueError, match="one class"):
        RVC().fit(X, np.zeros(len(X)))
    with pytest.raises(ValueError, match="Unknown label type"):
        RVC().fit(X, np.linspace(0, 1, len(X)))
    with pytest.raises(NotFittedError):
        RVC().predict_proba(X)
    with pytest.raises(ValueError, match="features"):
        clf.predict(X[:, :1])
    with pytest.raises(ValueError, match="moderated"):
        RVC(moderated="yes").fit(X, y)


def test_float32_screening_bernoulli(data):
    """Screening S, Q in float32 changes nothing that matters for the fitted classifier."""
    from bayes_fdi.rvm import RBF
    from bayes_fdi.rvm.sbl import Design, fast_bernoulli

    X, y, _, _ = data
    Xt, t = torch.tensor(X), torch.tensor(y, dtype=torch.float64)
    exact = fast_bernoulli(Design(kernel=RBF(1.0), X=Xt, screen=False), t)
    screen = fast_bernoulli(Design(kernel=RBF(1.0), X=Xt, screen=True), t)
    assert abs(screen.log_evidence - exact.log_evidence) < 0.05
    np.testing.assert_array_equal(screen.active.numpy(), exact.active.numpy())
    np.testing.assert_allclose(screen.mean.numpy(), exact.mean.numpy(), rtol=1e-3)

"""Full posteriors through the classifier: ``RVC(...).fit(X, y).fit_posterior(X, y)``."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import expit

from bayes_fdi.rvm import RVC
from bayes_fdi.rvm.posterior import OneVsRestPosterior


def test_rvc_binary_posterior_matches_type2_and_keeps_labels():
    rng = np.random.default_rng(0)
    n = 120
    X = rng.uniform(-3, 3, (n, 1))
    y = np.where(rng.random(n) < expit(3 * np.sin(X[:, 0])), "fault", "normal")
    rvc = RVC(width=1.0).fit(X, y)
    post = rvc.fit_posterior(X, y, num_samples=300, warmup_steps=300, seed=0)
    assert post.kind == "classification"
    assert list(post.classes) == list(rvc.classes_)
    d = post.diagnostics
    assert d.n_divergences == 0 and d.max_r_hat < 1.01
    Xt = np.linspace(-3, 3, 25)[:, None]
    proba = post.predict_proba(Xt)
    assert proba.shape == (25, 2) and np.all((proba >= 0) & (proba <= 1))
    np.testing.assert_allclose(proba.sum(1), 1.0)
    # the independent type-II + Laplace + MacKay-moderated answer of RVC
    assert np.max(np.abs(proba - rvc.predict_proba(Xt))) < 0.05
    # both against the generating probability
    truth = expit(3 * np.sin(Xt[:, 0]))
    fault = list(post.classes).index("fault")
    assert np.max(np.abs(proba[:, fault] - truth)) < 0.2
    assert set(post.predict(Xt)) <= {"fault", "normal"}
    idata = post.to_arviz()
    assert "diverging" in idata.sample_stats


def test_rvc_one_vs_rest_posterior():
    rng = np.random.default_rng(1)
    centres = np.array([[-2.0, 0.0], [2.0, 0.0], [0.0, 2.5]])
    labels = np.repeat(["f1", "f2", "fn"], 30)
    X = centres[np.repeat(np.arange(3), 30)] + 0.6 * rng.standard_normal((90, 2))
    rvc = RVC(width=1.5).fit(X, labels)
    post = rvc.fit_posterior(X, labels, inference="svi", num_samples=200, svi_steps=300, seed=0)
    assert isinstance(post, OneVsRestPosterior)
    assert list(post.classes) == ["f1", "f2", "fn"]
    proba = post.predict_proba(centres)
    np.testing.assert_allclose(proba.sum(1), 1.0)
    assert list(post.predict(centres)) == ["f1", "f2", "fn"]
    assert np.all(proba.max(1) > 0.6)
    np.testing.assert_allclose(proba, rvc.predict_proba(centres), atol=0.15)
    idata = post.to_arviz()
    assert {"log_alpha[f1]", "weights[fn]"} <= set(idata.posterior.data_vars)
    with pytest.raises(ValueError, match="predict_proba"):
        post.predict(centres, return_std=True)

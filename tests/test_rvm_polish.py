"""Polishing the fast fit (re-estimation restart + fast continuation) and its building blocks:
the fast solver's warm start and the re-estimation on a subset of columns.

References: the evidence by numpy on the N x N marginal covariance, Tipping's re-estimation
(``method="em"``) on the same design, the re-estimation on a column-restricted design matrix, and
the pool recomputed by numpy."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from blas_paths import EVERYTHING_ELSE, REFERENCE, run_python
from test_rvm_regression import gaussian_log_evidence

from bayes_fdi.rvm import RVR, load
from bayes_fdi.rvm.persistence import save
from bayes_fdi.rvm.sbl import (
    Design,
    SBLResult,
    em_gaussian,
    fast_gaussian,
    polish_gaussian,
    restart_pool,
)


def smooth_rbf_design(seed: int, n: int = 200, bias: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """RBF design (width 0.5, one column per sample, optional leading bias column) and noisy
    targets of the benchmark's smooth function on [-1, 1]^3."""
    rng = np.random.default_rng(seed)
    X = rng.uniform(-1, 1, (n, 3))
    f = np.sin(np.pi * X[:, 0]) * np.cos(0.5 * np.pi * X[:, 1]) + 0.5 * X[:, 2] ** 2
    y = f + 0.1 * rng.standard_normal(n)
    K = np.exp(-((X[:, None, :] - X[None, :, :]) ** 2).sum(-1) / (2 * 0.5**2))
    return (np.hstack([np.ones((n, 1)), K]) if bias else K), y


def evidence(model: RVR, D: np.ndarray, y: np.ndarray) -> float:
    return gaussian_log_evidence(D[:, model.relevance_indices_], model.alpha_, model.beta_, y)


# --------------------------------------------------------------------------- the check
@pytest.mark.parametrize("bias", [False, True], ids=["no-bias", "bias"])
@pytest.mark.parametrize("seed", [0, 1])
def test_polished_fast_reaches_em_on_a_fixed_rbf_design(seed, bias):
    D, y = smooth_rbf_design(seed, bias=bias)
    fast = RVR(kernel="precomputed", bias=False).fit(D, y)
    polished = RVR(kernel="precomputed", bias=False, polish=True).fit(D, y)
    em = RVR(kernel="precomputed", bias=False, method="em").fit(D, y)
    # each evidence as reported equals numpy's on the N x N covariance
    for m in (fast, polished, em):
        assert m.log_evidence_ == pytest.approx(evidence(m, D, y), abs=1e-8)
    # within 0.1 nat of the re-estimation's optimum (the target), never below the fast fit
    assert polished.log_evidence_ >= em.log_evidence_ - 0.1
    assert polished.log_evidence_ >= fast.log_evidence_
    assert polished.polish_.gain == pytest.approx(polished.log_evidence_ - fast.log_evidence_)
    assert polished.polish_.pool_size == D.shape[1]  # 200 columns: the whole basis
    assert fast.polish_ is None
    assert polished.log_evidence_ >= polished.polish_.restart_log_evidence - 1e-9


def test_polish_finds_the_better_optimum_here():
    """On this design the greedy fast fit stops 2.8 nats below the re-estimation's optimum (a
    different basis); the polish takes the restart's."""
    D, y = smooth_rbf_design(0)
    fast = RVR(kernel="precomputed", bias=False).fit(D, y)
    polished = RVR(kernel="precomputed", bias=False, polish=True).fit(D, y)
    assert polished.polish_.gain > 1.0
    assert set(polished.relevance_indices_) != set(fast.relevance_indices_)
    # a proper posterior of its own basis: mean and covariance by numpy's closed form
    Phi = D[:, polished.relevance_indices_]
    Sigma = np.linalg.inv(np.diag(polished.alpha_) + polished.beta_ * Phi.T @ Phi)
    np.testing.assert_allclose(polished.covariance_, Sigma, rtol=1e-7, atol=1e-12)
    np.testing.assert_allclose(polished.mean_, polished.beta_ * Sigma @ Phi.T @ y, rtol=1e-6)


def test_polish_on_a_kernel_basis_with_auto_width_and_scaled_targets():
    rng = np.random.default_rng(5)
    X = rng.uniform(-1, 1, (150, 2))
    y = np.sin(np.pi * X[:, 0]) + 0.1 * rng.standard_normal(150)
    a = RVR(width=0.5, polish=True).fit(X, y)
    b = RVR(width=0.5, polish=True).fit(X, y * 2.0**40)  # rescaled internally by a power of two
    # the sparse Bayesian model is scale-equivariant: the evidence shifts by -N log(scale)
    shift = 150 * 40 * np.log(2.0)
    assert b.log_evidence_ == pytest.approx(a.log_evidence_ - shift, abs=1e-6)
    assert b.polish_.gain == pytest.approx(a.polish_.gain, abs=1e-6)
    assert b.polish_.restart_log_evidence == pytest.approx(
        a.polish_.restart_log_evidence - shift, abs=1e-6
    )
    np.testing.assert_array_equal(a.relevance_indices_, b.relevance_indices_)
    auto = RVR(width="auto", polish=True).fit(X, y)  # polished at the chosen width only
    plain = RVR(width=auto.width_).fit(X, y)
    assert auto.log_evidence_ >= plain.log_evidence_ - 1e-9


# --------------------------------------------------------------------------- the pool
def test_restart_pool_is_the_basis_and_the_most_correlated_candidates():
    D, y = smooth_rbf_design(1, bias=True)
    design, t = Design(matrix=torch.tensor(D), bias=False), torch.tensor(y)
    fitted = fast_gaussian(design, t)
    # small basis: every usable column (two all-zero columns stay out)
    Z = D.copy()
    Z[:, [3, 7]] = 0.0
    zeroed = Design(matrix=torch.tensor(Z), bias=False)
    np.testing.assert_array_equal(
        restart_pool(zeroed, t, fitted, D.shape[1]).numpy(),
        np.setdiff1d(np.arange(D.shape[1]), [3, 7]),
    )
    pool = restart_pool(design, t, fitted, 60).numpy()
    # numpy: |b_i^T r| / ||b_i|| with r the fit's residual, the basis first
    act = fitted.active.numpy()
    r = y - D[:, act] @ fitted.mean.numpy()
    score = np.abs(D.T @ r) / np.linalg.norm(D, axis=0)
    others = np.setdiff1d(np.arange(D.shape[1]), act)
    top = others[np.argsort(-score[others], kind="stable")[: 60 - act.size]]
    np.testing.assert_array_equal(pool, np.sort(np.concatenate([act, top])))
    # the basis is always in, even beyond the requested size
    np.testing.assert_array_equal(restart_pool(design, t, fitted, 1).numpy(), act)
    with pytest.raises(ValueError, match="pool size"):
        restart_pool(design, t, fitted, 0)


def test_polish_from_a_restricted_pool_never_loses():
    D, y = smooth_rbf_design(0, bias=True)
    design, t = Design(matrix=torch.tensor(D), bias=False), torch.tensor(y)
    fitted = fast_gaussian(design, t)
    for size in (1, 40, 100):
        result, polish = polish_gaussian(design, t, fitted, pool_size=size)
        assert polish.pool_size == max(size, fitted.active.numel())
        assert result.log_evidence >= fitted.log_evidence
        assert polish.gain == pytest.approx(result.log_evidence - fitted.log_evidence)
        assert result.log_evidence == pytest.approx(
            gaussian_log_evidence(
                D[:, result.active.numpy()], result.alpha.numpy(), result.beta, y
            ),
            abs=1e-8,
        )


# --------------------------------------------------------------------------- building blocks
def test_em_on_columns_equals_em_on_the_restricted_matrix():
    D, y = smooth_rbf_design(1, n=120)
    cols = np.arange(0, 120, 3)
    t = torch.tensor(y)
    sub = em_gaussian(Design(matrix=torch.tensor(D), bias=False), t, columns=torch.tensor(cols))
    ref = em_gaussian(Design(matrix=torch.tensor(D[:, cols]), bias=False), t)
    np.testing.assert_array_equal(sub.active.numpy(), cols[ref.active.numpy()])
    assert sub.log_evidence == pytest.approx(ref.log_evidence, rel=1e-12)
    # prior variances: a diverging alpha (~1e9, a column on its way out) is set by rounding, but
    # its variance, ~1e-10 against the noise variance 1e-2, no longer matters
    np.testing.assert_allclose(1 / sub.alpha.numpy(), 1 / ref.alpha.numpy(), rtol=1e-8, atol=1e-12)
    with pytest.raises(ValueError, match="columns must index"):
        em_gaussian(Design(matrix=torch.tensor(D), bias=False), t, columns=torch.tensor([120]))
    Z = D.copy()
    Z[:, :2] = 0.0
    with pytest.raises(ValueError, match="no usable"):
        em_gaussian(Design(matrix=torch.tensor(Z), bias=False), t, columns=torch.tensor([0, 1]))


def test_fast_warm_start_raises_the_evidence_of_its_start():
    D, y = smooth_rbf_design(0, n=150, bias=True)
    design, t = Design(matrix=torch.tensor(D), bias=False), torch.tensor(y)
    em = em_gaussian(design, t, tol=1e-2)  # stopped early: far from any optimum of fast's
    cont = fast_gaussian(design, t, start=em)
    assert cont.evidence_trace[0].item() == pytest.approx(em.log_evidence, abs=1e-8)
    assert cont.log_evidence >= em.log_evidence
    assert bool((cont.evidence_trace[1:] >= cont.evidence_trace[:-1] - 1e-9).all())
    # a converged fit is a fixed point: started from itself, the fast solver stays
    fit = fast_gaussian(design, t)
    again = fast_gaussian(design, t, start=fit)
    np.testing.assert_array_equal(again.active.numpy(), fit.active.numpy())
    assert again.log_evidence == pytest.approx(fit.log_evidence, abs=1e-6)


def _with(result: SBLResult, **changes) -> SBLResult:
    return result._replace(**changes)


def test_fast_warm_start_rejects_bad_states():
    D, y = smooth_rbf_design(1, n=60)
    design, t = Design(matrix=torch.tensor(D), bias=False), torch.tensor(y)
    fit = fast_gaussian(design, t)
    a = fit.active
    bad = {
        "empty basis": _with(fit, active=a[:0], alpha=fit.alpha[:0]),
        "more than once": _with(
            fit, active=torch.cat([a[:1], a[:1]]), alpha=fit.alpha[:1].repeat(2)
        ),
        "outside the design": _with(fit, active=torch.cat([a[:-1], a.new_tensor([60])])),
        "finite and > 0": _with(fit, alpha=-fit.alpha),
        "noise precision": _with(fit, beta=float("nan")),
    }
    for what, state in bad.items():
        with pytest.raises(ValueError, match=what):
            fast_gaussian(design, t, start=state)
    Z = D.copy()
    Z[:, int(a[0])] = 0.0
    with pytest.raises(ValueError, match="all-zero column"):
        fast_gaussian(Design(matrix=torch.tensor(Z), bias=False), t, start=fit)


# --------------------------------------------------------------------------- estimator API
@pytest.mark.parametrize(
    "params, match",
    [
        ({"polish": 1}, "polish must be True or False"),
        ({"polish": True, "method": "em"}, "polish applies to method='fast'"),
        ({"polish_pool": 0}, "polish_pool must be a positive integer"),
        ({"polish_pool": 2.5}, "polish_pool must be a positive integer"),
        ({"polish_pool": True}, "polish_pool must be a positive integer"),
    ],
)
def test_polish_parameters_are_validated(params, match):
    X = np.linspace(-1, 1, 20)[:, None]
    model = RVR(**params)
    assert model.get_params()[next(iter(params))] is next(iter(params.values()))  # kept as given
    with pytest.raises(ValueError, match=match):
        model.fit(X, np.sin(3 * X[:, 0]))


def test_polish_record_survives_a_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    X = rng.uniform(-1, 1, (80, 2))
    y = np.cos(2 * X[:, 0]) + 0.1 * rng.standard_normal(80)
    for model in (RVR(width=0.5, polish=True).fit(X, y), RVR(width=0.5).fit(X, y)):
        save(model, tmp_path / "m")
        back = load(tmp_path / "m.npz")
        assert back.polish_ == model.polish_
        assert back.get_params() == model.get_params()
        np.testing.assert_array_equal(back.predict(X), model.predict(X))


def test_loading_rejects_a_bad_polish_record(tmp_path, monkeypatch):
    import json

    rng = np.random.default_rng(2)
    X = rng.uniform(-1, 1, (40, 2))
    model = RVR(width=0.5, polish=True).fit(X, np.cos(2 * X[:, 0]))
    save(model, tmp_path / "m")
    with np.load(tmp_path / "m.npz", allow_pickle=False) as f:
        arrays = dict(f)
    meta = json.loads(str(arrays.pop("metadata")))
    for record, match in (
        ({"gain": -1.0, "restart_log_evidence": 0.0, "pool_size": 3}, "gain must be >= 0"),
        ({"gain": 0.0, "restart_log_evidence": None, "pool_size": 3}, "finite number"),
        ({"gain": 0.0, "restart_log_evidence": 1.0, "pool_size": 0}, "pool_size"),
        ({"gain": 0.0}, "polish must be null or a table"),
    ):
        meta["polish"] = record
        np.savez(tmp_path / "bad.npz", metadata=np.array(json.dumps(meta)), **arrays)
        with pytest.raises(ValueError, match=match):
            load(tmp_path / "bad.npz")


# --------------------------------------------------------------------------- same numbers
_SCRIPT = """
import sys
import numpy as np
sys.path.insert(0, {tests!r})
from test_rvm_polish import smooth_rbf_design
from bayes_fdi.rvm import RVR
D, y = smooth_rbf_design(0, bias=True)
m = RVR(kernel="precomputed", bias=False, polish=True).fit(D, y)
print(m.relevance_indices_.tolist(), m.n_iter_, repr(m.log_evidence_), repr(m.polish_.gain))
"""


def test_polished_fit_is_the_same_on_another_blas_code_path_and_thread_count():
    """The restart's pruning and the continuation's decisions must not amplify rounding: the
    same basis and iteration count under MKL's AVX2 path, OpenBLAS's Haswell kernels and two
    threads as on the default path with one (evidence to rounding)."""
    script = _SCRIPT.format(tests=str(Path(__file__).parent))
    outs = [run_python(script, env).split() for env in (REFERENCE, EVERYTHING_ELSE)]
    a, b = outs
    assert a[:-2] == b[:-2]  # basis and iteration count
    assert float(a[-2]) == pytest.approx(float(b[-2]), rel=1e-12)
    assert float(a[-1]) == pytest.approx(float(b[-1]), abs=1e-9)

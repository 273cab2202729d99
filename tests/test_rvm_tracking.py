"""The carried screening factors of the fast Gaussian solver (``rvm.sbl.tracked_factors``) and
the lazy verification of its actions (``rvm.sbl.verification``).

The bounds are checked against an independent reference: the carried values are computed in
float32 and their error bounds must contain the float64 values of the same stored problem,
computed directly (dense solves) after every update of a random sequence. The lazy
verification must choose the action ``best_action`` picks on exact factors of every column.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import bayes_fdi.rvm.sbl.capacity as capacity_module  # the module whose constants are patched
import bayes_fdi.rvm.sbl.gaussian as gaussian_module  # the module whose constant is patched
from bayes_fdi.rvm import RVR
from bayes_fdi.rvm.sbl import (
    TrackedFactors,
    best_action,
    factor_precision,
    grown_capacity,
    lazy_verified_action,
    posterior_context,
    reestimate_gain_bounds,
    rounding_gamma,
    useful_lower_bound,
)


def _stored_problem(seed: int, N: int = 160, P: int = 60, width: float = 1.5, dtype=torch.float32):
    """A stored problem: unit kernel columns, their symmetric Gram products, B^T t."""
    rng = np.random.default_rng(seed)
    X = rng.uniform(-4, 4, size=(N, 2))
    centres = X[rng.choice(N, P, replace=False)]
    d2 = ((X[:, None, :] - centres[None, :, :]) ** 2).sum(-1)
    B = np.exp(-d2 / (2 * width**2))
    B /= np.linalg.norm(B, axis=0)
    t = np.sin(X[:, 0]) + 0.5 * np.cos(X[:, 1]) + 0.05 * rng.standard_normal(N)
    K = torch.tensor(B.T @ B, dtype=dtype)
    K = 0.5 * (K + K.T)  # exactly symmetric, as the solver's stored Gram block is used
    Bt_t = torch.tensor(B.T @ t, dtype=dtype)
    unit = K.diagonal().clone()
    eps = rounding_gamma(N + 8, dtype)
    return K, Bt_t, unit, eps


def _solve_ld(H: np.ndarray, R: np.ndarray) -> np.ndarray:
    """``H^-1 R`` in numpy's long double (80-bit on x86: 2000 times float64's precision) by
    Cholesky; numpy's linalg has no long double routines."""
    M = H.shape[0]
    L = np.zeros_like(H)
    for j in range(M):
        L[j, j] = np.sqrt(H[j, j] - (L[j, :j] ** 2).sum())
        L[j + 1 :, j] = (H[j + 1 :, j] - L[j + 1 :, :j] @ L[j, :j]) / L[j, j]
    Y = R.copy()
    for j in range(M):  # forward
        Y[j] = (Y[j] - L[j, :j] @ Y[:j]) / L[j, j]
    for j in reversed(range(M)):  # backward
        Y[j] = (Y[j] - L[j + 1 :, j] @ Y[j + 1 :]) / L[j, j]
    return Y


def _reference(K, Bt_t, unit, act, alpha, beta):
    """S_, Q_ of every column and the coefficients C* of the stored problem, in long double
    (float32 and float64 carried values are checked against it)."""
    ld = np.longdouble
    Kl, bl, ul = (
        K.double().numpy().astype(ld),
        Bt_t.double().numpy().astype(ld),
        unit.double().numpy().astype(ld),
    )
    a = np.array(act)
    Z = Kl[:, a]
    H = np.diag(np.array(alpha, dtype=ld) / ld(beta)) + Kl[np.ix_(a, a)]
    C = _solve_ld(H, Z.T.copy()).T
    mu = _solve_ld(H, bl[a][:, None])[:, 0]
    S = ul - (Z * C).sum(1)
    Q = bl - Z @ mu
    return S, Q, C, H, Z


def _post(K, Bt_t, act, alpha, beta, eps):
    a = torch.tensor(act)
    G = K[a][:, a]
    al = torch.tensor(alpha, dtype=K.dtype)
    fac = factor_precision(al, beta * G)
    mu = beta * fac.solve(Bt_t[a])
    return posterior_context(fac, al, beta, G, mu, Bt_t[a], eps)


def _check(tr, K, Bt_t, unit, act, alpha, beta):
    ld = np.longdouble
    M = len(act)
    S, Q, _, H, Z = _reference(K, Bt_t, unit, act, alpha, beta)

    def carried(v):
        return v.double().numpy().astype(ld)

    assert np.all(np.abs(carried(tr.S) - S) <= carried(tr.S_err)), "S outside its bound"
    assert np.all(np.abs(carried(tr.Q) - Q) <= carried(tr.Q_err)), "Q outside its bound"
    Cc = carried(tr.C[:, :M])
    root = np.sqrt(np.array(alpha, dtype=ld) / ld(beta))
    resid = np.sqrt((((Cc @ H - Z) / root) ** 2).sum(1))  # ||A^-1/2 (H c - z)||, H symmetric
    assert np.all(resid <= carried(tr.rho)), "residual outside its bound"
    assert np.all(np.sqrt((Cc**2).sum(1)) <= carried(tr.nu))
    return float(np.median(carried(tr.S_err) / np.abs(S)))


@pytest.mark.parametrize(
    ("seed", "dtype", "beta_step", "useful"),
    [
        (0, torch.float32, 3e-3, math.inf),
        (1, torch.float32, 3e-3, math.inf),
        (2, torch.float64, 3e-3, math.inf),
        (3, torch.float64, 1e-9, 1e-7),
    ],
)
def test_carried_factors_stay_within_their_bounds(seed, dtype, beta_step, useful):
    """Containment after every update of a random sequence of 60 (additions, re-estimates,
    deletions, noise updates of relative size ``beta_step``). A noise update's bound grows
    with its size (the coefficients are kept); with rounding-size ones, float64 bounds stay
    tight enough to screen with (median relative bound of S below 1e-7)."""
    K, Bt_t, unit, eps = _stored_problem(seed, dtype=dtype)
    P = K.shape[0]
    rng = np.random.default_rng(100 + seed)
    act = [int(Bt_t.abs().argmax())]
    alpha = [1.0]
    beta = 20.0
    tr = TrackedFactors(P, 4, unit, Bt_t)
    tr.prepare(_post(K, Bt_t, act, alpha, beta, eps), K[:, torch.tensor(act)])
    _check(tr, K, Bt_t, unit, act, alpha, beta)
    kinds = {"add": 0, "reestimate": 0, "delete": 0, "rescale": 0}
    for _ in range(60):
        post = _post(K, Bt_t, act, alpha, beta, eps)
        op = rng.choice(["add", "add", "reestimate", "reestimate", "delete", "rescale"])
        if op == "add" and len(act) < 25:
            i = int(rng.choice([m for m in range(P) if m not in act]))
            a_i = float(np.exp(rng.normal(0, 2)))
            tr.add(post, K[torch.tensor(act), i], float(K[i, i]), a_i, K[:, i], float(Bt_t[i]))
            act.append(i)
            alpha.append(a_i)
            tr.stale.add(i)
        elif op == "delete" and len(act) > 1:
            k = int(rng.integers(len(act)))
            tr.delete(post, k)
            del act[k], alpha[k]
        elif op == "rescale":
            beta_new = beta * float(np.exp(rng.normal(0, beta_step)))
            new = _post(K, Bt_t, act, alpha, beta_new, eps)
            tr.rescale(post, new, math.inf)
            beta = beta_new
        else:
            k = int(rng.integers(len(act)))
            a_new = alpha[k] * float(np.exp(rng.normal(0, 1)))
            tr.reestimate(post, k, a_new)
            alpha[k] = a_new
        kinds[op] += 1
        assert not tr.needs_refresh
        tr.prepare(_post(K, Bt_t, act, alpha, beta, eps), K[:, torch.tensor(act)])
        rel = _check(tr, K, Bt_t, unit, act, alpha, beta)
    assert all(v > 3 for v in kinds.values())
    assert rel < useful


def test_lazy_verification_chooses_the_exact_best_action():
    """Screened factors anywhere inside their bounds lead to best_action's choice on exact
    factors, for random states (re-estimates, additions, deletions and near-ties)."""
    gen = torch.Generator().manual_seed(7)
    n_checked = {0: 0, 1: 0, 2: 0}
    for trial in range(300):
        P, M = 40, 6
        act = torch.randperm(P, generator=gen)[:M]
        alpha = torch.rand(M, generator=gen, dtype=torch.float64) * 5 + 0.1
        S = torch.rand(P, generator=gen, dtype=torch.float64) * 2 + 0.01
        S[act] = alpha * torch.rand(M, generator=gen, dtype=torch.float64) * 0.99
        Q = torch.randn(P, generator=gen, dtype=torch.float64) * (1.0 + 2 * (trial % 3))
        if trial % 5 == 0:  # a near-tie between two additions
            j, k = (int(v) for v in torch.randperm(P, generator=gen)[:2])
            S[k], Q[k] = S[j], Q[j] * (1 + 1e-12)
        addable = torch.ones(P, dtype=torch.bool)
        addable[act] = False
        exact = best_action(S.clone(), Q.clone(), act, alpha, addable)
        rel = 10.0 ** -float(torch.randint(3, 12, (1,), generator=gen))
        S_err, Q_err = rel * S.abs(), rel * Q.abs()
        S_scr = S + S_err * (2 * torch.rand(P, generator=gen, dtype=S.dtype) - 1)
        Q_scr = Q + Q_err * (2 * torch.rand(P, generator=gen, dtype=Q.dtype) - 1)

        def oracle(idx, S=S, Q=Q):
            return S[idx].clone(), Q[idx].clone()

        got, _ = lazy_verified_action(S_scr, Q_scr, S_err, Q_err, act, alpha, addable, oracle)
        assert got is not None
        assert (got.kind, got.index) == (exact.kind, exact.index)
        assert got.gain == pytest.approx(exact.gain, rel=1e-12, abs=1e-15)
        if exact.kind >= 0:
            n_checked[exact.kind] += 1
    assert all(v > 10 for v in n_checked.values()), n_checked


def test_lazy_verification_gives_up_over_budget():
    P, M = 30, 3
    act = torch.arange(M)
    alpha = torch.ones(M, dtype=torch.float64)
    S = torch.full((P,), 0.5, dtype=torch.float64)
    Q = torch.full((P,), 2.0, dtype=torch.float64)
    addable = torch.ones(P, dtype=torch.bool)
    addable[act] = False
    loose = torch.full((P,), 0.4, dtype=torch.float64)
    got, n = lazy_verified_action(
        S, Q, loose, loose, act, alpha, addable, lambda i: (S[i], Q[i]), budget=2
    )
    assert got is None and n <= 2


@pytest.mark.parametrize(
    ("width", "n"), [(2.0, 300), (0.4, 400)], ids=["sinc-rbf", "smooth-narrow-width"]
)
def test_carried_screening_takes_the_refreshed_path(monkeypatch, width, n):
    """Carrying the factors changes the cost only: the fit equals the one that screens from a
    fresh factor every iteration (active set, iterations, evidence)."""
    rng = np.random.default_rng(3)
    X = rng.uniform(-6, 6, size=(n, 1))
    y = np.sinc(X[:, 0] / np.pi) + 0.1 * rng.standard_normal(n)
    carried = RVR(width=width).fit(X, y)
    monkeypatch.setattr(gaussian_module, "_REFRESH_EVERY_ITERATION", True)
    fresh = RVR(width=width).fit(X, y)
    np.testing.assert_array_equal(carried.relevance_indices_, fresh.relevance_indices_)
    assert carried.n_iter_ == fresh.n_iter_
    assert carried.log_evidence_ == pytest.approx(fresh.log_evidence_, rel=1e-10)


def test_gain_bounds_hold_over_their_box():
    """The re-estimation gain (best_action's formula) and q^2 - s at random points of the box
    of (S, Q) stay within the bounds computed from its corners."""
    gen = torch.Generator().manual_seed(11)
    K = 400
    alpha = torch.rand(K, generator=gen, dtype=torch.float64) * 10 + 0.01
    S = alpha * (0.05 + 0.9 * torch.rand(K, generator=gen, dtype=torch.float64))
    Q = torch.randn(K, generator=gen, dtype=torch.float64) * 2
    rel = 10.0 ** -torch.randint(1, 8, (K,), generator=gen).double()
    S_err, Q_err = rel * S, rel * Q.abs()
    ub = reestimate_gain_bounds(S, S_err, Q, Q_err)
    th_lo = useful_lower_bound(S, S_err, Q, Q_err, alpha)
    for _ in range(200):
        Sp = S + S_err * (2 * torch.rand(K, generator=gen, dtype=S.dtype) - 1)
        Qp = Q + Q_err * (2 * torch.rand(K, generator=gen, dtype=Q.dtype) - 1)
        s = alpha * Sp / (alpha - Sp)
        q = alpha * Qp / (alpha - Sp)
        theta = q * q - s
        assert torch.all(theta >= th_lo - 1e-12 * theta.abs())
        useful = theta > 0
        new_alpha = s * s / torch.where(useful, theta, 1.0)
        delta = 1.0 / new_alpha - 1.0 / alpha
        gain = 0.5 * (delta * Qp * Qp / (Sp * delta + 1.0) - torch.log1p(Sp * delta))
        assert torch.all(~useful | (gain <= ub + 1e-12 * gain.abs() + 1e-14))


def test_precise_data_screen_from_the_fresh_factor(monkeypatch):
    """With nearly noise-free data some alpha / beta fall below the stored Gram matrix's error
    and the carried bounds do not apply: those iterations screen from the fresh factor
    (``TrackedFactors.direct``), and the fit is the one of a full screening every iteration."""
    rng = np.random.default_rng(5)
    X = rng.uniform(-3, 3, size=(500, 2))
    y = np.sin(X[:, 0]) * np.cos(X[:, 1]) + 1e-7 * rng.standard_normal(500)
    calls = {"direct": 0}
    direct = TrackedFactors.direct

    def counting(self, *args, **kwargs):
        calls["direct"] += 1
        return direct(self, *args, **kwargs)

    monkeypatch.setattr(TrackedFactors, "direct", counting)
    carried = RVR(width=1.0).fit(X, y)
    assert calls["direct"] > 0
    monkeypatch.setattr(gaussian_module, "_REFRESH_EVERY_ITERATION", True)
    fresh = RVR(width=1.0).fit(X, y)
    np.testing.assert_array_equal(carried.relevance_indices_, fresh.relevance_indices_)
    assert carried.n_iter_ == fresh.n_iter_
    assert carried.log_evidence_ == pytest.approx(fresh.log_evidence_, rel=1e-10)


def test_buffer_capacity_grows_by_doubling_then_by_a_quarter():
    """Hand-computed growth: doubling up to 256 columns, then steps of a quarter (multiples of
    64), never beyond the number of candidates unless more columns are needed."""
    assert [grown_capacity(c, c + 1, 10_000) for c in (1, 64, 128, 256, 320, 512, 1000)] == [
        2,
        128,
        256,
        320,
        384,
        640,
        1192,
    ]
    assert grown_capacity(64, 300, 10_000) == 320  # 128, 256, 320
    assert grown_capacity(256, 257, 300) == 300
    assert grown_capacity(64, 65, 40) == 65  # more than the limit is needed: exactly that


def test_buffer_widths_change_storage_only(monkeypatch):
    """The fast Gaussian fit is bit-identical whatever the width of its column buffers, as long
    as it is a multiple of 8 columns (64-byte rows): from 8 columns growing 8 at a time (widths
    the default never uses) against the default capacities. (Widths of 1, 2, 4, 7, 10, ...
    columns move the fitted precisions by rounding, about 1e-14: BLAS takes other code paths
    on unaligned rows; the default keeps multiples of 64.)"""
    rng = np.random.default_rng(5)
    X = rng.uniform(-6, 6, size=(300, 2))
    y = np.sinc(X[:, 0] / np.pi) * np.cos(X[:, 1] / 3) + 0.05 * rng.standard_normal(300)
    default = RVR(width=1.0).fit(X, y)
    monkeypatch.setattr(gaussian_module, "_INITIAL_CAPACITY", 8)
    monkeypatch.setattr(capacity_module, "_DOUBLING_LIMIT", 8)
    monkeypatch.setattr(capacity_module, "_STEP", 8)
    narrow = RVR(width=1.0).fit(X, y)
    assert len(default.relevance_indices_) > 32  # the narrow buffers grew four times or more
    np.testing.assert_array_equal(default.relevance_indices_, narrow.relevance_indices_)
    assert default.n_iter_ == narrow.n_iter_
    for attr in ("alpha_", "mean_", "covariance_", "evidence_trace_"):
        np.testing.assert_array_equal(getattr(default, attr), getattr(narrow, attr))
    assert default.beta_ == narrow.beta_ and default.log_evidence_ == narrow.log_evidence_

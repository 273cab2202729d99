"""The compiled (numba) engine of the fast Gaussian solver against the torch rules it replaces:
the best action on exact factors (ties, deletions, the gain floor), the rounds of the lazy
verification (against the public bound functions), the carried factors' re-estimation update
(against its formulas in NumPy), the posterior's terms and the re-estimation update of the
Cholesky factor (against NumPy and a fresh factorisation), the carried factors' compiled
updates and posterior bounds (against the torch operations), and whole fits, which take the same
actions either way."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import bayes_fdi.rvm.sbl.action_kernels as action_kernels
import bayes_fdi.rvm.sbl.factor_kernels as factor_kernels
import bayes_fdi.rvm.sbl.gaussian as gaussian_module
import bayes_fdi.rvm.sbl.posterior_bounds as posterior_module
import bayes_fdi.rvm.sbl.tracked_factors as tracked_module
import bayes_fdi.rvm.sbl.tracked_kernels as tracked_kernels
import bayes_fdi.rvm.sbl.verification as verification_module
from bayes_fdi.rvm.kernels import RBF
from bayes_fdi.rvm.sbl import (
    Design,
    best_action,
    factor_precision,
    fast_gaussian,
    gaussian_screened_Q,
    optimistic_ratio,
    reestimate_gain_bounds,
    rounding_gamma,
    screened_factors,
    useful_lower_bound,
)
from bayes_fdi.rvm.threads import fit_threads


def _factors(seed: int, P: int = 60):
    """Random factors of ``P`` candidates, ``M`` actives (with precisions above ``S``, as a
    posterior has), duplicated candidates (ties) every third draw."""
    g = torch.Generator().manual_seed(seed)
    M = int(torch.randint(1, 12, (1,), generator=g))
    act = torch.randperm(P, generator=g)[:M]
    S = torch.rand(P, generator=g, dtype=torch.float64) * 2.0
    Q = torch.randn(P, generator=g, dtype=torch.float64) * 2.0
    if seed % 3 == 0:
        S[10:20], Q[10:20] = S[0], Q[0]
    alpha = torch.rand(M, generator=g, dtype=torch.float64) * 5.0 + S[act]
    addable = torch.rand(P, generator=g) > 0.3
    addable[act] = False
    return S, Q, act, alpha, addable


def test_compiled_best_action_is_the_torch_rules_choice():
    kinds = set()
    for seed in range(300):
        S, Q, act, alpha, addable = _factors(seed)
        want = best_action(S, Q, act, alpha, addable)
        index, gain, kind, new_alpha, position, any_delete = action_kernels.best_action_kernel(
            S.numpy(), Q.numpy(), act.numpy(), alpha.numpy(), addable.numpy()
        )
        assert (index, kind, position, bool(any_delete)) == (
            want.index,
            want.kind,
            want.position,
            want.any_delete,
        ), seed
        # the same formulas; only log1p's last bit may differ between libm and torch
        assert gain == want.gain or gain == pytest.approx(want.gain, rel=1e-14)
        assert new_alpha == want.new_alpha or new_alpha == pytest.approx(want.new_alpha, rel=1e-14)
        kinds.add(kind)
    assert kinds == {0, 1, 2}  # additions, re-estimates and deletions were compared


@pytest.mark.parametrize("seed", range(50))
def test_compiled_verification_round_matches_the_bound_functions(seed):
    S, Q, act, alpha, addable = _factors(seed)
    g = torch.Generator().manual_seed(1000 + seed)
    S_err = torch.rand(S.shape, generator=g, dtype=torch.float64) * 0.2
    Q_err = torch.rand(S.shape, generator=g, dtype=torch.float64) * 0.2
    verified = torch.rand(S.shape, generator=g) > 0.7
    arrays = [v.numpy() for v in (S, S_err, Q, Q_err, act, alpha, verified)]
    unsure = action_kernels.unsure_actives(*arrays)
    theta_lo = useful_lower_bound(S[act], S_err[act], Q[act], Q_err[act], alpha)
    want = act[~verified[act] & ~(theta_lo > 1e-12)]
    np.testing.assert_array_equal(unsure, want.numpy())

    band, ratio = 0.05, 1.4
    cand, ub = action_kernels.round_candidates(
        S.numpy(), Q.numpy(), S_err.numpy(), Q_err.numpy(), act.numpy(), addable.numpy(),
        verified.numpy(), band, ratio,
    )  # fmt: skip
    re_ub = reestimate_gain_bounds(S[act], S_err[act], Q[act], Q_err[act])
    reach = ~verified[act] & (re_ub >= band)
    x = torch.where(addable & ~verified, optimistic_ratio(S, Q, S_err, Q_err), 0.0)
    adds = (x >= ratio).nonzero().squeeze(1)
    np.testing.assert_array_equal(cand, torch.cat([act[reach], adds]).numpy())
    xa = x[adds]
    ub_add = torch.where(torch.isfinite(xa), 0.5 * (xa - 1.0 - torch.log(xa)), math.inf)
    np.testing.assert_allclose(ub, torch.cat([re_ub[reach], ub_add]).numpy(), rtol=1e-13)


def test_compiled_reestimation_update_follows_its_formulas():
    rng = np.random.default_rng(5)
    P, cap, M, k = 40, 8, 6, 2
    C = rng.standard_normal((P, cap))
    s = rng.standard_normal(M)
    S, Q = rng.random(P), rng.standard_normal(P)
    S_err, Q_err, rho, nu = (rng.random(P) * 1e-9 for _ in range(4))
    sc = dict(kappa=0.3, kappa_err=1e-12, kap=0.3 + 1e-12, e_scale=2.0, mk=-0.7, e_mu=1e-10)
    sc |= dict(g4=4.4e-16, grow=1.5, rho_ack=1e-11, rho_aa=1e-13, rho_nu=1e-12, s_norm=1.3)
    sc |= dict(g2=2.2e-16)
    c = C[:, k].copy()
    a = -sc["kappa"] * c
    e = sc["e_scale"] * rho
    dS, dQ = sc["kappa"] * c * c, sc["kappa"] * sc["mk"] * c
    want_S, want_Q = S + dS, Q + dQ
    want_Se = S_err + (
        sc["kappa_err"] * c * c
        + sc["kap"] * e * (2 * abs(c) + e)
        + sc["g4"] * (abs(want_S) + abs(dS))
    )
    want_Qe = Q_err + (
        sc["kappa_err"] * abs(sc["mk"]) * abs(c)
        + sc["kap"] * (sc["e_mu"] * abs(c) + (abs(sc["mk"]) + sc["e_mu"]) * e)
        + sc["g4"] * (abs(want_Q) + abs(dQ))
    )
    want_C = C.copy()
    want_C[:, :M] += np.outer(a, s)
    want_rho = (
        rho * sc["grow"]
        + abs(c) * sc["rho_ack"]
        + abs(a) * sc["rho_aa"]
        + sc["rho_nu"] * (nu + abs(a) * sc["s_norm"])
    )
    want_nu = (nu + abs(a) * sc["s_norm"]) * (1 + sc["g2"])
    tracked_kernels.reestimate_rows(
        C, M, k, s, S, Q, S_err, Q_err, rho, nu, np.array([*sc.values()])
    )
    for got, want in (
        (C, want_C), (S, want_S), (Q, want_Q), (S_err, want_Se), (Q_err, want_Qe),
        (rho, want_rho), (nu, want_nu),
    ):  # fmt: skip
        np.testing.assert_allclose(got, want, rtol=1e-14, atol=1e-300)


def _rbf_problem(seed: int, n: int, width: float):
    rng = np.random.default_rng(seed)
    X = rng.uniform(-10.0, 10.0, size=(n, 2))
    y = np.sinc(X / np.pi).sum(1) + 0.1 * rng.standard_normal(n)
    X_t = torch.from_numpy(X)
    return Design(matrix=RBF(width)(X_t, X_t), bias=True), torch.from_numpy(y)


@pytest.mark.parametrize(
    ("seed", "n", "width"),
    [(0, 150, 2.0), pytest.param(1, 400, 1.2, marks=pytest.mark.slow), (2, 120, 3.0)],
)
def test_compiled_engine_takes_the_torch_engines_actions(seed, n, width, monkeypatch):
    design, t = _rbf_problem(seed, n, width)
    with fit_threads():
        monkeypatch.setattr(gaussian_module, "UPDATED_FACTOR", True)  # the option, on
        fast = fast_gaussian(design, t)
        monkeypatch.setattr(verification_module, "COMPILED_RULES", False)
        monkeypatch.setattr(tracked_module, "COMPILED_UPDATE", False)
        monkeypatch.setattr(posterior_module, "COMPILED_POSTERIOR", False)
        monkeypatch.setattr(gaussian_module, "UPDATED_FACTOR", False)
        slow = fast_gaussian(design, t)
    assert torch.equal(fast.active, slow.active)
    assert fast.n_iter == slow.n_iter and fast.converged == slow.converged
    assert torch.equal(fast.alpha.isfinite(), slow.alpha.isfinite())
    torch.testing.assert_close(fast.alpha, slow.alpha, rtol=1e-8, atol=0.0)
    assert fast.log_evidence == pytest.approx(slow.log_evidence, rel=1e-12, abs=1e-9)


def _scaled_factor(G: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    d = alpha**-0.5
    return np.linalg.cholesky(d[:, None] * G * d[None, :] + np.eye(alpha.size))


@pytest.mark.parametrize("seed", range(6))
def test_factor_update_equals_a_fresh_factorisation(seed):
    rng = np.random.default_rng(seed)
    M = int(rng.integers(2, 40))
    A = rng.standard_normal((M, 3 * M))
    G = A @ A.T / M
    alpha = np.exp(rng.uniform(-4.0, 4.0, M))
    k = int(rng.integers(0, M))
    new = alpha.copy()
    new[k] = alpha[k] * np.exp(rng.uniform(-6.0, 6.0))  # updates and downdates
    L = _scaled_factor(G, alpha)
    amp = factor_kernels.reestimate_factor(L, k, math.sqrt(alpha[k] / new[k]))
    want = _scaled_factor(G, new)
    assert amp >= 1.0 and (amp == 1.0) == (new[k] >= alpha[k])
    np.testing.assert_allclose(L, want, rtol=0.0, atol=1e-12 * amp * np.abs(want).max())
    assert np.all(np.triu(L, 1) == 0.0)  # still lower triangular


@pytest.mark.parametrize("seed", range(4))
def test_posterior_terms_match_numpy(seed):
    rng = np.random.default_rng(seed)
    M = int(rng.integers(1, 30))
    G = rng.standard_normal((M, M))
    abar = np.exp(rng.uniform(-3.0, 3.0, M))
    mu, Phi_t = rng.standard_normal(M), rng.standard_normal(M)
    Hb, grad, absp = np.empty((M, M)), np.empty(M), np.empty(M)
    fro_sq = factor_kernels.posterior_terms(G, abar, mu, Phi_t, Hb, grad, absp)
    want = 0.5 * (G + G.T) + np.diag(abar)
    np.testing.assert_array_equal(Hb, want)
    assert fro_sq == pytest.approx(np.linalg.norm(want) ** 2, rel=1e-13)
    np.testing.assert_allclose(grad, want @ mu - Phi_t, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(absp, np.abs(want) @ np.abs(mu) + np.abs(Phi_t), rtol=1e-13)


@pytest.mark.parametrize("seed", range(4))
def test_screened_rows_match_the_torch_screening(seed):
    g = torch.Generator().manual_seed(seed)
    M, K, N = int(torch.randint(2, 25, (1,), generator=g)), 7, 80
    B = torch.randn(N, M + K, generator=g, dtype=torch.float64)
    B = B / torch.linalg.vector_norm(B, dim=0)
    Phi, Bc = B[:, :M], B[:, M:]
    t = torch.randn(N, generator=g, dtype=torch.float64)
    alpha = torch.rand(M, generator=g, dtype=torch.float64) * 3.0 + 0.1
    H = torch.diag(alpha) + Phi.T @ Phi
    fac = factor_precision(alpha, Phi.T @ Phi)
    mu = fac.solve(Phi.T @ t)
    grad = H @ mu - Phi.T @ t
    grad_err = rounding_gamma(M + 3, torch.float64) * (H.abs() @ mu.abs() + (Phi.T @ t).abs())
    Z, diag, bt = Bc.T @ Phi, (Bc * Bc).sum(0), Bc.T @ t
    trace = float(torch.linalg.eigvalsh(H).min()) ** -1
    zero = Z.new_zeros(M)
    scr = screened_factors(fac, H, Z, diag, z_error=zero, trace=trace)
    Q, Q_err = gaussian_screened_Q(scr, Z, bt, 0.0, mu, grad, grad_err, zero)
    H_F = float(torch.linalg.matrix_norm(H)) * (1.0 + rounding_gamma(M * M, torch.float64))
    gammas = [rounding_gamma(n, torch.float64) for n in (M + 2, 2 * M + 4, M + 3)]
    norms = [float(torch.linalg.vector_norm(v)) for v in (grad, grad_err, mu)]
    C, out = np.empty((K, M)), np.empty((K, 5))
    arrays = [v.numpy() for v in (fac.L, fac.d, H, Z, diag, bt, mu, grad)]
    factor_kernels.screened_rows(*arrays, np.array([trace, H_F, *norms, *gammas]), C, out)
    np.testing.assert_allclose(C, scr.C.numpy(), rtol=1e-10, atol=1e-13)
    for col, want in enumerate((scr.S, scr.S_error, Q, Q_err, scr.residual)):
        np.testing.assert_allclose(out[:, col], want.numpy(), rtol=1e-6, atol=1e-14)


def _carried_run(seed: int, compiled: bool, monkeypatch) -> tuple[list[np.ndarray], ...]:
    """A stored float64 problem and a seeded sequence of updates of the carried factors
    (re-estimations, noise updates, additions with their stale rows refreshed), by the compiled
    paths or by the torch operations; the carried arrays and the posterior bounds after each."""
    monkeypatch.setattr(tracked_module, "COMPILED_UPDATE", compiled)
    monkeypatch.setattr(posterior_module, "COMPILED_POSTERIOR", compiled)
    rng = np.random.default_rng(seed)
    N, P = 90, 40
    B = rng.standard_normal((N, P))
    B /= np.linalg.norm(B, axis=0)
    K = torch.from_numpy(B.T @ B)
    K = 0.5 * (K + K.T)
    Bt_t = torch.from_numpy(B.T @ rng.standard_normal(N))
    unit = K.diagonal().clone()

    def post(act, alpha, beta):
        a = torch.tensor(act)
        al = torch.tensor(alpha, dtype=torch.float64)
        fac = factor_precision(al, beta * K[a][:, a])
        mu = beta * fac.solve(Bt_t[a])
        return posterior_module.posterior_context(fac, al, beta, K[a][:, a], mu, Bt_t[a], 1e-15)

    act, alpha, beta = [0, 1, 2], [1.0, 2.0, 0.5], 30.0
    tr = tracked_module.TrackedFactors(P, 8, unit, Bt_t)
    tr.prepare(post(act, alpha, beta), K[:, torch.tensor(act)])
    states, bounds = [], []
    for step in range(12):
        p = post(act, alpha, beta)
        bounds.append(np.array([p.Hb_F, p.lam, p.psd, p.mu_error_w]))
        bounds.append(torch.cat([p.abar, p.root, p.gradient, p.gradient_error]).numpy())
        if step % 4 == 3:  # an addition; its row is refreshed (compiled: refresh_rows)
            i = 3 + step // 4
            tr.add(p, K[torch.tensor(act), i], float(K[i, i]), 0.7, K[:, i], float(Bt_t[i]))
            act, alpha = [*act, i], [*alpha, 0.7]
            tr.stale.add(i)
        elif step % 4 == 1:  # a noise update (compiled: rescale_rows)
            beta *= 1.002
            tr.rescale(p, post(act, alpha, beta), 1.0)
        else:  # a re-estimation (compiled: reestimate_terms, reestimate_rows)
            k = step % len(act)
            alpha[k] *= float(np.exp(rng.normal(0.0, 1.0)))
            tr.reestimate(p, k, alpha[k])
        assert not tr.needs_refresh
        tr.prepare(post(act, alpha, beta), K[:, torch.tensor(act)])
        states.append(np.concatenate([v.numpy().ravel() for v in tr.carried()]))
    _check_screen_is_the_torch_screen(tr, post(act, alpha, beta), P, unit, Bt_t, monkeypatch)
    return states, bounds


def _check_screen_is_the_torch_screen(tr, post, P, unit, Bt_t, monkeypatch):
    """The screening of the carried values (all rows, a few rows), by the compiled pass and
    by the torch operations on the same carried values: the same numbers, bit for bit."""
    compiled = tracked_module.COMPILED_UPDATE
    monkeypatch.setattr(tracked_module, "COMPILED_UPDATE", not compiled)
    other = tracked_module.TrackedFactors(P, 8, unit, Bt_t)
    for name in ("C", "S", "Q", "S_err", "Q_err", "rho", "nu"):
        setattr(other, name, getattr(tr, name).clone())
    for rows in (None, torch.tensor([3, 0, 7])):
        got = tr.screen(post, 1e-13, 1e-12, rows)
        want = other.screen(post, 1e-13, 1e-12, rows)
        assert all(torch.equal(a, b) for a, b in zip(got, want, strict=True))
    monkeypatch.setattr(tracked_module, "COMPILED_UPDATE", compiled)


@pytest.mark.parametrize("seed", range(3))
def test_compiled_carried_updates_follow_the_torch_updates(seed, monkeypatch):
    """The compiled noise update, re-estimation update, few-row refresh and posterior bounds
    against the torch operations they replace (the same formulas: equal up to the rounding of
    their sums); the compiled screening gives the torch screening's numbers exactly."""
    got_states, got_bounds = _carried_run(seed, True, monkeypatch)
    want_states, want_bounds = _carried_run(seed, False, monkeypatch)
    for got, want in zip(got_states + got_bounds, want_states + want_bounds, strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)

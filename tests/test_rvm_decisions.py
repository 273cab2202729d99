"""The fast solvers' decision rules (bayes_fdi.rvm.sbl.decisions) against independent
references: the textbook factors in 50-digit arithmetic (mpmath), a design with duplicated
columns in permuted order, a perturbed design, and the closed-form marginal likelihood
(Gaussian) or an independently computed Laplace approximation (Bernoulli)."""

from __future__ import annotations

import mpmath
import numpy as np
import pytest
import scipy.optimize
import scipy.special
import torch

from bayes_fdi.rvm.kernels import RBF
from bayes_fdi.rvm.sbl import (
    Design,
    best_action,
    exact_factors,
    factor_precision,
    fast_bernoulli,
    fast_gaussian,
    gaussian_screened_Q,
    lowest_index_in_band,
    optimistic_ratio,
    posterior_mode,
    rounding_gamma,
    screened_factors,
    thin_matmul,
    verified_argmax,
    weighted_exact_factors,
)
from bayes_fdi.rvm.threads import fit_threads


@pytest.fixture(autouse=True)
def _one_thread():
    """The solvers are called directly here: run them as the estimators' fits do (one thread;
    a second one only adds synchronisation on these small problems)."""
    with fit_threads():
        yield


def _smooth_problem(n=120, seed=0, width=0.4):
    """Nearly collinear RBF columns (a wide kernel on [0, 1]^2): the ill-conditioned case."""
    rng = np.random.default_rng(seed)
    X = torch.tensor(rng.uniform(0, 1, (n, 2)))
    t = torch.sin(3 * X[:, 0]) + X[:, 1] ** 2 + 0.05 * torch.tensor(rng.standard_normal(n))
    K = RBF(width)(X, X)
    return K, t


def _assert_factors_match_reference(S, Q, Phi, alpha, precisions, rhs, B, cand):
    """Compare ``S, Q`` with ``b^T C^-1 b`` and ``b^T C^-1 rhs`` in 50-digit arithmetic.

    ``C = diag(1 / precisions) + Phi A^-1 Phi^T`` is formed and solved with 50 significant digits
    from the same float64 inputs. S is a sum of squared residuals: relative error of a few
    float64 roundings (~1e-16; the textbook form in float64 is off by ~1e-7 for the active
    columns here). Q is an inner product of two residuals, ``|Q| <= sqrt(S rhs^T C^-1 rhs)``:
    its rounding is relative to that bound, not to ``|Q|`` itself (which may be small by
    cancellation), and grows with the residuals' coefficients, up to ~1e3 here for
    ``alpha = 1e-6``: 1e-12 allowed.
    """
    mpmath.mp.dps = 50
    Pm = mpmath.matrix(Phi.tolist())
    C = Pm * mpmath.diag([1 / mpmath.mpf(float(a)) for a in alpha]) * Pm.T
    for i in range(C.rows):
        C[i, i] += 1 / mpmath.mpf(precisions[i])
    rm = mpmath.matrix(rhs)
    Cr = mpmath.lu_solve(C, rm)
    rCr = (rm.T * Cr)[0]
    for k, c in enumerate(cand.tolist()):
        bm = mpmath.matrix(B[:, c].tolist())
        S_ref = (bm.T * mpmath.lu_solve(C, bm))[0]
        Q_ref = (bm.T * Cr)[0]
        assert abs(float(S[k]) - S_ref) <= 1e-13 * abs(S_ref)
        assert abs(float(Q[k]) - Q_ref) <= 1e-12 * mpmath.sqrt(S_ref * rCr)


def test_exact_factors_match_high_precision_textbook_form():
    K, t = _smooth_problem()
    B = K / torch.linalg.vector_norm(K, dim=0)
    act = torch.tensor([3, 40, 77, 101])
    Phi = B[:, act]
    alpha = torch.tensor([2e-5, 3e-4, 1e-6, 5e-3], dtype=torch.float64)
    beta = 400.0
    fac = factor_precision(alpha, beta * (Phi.T @ Phi))
    mu = beta * fac.solve(Phi.T @ t)
    resid = t - Phi @ mu
    cand = torch.tensor([5, 50, 90, 3, 77])  # additions and active columns
    Bc = B[:, cand]
    S, Q = exact_factors(fac, Phi, alpha, beta, mu, resid, Bc, Phi.T @ Bc)
    # independent reference: S = b^T C^-1 b, Q = b^T C^-1 t with C = I/beta + Phi A^-1 Phi^T,
    # formed and solved with 50 significant digits from the same float64 inputs
    _assert_factors_match_reference(S, Q, Phi, alpha, [beta] * Phi.shape[0], t.tolist(), B, cand)


@pytest.mark.parametrize("low", [torch.float32, torch.float64])
def test_screened_factors_bound_the_exact_ones(low):
    """Screening factors from ``B^T Phi`` rounded to ``low`` precision: the exact (residual
    form) ``S`` and ``Q`` lie within the stated error bounds, so the optimistic ratio bounds
    the exact ``Q^2/S`` of every candidate; in float64 the bounds are tight enough to screen
    (below 1e-6 of ``beta``), in float32 they are honest about being far looser."""
    K, t = _smooth_problem(n=300, seed=3)
    B = K / torch.linalg.vector_norm(K, dim=0)
    N = B.shape[0]
    act = torch.tensor([3, 40, 77, 101, 250])
    Phi = B[:, act]
    alpha = torch.tensor([2e-5, 3e-4, 1e-6, 5e-3, 1e-2], dtype=torch.float64)
    beta = 400.0
    M = act.numel()
    G = Phi.T @ Phi
    fac = factor_precision(alpha, beta * G)
    mu = beta * fac.solve(Phi.T @ t)
    resid = t - Phi @ mu
    S_ex, Q_ex = exact_factors(fac, Phi, alpha, beta, mu, resid, B, Phi.T @ B)
    BtPhi = (B.to(low).T @ Phi.to(low)).to(torch.float64)  # products rounded to `low`
    u = torch.finfo(low).eps / 2
    eps = (N + 8) * u / (1 - (N + 8) * u)  # Design.screening_error's bound
    u64 = torch.finfo(torch.float64).eps / 2
    z_error = torch.full((M,), beta * eps, dtype=torch.float64)
    H = torch.diag(alpha) + beta * G
    Z = beta * BtPhi
    screening = screened_factors(
        fac, H, Z, beta * torch.ones(N, dtype=torch.float64), z_error=z_error
    )
    b_t = beta * (B.T @ t)
    gradient = H @ mu - b_t[act]
    gradient_error = (M + 3) * u64 * (H.abs() @ mu.abs() + b_t[act].abs())
    b_t_error = beta * (N + 8) * u64 * float(torch.linalg.vector_norm(t))
    Q, Q_err = gaussian_screened_Q(
        screening, Z, b_t, b_t_error, mu, gradient, gradient_error, z_error
    )
    S, S_err = screening.S, screening.S_error
    assert bool(((S - S_ex).abs() <= S_err).all())
    assert bool(((Q - Q_ex).abs() <= Q_err).all())
    free = torch.ones(N, dtype=torch.bool)
    free[act] = False
    x_opt = optimistic_ratio(S, Q, S_err, Q_err)[free]
    assert bool((x_opt >= (Q_ex * Q_ex / S_ex)[free]).all())
    if low == torch.float64:
        assert float(S_err.max()) < 1e-6 * beta
    else:
        assert float(S_err.max()) > 1e-6 * beta


def test_lowest_index_wins_within_the_tie_band():
    score = torch.tensor([1.0, 3.0 * (1 - 1e-12), 2.0, 3.0], dtype=torch.float64)
    index = torch.tensor([9, 7, 1, 8])
    assert lowest_index_in_band(score, index) == 1  # 7 < 8, both within 1e-9 of 3.0
    score[1] = 3.0 * (1 - 1e-6)  # a real preference: the larger score wins
    assert lowest_index_in_band(score, index) == 3


def test_best_action_ties_between_duplicate_candidates_go_to_the_lowest_index():
    S = torch.tensor([0.5, 2.0, 2.0, 2.0], dtype=torch.float64)
    Q = torch.tensor([1.0, 5.0, 5.0 * (1 + 1e-14), 4.0], dtype=torch.float64)
    act = torch.tensor([0])
    alpha = torch.tensor([10.0], dtype=torch.float64)
    addable = torch.tensor([False, True, True, True])
    assert best_action(S, Q, act, alpha, addable).index == 1
    Q[1], Q[2] = Q[2], Q[1]  # swap the last bits: same choice
    assert best_action(S, Q, act, alpha, addable).index == 1


def _relevance_set(K, t, order):
    """Relevance columns of a fit on the columns in ``order``, as original column numbers."""
    res = fast_gaussian(Design(matrix=K[:, order], bias=True), t)
    cols = [-1 if i == 0 else int(order[i - 1]) for i in res.active.tolist()]
    return sorted(cols), res.log_evidence


def test_duplicated_columns_give_the_same_fit_in_any_order():
    K, t = _smooth_problem(n=80, seed=1, width=0.3)
    n = K.shape[1]
    Kd = torch.cat([K, K[:, :n]], dim=1)  # every column twice: columns j and n + j identical
    rng = np.random.default_rng(2)
    ref_set, ref_ev = _relevance_set(Kd, t, np.arange(2 * n))
    # relabel the duplicates: swap j <-> n + j for a random half of the pairs; the solver sees
    # a different column order, the chosen *functions* must be the same
    swap = rng.random(n) < 0.5
    order = np.arange(2 * n)
    order[:n][swap], order[n:][swap] = np.arange(n, 2 * n)[swap], np.arange(n)[swap]
    got_set, got_ev = _relevance_set(Kd, t, order)
    as_function = sorted({c % n if c >= 0 else -1 for c in got_set})
    assert as_function == sorted({c % n if c >= 0 else -1 for c in ref_set})
    # same model up to rounding: the evidence agrees to ~1e-12 relative (1e-9 allowed)
    assert got_ev == pytest.approx(ref_ev, rel=1e-9)


def _fit_and_perturbed_fit(solver, K, t, seed):
    """``solver`` on the design ``K`` and on ``K`` perturbed by 1e-13 (relative, seeded)."""
    rng = np.random.default_rng(seed)
    Kp = K * (1 + 1e-13 * torch.tensor(rng.standard_normal(K.shape)))
    return solver(Design(matrix=K, bias=True), t), solver(Design(matrix=Kp, bias=True), t)


def test_fit_is_unchanged_by_a_perturbation_of_rounding_size():
    K, t = _smooth_problem(n=150, seed=3, width=0.4)
    a, b = _fit_and_perturbed_fit(fast_gaussian, K, t, 4)
    assert a.active.tolist() == b.active.tolist()
    # a 1e-13 relative change of the data moves a log evidence of ~1e2 by ~1e-11 at most
    # through a well-conditioned path (1e-8 allowed)
    assert abs(a.log_evidence - b.log_evidence) <= 1e-8 * abs(a.log_evidence)


@pytest.mark.parametrize("seed", [0, 1])
def test_reported_evidence_is_the_exact_marginal_likelihood(seed):
    K, t = _smooth_problem(n=100, seed=seed, width=0.2)
    res = fast_gaussian(Design(matrix=K, bias=True), t)
    # independent closed form: log N(t | 0, I/beta + Phi A^-1 Phi^T) from the returned
    # (active, alpha, beta), by a dense N x N Cholesky (C's eigenvalues are >= 1/beta)
    B = torch.cat([torch.ones(K.shape[0], 1, dtype=K.dtype), K], dim=1)
    Phi = B[:, res.active]
    C = torch.eye(K.shape[0], dtype=K.dtype) / res.beta + (Phi / res.alpha) @ Phi.T
    ref = torch.distributions.MultivariateNormal(torch.zeros_like(t), C).log_prob(t)
    # an O(N) sum of terms of size ~1e2 in float64: agreement to ~1e-12 relative (1e-9 allowed)
    assert res.log_evidence == pytest.approx(float(ref), rel=1e-9)


# ---------------------------------------------------------------- Bernoulli (Laplace) model


def _classes(seed, n=300, sep=3.0):
    """Two Gaussian classes in 3-d; labels 0/1."""
    rng = np.random.default_rng(100 + seed)
    X = np.vstack([rng.normal(0, 1, (n // 2, 3)), rng.normal(sep, 1, (n // 2, 3))])
    return torch.tensor(X), torch.tensor(np.repeat([0.0, 1.0], n // 2))


def test_weighted_exact_factors_match_high_precision_textbook_form():
    K, _ = _smooth_problem(n=70)  # (a 50-digit LU costs O(N^3): N = 70 keeps it to seconds)
    B = K / torch.linalg.vector_norm(K, dim=0)
    act = torch.tensor([3, 40, 57, 66])
    Phi = B[:, act]
    alpha = torch.tensor([2e-5, 3e-4, 1e-6, 5e-3], dtype=torch.float64)
    rng = np.random.default_rng(5)
    t = torch.tensor((rng.random(B.shape[0]) < 0.5).astype(float))
    mu = torch.tensor([1.5, -2.0, 0.7, 3.0], dtype=torch.float64)  # any point, not only a mode
    y = torch.sigmoid(Phi @ mu)
    w = y * (1 - y)
    G = (Phi.T * w) @ Phi
    fac = factor_precision(alpha, G)
    cand = torch.tensor([5, 50, 60, 3, 57])
    Bc = B[:, cand]
    S, Q = weighted_exact_factors(fac, Phi, alpha, w, mu, t - y, Bc, Phi.T @ (w[:, None] * Bc))
    # independent reference (SparseBayes' Gaussian approximation at mu): S = b^T C^-1 b and
    # Q = b^T C^-1 t_hat with C = W^-1 + Phi A^-1 Phi^T, t_hat = Phi mu + W^-1 (t - y), formed
    # and solved with 50 significant digits from the same float64 inputs
    mpmath.mp.dps = 50
    a_m = mpmath.matrix(Phi.tolist()) * mpmath.matrix(mu.tolist())
    wm = [mpmath.mpf(float(v)) for v in w]
    t_hat = [a_m[i] + (float(t[i]) - float(y[i])) / wm[i] for i in range(len(wm))]
    _assert_factors_match_reference(S, Q, Phi, alpha, w.tolist(), t_hat, B, cand)


def test_verified_argmax_decides_on_exact_values():
    exact_vals = torch.tensor([0.5, -3.0, 3.0 * (1 + 1e-13), 2.0], dtype=torch.float64)
    screened = exact_vals * torch.tensor([1.0, 1.0 + 1e-6, 1.0 - 1e-6, 1.0], dtype=torch.float64)
    usable = torch.ones(4, dtype=torch.bool)
    got = verified_argmax(screened, usable, lambda idx: exact_vals[idx], relative=1e-5)
    assert got == 1  # |-3| and 3(1 + 1e-13) tie: the lower index, though screening preferred 2
    usable[1] = False
    assert verified_argmax(screened, usable, lambda idx: exact_vals[idx], relative=1e-5) == 2


def test_posterior_mode_is_found_to_rounding_level_from_any_start():
    X, t = _classes(11)
    B = RBF(0.5)(X, X)
    act = torch.tensor([3, 40, 160, 201, 290])
    Phi = B[:, act] / torch.linalg.vector_norm(B[:, act], dim=0)
    alpha = torch.tensor([1e-3, 1e-1, 1e-4, 1.0, 1e-2], dtype=torch.float64)
    a = posterior_mode(Phi, t, alpha, torch.zeros(5, dtype=torch.float64))
    b = posterior_mode(Phi, t, alpha, torch.tensor([5.0, -5, 5, -5, 5], dtype=torch.float64))
    # the gradient at the mode is zero to rounding (|g| ~ 1e-16 sqrt(N) |t - y|); through the
    # Hessian (eigenvalues >= min alpha = 1e-4) that moves mu by ~1e-11 at most (1e-9 allowed)
    assert torch.allclose(a.mu, b.mu, rtol=0, atol=1e-9 * float(a.mu.abs().max()))
    assert a.log_ml == pytest.approx(b.log_ml, rel=1e-12)


def _bernoulli_relevance_set(K, t, order):
    res = fast_bernoulli(Design(matrix=K[:, order], bias=True), t)
    cols = [-1 if i == 0 else int(order[i - 1]) for i in res.active.tolist()]
    return sorted(cols), res.log_evidence


def test_bernoulli_duplicated_columns_give_the_same_fit_in_any_order():
    X, t = _classes(1, n=150, sep=1.5)
    K = RBF(0.5)(X, X)
    n = K.shape[1]
    Kd = torch.cat([K, K], dim=1)
    ref_set, ref_ev = _bernoulli_relevance_set(Kd, t, np.arange(2 * n))
    swap = np.random.default_rng(2).random(n) < 0.5
    order = np.arange(2 * n)
    order[:n][swap], order[n:][swap] = np.arange(n, 2 * n)[swap], np.arange(n)[swap]
    got_set, got_ev = _bernoulli_relevance_set(Kd, t, order)
    assert len(ref_set) > 3
    assert sorted({c % n if c >= 0 else -1 for c in got_set}) == sorted(
        {c % n if c >= 0 else -1 for c in ref_set}
    )
    # same model up to rounding: a Laplace evidence of ~1e2 agrees to ~1e-12 relative
    assert got_ev == pytest.approx(ref_ev, rel=1e-9)


@pytest.mark.parametrize("perturbation_seed", [0, 2])
def test_bernoulli_fit_is_unchanged_by_a_perturbation_of_rounding_size(perturbation_seed):
    # a problem whose relevance set used to change with a 1e-13 perturbation of the design
    X, t = _classes(11)
    a, b = _fit_and_perturbed_fit(fast_bernoulli, RBF(0.5)(X, X), t, perturbation_seed)
    assert a.active.tolist() == b.active.tolist()
    # a 1e-13 relative change of the data moves a log evidence of ~1e2 by ~1e-11 (1e-8 allowed)
    assert abs(a.log_evidence - b.log_evidence) <= 1e-8 * abs(a.log_evidence)


@pytest.mark.parametrize("sep", [0.5, 1.5])
def test_bernoulli_evidence_is_the_laplace_approximation_at_the_mode(sep):
    # overlapping classes (a separable problem has weights -> infinity and no finite mode)
    X, t = _classes(3, n=200, sep=sep)
    K = RBF(0.5)(X, X)
    res = fast_bernoulli(Design(matrix=K, bias=True), t)
    # independent Laplace approximation from the returned (active, alpha), in the caller's
    # basis: the mode by scipy's trust-region Newton, the log-determinants by numpy
    B = np.hstack([np.ones((K.shape[0], 1)), K.numpy()])
    Phi, alpha, tn = B[:, res.active.numpy()], res.alpha.numpy(), t.numpy()

    def neg_log_post(m):
        a = Phi @ m
        return float(np.sum(np.logaddexp(0, a) - tn * a) + 0.5 * np.sum(alpha * m * m))

    def grad(m):
        return Phi.T @ (scipy.special.expit(Phi @ m) - tn) + alpha * m

    def hess(m):
        y = scipy.special.expit(Phi @ m)
        return (Phi.T * (y * (1 - y))) @ Phi + np.diag(alpha)

    opt = scipy.optimize.minimize(
        neg_log_post,
        np.zeros(len(alpha)),
        jac=grad,
        hess=hess,
        method="trust-exact",
        options={"gtol": 1e-12},
    )
    ref = -opt.fun + 0.5 * np.sum(np.log(alpha)) - 0.5 * np.linalg.slogdet(hess(opt.x))[1]
    # a sum of O(N) terms of size ~1e2, each exact to ~1e-14 at the mode (the objective is
    # flat there, so the scipy mode's ~1e-8 tolerance enters quadratically): 1e-9 relative
    assert res.log_evidence == pytest.approx(ref, rel=1e-9)
    np.testing.assert_allclose(res.mean.numpy(), opt.x, rtol=1e-5, atol=1e-8 * np.abs(opt.x).max())


def test_bernoulli_float32_screening_takes_the_exact_decisions():
    """The Bernoulli solver screening with float32 products (error bounded by
    ``Design.screening_error``) takes exactly the float64 design's path."""
    rng = np.random.default_rng(4)
    X = torch.tensor(rng.uniform(0, 1, (600, 2)))
    noise = torch.tensor(0.3 * rng.standard_normal(600))
    t = (torch.sin(4 * X[:, 0]) + X[:, 1] + noise > 0.6).to(torch.float64)
    exact = fast_bernoulli(Design(kernel=RBF(0.3), X=X, bias=True, screen=False), t)
    screen = fast_bernoulli(Design(kernel=RBF(0.3), X=X, bias=True, screen=True), t)
    assert screen.active.tolist() == exact.active.tolist()
    assert screen.n_iter == exact.n_iter
    assert screen.log_evidence == pytest.approx(exact.log_evidence, abs=1e-9)


@pytest.mark.parametrize("k", [1, 2, 5, 32, 33])
def test_thin_matmul_within_highams_bound(k):
    """``thin_matmul`` (the transposed product for thin right-hand sides) is ``A @ W`` within
    ``gamma_m sum |A| |W|``, on a column view of a wider buffer (as the solver's ``Phi``)."""

    rng = np.random.default_rng(k)
    buf = torch.tensor(rng.standard_normal((700, 64)))
    A = buf[:, :50]  # (700, 50) view, row stride 64
    W = torch.tensor(rng.standard_normal((50, k)))
    got = thin_matmul(A, W)
    assert got.shape == (700, k)
    exact = A.numpy().astype(np.longdouble) @ W.numpy().astype(np.longdouble)
    bound = rounding_gamma(50, torch.float64) * (A.abs() @ W.abs()).numpy()
    assert (np.abs(got.numpy() - exact) <= bound).all()
    # the transposed use of the solver (Phi^T B for candidate columns B)
    B = torch.tensor(rng.standard_normal((700, k)))
    got_t = thin_matmul(A.T, B)
    exact_t = A.numpy().T.astype(np.longdouble) @ B.numpy().astype(np.longdouble)
    bound_t = rounding_gamma(700, torch.float64) * (A.T.abs() @ B.abs()).numpy()
    assert (np.abs(got_t.numpy() - exact_t) <= bound_t).all()

r"""Sparse Bayesian learning solvers (type-II maximum likelihood for the RVM).

Four solvers share one result type, :class:`SBLResult`:

* :func:`fast_gaussian` / :func:`fast_bernoulli` -- Tipping & Faul (2003) sequential
  marginal-likelihood maximisation as realised in SparseBayes v2 (see
  ``shared/reference/fast-sbl.md``): candidate factors ``S, Q``, one add /
  re-estimate / delete per iteration chosen by the largest exact evidence gain,
  deletions first, a cache ``B^T Phi`` growing one column per addition, the alignment
  test and the SparseBayes stopping rules. Unlike SparseBayes, the posterior is
  refactorised each iteration (no rank-one updates, which drift) and every decision is
  taken on exact factors (:mod:`bayes_fdi.rvm.sbl_decisions`).
* :func:`em_gaussian` / :func:`em_bernoulli` -- the classical re-estimation of
  Tipping (2001), the paper's eqs. (10)-(11) and (26)-(29): ``alpha_i = gamma_i/mu_i^2``,
  ``sigma^2 = ||t - Phi mu||^2 / (N - sum gamma)``, pruning large ``alpha``.

All solvers work on unit-norm basis columns internally and rescale weights,
covariance and precisions to the caller's basis at output.  The log evidence is the
exact log marginal likelihood ``log N(t | 0, beta^-1 I + Phi A^-1 Phi^T)``
(Gaussian, including the ``-N/2 log 2 pi`` constant) or its Laplace approximation
(Bernoulli).
"""

from __future__ import annotations

import math
import warnings
from typing import NamedTuple

import torch
from torch import Tensor

from bayes_fdi.rvm.design import Design
from bayes_fdi.rvm.sbl_decisions import (
    exact_factors,
    exact_near_threshold,
    lowest_index_in_band,
    mean_error,
    optimistic_ratio,
    screened_factors,
    verified_action,
    verified_argmax,
    weighted_exact_factors,
)

__all__ = [
    "NumericalWarning",
    "SBLResult",
    "cholesky_jitter",
    "em_bernoulli",
    "em_gaussian",
    "fast_bernoulli",
    "fast_gaussian",
    "posterior_mode",
]

# SparseBayes v2 constants

_ALIGNMENT_MAX = 1.0 - 1e-3
_BETA_MAX_FACTOR = 1e6
_BETA_UPDATE_START = 10
_BETA_UPDATE_FREQUENCY = 5
_MIN_DELTA_LOG_BETA = 1e-6
_POSTERIOR_MODE_ITS = 50
# Newton decrement g^T H^-1 g below which the posterior-mode iteration takes full steps
# (quadratic regime), and below which (relative to 1 + |log posterior|) it stops
_MODE_QUADRATIC = 1e-8
_MODE_FLOOR = 1e-24
_LINE_SEARCH_MIN_STEP = 2.0**-8
_LOG_2PI = math.log(2.0 * math.pi)
# Bernoulli fast solver: stop when the Laplace evidence has not risen by _STALL_GAIN
# for _STALL_ITERATIONS iterations (not in SparseBayes, which cycles until its limit)
_STALL_GAIN = 1e-4
_STALL_ITERATIONS = 50
# Gaussian fast solver: also stop when, for _GAUSS_STALL_WINDOW iterations, every action
# was a re-estimation (no basis function added or deleted) and the log evidence rose by less
# than _GAUSS_STALL_GAIN in all. On smooth data a weakly determined alpha can otherwise keep
# being re-estimated by more than ``tol`` in log for thousands of iterations while the
# evidence creeps by 1e-5 per iteration (SparseBayes runs to its iteration limit there).
_GAUSS_STALL_GAIN = 1e-3
_GAUSS_STALL_WINDOW = 200
# initial number of columns of the fast Gaussian solver's Phi / B^T Phi buffers
_INITIAL_CAPACITY = 64


class NumericalWarning(UserWarning):
    """A numerical safeguard (e.g. Cholesky jitter) was needed."""


class SBLResult(NamedTuple):
    """Result of a sparse Bayesian solver (immutable).

    Attributes
    ----------
    active : Tensor
        ``(M,)`` long indices of the selected columns of the candidate basis, sorted.
    mean : Tensor
        ``(M,)`` posterior mean (mode) of the weights of the active columns.
    covariance : Tensor
        ``(M, M)`` posterior covariance ``(A + Phi^T B Phi)^-1``.
    alpha : Tensor
        ``(M,)`` prior precisions of the active weights.
    beta : float
        Noise precision (Gaussian); ``nan`` for the Bernoulli likelihood.
    evidence_trace : Tensor
        Log marginal likelihood after each iteration.
    log_evidence : float
        Final log marginal likelihood (exact for Gaussian, Laplace for Bernoulli).
    n_iter : int
        Iterations performed.
    converged : bool
        Whether a stopping rule (not the iteration limit) ended the run.
    """

    active: Tensor
    mean: Tensor
    covariance: Tensor
    alpha: Tensor
    beta: float
    evidence_trace: Tensor
    log_evidence: float
    n_iter: int
    converged: bool


def cholesky_jitter(H: Tensor, *, what: str = "posterior precision") -> Tensor:
    """Lower Cholesky factor of the SPD matrix ``H``, retrying with growing jitter.

    A :class:`NumericalWarning` is emitted when jitter is needed.

    Raises
    ------
    ValueError
        If ``H`` is not positive definite even with jitter ``1e-2 * mean(diag)``.
    """
    L, info = torch.linalg.cholesky_ex(H)
    if int(info) == 0:
        return L
    scale = float(H.diagonal().abs().mean()) or 1.0
    eye = torch.eye(H.shape[0], dtype=H.dtype, device=H.device)
    jitter = 1e-12 * scale
    while jitter <= 1e-2 * scale:
        L, info = torch.linalg.cholesky_ex(H + jitter * eye)
        if int(info) == 0:
            warnings.warn(
                f"{what} not positive definite; added jitter {jitter:.3g} to its diagonal",
                NumericalWarning,
                stacklevel=3,
            )
            return L
        jitter *= 10.0
    raise ValueError(f"{what} is not positive definite (Cholesky failed even with jitter)")


class _Factor(NamedTuple):
    """Cholesky factor of a posterior precision ``H = diag(alpha) + G`` in scaled form.

    ``H = D^-1 (I + D G D) D^-1`` with ``D = diag(alpha^-1/2)``; the scaled matrix has all
    eigenvalues >= 1, so its Cholesky factor ``L`` exists even when ``H`` is badly scaled.
    """

    L: Tensor
    d: Tensor

    def solve(self, b: Tensor) -> Tensor:
        """``H^-1 b`` for a vector ``b``."""
        return self.d * torch.cholesky_solve((self.d * b)[:, None], self.L)[:, 0]

    def solve_matrix(self, B: Tensor) -> Tensor:
        """``H^-1 B`` for a matrix ``B`` (``(M, K)``)."""
        return self.d[:, None] * torch.cholesky_solve(self.d[:, None] * B, self.L)

    def covariance(self) -> Tensor:
        """``Sigma = H^-1`` (needed explicitly by the rank-one updates)."""
        return self.d[:, None] * torch.cholesky_inverse(self.L) * self.d[None, :]

    def half_logdet_scaled(self) -> float:
        """``(log|H| - sum log alpha) / 2``, the evidence's log-determinant term."""
        return float(torch.log(self.L.diagonal()).sum())


def _factor(alpha: Tensor, G: Tensor, *, what: str = "posterior precision") -> _Factor:
    d = alpha.rsqrt()
    Hs = d[:, None] * (0.5 * (G + G.T)) * d[None, :]
    Hs.diagonal().add_(1.0)
    return _Factor(cholesky_jitter(Hs, what=what), d)


def _gaussian_log_ml(
    N: int, beta: float, ee: float, alpha: Tensor, mu: Tensor, fac: _Factor
) -> float:
    """Exact ``log N(t | 0, beta^-1 I + Phi A^-1 Phi^T)`` from the posterior statistics."""
    return (
        0.5 * (N * math.log(beta) - beta * ee - N * _LOG_2PI - float((alpha * mu * mu).sum()))
        - fac.half_logdet_scaled()
    )


def _unit_columns(design: Design) -> tuple[Tensor, Tensor]:
    """Column norms (zero norms replaced by 1) and a mask of usable (non-zero) columns."""
    norms = design.column_norms()
    valid = norms > 0
    return torch.where(valid, norms, torch.ones_like(norms)), valid


def _result(
    active: Tensor,
    mu: Tensor,
    Sigma: Tensor,
    alpha: Tensor,
    norms: Tensor,
    *,
    beta: float,
    trace: list[float],
    log_ml: float,
    n_iter: int,
    converged: bool,
) -> SBLResult:
    """The :class:`SBLResult` of a solver run: unit-norm-basis weights, covariance and
    precisions mapped to the caller's basis, sorted by column index."""
    order = torch.argsort(active)
    active = active[order]
    d = norms[active]
    return SBLResult(
        active=active,
        mean=mu[order] / d,
        covariance=Sigma[order][:, order] / (d[:, None] * d[None, :]),
        alpha=alpha[order] * d * d,
        beta=float(beta),
        evidence_trace=torch.tensor(trace, dtype=torch.float64),
        log_evidence=float(log_ml),
        n_iter=n_iter,
        converged=converged,
    )


class _Alignment:
    """Alignment test of SparseBayes: refuse candidates nearly parallel to an active column."""

    def __init__(self, n_basis: int, device: torch.device) -> None:
        self.count = torch.zeros(n_basis, dtype=torch.long, device=device)

    def add(self, col: Tensor) -> None:
        self.count += (col.abs() > _ALIGNMENT_MAX).long()

    def remove(self, col: Tensor) -> None:
        self.count -= (col.abs() > _ALIGNMENT_MAX).long()

    @property
    def free(self) -> Tensor:
        return self.count == 0


def _exact_alignment(
    BtBi: Tensor, design: Design, norms: Tensor, b_i: Tensor, error: float
) -> None:
    """Recompute exactly (in place) the screened cosines ``B^T b_i`` within their error bound
    ``error`` (``Design.screening_error``) of the alignment threshold
    (``sbl_decisions.exact_near_threshold``)."""
    exact_near_threshold(
        BtBi,
        _ALIGNMENT_MAX,
        lambda idx: (design.columns(idx) / norms[idx]).T @ b_i,
        relative=2.0 * error / _ALIGNMENT_MAX,
    )


class _ExactColumns:
    """``idx -> (S_idx, Q_idx)`` in residual form (`sbl_decisions.exact_factors`) for the fast
    Gaussian solver's current state; keeps the fetched columns and their Gram entries with the
    active columns (an addition reuses them)."""

    def __init__(
        self,
        design: Design,
        norms: Tensor,
        fac: _Factor,
        Phi: Tensor,
        G: Tensor,
        act: Tensor,
        alpha: Tensor,
        beta: float,
        mu: Tensor,
        resid: Tensor,
    ) -> None:
        self.design, self.norms, self.fac, self.Phi, self.G, self.act = (
            design,
            norms,
            fac,
            Phi,
            G,
            act,
        )
        self.alpha, self.beta, self.mu, self.resid = alpha, beta, mu, resid
        self.fetched: dict[int, tuple[Tensor, Tensor]] = {}

    def __call__(self, idx: Tensor) -> tuple[Tensor, Tensor]:
        if idx is self.act:
            Bc, Z = self.Phi, self.G.T  # exact Gram entries among the active columns
        else:
            Bc = self.design.columns(idx) / self.norms[idx]
            Z = self.Phi.T @ Bc
            for k, i in enumerate(idx.tolist()):
                self.fetched[i] = (Bc[:, k], Z[:, k])
        return exact_factors(self.fac, self.Phi, self.alpha, self.beta, self.mu, self.resid, Bc, Z)


def fast_gaussian(
    design: Design,
    t: Tensor,
    *,
    max_iter: int = 10000,
    tol: float = 1e-3,
) -> SBLResult:
    """Tipping & Faul fast marginal-likelihood maximisation, Gaussian noise.

    Parameters
    ----------
    design : Design
        The candidate basis ``B`` (``N x N_B``).
    t : Tensor
        ``(N,)`` targets.
    max_iter : int
        Iteration limit (a safety net; one action per iteration).
    tol : float
        Stop when the best action is a re-estimate changing ``log alpha`` by less than this
        (SparseBayes ``MinDeltaLogAlpha``) and no deletion is pending. The solver also stops
        (converged) after 200 iterations of re-estimations only (no addition or deletion)
        that raised the log evidence by less than 1e-3 in all: a weakly determined ``alpha``
        can otherwise be re-estimated for thousands of iterations at no gain.

    Each iteration the posterior is refactorised (Cholesky of the scaled precision) and the
    candidates are screened from that factor with error bounds; the action is decided on
    exact factors (``sbl_decisions.verified_action``), so the path of actions does not depend
    on the BLAS code path, the thread count or a float32 screening copy of the design.

    Returns
    -------
    SBLResult
    """
    N, P = design.n_samples, design.n_basis
    dtype, device = design.dtype, design.device
    norms, valid = _unit_columns(design)
    unit = valid.to(dtype)  # b^T b of the normalised columns
    Bt_t = design.rhs_product(t) / norms
    t_var = float(t.var(unbiased=False))
    t_sq = float(t @ t)
    var_floor = max(t_var, 1e-12 * t_sq / N, 1e-300)
    beta_max = _BETA_MAX_FACTOR / var_floor
    beta = min(1.0 / (0.1 * math.sqrt(var_floor)) ** 2, beta_max)
    # final-beta-update tolerance: SparseBayes' 1e-6, but no finer than the rounding error
    # of the N-term sums behind beta (float32 would otherwise cycle on rounding noise)
    beta_tol = max(_MIN_DELTA_LOG_BETA, N * torch.finfo(dtype).eps)

    # initial basis: largest |b^T t| among usable columns
    # (B^T t is exact: near-ties, e.g. duplicated columns, go to the lowest index)
    j = lowest_index_in_band(torch.where(valid, Bt_t.abs(), -1.0), torch.arange(P, device=device))
    phi = design.columns([j])[:, 0] / norms[j]
    p, q = beta, beta * float(Bt_t[j])
    a0 = p * p / (q * q - p) if q * q > p else -1.0
    alpha = torch.tensor([a0 if a0 > 0 else 1e3], dtype=dtype, device=device)
    active = [j]
    # Phi and the cache B^T Phi live in preallocated buffers (columns in active order);
    # B^T Phi has screening precision for candidates and is exact among active columns
    cap = min(P, _INITIAL_CAPACITY)
    Phi_buf = torch.empty(N, cap, dtype=dtype, device=device)
    BtPhi_buf = torch.empty(P, cap, dtype=dtype, device=device)
    Phi_buf[:, 0] = phi
    BtPhi_buf[:, :1] = design.rmatmul(phi[:, None], exact=False) / norms[:, None]
    BtPhi_buf[j, 0] = phi @ phi
    act_t = torch.tensor(active, dtype=torch.long, device=device)
    align = _Alignment(P, device)
    _exact_alignment(BtPhi_buf[:, 0], design, norms, phi, design.screening_error())
    align.add(BtPhi_buf[:, 0])
    in_model = torch.zeros(P, dtype=torch.bool, device=device)
    in_model[j] = True

    def addable_mask() -> Tensor:
        return valid & align.free & ~in_model

    addable = addable_mask()

    def statistics(beta: float, alpha: Tensor, Phi: Tensor, BtPhi: Tensor):
        """Posterior from a fresh factorisation (never from rank-one updates, which drift)."""
        fac = _factor(alpha, beta * BtPhi[act_t])
        mu = beta * fac.solve(Bt_t[act_t])
        resid = t - Phi @ mu
        log_ml = _gaussian_log_ml(N, beta, float(resid @ resid), alpha, mu, fac)
        return fac, mu, resid, log_ml

    eps = design.screening_error()  # error bound of the cosines in B^T Phi
    M = 1
    fac, mu, resid, log_ml = statistics(beta, alpha, Phi_buf[:, :M], BtPhi_buf[:, :M])
    trace = [log_ml]
    converged = False
    it = 0
    last_structural = 0  # iteration of the last addition or deletion
    for it in range(1, max_iter + 1):
        Phi, BtPhi = Phi_buf[:, :M], BtPhi_buf[:, :M]
        if it > 1:
            fac, mu, resid, _ = statistics(beta, alpha, Phi, BtPhi)
        # screening factors from the fresh factor, with bounds of their error: the actions
        # are decided on exact factors whatever the rounding of B^T Phi (float32 or not)
        # (Q = beta b^T t - z^T mu with z = beta B^T Phi: the errors of z, of mu's solve, and
        # of the M + 1 term sums)
        Z = beta * BtPhi
        S, S_err, v_norm = screened_factors(fac, Z, beta * unit, z_error=beta * eps * M**0.5)
        Q = beta * Bt_t - Z @ mu
        Q_err = (
            beta * eps * float(mu.abs().sum())
            + mean_error(fac, mu, v_norm)
            + (M + 2) * torch.finfo(dtype).eps * (beta * Bt_t.abs() + Z.abs() @ mu.abs())
        )
        exact = _ExactColumns(design, norms, fac, Phi, BtPhi[act_t], act_t, alpha, beta, mu, resid)
        best, _ = verified_action(
            S, Q, act_t, alpha, addable, exact, optimistic=optimistic_ratio(S, Q, S_err, Q_err)
        )
        nu, gain, action, jj = best.index, best.gain, best.kind, best.position
        last = not gain > 0
        if not last and action == 1:
            if abs(math.log(best.new_alpha) - math.log(float(alpha[jj]))) < tol:
                last = True
        if not last:
            if action != 1:
                last_structural = it
            if action == 1:  # re-estimate
                alpha = alpha.clone()
                alpha[jj] = best.new_alpha
            elif action == 0:  # add
                if M == Phi_buf.shape[1]:  # grow the buffers
                    cap = min(P, 2 * M)
                    Phi_buf = torch.cat([Phi_buf, Phi_buf.new_empty(N, cap - M)], dim=1)
                    BtPhi_buf = torch.cat([BtPhi_buf, BtPhi_buf.new_empty(P, cap - M)], dim=1)
                    Phi, BtPhi = Phi_buf[:, :M], BtPhi_buf[:, :M]
                if nu in exact.fetched:  # the exact column its factors were computed from
                    b_i, gram = exact.fetched[nu]
                else:
                    b_i = design.columns([nu])[:, 0] / norms[nu]
                    gram = Phi.T @ b_i
                BtBi = BtPhi_buf[:, M]
                BtBi.copy_(design.rmatmul(b_i[:, None], exact=False)[:, 0])
                BtBi.div_(norms)
                BtBi[act_t] = gram
                BtBi[nu] = b_i @ b_i
                _exact_alignment(BtBi, design, norms, b_i, eps)
                BtPhi[nu] = gram
                Phi_buf[:, M] = b_i
                alpha = torch.cat([alpha, alpha.new_tensor([best.new_alpha])])
                active.append(nu)
                act_t = torch.cat([act_t, act_t.new_tensor([nu])])
                M += 1
                in_model[nu] = True
                align.add(BtBi)
                addable = addable_mask()
            else:  # delete
                keep_t = torch.tensor(
                    [k for k in range(M) if k != jj], dtype=torch.long, device=device
                )
                align.remove(BtPhi[:, jj])
                alpha = alpha[keep_t]
                if jj < M - 1:  # close the gap in the buffers
                    Phi_buf[:, jj : M - 1] = Phi_buf[:, jj + 1 : M].clone()
                    BtPhi_buf[:, jj : M - 1] = BtPhi_buf[:, jj + 1 : M].clone()
                M -= 1
                del active[jj]
                act_t = act_t[keep_t]
                in_model[nu] = False
                addable = addable_mask()
            log_ml += gain
        if it <= _BETA_UPDATE_START or it % _BETA_UPDATE_FREQUENCY == 0 or last:
            Phi, BtPhi = Phi_buf[:, :M], BtPhi_buf[:, :M]
            if not last:
                fac, mu, resid, _ = statistics(beta, alpha, Phi, BtPhi)
            gamma = 1.0 - alpha * fac.covariance().diagonal()
            beta_old = beta
            beta = min((N - float(gamma.sum())) / max(float(resid @ resid), 1e-300), beta_max)
            beta = max(beta, 1e-300)
            fac, mu, resid, log_ml = statistics(beta, alpha, Phi, BtPhi)
            if last and abs(math.log(beta) - math.log(beta_old)) > beta_tol:
                last = False
        trace.append(log_ml)
        if last:
            converged = True
            break
        if (
            it - last_structural >= _GAUSS_STALL_WINDOW
            and log_ml - trace[-1 - _GAUSS_STALL_WINDOW] < _GAUSS_STALL_GAIN
        ):
            # only re-estimations, at no gain: the optimum is reached within the tolerance
            converged = True
            break

    # the reported posterior and evidence: exact, from a fresh factorisation
    Phi, BtPhi = Phi_buf[:, :M], BtPhi_buf[:, :M]
    fac, mu, resid, log_ml = statistics(beta, alpha, Phi, BtPhi)
    trace[-1] = log_ml
    return _result(
        torch.tensor(active, device=device),
        mu,
        fac.covariance(),
        alpha,
        norms,
        beta=beta,
        trace=trace,
        log_ml=log_ml,
        n_iter=it,
        converged=converged,
    )


def em_gaussian(
    design: Design,
    t: Tensor,
    *,
    max_iter: int = 1000,
    tol: float = 1e-3,
    prune: float = 1e8,
) -> SBLResult:
    """Tipping's (2001) re-estimation (the paper's eqs. 10-11), Gaussian noise.

    Starts from the whole candidate basis; costs ``O(M^3 + N M^2)`` per iteration, so it
    is a reference implementation for small problems.

    Parameters
    ----------
    design : Design
        The candidate basis ``B``.
    t : Tensor
        ``(N,)`` targets.
    max_iter : int
        Iteration limit.
    tol : float
        Stop when ``max |Delta log alpha|`` over the active set and ``|Delta log beta|``
        fall below ``tol``, or when an iteration raises the log evidence by less than
        ``1e-3 * tol`` (EM's parameters creep for thousands of iterations after the
        evidence has converged).
    prune : float
        Remove a basis when its (unit-norm) precision exceeds ``prune * beta``: its
        contribution ``b b^T / alpha`` to the marginal covariance is then below
        ``1/prune`` of the noise variance and changes the evidence by at most ~``1/prune``.
    """
    N = design.n_samples
    dtype, device = design.dtype, design.device
    norms, valid = _unit_columns(design)
    active = valid.nonzero().squeeze(1)
    Phi_all = design.columns(active) / norms[active]
    G_all = Phi_all.T @ Phi_all
    Pt_all = Phi_all.T @ t
    t_var = float(t.var(unbiased=False))
    t_sq = float(t @ t)
    var_floor = max(t_var, 1e-12 * t_sq / N, 1e-300)
    beta_max = _BETA_MAX_FACTOR / var_floor
    beta = min(1.0 / (0.1 * math.sqrt(var_floor)) ** 2, beta_max)
    alpha = torch.full(
        (active.numel(),), active.numel() / max(t_sq, 1e-300), dtype=dtype, device=device
    )
    keep = torch.arange(active.numel(), device=device)  # positions in Phi_all
    alpha_floor = 1e-10 / max(t_sq, 1e-300)  # prior sd at most 1e5 |t| on a unit column
    trace: list[float] = []
    converged = False
    it = 0
    mu = Sigma = None
    log_ml = -math.inf
    for it in range(1, max_iter + 1):  # noqa: B007
        fac = _factor(alpha, beta * G_all[keep][:, keep])
        mu = beta * fac.solve(Pt_all[keep])
        Sigma = fac.covariance()
        resid = t - Phi_all[:, keep] @ mu
        ee = float(resid @ resid)
        log_ml = _gaussian_log_ml(N, beta, ee, alpha, mu, fac)
        gain = log_ml - trace[-1] if trace else math.inf
        trace.append(log_ml)
        gamma = (1.0 - alpha * Sigma.diagonal()).clamp(0.0, 1.0)
        new_alpha = (gamma / (mu * mu).clamp_min(1e-300)).clamp_min(alpha_floor)
        new_beta = min((N - float(gamma.sum())) / max(ee, 1e-300), beta_max)
        new_beta = max(new_beta, 1e-300)
        d_alpha = float((torch.log(new_alpha) - torch.log(alpha)).abs().max())
        d_beta = abs(math.log(new_beta) - math.log(beta))
        if (d_alpha < tol and d_beta < tol) or abs(gain) < 1e-3 * tol:
            converged = True
            break
        alpha, beta = new_alpha, new_beta
        small = alpha < prune * beta
        if not bool(small.any()):  # keep the most relevant basis
            small = alpha == alpha.min()
        keep, alpha = keep[small], alpha[small]
    if not converged:  # statistics of the last hyperparameters
        fac = _factor(alpha, beta * G_all[keep][:, keep])
        mu = beta * fac.solve(Pt_all[keep])
        Sigma = fac.covariance()
        resid = t - Phi_all[:, keep] @ mu
        log_ml = _gaussian_log_ml(N, beta, float(resid @ resid), alpha, mu, fac)
        trace.append(log_ml)
    return _result(
        active[keep],
        mu,
        Sigma,
        alpha,
        norms,
        beta=beta,
        trace=trace,
        log_ml=log_ml,
        n_iter=it,
        converged=converged,
    )


class _Mode(NamedTuple):
    mu: Tensor
    Sigma: Tensor
    y: Tensor
    w: Tensor
    log_ml: float
    fac: _Factor  # fresh Cholesky factor of H = A + Phi^T W Phi at the mode
    G: Tensor  # Phi^T W Phi


def _log_lik(a: Tensor, t: Tensor) -> Tensor:
    return (
        t * torch.nn.functional.logsigmoid(a) + (1 - t) * torch.nn.functional.logsigmoid(-a)
    ).sum()


def posterior_mode(Phi: Tensor, t: Tensor, alpha: Tensor, mu: Tensor) -> _Mode:
    """Laplace approximation of the Bernoulli-likelihood weight posterior.

    Newton / IRLS on ``log p(t|w) - w^T A w / 2`` (paper eq. 26), then
    ``Sigma = (Phi^T B Phi + A)^-1`` (eq. 28) and the Laplace log evidence.

    The mode is found to rounding level, whatever the scale of the problem, so that it does
    not depend on the BLAS code path (``sbl_decisions``): convergence is measured by the
    affine-invariant Newton decrement ``lambda^2 = g^T H^-1 g`` (twice the predicted gain of
    the step). Steps are halved (down to ``2^-8``) while ``lambda^2 > 1e-8``; below that the
    iteration is in its quadratic regime and takes full steps (objective comparisons there
    would be decided by rounding) until ``lambda^2`` stops falling by 4x per step -- its
    rounding floor -- or falls below ``1e-24 (1 + |objective|)``. At most 50 steps.
    """
    G = fac = g = y = w = None
    prev = math.inf
    obj = _objective(Phi, t, alpha, mu)
    scale = 1.0 + abs(obj)  # of the log posterior, for the stopping threshold
    for it in range(_POSTERIOR_MODE_ITS + 1):
        a = Phi @ mu
        y = torch.sigmoid(a)
        w = y * (1 - y)
        G = (Phi.T * w) @ Phi
        fac = _factor(alpha, G, what="Hessian of the log posterior")
        g = Phi.T @ (t - y) - alpha * mu
        step = fac.solve(g)
        dec = float(g @ step)
        if it == _POSTERIOR_MODE_ITS or dec <= _MODE_FLOOR * scale:
            break
        if dec <= _MODE_QUADRATIC:
            if dec > 0.25 * prev:  # no quadratic decrease any more: at the rounding floor
                break
            mu = mu + step  # (the objective, needed by damped steps only, is not tracked)
            obj = math.nan
        else:
            if math.isnan(obj):
                obj = _objective(Phi, t, alpha, mu)
            lr = 1.0
            while True:
                cand = mu + lr * step
                new_obj = _objective(Phi, t, alpha, cand)
                if new_obj >= obj or lr <= _LINE_SEARCH_MIN_STEP:
                    break
                lr *= 0.5
            if new_obj < obj:  # no ascent possible at the minimum step: at the mode numerically
                break
            mu, obj = cand, new_obj
            scale = 1.0 + abs(obj)
        prev = dec
    assert G is not None and fac is not None and y is not None and w is not None
    Sigma = fac.covariance()
    log_ml = (
        float(_log_lik(Phi @ mu, t))
        - 0.5 * float((alpha * mu * mu).sum())
        - fac.half_logdet_scaled()
    )
    return _Mode(mu, Sigma, y, w, log_ml, fac, G)


def _objective(Phi: Tensor, t: Tensor, alpha: Tensor, m: Tensor) -> float:
    """Log posterior ``log p(t|m) - m^T A m / 2`` (up to a constant)."""
    return float(_log_lik(Phi @ m, t)) - 0.5 * float((alpha * m * m).sum())


class _LaplaceColumns:
    """``idx -> (S_idx, Q_idx)`` in residual form (`sbl_decisions.weighted_exact_factors`) at
    the fast Bernoulli solver's current mode; keeps the fetched columns (an addition reuses
    them)."""

    def __init__(
        self,
        design: Design,
        norms: Tensor,
        mode: _Mode,
        Phi: Tensor,
        act: Tensor,
        alpha: Tensor,
        t: Tensor,
    ) -> None:
        self.design, self.norms, self.mode, self.Phi, self.act = design, norms, mode, Phi, act
        self.alpha, self.score = alpha, t - mode.y
        self.fetched: dict[int, Tensor] = {}

    def __call__(self, idx: Tensor) -> tuple[Tensor, Tensor]:
        mode = self.mode
        if idx is self.act:
            Bc, WZ = self.Phi, mode.G  # exact weighted Gram among the active columns
        else:
            Bc = self.design.columns(idx) / self.norms[idx]
            WZ = self.Phi.T @ (mode.w[:, None] * Bc)
            for k, i in enumerate(idx.tolist()):
                self.fetched[i] = Bc[:, k]
        return weighted_exact_factors(
            mode.fac, self.Phi, self.alpha, mode.w, mode.mu, self.score, Bc, WZ
        )


def fast_bernoulli(
    design: Design,
    t: Tensor,
    *,
    max_iter: int = 10000,
    tol: float = 1e-3,
) -> SBLResult:
    """Tipping & Faul fast marginal-likelihood maximisation, Bernoulli likelihood (Laplace).

    After every action the posterior mode is re-found (to rounding level, see
    :func:`posterior_mode`) and ``S, Q`` are recomputed in full
    (``S_m = b^T W b - b^T W Phi Sigma Phi^T W b``, ``Q_m = b^T (t - y)``) to screen the
    candidates; the action is then chosen on the actives' and the contending candidates'
    factors recomputed in residual form (``sbl_decisions.verified_action`` with
    ``weighted_exact_factors``), with the same tie and stopping rules as
    :func:`fast_gaussian`.

    The gains are exact only for the Gaussian approximation at the current mode; when the
    data are (nearly) separable some ``alpha`` head to zero and the actions can cycle with
    the Laplace evidence going up and down.  Beyond SparseBayes, the solver therefore stops
    when the evidence has not improved by 1e-4 for 50 iterations and returns the best model
    seen (its trace then ends with that model's evidence).

    Parameters
    ----------
    design : Design
        The candidate basis ``B``.
    t : Tensor
        ``(N,)`` targets in ``{0, 1}``.
    max_iter, tol
        As in :func:`fast_gaussian`.
    """
    P, device = design.n_basis, design.device
    norms, valid = _unit_columns(design)
    tp = 2.0 * t - 1.0
    Bt_tp = design.rmatmul(tp[:, None], exact=False)[:, 0] / norms
    # the initial column: largest |b^T tp|, decided on exact products near the screened top
    eps = design.screening_error()  # error bound of screened cosines (unit vectors)
    top = float(torch.where(valid, Bt_tp.abs(), 0.0).max())
    j = verified_argmax(
        Bt_tp,
        valid,
        lambda idx: (design.columns(idx) / norms[idx]).T @ tp,
        relative=eps * math.sqrt(t.numel()) / max(top, 1e-300),  # ||tp|| = sqrt(N)
    )
    Phi = design.columns([j]) / norms[j]
    target = (tp * 0.9 + 1.0) / 2.0
    logit = torch.log(target / (1.0 - target))
    mu = torch.linalg.lstsq(Phi, logit[:, None]).solution[:, 0]
    alpha = (1.0 / (mu * mu).clamp_min(1e-300)).clamp(1e-3, 1e3)
    active = [j]
    BtPhi = design.rmatmul(Phi, exact=False) / norms[:, None]
    in_model = torch.zeros(P, dtype=torch.bool, device=device)
    in_model[j] = True
    align = _Alignment(P, device)
    _exact_alignment(BtPhi[:, 0], design, norms, Phi[:, 0], eps)
    align.add(BtPhi[:, 0])

    def full_statistics(Phi: Tensor, alpha: Tensor, mu: Tensor):
        """The mode, the screening factors (textbook form, possibly float32 products) and
        bounds of their exact ``Q^2/S`` (``sbl_decisions.optimistic_ratio``)."""
        mode = posterior_mode(Phi, t, alpha, mu)
        V = torch.cat([mode.w[:, None] * Phi, (t - mode.y)[:, None]], dim=1)
        BtV = design.rmatmul(V, exact=False) / norms[:, None]
        BtWPhi, Q = BtV[:, :-1], BtV[:, -1]
        # each product is within eps * ||v|| of the exact one (unit columns); the weighted
        # squared norms (B * B)^T w / ||b||^2 of positive terms within eps * max(w)
        v_norms = torch.linalg.vector_norm(V, dim=0)
        S, S_err, _ = screened_factors(
            mode.fac,
            BtWPhi,
            design.sq_rmatmul(mode.w, exact=False) / norms**2,
            z_error=eps * float(torch.linalg.vector_norm(v_norms[:-1])),
            diag_error=eps * float(mode.w.max()),
        )
        Q_err = eps * float(v_norms[-1]) + 4.0 * eps * Q.abs()  # + rounding of the division
        return mode, S, Q, optimistic_ratio(S, Q, S_err, Q_err)

    mode, S, Q, x_opt = full_statistics(Phi, alpha, mu)
    trace = [mode.log_ml]
    best = (mode.log_ml, 0, list(active), alpha.clone())
    converged = False
    it = 0
    for it in range(1, max_iter + 1):
        act_t = torch.tensor(active, dtype=torch.long, device=device)
        exact = _LaplaceColumns(design, norms, mode, Phi, act_t, alpha, t)
        addable = valid & align.free & ~in_model
        choice, _ = verified_action(S, Q, act_t, alpha, addable, exact, optimistic=x_opt)
        nu, gain, action, jj = choice.index, choice.gain, choice.kind, choice.position
        if not gain > 0:
            converged = True
            break
        if action == 1:
            if abs(math.log(choice.new_alpha) - math.log(float(alpha[jj]))) < tol:
                converged = True
                break
            alpha = alpha.clone()
            alpha[jj] = choice.new_alpha
            mu = mode.mu
        elif action == 0:
            b_i = exact.fetched[nu][:, None]  # the exact column its factors were computed from
            BtBi = design.rmatmul(b_i, exact=False)[:, 0] / norms
            _exact_alignment(BtBi, design, norms, b_i[:, 0], eps)
            a_new = choice.new_alpha
            mu_i = float(Q[nu]) / (a_new + float(S[nu]))
            Phi = torch.cat([Phi, b_i], dim=1)
            BtPhi = torch.cat([BtPhi, BtBi[:, None]], dim=1)
            alpha = torch.cat([alpha, alpha.new_tensor([a_new])])
            mu = torch.cat([mode.mu, mode.mu.new_tensor([mu_i])])
            active.append(nu)
            in_model[nu] = True
            align.add(BtBi)
        else:
            keep_t = torch.tensor([k for k in range(len(active)) if k != jj], device=device)
            align.remove(BtPhi[:, jj])
            Phi, BtPhi = Phi[:, keep_t], BtPhi[:, keep_t]
            alpha, mu = alpha[keep_t], mode.mu[keep_t]
            del active[jj]
            in_model[nu] = False
        mode, S, Q, x_opt = full_statistics(Phi, alpha, mu)
        trace.append(mode.log_ml)
        if mode.log_ml > best[0] + _STALL_GAIN:
            best = (mode.log_ml, it, list(active), alpha.clone())
        elif it - best[1] >= _STALL_ITERATIONS:
            # The Laplace evidence has stopped improving: the Gaussian-approximation gains
            # cycle (typically a nearly separating basis with alpha -> 0).  Stop at the best.
            converged = True
            break

    if best[0] > mode.log_ml + _STALL_GAIN:
        active, alpha = best[2], best[3]
        Phi = design.columns(active) / norms[torch.tensor(active, device=device)]
        mode = posterior_mode(Phi, t, alpha, torch.zeros_like(alpha))
        trace.append(mode.log_ml)
    return _result(
        torch.tensor(active, device=device),
        mode.mu,
        mode.Sigma,
        alpha,
        norms,
        beta=math.nan,
        trace=trace,
        log_ml=mode.log_ml,
        n_iter=it,
        converged=converged,
    )


def em_bernoulli(
    design: Design,
    t: Tensor,
    *,
    max_iter: int = 1000,
    tol: float = 1e-3,
    prune: float = 1e8,
) -> SBLResult:
    """Tipping's (2001) re-estimation with the Laplace approximation (paper eqs. 26-29).

    Parameters
    ----------
    design : Design
        The candidate basis ``B``.
    t : Tensor
        ``(N,)`` targets in ``{0, 1}``.
    max_iter, tol, prune
        As in :func:`em_gaussian` (convergence on ``log alpha`` or the evidence; the Bernoulli noise
        precision ``y(1-y)`` is at most 1/4, so a basis is pruned when ``alpha > prune / 4``).
    """
    dtype, device = design.dtype, design.device
    norms, valid = _unit_columns(design)
    active = valid.nonzero().squeeze(1)
    Phi_all = design.columns(active) / norms[active]
    keep = torch.arange(active.numel(), device=device)
    alpha = torch.full(
        (active.numel(),), float(active.numel()) / design.n_samples, dtype=dtype, device=device
    )
    mu = torch.zeros(active.numel(), dtype=dtype, device=device)
    trace: list[float] = []
    converged = False
    it = 0
    mode = None
    for it in range(1, max_iter + 1):  # noqa: B007
        mode = posterior_mode(Phi_all[:, keep], t, alpha, mu)
        gain = mode.log_ml - trace[-1] if trace else math.inf
        trace.append(mode.log_ml)
        gamma = 1.0 - alpha * mode.Sigma.diagonal()
        new_alpha = gamma.clamp_min(1e-300) / (mode.mu * mode.mu).clamp_min(1e-300)
        d_alpha = float((torch.log(new_alpha) - torch.log(alpha)).abs().max())
        if d_alpha < tol or abs(gain) < 1e-3 * tol:
            converged = True
            break
        alpha, mu = new_alpha, mode.mu
        small = alpha < 0.25 * prune
        if not bool(small.any()):
            small = alpha == alpha.min()
        keep, alpha, mu = keep[small], alpha[small], mu[small]
    if not converged:
        mode = posterior_mode(Phi_all[:, keep], t, alpha, mu)
        trace.append(mode.log_ml)
    assert mode is not None
    return _result(
        active[keep],
        mode.mu,
        mode.Sigma,
        alpha,
        norms,
        beta=math.nan,
        trace=trace,
        log_ml=mode.log_ml,
        n_iter=it,
        converged=converged,
    )

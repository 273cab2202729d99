"""Tipping & Faul's fast sequential marginal-likelihood maximisation, Gaussian noise
(:func:`fast_gaussian`).

Written by hand: no maintained library implements it (``shared/reference/fast-sbl.md``;
SparseBayes v2 is MATLAB). One add / re-estimate / delete per iteration, decided on exact
factors (:mod:`bayes_fdi.rvm.sbl.decisions`, :mod:`bayes_fdi.rvm.sbl.verification`) from
screening factors carried with error bounds (:mod:`bayes_fdi.rvm.sbl.tracked_factors`).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from bayes_fdi.rvm.sbl.design import Design
from bayes_fdi.rvm.sbl.decisions import (
    exact_factors,
    lowest_index_in_band,
    rounding_gamma,
    thin_matmul,
)
from bayes_fdi.rvm.sbl.precision_factor import (
    SBLResult,
    _Alignment,
    _exact_alignment,
    _Factor,
    _factor,
    _gaussian_log_ml,
    _result,
    _unit_columns,
)
from bayes_fdi.rvm.sbl.tracked_factors import Posterior, TrackedFactors, posterior_context
from bayes_fdi.rvm.sbl.verification import lazy_verified_action

__all__ = ["fast_gaussian"]

# SparseBayes v2 constants
_BETA_MAX_FACTOR = 1e6
_BETA_UPDATE_START = 10
_BETA_UPDATE_FREQUENCY = 5
_MIN_DELTA_LOG_BETA = 1e-6
# Gaussian fast solver: also stop when, for _GAUSS_STALL_WINDOW iterations, every action
# was a re-estimation (no basis function added or deleted) and the log evidence rose by less
# than _GAUSS_STALL_GAIN in all. On smooth data a weakly determined alpha can otherwise keep
# being re-estimated by more than ``tol`` in log for thousands of iterations while the
# evidence creeps by 1e-5 per iteration (SparseBayes runs to its iteration limit there).
_GAUSS_STALL_GAIN = 1e-3
_GAUSS_STALL_WINDOW = 200
# the carried screening factors (sbl_tracking): a noise update moving some alpha / beta by
# more than this (relative) refreshes them instead of carrying them; more than
# max(_MIN_EXACT_BUDGET, M / 4) exact columns, or P / 8 tightened rows, in one round of a
# decision refreshes them too (these choices change the cost, never the action). Tests set
# _REFRESH_EVERY_ITERATION to compare.
_BETA_RELATIVE_REFRESH = 1e-2
_MIN_EXACT_BUDGET = 8
_REFRESH_EVERY_ITERATION = False
# initial number of columns of the fast Gaussian solver's Phi / B^T Phi buffers
_INITIAL_CAPACITY = 64


class _ExactColumns:
    """``idx -> (S_idx, Q_idx)`` in residual form (`sbl_decisions.exact_factors`) for the fast
    Gaussian solver's current state, active columns or not; keeps the fetched candidate columns
    and their Gram entries (an addition reuses them)."""

    def __init__(
        self,
        design: Design,
        norms: Tensor,
        fac: _Factor,
        Phi: Tensor,
        G: Tensor,
        position: Tensor,
        alpha: Tensor,
        beta: float,
        mu: Tensor,
        resid: Tensor,
    ) -> None:
        self.design, self.norms, self.fac, self.Phi, self.G = design, norms, fac, Phi, G
        self.position = position  # (P,) position in the active set, -1 for candidates
        self.alpha, self.beta, self.mu, self.resid = alpha, beta, mu, resid
        self.fetched: dict[int, tuple[Tensor, Tensor]] = {}

    def __call__(self, idx: Tensor) -> tuple[Tensor, Tensor]:
        pos = self.position[idx]
        is_act = pos >= 0
        n_act = int(is_act.sum())
        if n_act == idx.numel():  # active columns only: their exact Gram entries
            Bc, Z = self.Phi[:, pos], self.G[:, pos]
        elif n_act == 0:
            Bc, Z = self._candidates(idx)
        else:
            N, K = self.Phi.shape[0], idx.numel()
            Bc = self.Phi.new_empty(N, K)
            Z = self.Phi.new_empty(self.Phi.shape[1], K)
            pa = pos[is_act]
            Bc[:, is_act] = self.Phi[:, pa]
            Z[:, is_act] = self.G[:, pa]
            Bc[:, ~is_act], Z[:, ~is_act] = self._candidates(idx[~is_act])
        return exact_factors(self.fac, self.Phi, self.alpha, self.beta, self.mu, self.resid, Bc, Z)

    def _candidates(self, idx: Tensor) -> tuple[Tensor, Tensor]:
        Bn = self.design.columns(idx) / self.norms[idx]
        Zn = thin_matmul(self.Phi.T, Bn)
        for k, i in enumerate(idx.tolist()):
            self.fetched[i] = (Bn[:, k], Zn[:, k])
        return Bn, Zn


def _start_state(
    start: SBLResult, norms: Tensor, valid: Tensor, beta_max: float
) -> tuple[list[int], Tensor, float]:
    """Basis, unit-column precisions and noise precision of a warm start (validated)."""
    active = start.active.to(norms.device)
    if active.numel() == 0:
        raise ValueError("start has an empty basis")
    if active.unique().numel() != active.numel():
        raise ValueError("start has a basis column more than once")
    if int(active.min()) < 0 or int(active.max()) >= norms.numel():
        raise ValueError(f"start's basis indices lie outside the design's {norms.numel()} columns")
    if not bool(valid[active].all()):
        raise ValueError("start's basis contains an all-zero column")
    d = norms[active]
    alpha = start.alpha.to(device=norms.device, dtype=norms.dtype) / (d * d)
    if alpha.shape != active.shape or not bool(((alpha > 0) & torch.isfinite(alpha)).all()):
        raise ValueError("start's precisions must be finite and > 0, one per basis column")
    beta = float(start.beta)
    if not (math.isfinite(beta) and beta > 0):
        raise ValueError(f"start's noise precision must be finite and > 0, got {beta}")
    return active.tolist(), alpha, min(beta, beta_max)


def fast_gaussian(
    design: Design,
    t: Tensor,
    *,
    max_iter: int = 10000,
    tol: float = 1e-3,
    start: SBLResult | None = None,
) -> SBLResult:
    """Tipping & Faul fast marginal-likelihood maximisation, Gaussian noise.

    Each iteration the posterior is refactorised (Cholesky of the scaled precision); the
    candidates' screening factors are carried by rank-one updates with rigorous error bounds
    (``sbl_tracking``) and the action is decided on exact factors of whatever could win
    (``sbl_verification.lazy_verified_action``), so the path of actions does not depend on the
    BLAS code path, the thread count, the device or a reduced-precision screening copy of the
    design.

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
    start : SBLResult or None
        Start from this state on the same design (its basis, precisions and noise precision,
        e.g. a re-estimation run's, as :func:`bayes_fdi.rvm.sbl.polish.polish_gaussian` does)
        instead of the single column best aligned with ``t``. Each addition, re-estimation
        and deletion from there raises the evidence (the noise precision is re-estimated on
        SparseBayes' schedule as in a fresh run).

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

    eps = design.screening_error()  # error bound of the cosines in B^T Phi
    # the Gram entries among active columns are products of exact columns (stored at each
    # addition), whatever precision screens the candidates
    gram_eps = design.product_error()
    if start is None:
        # initial basis: largest |b^T t| among usable columns
        # (B^T t is exact: near-ties, e.g. duplicated columns, go to the lowest index)
        j = lowest_index_in_band(
            torch.where(valid, Bt_t.abs(), -1.0), torch.arange(P, device=device)
        )
        p, q = beta, beta * float(Bt_t[j])
        a0 = p * p / (q * q - p) if q * q > p else -1.0
        alpha = torch.tensor([a0 if a0 > 0 else 1e3], dtype=dtype, device=device)
        active = [j]
    else:
        active, alpha, beta = _start_state(start, norms, valid, beta_max)
    M = len(active)
    act_t = torch.tensor(active, dtype=torch.long, device=device)
    # Phi and the cache B^T Phi live in preallocated buffers (columns in active order);
    # B^T Phi has screening precision for candidates and is exact among active columns
    cap = min(P, max(_INITIAL_CAPACITY, 2 * M))
    Phi_buf = torch.empty(N, cap, dtype=dtype, device=device)
    BtPhi_buf = torch.empty(P, cap, dtype=dtype, device=device)
    Phi0 = design.columns(act_t) / norms[act_t]
    Phi_buf[:, :M] = Phi0
    BtPhi_buf[:, :M] = design.rmatmul(Phi0, exact=False) / norms[:, None]
    align = _Alignment(P, device)
    for k in range(M):
        # exact Gram entries among the actives (as an addition stores them)
        BtPhi_buf[act_t, k] = Phi0.T @ Phi0[:, k]
        BtPhi_buf[active[k], k] = Phi0[:, k] @ Phi0[:, k]
        _exact_alignment(BtPhi_buf[:, k], design, norms, Phi0[:, k], eps)
        align.add(BtPhi_buf[:, k])
    in_model = torch.zeros(P, dtype=torch.bool, device=device)
    in_model[act_t] = True
    position = torch.full((P,), -1, dtype=torch.long, device=device)
    position[act_t] = torch.arange(M, device=device)
    tracker = TrackedFactors(P, cap, unit, Bt_t)

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

    def context(fac: _Factor, mu: Tensor, BtPhi: Tensor) -> Posterior:
        return posterior_context(fac, alpha, beta, BtPhi[act_t], mu, Bt_t[act_t], gram_eps)

    # B^T t of unit columns: a product of N terms in the design's dtype, within gamma_N ||t||
    bt_error = rounding_gamma(N + 8, dtype) * math.sqrt(t_sq)
    fac, mu, resid, log_ml = statistics(beta, alpha, Phi_buf[:, :M], BtPhi_buf[:, :M])
    current = True  # whether fac, mu, resid are those of the present alpha, beta and basis
    trace = [log_ml]
    converged = False
    it = 0
    last_structural = 0  # iteration of the last addition or deletion
    for it in range(1, max_iter + 1):
        Phi, BtPhi = Phi_buf[:, :M], BtPhi_buf[:, :M]
        if not current:
            fac, mu, resid, _ = statistics(beta, alpha, Phi, BtPhi)
            current = True
        # screening factors carried with rigorous bounds of their error (sbl_tracking): the
        # action is decided on exact factors of whatever could win (sbl_verification), so it
        # does not depend on the BLAS code path, the thread count or how the bounds were made
        post = context(fac, mu, BtPhi)
        exact = _ExactColumns(
            design, norms, fac, Phi, BtPhi[act_t], position, alpha, beta, mu, resid
        )
        if not tracker.usable(post):  # bounds of the fresh factor only, as a full screening
            best, _ = lazy_verified_action(
                *tracker.direct(post, BtPhi, eps, bt_error),
                act_t,
                alpha,
                addable,
                exact,
            )
        else:
            if _REFRESH_EVERY_ITERATION:
                tracker.needs_refresh = True
            tracker.prepare(post, BtPhi)
            best, _ = lazy_verified_action(
                *tracker.screen(post, eps, bt_error),
                act_t,
                alpha,
                addable,
                exact,
                tighten=lambda idx, post=post, Z=BtPhi: tracker.tighten(
                    post, Z, idx, eps, bt_error
                ),
                budget=max(_MIN_EXACT_BUDGET, M // 4),
                tighten_budget=max(_MIN_EXACT_BUDGET, P // 8),
            )
            if best is None:  # the carried bounds have grown too loose: screen afresh
                tracker.needs_refresh = True
                tracker.prepare(post, BtPhi)
                best, _ = lazy_verified_action(
                    *tracker.screen(post, eps, bt_error), act_t, alpha, addable, exact
                )
        assert best is not None
        nu, gain, action, jj = best.index, best.gain, best.kind, best.position
        last = not gain > 0
        if not last and action == 1:
            if abs(math.log(best.new_alpha) - math.log(float(alpha[jj]))) < tol:
                last = True
        if not last:
            current = False
            if action != 1:
                last_structural = it
            if action == 1:  # re-estimate
                tracker.reestimate(post, jj, best.new_alpha)
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
                tracker.add(post, gram, float(BtBi[nu]), best.new_alpha, BtBi, float(Bt_t[nu]))
                tracker.stale.add(nu)  # its stored products became the exact Gram entries
                position[nu] = M - 1
            else:  # delete
                tracker.delete(post, jj)
                position[act_t[jj + 1 :]] -= 1
                position[nu] = -1
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
            if not current:
                fac, mu, resid, _ = statistics(beta, alpha, Phi, BtPhi)
            # the carried factors follow the noise update unless a refresh is pending anyway
            before = None if tracker.needs_refresh else context(fac, mu, BtPhi)
            gamma = 1.0 - alpha * fac.covariance().diagonal()
            beta_old = beta
            beta = min((N - float(gamma.sum())) / max(float(resid @ resid), 1e-300), beta_max)
            beta = max(beta, 1e-300)
            fac, mu, resid, log_ml = statistics(beta, alpha, Phi, BtPhi)
            current = True
            if before is not None:  # and the actives' afresh (O(M^3))
                tracker.rescale(before, context(fac, mu, BtPhi), _BETA_RELATIVE_REFRESH)
                tracker.stale.update(active)
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
    if not current:
        fac, mu, resid, log_ml = statistics(beta, alpha, Phi_buf[:, :M], BtPhi_buf[:, :M])
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

"""Tipping & Faul's fast sequential marginal-likelihood maximisation, Gaussian noise
(:func:`fast_gaussian`).

Tipping & Faul 2003, "Fast marginal likelihood maximisation for sparse Bayesian models"
(AISTATS), as realised in SparseBayes v2: one add / re-estimate / delete per iteration, chosen
by the largest exact evidence gain and decided on exact factors
(:mod:`bayes_fdi.rvm.sbl.decisions`, :mod:`bayes_fdi.rvm.sbl.verification`) from screening
factors carried with error bounds (:mod:`bayes_fdi.rvm.sbl.tracked_factors`); the noise
precision re-estimated on SparseBayes' schedule (:mod:`bayes_fdi.rvm.sbl.noise`).

Imports the rest of the solver family below it (everything but the Bernoulli, re-estimation and
polish solvers). Written by hand: no maintained library implements it (SparseBayes v2 is
MATLAB).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from bayes_fdi.rvm.sbl.alignment import Alignment, exact_alignment
from bayes_fdi.rvm.sbl.capacity import grown_capacity
from bayes_fdi.rvm.sbl.decisions import Action, lowest_index_in_band
from bayes_fdi.rvm.sbl.design import Design
from bayes_fdi.rvm.sbl.factor_kernels import reestimate_factor
from bayes_fdi.rvm.sbl.noise import initial_noise_precision, reestimated_noise_precision
from bayes_fdi.rvm.sbl.posterior_bounds import Posterior, posterior_context
from bayes_fdi.rvm.sbl.precision_factor import (
    PrecisionFactor,
    factor_precision,
    gaussian_log_evidence,
)
from bayes_fdi.rvm.sbl.residual_factors import exact_factors
from bayes_fdi.rvm.sbl.result import SBLResult, result_in_caller_basis, unit_columns
from bayes_fdi.rvm.sbl.rounding import rounding_gamma, thin_matmul
from bayes_fdi.rvm.sbl.tracked_factors import TrackedFactors
from bayes_fdi.rvm.sbl.verification import lazy_verified_action

__all__ = ["UPDATED_FACTOR", "fast_gaussian"]

#: After a re-estimation, move the posterior's Cholesky factor by a compiled rank-one step
#: (:func:`~bayes_fdi.rvm.sbl.factor_kernels.reestimate_factor`, CPU float64) instead of
#: refactorising. Off by default: it keeps every decision but moves the re-estimated precisions
#: by rounding, and that changed a downstream result (the full-posteriors notebook's NUTS fits of
#: two RVR posteriors no longer converged on its small settings); tests set it to check it.
UPDATED_FACTOR = False

# SparseBayes v2 constants
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
# the carried screening factors (tracked_factors): a noise update moving some alpha / beta by
# more than this (relative) refreshes them instead of carrying them; more than
# max(_MIN_EXACT_BUDGET, M / 4) exact columns, or P / 8 tightened rows, in one round of a
# decision refreshes them too (these choices change the cost, never the action). Tests set
# _REFRESH_EVERY_ITERATION to compare.
_BETA_RELATIVE_REFRESH = 1e-2
_MIN_EXACT_BUDGET = 8
_REFRESH_EVERY_ITERATION = False
# initial number of columns of the fast Gaussian solver's Phi / B^T Phi buffers
_INITIAL_CAPACITY = 64
# an updated factor is used while its estimated backward error stays within this many times a
# fresh factorisation's (gamma_{M+1}); each rank-one update adds one, a downdate its
# amplification squared. Additions, deletions, noise updates and the reported result always
# refactorise afresh.
_FACTOR_ERROR_BUDGET = 8.0


def fast_gaussian(
    design: Design,
    t: Tensor,
    *,
    max_iter: int = 10000,
    tol: float = 1e-3,
    start: SBLResult | None = None,
) -> SBLResult:
    """Tipping & Faul fast marginal-likelihood maximisation, Gaussian noise.

    The posterior is refactorised (Cholesky of the scaled precision) after each addition,
    deletion and noise update and moved by a rank-one step after a re-estimation; the
    candidates' screening factors are carried by rank-one updates with rigorous error bounds
    (:mod:`~bayes_fdi.rvm.sbl.tracked_factors`) and the action is decided on exact factors of
    whatever could win (:func:`~bayes_fdi.rvm.sbl.verification.lazy_verified_action`), so the
    path of actions does not depend on the BLAS code path, the thread count, the device or a
    reduced-precision screening copy of the design.

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
    run = _FastGaussianRun(design, t, start)
    trace = [run.log_ml]
    converged = False
    it = 0
    last_structural = 0  # iteration of the last addition or deletion
    for it in range(1, max_iter + 1):
        if not run.current:
            run.fac, run.mu, run.resid, _ = run.statistics()
            run.current = True
        best, exact, post = run.decide()
        last = not best.gain > 0
        if not last and best.kind == 1:
            if abs(math.log(best.new_alpha) - math.log(float(run.alpha[best.position]))) < tol:
                last = True
        if not last:
            run.current = False
            if best.kind != 1:
                last_structural = it
            if best.kind == 1:
                run.reestimate(post, best)
            elif best.kind == 0:
                run.add(post, exact, best)
            else:
                run.delete(post, best)
            run.log_ml += best.gain
        if it <= _BETA_UPDATE_START or it % _BETA_UPDATE_FREQUENCY == 0 or last:
            last = run.update_noise(last)
        trace.append(run.log_ml)
        if last:
            converged = True
            break
        if (
            it - last_structural >= _GAUSS_STALL_WINDOW
            and run.log_ml - trace[-1 - _GAUSS_STALL_WINDOW] < _GAUSS_STALL_GAIN
        ):
            # only re-estimations, at no gain: the optimum is reached within the tolerance
            converged = True
            break
    return run.result(trace, it, converged)


class _ExactColumns:
    """``idx -> (S_idx, Q_idx)`` in residual form
    (:func:`~bayes_fdi.rvm.sbl.residual_factors.exact_factors`) for the fast Gaussian solver's
    current state, active columns or not; keeps the fetched candidate columns and their Gram
    entries (an addition reuses them)."""

    def __init__(
        self,
        design: Design,
        norms: Tensor,
        fac: PrecisionFactor,
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


def _initial_column(
    Bt_t: Tensor, valid: Tensor, beta: float, dtype: torch.dtype
) -> tuple[list[int], Tensor]:
    """SparseBayes' start: the usable column of largest ``|b^T t|`` (``B^T t`` is exact:
    near-ties, e.g. duplicated columns, go to the lowest index) and its optimal precision
    ``p^2 / (q^2 - p)`` (``1e3`` when that is not positive)."""
    P = Bt_t.numel()
    j = lowest_index_in_band(
        torch.where(valid, Bt_t.abs(), -1.0), torch.arange(P, device=Bt_t.device)
    )
    p, q = beta, beta * float(Bt_t[j])
    a0 = p * p / (q * q - p) if q * q > p else -1.0
    alpha = torch.tensor([a0 if a0 > 0 else 1e3], dtype=dtype, device=Bt_t.device)
    return [j], alpha


class _FastGaussianRun:
    """The state of one :func:`fast_gaussian` run and its steps.

    The active columns ``Phi`` and the cache ``B^T Phi`` live in preallocated buffers (columns
    in active order); ``B^T Phi`` has screening precision for candidates and is exact among
    active columns. ``fac, mu, resid`` are the posterior of the last fresh factorisation
    (``current``: of the present ``alpha``, ``beta`` and basis); ``log_ml`` the log evidence.
    """

    def __init__(self, design: Design, t: Tensor, start: SBLResult | None) -> None:
        N, P = design.n_samples, design.n_basis
        dtype, device = design.dtype, design.device
        self.design, self.t, self.N, self.P, self.device = design, t, N, P, device
        self.norms, self.valid = unit_columns(design)
        self.unit = self.valid.to(dtype)  # b^T b of the normalised columns
        self.Bt_t = design.rhs_product(t) / self.norms
        t_sq = float(t @ t)
        beta, self.beta_max = initial_noise_precision(t, N)
        # final-beta-update tolerance: SparseBayes' 1e-6, but no finer than the rounding error
        # of the N-term sums behind beta (float32 would otherwise cycle on rounding noise)
        self.beta_tol = max(_MIN_DELTA_LOG_BETA, N * torch.finfo(dtype).eps)
        self.eps = design.screening_error()  # error bound of the cosines in B^T Phi
        # the Gram entries among active columns are products of exact columns (stored at each
        # addition), whatever precision screens the candidates
        self.gram_eps = design.product_error()
        if start is None:
            active, alpha = _initial_column(self.Bt_t, self.valid, beta, dtype)
        else:
            active, alpha, beta = _start_state(start, self.norms, self.valid, self.beta_max)
        self.active, self.alpha, self.beta = active, alpha, beta
        # the factor of the present state moved by re-estimations (None: refactorise), and the
        # estimated backward error of the factor in use, in units of gamma_{M+1}
        self.updated_fac: PrecisionFactor | None = None
        self.factor_error = 0.0
        self._fill_buffers()
        # B^T t of unit columns: a product of N terms in the design's dtype, within gamma_N ||t||
        self.bt_error = rounding_gamma(N + 8, dtype) * math.sqrt(t_sq)
        self.fac, self.mu, self.resid, self.log_ml = self.statistics()
        self.current = True  # whether fac, mu, resid are those of the present alpha, beta, basis

    def _fill_buffers(self) -> None:
        """The buffers, alignment counts, masks and carried factors of the starting basis."""
        design, norms, P, device = self.design, self.norms, self.P, self.device
        self.M = M = len(self.active)
        self.act_t = act_t = torch.tensor(self.active, dtype=torch.long, device=device)
        cap = min(P, max(_INITIAL_CAPACITY, 2 * M))
        self.Phi_buf = torch.empty(self.N, cap, dtype=design.dtype, device=device)
        self.BtPhi_buf = torch.empty(P, cap, dtype=design.dtype, device=device)
        Phi0 = design.columns(act_t) / norms[act_t]
        self.Phi_buf[:, :M] = Phi0
        self.BtPhi_buf[:, :M] = design.rmatmul(Phi0, exact=False) / norms[:, None]
        self.align = Alignment(P, device)
        for k in range(M):
            # exact Gram entries among the actives (as an addition stores them)
            self.BtPhi_buf[act_t, k] = Phi0.T @ Phi0[:, k]
            self.BtPhi_buf[self.active[k], k] = Phi0[:, k] @ Phi0[:, k]
            exact_alignment(self.BtPhi_buf[:, k], design, norms, Phi0[:, k], self.eps)
            self.align.add(self.BtPhi_buf[:, k])
        self.in_model = torch.zeros(P, dtype=torch.bool, device=device)
        self.in_model[act_t] = True
        self.position = torch.full((P,), -1, dtype=torch.long, device=device)
        self.position[act_t] = torch.arange(M, device=device)
        self.tracker = TrackedFactors(P, cap, self.unit, self.Bt_t)
        self.addable = self.addable_mask()
        self.gram = self.views()[1][self.act_t]  # B^T Phi's active rows, until the basis changes

    def addable_mask(self) -> Tensor:
        """Candidates that may be added: usable, aligned with no active column, not active."""
        return self.valid & self.align.free & ~self.in_model

    def views(self) -> tuple[Tensor, Tensor]:
        """``Phi`` and ``B^T Phi`` of the current basis (views of the buffers)."""
        return self.Phi_buf[:, : self.M], self.BtPhi_buf[:, : self.M]

    def statistics(self, fresh: bool = False) -> tuple[PrecisionFactor, Tensor, Tensor, float]:
        """Posterior from the factor of the present state: the re-estimation-updated one where
        it is within its error budget (:meth:`reestimate`) and ``fresh`` is False, else a
        fresh factorisation."""
        Phi = self.views()[0]
        act_t, alpha, beta = self.act_t, self.alpha, self.beta
        fac = self.updated_fac
        self.updated_fac = None
        if fresh or fac is None:
            fac = factor_precision(alpha, beta * self.gram)
            self.factor_error = 0.0
        mu = beta * fac.solve(self.Bt_t[act_t])
        resid = self.t - Phi @ mu
        log_ml = gaussian_log_evidence(self.N, beta, float(resid @ resid), alpha, mu, fac)
        return fac, mu, resid, log_ml

    def context(self) -> Posterior:
        """The current posterior with the bounds the carried factors need."""
        Phi_t = self.Bt_t[self.act_t]
        return posterior_context(
            self.fac, self.alpha, self.beta, self.gram, self.mu, Phi_t, self.gram_eps
        )

    def decide(self) -> tuple[Action, _ExactColumns, Posterior]:
        """The action of this iteration, on exact factors of whatever could win.

        Screening factors carried with rigorous bounds of their error (tracked_factors): the
        action is decided on exact factors of whatever could win (verification), so it does not
        depend on the BLAS code path, the thread count or how the bounds were made.
        """
        Phi, BtPhi = self.views()
        tracker, eps, bt_error, M, P = self.tracker, self.eps, self.bt_error, self.M, self.P
        post = self.context()
        exact = _ExactColumns(
            self.design,
            self.norms,
            self.fac,
            Phi,
            self.gram,
            self.position,
            self.alpha,
            self.beta,
            self.mu,
            self.resid,
        )
        choice = (self.act_t, self.alpha, self.addable, exact)
        if not tracker.usable(post):  # bounds of the fresh factor only, as a full screening
            best, _ = lazy_verified_action(*tracker.direct(post, BtPhi, eps, bt_error), *choice)
        else:
            if _REFRESH_EVERY_ITERATION:
                tracker.needs_refresh = True
            tracker.prepare(post, BtPhi)
            best, _ = lazy_verified_action(
                *tracker.screen(post, eps, bt_error),
                *choice,
                tighten=lambda idx, post=post, Z=BtPhi: tracker.tighten(
                    post, Z, idx, eps, bt_error
                ),
                budget=max(_MIN_EXACT_BUDGET, M // 4),
                tighten_budget=max(_MIN_EXACT_BUDGET, P // 8),
            )
            if best is None:  # the carried bounds have grown too loose: screen afresh
                tracker.needs_refresh = True
                tracker.prepare(post, BtPhi)
                best, _ = lazy_verified_action(*tracker.screen(post, eps, bt_error), *choice)
        assert best is not None
        return best, exact, post

    def reestimate(self, post: Posterior, best: Action) -> None:
        """Re-estimate the precision of the active column at ``best.position``."""
        self.tracker.reestimate(post, best.position, best.new_alpha)
        k, old_alpha = best.position, float(self.alpha[best.position])
        self.alpha = self.alpha.clone()
        self.alpha[k] = best.new_alpha
        self.updated_fac = self._updated_factor(k, old_alpha, best.new_alpha)

    def _updated_factor(self, k: int, old_alpha: float, new_alpha: float) -> PrecisionFactor | None:
        """The present factor moved to ``alpha_k = new_alpha`` by one compiled rank-one step,
        or None (refactorise) off CPU float64, with :data:`UPDATED_FACTOR` cleared, or when the
        estimated backward error leaves :data:`_FACTOR_ERROR_BUDGET`."""
        fac = self.fac
        L = fac.L
        if not UPDATED_FACTOR or L.device.type != "cpu" or L.dtype != torch.float64:
            return None
        L = L.clone()
        amp = reestimate_factor(L.numpy(), k, math.sqrt(old_alpha / new_alpha))
        self.factor_error += amp * amp
        if not self.factor_error <= _FACTOR_ERROR_BUDGET:
            return None
        d = fac.d.clone()
        d[k] = 1.0 / math.sqrt(new_alpha)
        return PrecisionFactor(L, d)

    def add(self, post: Posterior, exact: _ExactColumns, best: Action) -> None:
        """Add the candidate ``best.index``, from the exact column its factors came from."""
        design, norms, nu, M, P = self.design, self.norms, best.index, self.M, self.P
        Phi, BtPhi = self.views()
        if M == self.Phi_buf.shape[1]:  # grow the buffers
            cap = grown_capacity(M, M + 1, P)
            self.Phi_buf = torch.cat([self.Phi_buf, self.Phi_buf.new_empty(self.N, cap - M)], 1)
            self.BtPhi_buf = torch.cat([self.BtPhi_buf, self.BtPhi_buf.new_empty(P, cap - M)], 1)
            Phi, BtPhi = self.views()
        if nu in exact.fetched:  # the exact column its factors were computed from
            b_i, gram = exact.fetched[nu]
        else:
            b_i = design.columns([nu])[:, 0] / norms[nu]
            gram = Phi.T @ b_i
        BtBi = self.BtPhi_buf[:, M]
        BtBi.copy_(design.rmatmul(b_i[:, None], exact=False)[:, 0])
        BtBi.div_(norms)
        BtBi[self.act_t] = gram
        BtBi[nu] = b_i @ b_i
        exact_alignment(BtBi, design, norms, b_i, self.eps)
        BtPhi[nu] = gram
        self.Phi_buf[:, M] = b_i
        self.alpha = torch.cat([self.alpha, self.alpha.new_tensor([best.new_alpha])])
        self.active.append(nu)
        self.act_t = torch.cat([self.act_t, self.act_t.new_tensor([nu])])
        self.M = M = M + 1
        self.in_model[nu] = True
        self.align.add(BtBi)
        self.addable = self.addable_mask()
        self.gram = self.views()[1][self.act_t]  # B^T Phi's active rows, until the basis changes
        self.tracker.add(post, gram, float(BtBi[nu]), best.new_alpha, BtBi, float(self.Bt_t[nu]))
        self.tracker.stale.add(nu)  # its stored products became the exact Gram entries
        self.position[nu] = M - 1
        self.updated_fac = None

    def delete(self, post: Posterior, best: Action) -> None:
        """Delete the active column at ``best.position`` and close the gap in the buffers."""
        nu, jj, M = best.index, best.position, self.M
        self.tracker.delete(post, jj)
        self.position[self.act_t[jj + 1 :]] -= 1
        self.position[nu] = -1
        keep_t = torch.tensor(
            [k for k in range(M) if k != jj], dtype=torch.long, device=self.device
        )
        self.align.remove(self.BtPhi_buf[:, jj])
        self.alpha = self.alpha[keep_t]
        if jj < M - 1:  # close the gap in the buffers
            self.Phi_buf[:, jj : M - 1] = self.Phi_buf[:, jj + 1 : M].clone()
            self.BtPhi_buf[:, jj : M - 1] = self.BtPhi_buf[:, jj + 1 : M].clone()
        self.M = M - 1
        del self.active[jj]
        self.act_t = self.act_t[keep_t]
        self.in_model[nu] = False
        self.addable = self.addable_mask()
        self.gram = self.views()[1][self.act_t]  # B^T Phi's active rows, until the basis changes
        self.updated_fac = None

    def update_noise(self, last: bool) -> bool:
        """Re-estimate ``beta`` (and refactorise); returns ``last``, cleared when this was to be
        the last iteration and ``log beta`` moved by more than the tolerance."""
        tracker = self.tracker
        if not self.current:
            self.fac, self.mu, self.resid, _ = self.statistics(fresh=True)
        # the carried factors follow the noise update unless a refresh is pending anyway
        before = None if tracker.needs_refresh else self.context()
        gamma = 1.0 - self.alpha * self.fac.covariance().diagonal()
        beta_old = self.beta
        ee = float(self.resid @ self.resid)
        self.beta = reestimated_noise_precision(self.N, float(gamma.sum()), ee, self.beta_max)
        self.fac, self.mu, self.resid, self.log_ml = self.statistics(fresh=True)
        self.current = True
        if before is not None:  # and the actives' afresh (O(M^3))
            tracker.rescale(before, self.context(), _BETA_RELATIVE_REFRESH)
            tracker.stale.update(self.active)
        if last and abs(math.log(self.beta) - math.log(beta_old)) > self.beta_tol:
            last = False
        return last

    def result(self, trace: list[float], n_iter: int, converged: bool) -> SBLResult:
        """The reported posterior and evidence: exact, from a fresh factorisation."""
        if not self.current:
            self.fac, self.mu, self.resid, self.log_ml = self.statistics(fresh=True)
            trace[-1] = self.log_ml
        return result_in_caller_basis(
            torch.tensor(self.active, device=self.device),
            self.mu,
            self.fac.covariance(),
            self.alpha,
            self.norms,
            beta=self.beta,
            trace=trace,
            log_ml=self.log_ml,
            n_iter=n_iter,
            converged=converged,
        )

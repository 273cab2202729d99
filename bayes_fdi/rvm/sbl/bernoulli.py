"""Tipping & Faul's fast sequential marginal-likelihood maximisation for the Bernoulli
likelihood with the Laplace approximation (:func:`fast_bernoulli`).

Tipping & Faul 2003, "Fast marginal likelihood maximisation for sparse Bayesian models"
(AISTATS), as realised in SparseBayes v2: after every action the posterior mode is re-found
(:mod:`bayes_fdi.rvm.sbl.laplace`) and the candidates screened afresh
(:mod:`bayes_fdi.rvm.sbl.screening`); the action is decided on exact factors
(:mod:`bayes_fdi.rvm.sbl.verification`).

Imports the solver family's numerics, decisions and Laplace approximation (not the other
solvers). Written by hand: no maintained library implements it.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from bayes_fdi.rvm.sbl.alignment import Alignment, exact_alignment
from bayes_fdi.rvm.sbl.decisions import Action
from bayes_fdi.rvm.sbl.design import Design
from bayes_fdi.rvm.sbl.laplace import LaplaceMode, posterior_mode
from bayes_fdi.rvm.sbl.residual_factors import weighted_exact_factors
from bayes_fdi.rvm.sbl.result import SBLResult, result_in_caller_basis, unit_columns
from bayes_fdi.rvm.sbl.screening import screened_factors
from bayes_fdi.rvm.sbl.verification import optimistic_ratio, verified_action, verified_argmax

__all__ = ["fast_bernoulli"]

# Bernoulli fast solver: stop when the Laplace evidence has not risen by _STALL_GAIN
# for _STALL_ITERATIONS iterations (not in SparseBayes, which cycles until its limit)
_STALL_GAIN = 1e-4
_STALL_ITERATIONS = 50


def fast_bernoulli(
    design: Design,
    t: Tensor,
    *,
    max_iter: int = 10000,
    tol: float = 1e-3,
) -> SBLResult:
    """Tipping & Faul fast marginal-likelihood maximisation, Bernoulli likelihood (Laplace).

    After every action the posterior mode is re-found (to rounding level, see
    :func:`~bayes_fdi.rvm.sbl.laplace.posterior_mode`) and ``S, Q`` are recomputed in full
    (``S_m = b^T W b - b^T W Phi Sigma Phi^T W b``, ``Q_m = b^T (t - y)``) to screen the
    candidates; the action is then chosen on the actives' and the contending candidates'
    factors recomputed in residual form
    (:func:`~bayes_fdi.rvm.sbl.verification.verified_action` with
    :func:`~bayes_fdi.rvm.sbl.residual_factors.weighted_exact_factors`), with the same tie and
    stopping rules as :func:`~bayes_fdi.rvm.sbl.gaussian.fast_gaussian`.

    The gains are exact only for the Gaussian approximation at the current mode; when the
    data are (nearly) separable some ``alpha`` head to zero and the actions can cycle with
    the Laplace evidence going up and down.  Beyond SparseBayes, the solver therefore stops
    when the evidence has not improved by 1e-4 for 50 iterations and returns the best model
    seen (its trace then ends with that model's evidence). Where the basis separates the
    classes so completely that an action's precision underflows to 0 (seen with wide RBF
    kernels: every training target predicted to within rounding), it stops there too, at the
    best model seen, instead of adding a column whose weight would be unbounded.

    Parameters
    ----------
    design : Design
        The candidate basis ``B``.
    t : Tensor
        ``(N,)`` targets in ``{0, 1}``.
    max_iter, tol
        As in :func:`~bayes_fdi.rvm.sbl.gaussian.fast_gaussian`.
    """
    run = _FastBernoulliRun(design, t)
    mode = run.mode
    trace = [mode.log_ml]
    best = (mode.log_ml, 0, list(run.active), run.alpha.clone())
    converged = False
    it = 0
    for it in range(1, max_iter + 1):
        act_t = torch.tensor(run.active, dtype=torch.long, device=design.device)
        exact = _LaplaceColumns(design, run.norms, mode, run.Phi, act_t, run.alpha, t)
        addable = run.valid & run.align.free & ~run.in_model
        choice, _ = verified_action(
            run.S, run.Q, act_t, run.alpha, addable, exact, optimistic=run.x_opt
        )
        if not choice.gain > 0:
            converged = True
            break
        if choice.kind != 2 and not 0.0 < choice.new_alpha < math.inf:
            # A precision of 0 (underflow): the basis separates the classes, every weight
            # y (1 - y) has underflowed and the mode would run off to infinity. Stop at the
            # best model seen.
            converged = True
            break
        if choice.kind == 1 and (
            abs(math.log(choice.new_alpha) - math.log(float(run.alpha[choice.position]))) < tol
        ):
            converged = True
            break
        run.act(choice, exact)
        mode = run.mode
        trace.append(mode.log_ml)
        if mode.log_ml > best[0] + _STALL_GAIN:
            best = (mode.log_ml, it, list(run.active), run.alpha.clone())
        elif it - best[1] >= _STALL_ITERATIONS:
            # The Laplace evidence has stopped improving: the Gaussian-approximation gains
            # cycle (typically a nearly separating basis with alpha -> 0).  Stop at the best.
            converged = True
            break

    active, alpha = run.active, run.alpha
    if best[0] > mode.log_ml + _STALL_GAIN:
        active, alpha = best[2], best[3]
        Phi = design.columns(active) / run.norms[torch.tensor(active, device=design.device)]
        mode = posterior_mode(Phi, t, alpha, torch.zeros_like(alpha))
        trace.append(mode.log_ml)
    return result_in_caller_basis(
        torch.tensor(active, device=design.device),
        mode.mu,
        mode.Sigma,
        alpha,
        run.norms,
        beta=math.nan,
        trace=trace,
        log_ml=mode.log_ml,
        n_iter=it,
        converged=converged,
    )


class _LaplaceColumns:
    """``idx -> (S_idx, Q_idx)`` in residual form
    (:func:`~bayes_fdi.rvm.sbl.residual_factors.weighted_exact_factors`) at the fast Bernoulli
    solver's current mode; keeps the fetched columns (an addition reuses them)."""

    def __init__(
        self,
        design: Design,
        norms: Tensor,
        mode: LaplaceMode,
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


class _FastBernoulliRun:
    """The state of one :func:`fast_bernoulli` run: the active columns ``Phi`` (in active
    order) and their screened products ``B^T Phi``, the precisions, the alignment counts, and
    the mode with the screening factors of every candidate (:meth:`screen`)."""

    def __init__(self, design: Design, t: Tensor) -> None:
        P, device = design.n_basis, design.device
        self.design, self.t = design, t
        self.norms, self.valid = norms, valid = unit_columns(design)
        tp = 2.0 * t - 1.0
        Bt_tp = design.rmatmul(tp[:, None], exact=False)[:, 0] / norms
        # the initial column: largest |b^T tp|, decided on exact products near the screened top
        self.eps = eps = design.screening_error()  # error bound of screened cosines (unit vectors)
        top = float(torch.where(valid, Bt_tp.abs(), 0.0).max())
        j = verified_argmax(
            Bt_tp,
            valid,
            lambda idx: (design.columns(idx) / norms[idx]).T @ tp,
            relative=eps * math.sqrt(t.numel()) / max(top, 1e-300),  # ||tp|| = sqrt(N)
        )
        self.Phi = Phi = design.columns([j]) / norms[j]
        target = (tp * 0.9 + 1.0) / 2.0
        logit = torch.log(target / (1.0 - target))
        mu = torch.linalg.lstsq(Phi, logit[:, None]).solution[:, 0]
        self.alpha = (1.0 / (mu * mu).clamp_min(1e-300)).clamp(1e-3, 1e3)
        self.active = [j]
        self.BtPhi = design.rmatmul(Phi, exact=False) / norms[:, None]
        self.in_model = torch.zeros(P, dtype=torch.bool, device=device)
        self.in_model[j] = True
        self.align = Alignment(P, device)
        exact_alignment(self.BtPhi[:, 0], design, norms, Phi[:, 0], eps)
        self.align.add(self.BtPhi[:, 0])
        self.screen(mu)

    def screen(self, mu: Tensor) -> None:
        """The mode (from ``mu``), the screening factors ``S, Q`` (textbook form, possibly from
        float32 products) and bounds of their exact ``Q^2/S``
        (:func:`~bayes_fdi.rvm.sbl.verification.optimistic_ratio`)."""
        design, t, norms, eps, Phi = self.design, self.t, self.norms, self.eps, self.Phi
        mode = posterior_mode(Phi, t, self.alpha, mu)
        V = torch.cat([mode.w[:, None] * Phi, (t - mode.y)[:, None]], dim=1)
        BtV = design.rmatmul(V, exact=False) / norms[:, None]
        BtWPhi, Q = BtV[:, :-1], BtV[:, -1]
        # each product is within eps * ||v|| of the exact one (unit columns); the weighted
        # squared norms (B * B)^T w / ||b||^2 of positive terms within eps * max(w)
        v_norms = torch.linalg.vector_norm(V, dim=0)
        screening = screened_factors(
            mode.fac,
            torch.diag(self.alpha) + 0.5 * (mode.G + mode.G.T),
            BtWPhi,
            design.sq_rmatmul(mode.w, exact=False) / norms**2,
            z_error=eps * v_norms[:-1],
            diag_error=eps * float(mode.w.max()),
        )
        S, S_err = screening.S, screening.S_error
        Q_err = eps * float(v_norms[-1]) + 4.0 * eps * Q.abs()  # + rounding of the division
        self.mode, self.S, self.Q = mode, S, Q
        self.x_opt = optimistic_ratio(S, Q, S_err, Q_err)

    def act(self, choice: Action, exact: _LaplaceColumns) -> None:
        """Take the action ``choice`` (re-estimate, add or delete), then :meth:`screen`."""
        design, norms, mode = self.design, self.norms, self.mode
        nu, jj = choice.index, choice.position
        if choice.kind == 1:
            self.alpha = self.alpha.clone()
            self.alpha[jj] = choice.new_alpha
            mu = mode.mu
        elif choice.kind == 0:
            b_i = exact.fetched[nu][:, None]  # the exact column its factors were computed from
            BtBi = design.rmatmul(b_i, exact=False)[:, 0] / norms
            exact_alignment(BtBi, design, norms, b_i[:, 0], self.eps)
            a_new = choice.new_alpha
            mu_i = float(self.Q[nu]) / (a_new + float(self.S[nu]))
            self.Phi = torch.cat([self.Phi, b_i], dim=1)
            self.BtPhi = torch.cat([self.BtPhi, BtBi[:, None]], dim=1)
            self.alpha = torch.cat([self.alpha, self.alpha.new_tensor([a_new])])
            mu = torch.cat([mode.mu, mode.mu.new_tensor([mu_i])])
            self.active.append(nu)
            self.in_model[nu] = True
            self.align.add(BtBi)
        else:
            keep = [k for k in range(len(self.active)) if k != jj]
            keep_t = torch.tensor(keep, device=design.device)
            self.align.remove(self.BtPhi[:, jj])
            self.Phi, self.BtPhi = self.Phi[:, keep_t], self.BtPhi[:, keep_t]
            self.alpha, mu = self.alpha[keep_t], mode.mu[keep_t]
            del self.active[jj]
            self.in_model[nu] = False
        self.screen(mu)

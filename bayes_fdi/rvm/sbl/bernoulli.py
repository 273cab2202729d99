"""Tipping & Faul's fast sequential marginal-likelihood maximisation for the Bernoulli
likelihood (:func:`fast_bernoulli`, Laplace approximation) and the posterior mode it needs
(:func:`posterior_mode`, Newton's method to rounding level).

Written by hand: no maintained library implements it (``shared/reference/fast-sbl.md``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
from torch import Tensor

from bayes_fdi.rvm.sbl.design import Design
from bayes_fdi.rvm.sbl.decisions import (
    optimistic_ratio,
    screened_factors,
    verified_action,
    verified_argmax,
    weighted_exact_factors,
)
from bayes_fdi.rvm.sbl.precision_factor import (
    SBLResult,
    _Alignment,
    _exact_alignment,
    _Factor,
    _factor,
    _result,
    _unit_columns,
)

__all__ = ["fast_bernoulli", "posterior_mode"]

_POSTERIOR_MODE_ITS = 50
# Newton decrement g^T H^-1 g below which the posterior-mode iteration takes full steps
# (quadratic regime), and below which (relative to 1 + |log posterior|) it stops
_MODE_QUADRATIC = 1e-8
_MODE_FLOOR = 1e-24
_LINE_SEARCH_MIN_STEP = 2.0**-8
# Bernoulli fast solver: stop when the Laplace evidence has not risen by _STALL_GAIN
# for _STALL_ITERATIONS iterations (not in SparseBayes, which cycles until its limit)
_STALL_GAIN = 1e-4
_STALL_ITERATIONS = 50


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
        screening = screened_factors(
            mode.fac,
            torch.diag(alpha) + 0.5 * (mode.G + mode.G.T),
            BtWPhi,
            design.sq_rmatmul(mode.w, exact=False) / norms**2,
            z_error=eps * v_norms[:-1],
            diag_error=eps * float(mode.w.max()),
        )
        S, S_err = screening.S, screening.S_error
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

r"""The fast solver's action chosen on exact factors, looking exactly only at the actions that
could win (:func:`lazy_verified_action`).

Written by hand (no maintained library implements Tipping & Faul's solver). Given screened
factors ``S, Q`` of every column -- active or not -- with rigorous bounds of their error
(:mod:`bayes_fdi.rvm.sbl.tracked_factors`), each action's evidence gain is bounded from above:

* an **addition** by the largest ``Q^2/S`` the bounds allow
  (:func:`bayes_fdi.rvm.sbl.decisions.optimistic_ratio`);
* a **re-estimation** of active ``j`` by the gain written as
  ``2 Delta L = v - 1 - log v`` with ``v = Q^2 / S`` (:func:`reestimate_gain_bounds`), whose
  largest value over the box of ``(S, |Q|)`` is at one of its corners;
* whether active ``j`` is still *useful* (``q^2 - s > 0``, else a deletion is pending) by the
  sign of ``alpha Q^2 - S (alpha - S)`` over the box.

Actives whose usefulness is uncertain are recomputed exactly at once (deletions pre-empt, so
they must be known). Then, round by round, every action whose upper bound reaches the best
exact gain (minus the tie band of :func:`~bayes_fdi.rvm.sbl.decisions.lowest_index_in_band`) is
recomputed exactly, until none is left. The chosen action is therefore the one
:func:`~bayes_fdi.rvm.sbl.decisions.best_action` picks on exact factors of every column, as in
:func:`~bayes_fdi.rvm.sbl.decisions.verified_action`, at the cost of a few exact columns per
iteration instead of all ``M`` actives.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch
from torch import Tensor

from bayes_fdi.rvm.sbl.decisions import (
    NEGLIGIBLE_GAIN,
    TIE_RELATIVE,
    ZERO_FACTOR,
    Action,
    _ratio_of_gain,
    best_action,
    optimistic_ratio,
)

__all__ = ["lazy_verified_action", "reestimate_gain_bounds", "useful_lower_bound"]

#: relative slack on the bounds for the rounding of their own evaluation
_SLACK = 1e-12


def _box(S: Tensor, S_err: Tensor, Q: Tensor, Q_err: Tensor):
    S_lo = (S - S_err).clamp_min(0.0)
    S_hi = S + S_err
    Qa_lo = (Q.abs() - Q_err).clamp_min(0.0)
    Qa_hi = Q.abs() + Q_err
    return S_lo, S_hi, Qa_lo, Qa_hi


def _product_max(S_lo: Tensor, S_hi: Tensor, alpha: Tensor) -> Tensor:
    """Largest ``S (alpha - S)`` over ``[S_lo, S_hi]`` (concave, top at ``alpha / 2``)."""
    half = 0.5 * alpha
    inside = (S_lo <= half) & (half <= S_hi)
    ends = torch.maximum(S_lo * (alpha - S_lo), S_hi * (alpha - S_hi))
    return torch.where(inside, half * half, ends)


def _ratio_gain(v: Tensor) -> Tensor:
    """``(v - 1 - log v) / 2``: the gain of moving a precision to its optimum (re-estimation)
    or from infinity (addition, ``v = Q^2 / S``)."""
    v = v.clamp_min(torch.finfo(v.dtype).tiny)
    return 0.5 * ((v - 1.0) - torch.log(v))


def useful_lower_bound(S: Tensor, S_err: Tensor, Q: Tensor, Q_err: Tensor, alpha: Tensor) -> Tensor:
    """Lower bound of ``theta = q^2 - s = alpha f / (alpha - S)^2`` with
    ``f = alpha Q^2 - S (alpha - S)``, for active columns (``-inf`` where unknown)."""
    S_lo, S_hi, Qa_lo, _ = _box(S, S_err, Q, Q_err)
    prod_hi = _product_max(S_lo, S_hi, alpha)
    f_lo = alpha * Qa_lo * Qa_lo - prod_hi
    f_lo = f_lo - _SLACK * (alpha * Qa_lo * Qa_lo + prod_hi)
    ok = S_hi < alpha
    low = torch.where(
        f_lo > 0, alpha * f_lo / (alpha - S_lo).square(), alpha * f_lo / (alpha - S_hi).square()
    )
    return torch.where(ok, low, -math.inf)


def reestimate_gain_bounds(S: Tensor, S_err: Tensor, Q: Tensor, Q_err: Tensor) -> Tensor:
    """Upper bound of the re-estimation gain ``Delta L`` of useful active columns.

    Moving ``alpha`` of an active column to its optimum gains ``(v - 1 - log v) / 2`` with
    ``v = Q^2 / S`` (the factors with the column included; with ``s = alpha S / (alpha - S)``,
    ``q = alpha Q / (alpha - S)`` this is ``v = alpha q^2 / (s (alpha + s))``), a convex
    function of ``v`` with its minimum 0 at ``v = 1``: over the box of ``(S, |Q|)`` its largest
    value is at an end of ``[Q_lo^2 / S_hi, Q_hi^2 / S_lo]``. ``inf`` where ``S`` may be 0.
    """
    S_lo, S_hi, Qa_lo, Qa_hi = _box(S, S_err, Q, Q_err)
    ok = S_lo > 0
    v_lo = Qa_lo * Qa_lo / S_hi
    v_hi = torch.where(ok, Qa_hi * Qa_hi / torch.where(ok, S_lo, 1.0), 1.0)
    ub = torch.maximum(_ratio_gain(v_lo), _ratio_gain(v_hi))
    ub = ub + _SLACK * (ub + 1e-300) + 1e-15 * (v_hi - v_lo).abs()
    return torch.where(ok, ub, math.inf)


def lazy_verified_action(
    S: Tensor,
    Q: Tensor,
    S_err: Tensor,
    Q_err: Tensor,
    act: Tensor,
    alpha: Tensor,
    addable: Tensor,
    exact: Callable[[Tensor], tuple[Tensor, Tensor]],
    *,
    tighten: Callable[[Tensor], tuple[Tensor, ...]] | None = None,
    shortlist: int = 64,
    budget: int | None = None,
    tighten_budget: int | None = None,
) -> tuple[Action | None, int]:
    """The best action on exact factors, recomputing only what could win (module docstring).

    Parameters
    ----------
    S, Q, S_err, Q_err : Tensor
        ``(N_B,)`` screened factors of every column and bounds of their error; overwritten
        where tightened or recomputed exactly (exact values get a zero bound).
    act, alpha, addable
        As in :func:`~bayes_fdi.rvm.sbl.decisions.best_action`.
    exact : callable
        ``idx -> (S_idx, Q_idx)`` exact factors of basis columns (active or not).
    tighten : callable, optional
        ``idx -> (S, Q, S_err, Q_err)`` of those columns with tighter bounds, cheaper than
        ``exact`` (the carried factors of a few rows recomputed from the fresh factor). A column
        that could win is tightened first, and recomputed exactly only if it still could.
    shortlist : int
        At most this many columns are tightened or recomputed per round.
    budget, tighten_budget : int, optional
        Give up (``action`` None) rather than recompute exactly (tighten) more than this many
        columns in one round: the caller's bounds are too loose to be worth using.

    Returns
    -------
    action : Action or None
    n_exact : int
        Number of columns recomputed exactly.
    """
    P = S.numel()
    verified = torch.zeros(P, dtype=torch.bool, device=S.device)
    tightened = torch.zeros(P, dtype=torch.bool, device=S.device)
    n_exact = 0

    def recompute(idx: Tensor) -> None:
        nonlocal n_exact
        S[idx], Q[idx] = exact(idx)
        S_err[idx], Q_err[idx] = 0.0, 0.0
        verified[idx] = True
        tightened[idx] = True
        n_exact += idx.numel()

    def look(idx: Tensor, likely: int = -1) -> bool:
        """Tighten the columns not yet tightened, else recompute exactly; the ``likely``
        winner (the best on screened values) is recomputed at once. False: over budget."""
        idx = idx.sort().values
        if tighten is not None:
            loose = idx[~tightened[idx]]
            if loose.numel():
                if tighten_budget is not None and loose.numel() > tighten_budget:
                    return False
                if likely >= 0 and bool((loose == likely).any()):
                    recompute(loose.new_tensor([likely]))
                    loose = loose[loose != likely]
                if loose.numel():
                    S[loose], Q[loose], S_err[loose], Q_err[loose] = tighten(loose)
                    tightened[loose] = True
                return True
        if budget is not None and idx.numel() > budget:
            return False
        recompute(idx)
        return True

    while True:
        if act.numel() > 1:  # deletions pre-empt: possibly useless actives are looked at first
            theta_lo = useful_lower_bound(S[act], S_err[act], Q[act], Q_err[act], alpha)
            unsure = act[~verified[act] & ~(theta_lo > ZERO_FACTOR)]
            if unsure.numel():
                if not look(unsure):
                    return None, n_exact
                continue
        best = best_action(S, Q, act, alpha, addable)
        if best.kind == 2:
            return best, n_exact
        g = best.gain if best.kind >= 0 else NEGLIGIBLE_GAIN
        band = g - TIE_RELATIVE * abs(g) if best.kind >= 0 else NEGLIGIBLE_GAIN
        # re-estimations that could reach the band
        un_a = ~verified[act]
        re_ub = reestimate_gain_bounds(S[act], S_err[act], Q[act], Q_err[act])
        reach = un_a & (re_ub >= band)
        cand_a, ub_a = act[reach], re_ub[reach]
        # additions that could reach it
        x = torch.where(addable & ~verified, optimistic_ratio(S, Q, S_err, Q_err), 0.0)
        cand_n = (x >= _ratio_of_gain(band) * (1.0 - 1e-8)).nonzero().squeeze(1)
        if cand_a.numel() + cand_n.numel() == 0:
            return best, n_exact
        cand = torch.cat([cand_a, cand_n])
        limit = shortlist if tighten is None else max(shortlist, tighten_budget or 0)
        if cand.numel() > limit:  # the most promising first: by upper bound of the gain
            xn = x[cand_n]
            ub_n = torch.where(torch.isfinite(xn), _ratio_gain(xn.clamp_min(1.0)), math.inf)
            cand = cand[torch.topk(torch.cat([ub_a, ub_n]), limit).indices]
        likely = best.index if best.kind >= 0 and not bool(verified[best.index]) else -1
        if not look(cand, likely):
            return None, n_exact

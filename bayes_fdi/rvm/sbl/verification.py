r"""The fast solvers' action chosen on exact factors from screened ones with error bounds.

Rules 2 and 4 of :mod:`bayes_fdi.rvm.sbl.decisions`. Given screened factors ``S, Q`` of every
column -- active or not -- with rigorous bounds of their error
(:mod:`bayes_fdi.rvm.sbl.screening`, :mod:`bayes_fdi.rvm.sbl.tracked_factors`), each action's
evidence gain is bounded from above:

* an **addition** by the largest ``Q^2/S`` the bounds allow (:func:`optimistic_ratio`);
* a **re-estimation** of active ``j`` by the gain written as
  ``2 Delta L = v - 1 - log v`` with ``v = Q^2 / S`` (:func:`reestimate_gain_bounds`), whose
  largest value over the box of ``(S, |Q|)`` is at one of its corners;
* whether active ``j`` is still *useful* (``q^2 - s > 0``, else a deletion is pending) by the
  sign of ``alpha Q^2 - S (alpha - S)`` over the box (:func:`useful_lower_bound`).

:func:`verified_action` recomputes the actives' factors and those of every addition candidate
that could win. :func:`lazy_verified_action` looks exactly only at the actions that could win:
actives whose usefulness is uncertain are recomputed exactly at once (deletions pre-empt, so
they must be known); then, round by round, every action whose upper bound reaches the best
exact gain (minus the tie band of :func:`~bayes_fdi.rvm.sbl.decisions.lowest_index_in_band`) is
recomputed exactly, until none is left. Either way the chosen action is the one
:func:`~bayes_fdi.rvm.sbl.decisions.best_action` picks on exact factors of every column.
:func:`verified_argmax` and :func:`exact_near_threshold` decide an arg-max and a threshold test
on exact values the same way.

Imports :mod:`~bayes_fdi.rvm.sbl.decisions` only. Written by hand: no maintained library
implements Tipping & Faul's solver, let alone these safeguards.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch
from torch import Tensor

from bayes_fdi.rvm.sbl.action_kernels import (
    best_action_kernel,
    round_candidates,
    unsure_actives,
)
from bayes_fdi.rvm.sbl.decisions import (
    NEGLIGIBLE_GAIN,
    TIE_RELATIVE,
    ZERO_FACTOR,
    Action,
    best_action,
    lowest_index_in_band,
)

__all__ = [
    "COMPILED_RULES",
    "SHORTLIST_MAX",
    "exact_near_threshold",
    "lazy_verified_action",
    "optimistic_ratio",
    "reestimate_gain_bounds",
    "useful_lower_bound",
    "verified_action",
    "verified_argmax",
]

#: At most this many addition candidates are recomputed exactly per round of verification.
SHORTLIST_MAX = 64
#: Decide with the compiled rules (:mod:`~bayes_fdi.rvm.sbl.action_kernels`) on CPU float64
#: factors; tests clear it to compare with the torch rules.
COMPILED_RULES = True
#: relative slack on the bounds for the rounding of their own evaluation
_SLACK = 1e-12


def verified_argmax(
    screened: Tensor,
    usable: Tensor,
    exact: Callable[[Tensor], Tensor],
    *,
    relative: float,
) -> int:
    """Index of the largest ``|value|`` among ``usable`` entries, decided on exact values.

    ``screened`` holds approximate values (e.g. float32 products) accurate to ``relative`` of
    the largest magnitude; every usable entry within that distance of the top is recomputed by
    ``exact`` (``idx -> values``) and the winner is chosen by
    :func:`~bayes_fdi.rvm.sbl.decisions.lowest_index_in_band`.
    """
    mag = torch.where(usable, screened.abs(), -1.0)
    top = float(mag.max())
    near = (usable & (mag >= top * (1.0 - 2.0 * relative))).nonzero().squeeze(1)
    exact_mag = exact(near).abs()
    return int(near[lowest_index_in_band(exact_mag, near)])


def exact_near_threshold(
    screened: Tensor,
    threshold: float,
    exact: Callable[[Tensor], Tensor],
    *,
    relative: float,
) -> Tensor:
    """Recompute (in place) the entries of ``screened`` whose magnitude is within ``relative``
    (relative) of ``threshold`` by ``exact`` (``idx -> values``), so that a test
    ``|value| > threshold`` (the alignment test) is decided on exact values. Returns
    ``screened``.
    """
    near = ((screened.abs() - threshold).abs() <= relative * threshold).nonzero().squeeze(1)
    if near.numel():
        screened[near] = exact(near)
    return screened


def optimistic_ratio(S: Tensor, Q: Tensor, S_error: Tensor, Q_error: Tensor) -> Tensor:
    """The largest ``Q^2/S`` consistent with screened factors and their error bounds:
    ``(|Q| + Q_error)^2 / (S - S_error)``, ``inf`` where ``S - S_error <= 0``."""
    low = S - S_error
    high = (Q.abs() + Q_error).square()
    return torch.where(low > 0, high / low.clamp_min(torch.finfo(S.dtype).tiny), math.inf)


def verified_action(
    S: Tensor,
    Q: Tensor,
    act: Tensor,
    alpha: Tensor,
    addable: Tensor,
    exact: Callable[[Tensor], tuple[Tensor, Tensor]],
    *,
    optimistic: Tensor,
) -> tuple[Action, int]:
    """The best action chosen on exactly recomputed factors (rule 2 of
    :mod:`bayes_fdi.rvm.sbl.decisions`).

    The actives' factors and those of every addition candidate that could still win are
    recomputed by ``exact`` and written into ``S, Q`` (in place); candidates are verified in
    rounds, best bound first, until no unverified candidate's ``optimistic`` ratio (an upper
    bound of its exact ``Q^2/S`` from the error bounds of its screened factors,
    :func:`optimistic_ratio`) reaches the best verified gain. The choice is therefore the one
    on exact factors, whatever the rounding of the screening.

    Parameters
    ----------
    S, Q : Tensor
        ``(N_B,)`` screened factors, overwritten with exact values where recomputed.
    act, alpha, addable
        As in :func:`~bayes_fdi.rvm.sbl.decisions.best_action`.
    exact : callable
        ``idx -> (S_idx, Q_idx)``, the exact factors of the basis columns ``idx``
        (see :func:`~bayes_fdi.rvm.sbl.residual_factors.exact_factors`).
    optimistic : Tensor
        ``(N_B,)`` upper bounds of the exact ``Q^2/S`` of the candidates (``inf``: unknown).

    Returns
    -------
    action : Action
    n_verified : int
        Number of addition candidates recomputed exactly.
    """

    def refresh(idx: Tensor) -> None:
        S[idx], Q[idx] = exact(idx)

    refresh(act)
    verified = torch.zeros_like(addable)
    verified[act] = True
    n_verified = 0
    cleared = math.inf  # a gain that no unverified candidate could reach
    while True:
        best = best_action(S, Q, act, alpha, addable)
        if best.kind == 2:  # deletions pre-empt: additions cannot change the choice
            return best, n_verified
        if best.gain >= cleared:
            return best, n_verified  # the verified best still beats every unverified one
        x = torch.where(addable & ~verified, optimistic, 0.0)
        # optimistic gain above the best verified one (or above nothing when none applies);
        # the factor 1 - 1e-8 keeps candidates in the tie band of the best
        g = best.gain if best.kind >= 0 else NEGLIGIBLE_GAIN
        cand = (x >= _ratio_of_gain(g) * (1.0 - 1e-8)).nonzero().squeeze(1)
        if cand.numel() == 0:
            return best, n_verified
        cleared = g
        if cand.numel() > SHORTLIST_MAX:
            cand = cand[torch.topk(x[cand], SHORTLIST_MAX).indices]
            cleared = math.inf  # candidates above the cut remain unverified
        cand = cand.sort().values
        refresh(cand)
        verified[cand] = True
        n_verified += cand.numel()


def _ratio_of_gain(g: float) -> float:
    """The ``x > 1`` with ``(x - 1 - log x) / 2 = g`` (Newton, from above; exact to ~1e-15)."""
    if g <= 0:
        return 1.0
    x = 2.0 * g + 1.0 + math.log(2.0 * g + 1.0) + 1.0  # above the root
    for _ in range(60):
        f = 0.5 * (x - 1.0 - math.log(x)) - g
        step = f / (0.5 * (1.0 - 1.0 / x))
        x -= step
        if abs(step) <= 1e-15 * x:
            break
    return x


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
    looked = _Looked(S, Q, S_err, Q_err, exact, tighten, budget, tighten_budget)
    verified = looked.verified
    arrays = _cpu_arrays(S, Q, S_err, Q_err, act, alpha, addable, verified)
    while True:
        if act.numel() > 1:  # deletions pre-empt: possibly useless actives are looked at first
            if arrays is not None:  # the compiled rule (action_kernels)
                Sn, Qn, Sen, Qen, actn, alphan, _, vn = arrays
                unsure = torch.from_numpy(unsure_actives(Sn, Sen, Qn, Qen, actn, alphan, vn))
            else:
                theta_lo = useful_lower_bound(S[act], S_err[act], Q[act], Q_err[act], alpha)
                unsure = act[~verified[act] & ~(theta_lo > ZERO_FACTOR)]
            if unsure.numel():
                if not looked.look(unsure):
                    return None, looked.n_exact
                continue
        best = _best_action(S, Q, act, alpha, addable, arrays)
        if best.kind == 2:
            return best, looked.n_exact
        g = best.gain if best.kind >= 0 else NEGLIGIBLE_GAIN
        band = g - TIE_RELATIVE * abs(g) if best.kind >= 0 else NEGLIGIBLE_GAIN
        ratio = _ratio_of_gain(band) * (1.0 - 1e-8)
        if arrays is not None:
            Sn, Qn, Sen, Qen, actn, _, addn, vn = arrays
            cand_np, ub_np = round_candidates(Sn, Qn, Sen, Qen, actn, addn, vn, band, ratio)
            cand, ub = torch.from_numpy(cand_np), torch.from_numpy(ub_np)
        else:
            cand, ub = _round_candidates(S, Q, S_err, Q_err, act, addable, verified, band, ratio)
        if cand.numel() == 0:
            return best, looked.n_exact
        limit = shortlist if tighten is None else max(shortlist, tighten_budget or 0)
        if cand.numel() > limit:  # the most promising first: by upper bound of the gain
            cand = cand[torch.topk(ub, limit).indices]
        likely = best.index if best.kind >= 0 and not bool(verified[best.index]) else -1
        if not looked.look(cand, likely):
            return None, looked.n_exact


def _round_candidates(
    S: Tensor,
    Q: Tensor,
    S_err: Tensor,
    Q_err: Tensor,
    act: Tensor,
    addable: Tensor,
    verified: Tensor,
    band: float,
    ratio: float,
) -> tuple[Tensor, Tensor]:
    """One round's candidates (torch; :func:`~bayes_fdi.rvm.sbl.action_kernels.round_candidates`
    on CPU float64): unverified re-estimations whose gain could reach ``band``, then unverified
    additions whose optimistic ratio reaches ``ratio``, with upper bounds of their gains."""
    re_ub = reestimate_gain_bounds(S[act], S_err[act], Q[act], Q_err[act])
    reach = ~verified[act] & (re_ub >= band)
    x = torch.where(addable & ~verified, optimistic_ratio(S, Q, S_err, Q_err), 0.0)
    cand_n = (x >= ratio).nonzero().squeeze(1)
    xn = x[cand_n]
    ub_n = torch.where(torch.isfinite(xn), _ratio_gain(xn.clamp_min(1.0)), math.inf)
    return torch.cat([act[reach], cand_n]), torch.cat([re_ub[reach], ub_n])


def _cpu_arrays(*tensors: Tensor) -> tuple | None:
    """NumPy views of the decision's tensors (sharing memory) when the compiled rules apply:
    CPU, float64 factors; None otherwise (torch rules, any device or dtype)."""
    if not COMPILED_RULES or tensors[0].dtype != torch.float64:
        return None
    if any(t.device.type != "cpu" for t in tensors):
        return None
    if tensors[5].dtype != torch.float64:
        return None
    return tuple(t.numpy() for t in tensors)


def _best_action(
    S: Tensor, Q: Tensor, act: Tensor, alpha: Tensor, addable: Tensor, arrays: tuple | None
) -> Action:
    """:func:`~bayes_fdi.rvm.sbl.decisions.best_action`, compiled on CPU float64 arrays."""
    if arrays is None or act.numel() == 0:
        return best_action(S, Q, act, alpha, addable)
    Sn, Qn, _, _, actn, alphan, addn, _ = arrays
    index, gain, kind, new_alpha, position, any_delete = best_action_kernel(
        Sn, Qn, actn, alphan, addn
    )
    return Action(
        int(index), float(gain), int(kind), float(new_alpha), int(position), bool(any_delete)
    )


class _Looked:
    """The columns one :func:`lazy_verified_action` has tightened or recomputed exactly; their
    new factors and bounds are written into the caller's ``S, Q, S_err, Q_err``."""

    def __init__(
        self,
        S: Tensor,
        Q: Tensor,
        S_err: Tensor,
        Q_err: Tensor,
        exact: Callable[[Tensor], tuple[Tensor, Tensor]],
        tighten: Callable[[Tensor], tuple[Tensor, ...]] | None,
        budget: int | None,
        tighten_budget: int | None,
    ) -> None:
        P = S.numel()
        self.S, self.Q, self.S_err, self.Q_err = S, Q, S_err, Q_err
        self.exact, self.tighten = exact, tighten
        self.budget, self.tighten_budget = budget, tighten_budget
        self.verified = torch.zeros(P, dtype=torch.bool, device=S.device)
        self.tightened = torch.zeros(P, dtype=torch.bool, device=S.device)
        self.n_exact = 0

    def recompute(self, idx: Tensor) -> None:
        """Recompute the columns ``idx`` exactly (their bounds become 0)."""
        self.S[idx], self.Q[idx] = self.exact(idx)
        self.S_err[idx], self.Q_err[idx] = 0.0, 0.0
        self.verified[idx] = True
        self.tightened[idx] = True
        self.n_exact += idx.numel()

    def look(self, idx: Tensor, likely: int = -1) -> bool:
        """Tighten the columns not yet tightened, else recompute exactly; the ``likely``
        winner (the best on screened values) is recomputed at once. False: over budget."""
        idx = idx.sort().values
        if self.tighten is not None:
            loose = idx[~self.tightened[idx]]
            if loose.numel():
                if self.tighten_budget is not None and loose.numel() > self.tighten_budget:
                    return False
                if likely >= 0 and bool((loose == likely).any()):
                    self.recompute(loose.new_tensor([likely]))
                    loose = loose[loose != likely]
                if loose.numel():
                    S, Q, S_err, Q_err = self.S, self.Q, self.S_err, self.Q_err
                    S[loose], Q[loose], S_err[loose], Q_err[loose] = self.tighten(loose)
                    self.tightened[loose] = True
                return True
        if self.budget is not None and idx.numel() > self.budget:
            return False
        self.recompute(idx)
        return True

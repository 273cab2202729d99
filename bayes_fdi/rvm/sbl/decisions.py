r"""Decision rules of the fast sparse Bayesian solvers: the action of an iteration from exact
factors (:func:`best_action`), with deterministic ties and a stopping margin.

Tipping & Faul's fast solver (Tipping & Faul 2003, "Fast marginal likelihood maximisation for
sparse Bayesian models", AISTATS) chooses one action per iteration (add, re-estimate or delete
a basis function) by the largest exact evidence gain computed from the factors ``S_m, Q_m``.
With smooth kernels the active columns are nearly collinear and those factors lose most of
their digits twice:

* the textbook form ``S_m = beta b^T b - beta^2 z^T Sigma z`` (``z = Phi^T b``) subtracts two
  numbers that agree to 5-8 digits, through an explicit inverse ``Sigma`` of condition 1e7+;
* the rank-one updates of ``S`` and ``Q`` accumulate that error from iteration to iteration
  (relative errors of 1e-3 after two additions on width-0.4 RBF fits);
* products in float32 (a screening copy of the kernel matrix) resolve ``S`` only to ~1e-4 of
  ``beta``, while on smooth kernels most candidates have ``S`` near 1e-6 of ``beta``.

Gains computed this way differ between BLAS code paths in their 4th digit, so the path of
actions -- and the local optimum reached -- would change with the machine. The solver family
therefore makes every decision from factors accurate to ~1e-13 (relative) whatever the code
path:

1. **Residual form** (:func:`~bayes_fdi.rvm.sbl.residual_factors.exact_factors`). With
   ``H = A + beta Phi^T Phi`` and ``c = beta H^-1 Phi^T b``, ``S = beta ||b - Phi c||^2 +
   c^T A c`` and ``Q = beta (b - Phi c)^T (t - Phi mu) + c^T A mu``. Both are sums over
   residuals, ``S`` is the minimum over ``c`` of that quadratic (an error ``delta`` in ``c``
   changes it by ``delta^T H delta`` only), and ``Q`` is the inner product of two projection
   residuals (first-order errors are orthogonal to the other residual), so neither suffers
   cancellation.
2. **Screening with error bounds, verified action**
   (:func:`~bayes_fdi.rvm.sbl.screening.screened_factors`,
   :func:`~bayes_fdi.rvm.sbl.verification.optimistic_ratio`,
   :func:`~bayes_fdi.rvm.sbl.verification.verified_action`). Each iteration the screening
   factors of all candidates are computed from a fresh Cholesky factor (never by rank-one
   updates, which drift), in a form stationary in the solves
   (:func:`~bayes_fdi.rvm.sbl.screening.gaussian_screened_Q`; the factor's backward error
   enters to second order only), together with a rigorous bound of their error: that of the
   products ``B^T Phi`` behind them (``Design.screening_error``: float64, or the stored
   precision of a screening copy), of the solves (from their computed residuals) and of the
   sums (Higham's bounds). The actives' factors and those of every addition candidate whose
   *optimistic* ratio -- the largest ``Q^2/S`` its screened factors and their bounds allow --
   reaches the best verified gain are recomputed in residual form before the action is
   chosen. The action is thus the one on exact factors whatever the rounding of the
   screening, and only candidates that could win cost an exact recomputation (0.16 per
   iteration on a 7000-sample regression; most candidates with float32 products on smooth
   kernels, whose ``S`` is below float32's resolution).
3. **Deterministic ties** (:func:`lowest_index_in_band`). Gains within :data:`TIE_RELATIVE`
   (relative) of the best are a tie, won by the lowest basis index; a re-estimate and an
   addition tie the same way. Duplicated columns therefore give the same choice whatever
   their order or the last bits of their gains.
4. **Exact thresholds and arg-maxima**
   (:func:`~bayes_fdi.rvm.sbl.verification.exact_near_threshold`,
   :func:`~bayes_fdi.rvm.sbl.verification.verified_argmax`). Screened products that decide a
   threshold test (the alignment test) or an arg-max (the first basis column) are recomputed
   exactly where the screened value is within its error bound of the decision.
5. **Stopping margin**. An action with gain below :data:`NEGLIGIBLE_GAIN` nats counts as no
   action (a gain of 1e-9 nats is a Bayes factor of 1.000000001): the stop rule does not hinge
   on the sign of a gain at rounding level.

This module holds the rules that act on exact factors (1 computes them, 2 and 4 verify
screened ones): the constants, :class:`Action` and :func:`best_action`. It imports torch only.
Written by hand: no maintained library implements Tipping & Faul's sequential solver, let
alone these safeguards.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
from torch import Tensor

__all__ = [
    "NEGLIGIBLE_GAIN",
    "TIE_RELATIVE",
    "ZERO_FACTOR",
    "Action",
    "best_action",
    "lowest_index_in_band",
]

#: theta = q^2 - s <= this counts as zero (SparseBayes v2)
ZERO_FACTOR = 1e-12
#: Gains within this relative distance of the best tie; the lowest basis index wins. The
#: verified factors are accurate to ~1e-13 (relative), so a gap above 1e-9 is a real preference
#: and one below it is either a true tie (duplicated columns) or indistinguishable from one.
TIE_RELATIVE = 1e-9
#: Actions gaining less than this (nats) are not taken: the stopping rule never depends on the
#: sign of a gain of rounding size.
NEGLIGIBLE_GAIN = 1e-9


class Action(NamedTuple):
    """The best action of one fast-solver iteration (see :func:`best_action`)."""

    index: int  # candidate column (-1: none)
    gain: float  # Delta L (-inf: no action applies)
    kind: int  # 0 add, 1 re-estimate, 2 delete, -1 none
    new_alpha: float  # the candidate's new precision (inf for a deletion)
    position: int  # position in the active set (re-estimate / delete), else -1
    any_delete: bool  # a deletion with positive gain was pending


_NONE = Action(-1, -math.inf, -1, math.inf, -1, False)


def lowest_index_in_band(score: Tensor, index: Tensor) -> int:
    """Position of the winner of ``score``: the lowest ``index`` among the scores within
    :data:`TIE_RELATIVE` (relative) of the largest.

    Parameters
    ----------
    score : Tensor
        ``(K,)`` scores (gains, or a quantity increasing with the gain); ``-inf`` excluded.
    index : Tensor
        ``(K,)`` basis indices of the entries (distinct).
    """
    top = float(score.max())
    if not math.isfinite(top):
        return int(score.argmax())
    band = score >= top - TIE_RELATIVE * abs(top)
    big = torch.iinfo(torch.long).max
    return int(torch.where(band, index, big).argmin())


def _gain_of_ratio(x: float) -> float:
    """Addition gain ``Delta L = (x - 1 - log x) / 2`` of a candidate with ``x = Q^2/S``."""
    return 0.5 * (x - 1.0 - math.log(x)) if x > 1.0 else -math.inf


def best_action(
    S: Tensor,
    Q: Tensor,
    act: Tensor,
    alpha: Tensor,
    addable: Tensor,
) -> Action:
    """Exact evidence gains ``Delta L`` of every possible action; the best one.

    Deletions pre-empt (SparseBayes' PriorityDeletion); ties are resolved by
    :func:`lowest_index_in_band` within deletions, within re-estimates, within additions, and
    between the best re-estimate and the best addition. Re-estimates and deletions are
    evaluated on the ``M`` active columns only, additions on all candidates.

    Parameters
    ----------
    S, Q : Tensor
        ``(N_B,)`` candidate factors.
    act : Tensor
        ``(M,)`` indices of the active columns, ``alpha`` ``(M,)`` their precisions.
    addable : Tensor
        ``(N_B,)`` mask of candidates that may be added (not active, usable, aligned-free).
    """
    M = act.numel()
    Sa, Qa = S[act], Q[act]
    denom = alpha - Sa
    s = alpha * Sa / denom
    q = alpha * Qa / denom
    theta_a = q * q - s
    useful_a = theta_a > ZERO_FACTOR
    new_alpha_a = torch.where(useful_a, s * s / torch.where(useful_a, theta_a, 1.0), math.inf)
    if M > 1:
        de = ~useful_a
        de_gain = -0.5 * (q * q / (s + alpha) - torch.log1p(s / alpha))
        de_gain = torch.where(de & (de_gain > NEGLIGIBLE_GAIN), de_gain, -math.inf)
        if bool(torch.isfinite(de_gain).any()):  # deletions pre-empt (PriorityDeletion)
            k = lowest_index_in_band(de_gain, act)
            return Action(int(act[k]), float(de_gain[k]), 2, math.inf, k, True)
    # re-estimate: with delta = 1/new - 1/old
    delta = 1.0 / new_alpha_a - 1.0 / alpha
    re_gain = 0.5 * (delta * Qa * Qa / (Sa * delta + 1.0) - torch.log1p(Sa * delta))
    re_gain = torch.where(useful_a & (re_gain > NEGLIGIBLE_GAIN), re_gain, -math.inf)
    # add (not in the model: s = S, q = Q): 2 Delta L = x - 1 - log x with x = Q^2 / S,
    # increasing in x > 1, so the best addition is the admissible candidate of largest x
    Q2 = Q * Q
    ad = addable & (Q2 - S > ZERO_FACTOR) & (S > 0)
    x = torch.where(ad, Q2 / S, 0.0)
    ka = lowest_index_in_band(re_gain, act)
    kn = lowest_index_in_band(x, torch.arange(x.numel(), device=x.device))
    g_re, x_n = (float(v) for v in torch.stack([re_gain[ka], x[kn]]).tolist())
    g_add = _gain_of_ratio(x_n)
    if not g_add > NEGLIGIBLE_GAIN:
        g_add = -math.inf
    i_re = int(act[ka])
    top = max(g_re, g_add)
    if top == -math.inf:
        return _NONE
    tied = abs(g_re - g_add) <= TIE_RELATIVE * abs(top)
    if (g_re > g_add and not tied) or (tied and i_re < kn):
        return Action(i_re, g_re, 1, float(new_alpha_a[ka]), ka, False)
    s_n, q_n = (float(v) for v in torch.stack([S[kn], Q[kn]]).tolist())
    return Action(kn, g_add, 0, s_n * s_n / (q_n * q_n - s_n), -1, False)

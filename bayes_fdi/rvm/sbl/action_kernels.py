r"""Compiled (numba) kernels of the fast solvers' decision rules on CPU float64 arrays: the best
action on exact factors (:func:`best_action_kernel`) and the rounds of the lazy verification
(:func:`unsure_actives`, :func:`round_candidates`).

Each kernel is the same arithmetic as its torch counterpart in
:mod:`~bayes_fdi.rvm.sbl.decisions` and :mod:`~bayes_fdi.rvm.sbl.verification` (same formulas,
same order of operations, no fast-math, so no contraction into fused multiply-adds), written as
explicit loops over the ``P`` candidates: the per-iteration cost is one pass over the factors
instead of some forty small torch calls. Nothing here depends on a BLAS library or a thread
count; the choices are those of :func:`~bayes_fdi.rvm.sbl.decisions.best_action` (the tie rule
of :func:`~bayes_fdi.rvm.sbl.decisions.lowest_index_in_band`, the gain floor, the factor
threshold), which ``tests/test_rvm_engine.py`` checks against the torch rules.

Imports numba and numpy only. Written by hand: no maintained library implements these rules.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "NONE_KIND",
    "best_action_kernel",
    "round_candidates",
    "unsure_actives",
]

#: ``kind`` of "no action" (as :class:`~bayes_fdi.rvm.sbl.decisions.Action`)
NONE_KIND = -1
# the rules' constants, as in decisions.py and verification.py (the tests compare them)
_ZERO_FACTOR = 1e-12
_TIE_RELATIVE = 1e-9
_NEGLIGIBLE_GAIN = 1e-9
_SLACK = 1e-12
_TINY = np.finfo(np.float64).tiny
_BIG = np.iinfo(np.int64).max


@njit(cache=True, error_model="numpy")
def _lowest_in_band(score, index):  # pragma: no cover - compiled
    """:func:`~bayes_fdi.rvm.sbl.decisions.lowest_index_in_band` on arrays (NaN as torch's
    ``max`` / ``argmax``: propagated, first NaN wins)."""
    n = score.shape[0]
    top = -np.inf
    first_top = 0
    for k in range(n):
        v = score[k]
        if math.isnan(v):
            return k
        if v > top:
            top = v
            first_top = k
    if not math.isfinite(top):
        return first_top
    edge = top - _TIE_RELATIVE * abs(top)
    best_k = 0
    best_i = _BIG
    for k in range(n):
        if score[k] >= edge and index[k] < best_i:
            best_i = index[k]
            best_k = k
    return best_k


@njit(cache=True, error_model="numpy")
def _gain_of_ratio(x):  # pragma: no cover - compiled
    return 0.5 * (x - 1.0 - math.log(x)) if x > 1.0 else -np.inf


@njit(cache=True, error_model="numpy")
def best_action_kernel(S, Q, act, alpha, addable):  # pragma: no cover - compiled
    """:func:`~bayes_fdi.rvm.sbl.decisions.best_action` on float64 arrays.

    Returns ``(index, gain, kind, new_alpha, position, any_delete)``, the fields of
    :class:`~bayes_fdi.rvm.sbl.decisions.Action`.
    """
    M = act.shape[0]
    P = S.shape[0]
    useful = np.empty(M, dtype=np.bool_)
    new_alpha = np.empty(M)
    de_gain = np.full(M, -np.inf)
    re_gain = np.full(M, -np.inf)
    any_de = False
    for k in range(M):
        a = alpha[k]
        Sa = S[act[k]]
        Qa = Q[act[k]]
        denom = a - Sa
        s = a * Sa / denom
        q = a * Qa / denom
        theta = q * q - s
        useful[k] = theta > _ZERO_FACTOR
        if useful[k]:
            new_alpha[k] = s * s / theta
            delta = 1.0 / new_alpha[k] - 1.0 / a
            g = 0.5 * (delta * Qa * Qa / (Sa * delta + 1.0) - math.log1p(Sa * delta))
            if g > _NEGLIGIBLE_GAIN:
                re_gain[k] = g
        else:
            new_alpha[k] = np.inf
            g = -0.5 * (q * q / (s + a) - math.log1p(s / a))
            if g > _NEGLIGIBLE_GAIN:
                de_gain[k] = g
                any_de = True
    if M > 1 and any_de:  # deletions pre-empt (PriorityDeletion)
        k = _lowest_in_band(de_gain, act)
        return act[k], de_gain[k], 2, np.inf, k, True
    x = np.zeros(P)
    for i in range(P):
        Q2 = Q[i] * Q[i]
        if addable[i] and Q2 - S[i] > _ZERO_FACTOR and S[i] > 0:
            x[i] = Q2 / S[i]
    ka = _lowest_in_band(re_gain, act)
    kn = _lowest_in_band(x, np.arange(P))
    g_re = re_gain[ka] if M > 0 else -np.inf
    g_add = _gain_of_ratio(x[kn])
    if not g_add > _NEGLIGIBLE_GAIN:
        g_add = -np.inf
    i_re = act[ka] if M > 0 else -1
    top = max(g_re, g_add)
    if top == -np.inf:
        return -1, -np.inf, NONE_KIND, np.inf, -1, False
    tied = abs(g_re - g_add) <= _TIE_RELATIVE * abs(top)
    if (g_re > g_add and not tied) or (tied and i_re < kn):
        return i_re, g_re, 1, new_alpha[ka], ka, False
    s_n, q_n = S[kn], Q[kn]
    return kn, g_add, 0, s_n * s_n / (q_n * q_n - s_n), -1, False


@njit(cache=True, error_model="numpy")
def _box(S, S_err, Q, Q_err):  # pragma: no cover - compiled
    S_lo = max(S - S_err, 0.0) if not math.isnan(S - S_err) else S - S_err
    Qa = abs(Q)
    Qa_lo = max(Qa - Q_err, 0.0) if not math.isnan(Qa - Q_err) else Qa - Q_err
    return S_lo, S + S_err, Qa_lo, Qa + Q_err


@njit(cache=True, error_model="numpy")
def _ratio_gain(v):  # pragma: no cover - compiled
    if v < _TINY:
        v = _TINY
    return 0.5 * ((v - 1.0) - math.log(v))


@njit(cache=True, error_model="numpy")
def unsure_actives(S, S_err, Q, Q_err, act, alpha, verified):  # pragma: no cover - compiled
    """Basis indices of the unverified actives whose usefulness ``q^2 - s > 0`` the bounds
    cannot confirm (:func:`~bayes_fdi.rvm.sbl.verification.useful_lower_bound`)."""
    M = act.shape[0]
    out = np.empty(M, dtype=np.int64)
    n = 0
    for k in range(M):
        j = act[k]
        if verified[j]:
            continue
        a = alpha[k]
        S_lo, S_hi, Qa_lo, _ = _box(S[j], S_err[j], Q[j], Q_err[j])
        half = 0.5 * a
        if S_lo <= half and half <= S_hi:
            prod_hi = half * half
        else:
            prod_hi = max(S_lo * (a - S_lo), S_hi * (a - S_hi))
        f_lo = a * Qa_lo * Qa_lo - prod_hi
        f_lo = f_lo - _SLACK * (a * Qa_lo * Qa_lo + prod_hi)
        if S_hi < a:
            d = (a - S_lo) if f_lo > 0 else (a - S_hi)
            low = a * f_lo / (d * d)
        else:
            low = -np.inf
        if not low > _ZERO_FACTOR:
            out[n] = j
            n += 1
    return out[:n]


@njit(cache=True, error_model="numpy")
def round_candidates(
    S, Q, S_err, Q_err, act, addable, verified, band, ratio
):  # pragma: no cover - compiled
    """One round of :func:`~bayes_fdi.rvm.sbl.verification.lazy_verified_action`: the
    unverified actives whose re-estimation gain could reach ``band``, then (ascending) the
    unverified addable candidates whose optimistic ``Q^2/S`` reaches ``ratio``; with each one's
    upper bound of its gain (for the shortlist)."""
    M = act.shape[0]
    P = S.shape[0]
    cand = np.empty(M + P, dtype=np.int64)
    ub = np.empty(M + P)
    n = 0
    for k in range(M):
        j = act[k]
        if verified[j]:
            continue
        S_lo, S_hi, Qa_lo, Qa_hi = _box(S[j], S_err[j], Q[j], Q_err[j])
        if S_lo > 0:
            v_lo = Qa_lo * Qa_lo / S_hi
            v_hi = Qa_hi * Qa_hi / S_lo
            u = max(_ratio_gain(v_lo), _ratio_gain(v_hi))
            u = u + _SLACK * (u + 1e-300) + 1e-15 * abs(v_hi - v_lo)
        else:
            u = np.inf
        if u >= band:
            cand[n] = j
            ub[n] = u
            n += 1
    for i in range(P):
        if not addable[i] or verified[i]:
            continue
        low = S[i] - S_err[i]
        high = abs(Q[i]) + Q_err[i]
        high = high * high
        x = high / max(low, _TINY) if low > 0 else np.inf
        if x >= ratio:
            cand[n] = i
            ub[n] = _ratio_gain(max(x, 1.0)) if math.isfinite(x) else np.inf
            n += 1
    return cand[:n], ub[:n]

r"""Decisions of the fast sparse Bayesian solvers that do not depend on rounding.

Written by hand: no maintained library implements Tipping & Faul's sequential solver, let alone
these safeguards. The fast solver (:mod:`bayes_fdi.rvm.sbl`) chooses one action per
iteration (add, re-estimate or delete a basis function) by the largest exact evidence gain
computed from the factors ``S_m, Q_m`` (``shared/reference/fast-sbl.md``). With smooth kernels
the active columns are nearly collinear and those factors lose most of their digits twice:

* the textbook form ``S_m = beta b^T b - beta^2 z^T Sigma z`` (``z = Phi^T b``) subtracts two
  numbers that agree to 5-8 digits, through an explicit inverse ``Sigma`` of condition 1e7+;
* the rank-one updates of ``S`` and ``Q`` accumulate that error from iteration to iteration
  (relative errors of 1e-3 after two additions on the normal models' width-0.4 fits);
* products in float32 (a screening copy of the kernel matrix) resolve ``S`` only to ~1e-4 of
  ``beta``, while on smooth kernels most candidates have ``S`` near 1e-6 of ``beta``.

Gains computed this way differ between BLAS code paths in their 4th digit, so the path of
actions -- and the local optimum reached -- changed with the machine. The rules here make every
decision from factors accurate to ~1e-13 (relative) whatever the code path:

1. **Residual form** (:func:`exact_factors`). With ``H = A + beta Phi^T Phi`` and
   ``c = beta H^-1 Phi^T b``, ``S = beta ||b - Phi c||^2 + c^T A c`` and
   ``Q = beta (b - Phi c)^T (t - Phi mu) + c^T A mu``. Both are sums over residuals, ``S`` is the
   minimum over ``c`` of that quadratic (an error ``delta`` in ``c`` changes it by
   ``delta^T H delta`` only), and ``Q`` is the inner product of two projection residuals
   (first-order errors are orthogonal to the other residual), so neither suffers cancellation.
2. **Screening with error bounds, verified action** (:func:`screened_factors`,
   :func:`optimistic_ratio`, :func:`verified_action`). Each iteration the screening factors
   of all candidates are computed from a fresh Cholesky factor (never by rank-one updates,
   which drift), in a form stationary in the solves (:func:`gaussian_screened_Q`; the
   factor's backward error enters to second order only), together with a rigorous bound of
   their error: that of the products ``B^T Phi`` behind them (``Design.screening_error``:
   float64, or the stored precision of a screening copy), of the solves (from their computed
   residuals) and of the sums (Higham's bounds). The actives' factors and those
   of every addition candidate whose *optimistic* ratio -- the largest ``Q^2/S`` its screened
   factors and their bounds allow -- reaches the best verified gain are recomputed in
   residual form before the action is chosen. The action is thus the one on exact factors
   whatever the rounding of the screening, and only candidates that could win cost an exact
   recomputation (0.16 per iteration on a 7000-sample dynamic normal model; most
   candidates with float32 products on smooth kernels, whose ``S`` is below float32's
   resolution).
3. **Deterministic ties** (:func:`lowest_index_in_band`). Gains within :data:`TIE_RELATIVE`
   (relative) of the best are a tie, won by the lowest basis index; a re-estimate and an
   addition tie the same way. Duplicated columns therefore give the same choice whatever
   their order or the last bits of their gains.
4. **Exact thresholds and arg-maxima** (:func:`exact_near_threshold`,
   :func:`verified_argmax`). Screened products that decide a threshold test (the alignment
   test) or an arg-max (the first basis column) are recomputed exactly where the screened
   value is within its error bound of the decision.
5. **Stopping margin**. An action with gain below :data:`NEGLIGIBLE_GAIN` nats counts as no
   action (a gain of 1e-9 nats is a Bayes factor of 1.000000001): the stop rule does not hinge
   on the sign of a gain at rounding level.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

import torch
from torch import Tensor

if TYPE_CHECKING:  # pragma: no cover
    from bayes_fdi.rvm.sbl.precision_factor import _Factor

__all__ = [
    "NEGLIGIBLE_GAIN",
    "TIE_RELATIVE",
    "Action",
    "Screening",
    "best_action",
    "exact_factors",
    "exact_near_threshold",
    "factor_trace",
    "gaussian_screened_Q",
    "lowest_index_in_band",
    "optimistic_ratio",
    "rounding_gamma",
    "screened_factors",
    "verified_action",
    "verified_argmax",
    "weighted_exact_factors",
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
#: At most this many addition candidates are recomputed exactly per round of verification.
SHORTLIST_MAX = 64


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


def exact_factors(
    fac: _Factor,
    Phi: Tensor,
    alpha: Tensor,
    beta: float,
    mu: Tensor,
    resid: Tensor,
    Bc: Tensor,
    Z: Tensor,
) -> tuple[Tensor, Tensor]:
    """``S`` and ``Q`` of candidate columns ``Bc`` in residual form (no cancellation), Gaussian
    noise of precision ``beta``.

    With ``c = beta H^-1 Phi^T b``: ``S = beta ||b - Phi c||^2 + c^T A c`` and
    ``Q = beta (b - Phi c)^T (t - Phi mu) + c^T A mu`` (equal to the textbook
    ``beta b^T b - beta^2 b^T Phi Sigma Phi^T b`` and ``beta b^T t - beta^2 b^T Phi Sigma Phi^T t``
    in exact arithmetic). Cost ``O(N M K)``. :func:`weighted_exact_factors` is the same for
    per-sample noise precisions (the Bernoulli model's Laplace approximation).

    Parameters
    ----------
    fac : _Factor
        Cholesky factor of ``H = A + beta Phi^T Phi`` (fresh, not rank-one updated).
    Phi : Tensor
        ``(N, M)`` active columns; ``alpha`` ``(M,)`` their precisions; ``beta`` the noise
        precision.
    mu, resid : Tensor
        ``(M,)`` posterior mean ``beta H^-1 Phi^T t`` and ``(N,)`` residual ``t - Phi mu``.
    Bc : Tensor
        ``(N, K)`` candidate columns (active columns allowed).
    Z : Tensor
        ``(M, K)`` their exact Gram entries ``Phi^T Bc``.
    """
    C = beta * fac.solve_matrix(Z)
    R = Bc - thin_matmul(Phi, C)
    AC = alpha[:, None] * C
    S = beta * (R * R).sum(0) + (AC * C).sum(0)
    Q = beta * (R.T @ resid) + AC.T @ mu
    return S, Q


def weighted_exact_factors(
    fac: _Factor,
    Phi: Tensor,
    alpha: Tensor,
    weights: Tensor,
    mu: Tensor,
    score: Tensor,
    Bc: Tensor,
    WZ: Tensor,
) -> tuple[Tensor, Tensor]:
    """``S`` and ``Q`` in residual form for per-sample noise precisions ``W = diag(weights)``.

    The Laplace approximation of the Bernoulli model at the mode ``mu`` is a Gaussian model
    with noise precisions ``w = y (1 - y)`` and working targets ``t_hat = Phi mu + W^-1 (t - y)``
    (SparseBayes). With ``H = A + Phi^T W Phi`` and ``c = H^-1 Phi^T W b``:

    ``S = (b - Phi c)^T W (b - Phi c) + c^T A c``,
    ``Q = (b - Phi c)^T (t - y) + c^T A mu``,

    equal in exact arithmetic to the textbook ``b^T W b - b^T W Phi Sigma Phi^T W b`` and
    ``b^T W t_hat - b^T W Phi Sigma Phi^T W t_hat = b^T (t - y) - c^T g`` with the gradient
    ``g = Phi^T (t - y) - A mu`` of the log posterior. ``Q`` is thus the factor at the Newton
    update of ``mu``, and an error ``delta`` of the mode changes it only to second order
    (``d(b^T (t - y)) = -b^T W Phi delta`` is cancelled by ``-c^T dg = c^T H delta``): the
    decisions do not depend on how the last Newton step rounded. Cost ``O(N M K)``.

    Parameters
    ----------
    fac : _Factor
        Cholesky factor of ``H = A + Phi^T W Phi`` (fresh, not rank-one updated).
    Phi : Tensor
        ``(N, M)`` active columns; ``alpha`` ``(M,)`` their precisions.
    weights : Tensor
        ``(N,)`` noise precisions ``w`` (``y (1 - y)`` at the mode).
    mu : Tensor
        ``(M,)`` mode (posterior mean).
    score : Tensor
        ``(N,)`` weighted working residual ``W (t_hat - Phi mu)`` (Bernoulli: ``t - y``).
    Bc : Tensor
        ``(N, K)`` candidate columns (active columns allowed).
    WZ : Tensor
        ``(M, K)`` their weighted Gram entries ``Phi^T W Bc``.
    """
    C = fac.solve_matrix(WZ)
    R = Bc - thin_matmul(Phi, C)
    AC = alpha[:, None] * C
    S = (weights[:, None] * R * R).sum(0) + (AC * C).sum(0)
    Q = R.T @ score + AC.T @ mu
    return S, Q


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
    ``exact`` (``idx -> values``) and the winner is chosen by :func:`lowest_index_in_band`.
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


#: right-hand sides with at most this many columns go through :func:`thin_matmul`'s transpose
_THIN_COLUMNS = 32


def thin_matmul(A: Tensor, W: Tensor) -> Tensor:
    """``A @ W`` for a tall ``A`` (``(n, m)``) and a thin ``W`` (``(m, k)``, a few columns),
    computed as ``(W^T A^T)^T``.

    The same products in another summation order (any order is within Higham's bounds, which the
    solvers' error bounds use). MKL's general product is several times slower for the tall-thin
    shape than for the transposed wide one: ``(5000 x 227) @ (227 x 2)`` 1.3 ms against 0.5 ms,
    ``(227 x 5000) @ (5000 x 2)`` 3.6 ms against 0.4 ms (one thread, AMD EPYC, torch 2.13 with
    MKL); a single column is a matrix-vector product either way.
    """
    if W.ndim == 2 and 1 < W.shape[1] <= _THIN_COLUMNS:
        return (W.T @ A.T).T
    return A @ W


def rounding_gamma(n: int, dtype: torch.dtype) -> float:
    """Higham's ``gamma_n = n u / (1 - n u)``: the relative error bound of ``n`` roundings."""
    nu = n * torch.finfo(dtype).eps / 2.0
    return nu / (1.0 - nu)


class Screening(NamedTuple):
    """Screening factors of every candidate and what their error bounds need
    (:func:`screened_factors`)."""

    S: Tensor  # (N_B,) screened S
    S_error: Tensor  # (N_B,) bound of |S - exact S|
    C: Tensor  # (N_B, M) rows: solve coefficients c = H^-1 z (for the Gaussian model's Q)
    solve_error: Tensor  # (N_B,) bound of ||H^-1/2 (H c - z)||: the solve's error in H-norm
    residual: Tensor  # (N_B,) bound of ||H c - z||
    c_norm: Tensor  # (N_B,) ||c||
    z_norm: Tensor  # (N_B,) ||z||
    trace: float  # upper bound of lambda_max(H^-1) (tr(H^-1) unless given)


def screened_factors(
    fac: _Factor,
    H: Tensor,
    Z: Tensor,
    diag: Tensor,
    *,
    z_error: Tensor,
    diag_error: Tensor | float = 0.0,
    trace: float | None = None,
) -> Screening:
    """Screening ``S = diag - z^T H^-1 z`` for the rows ``z`` of ``Z`` (``(N_B, M)``) from a
    fresh Cholesky factor, in a form stationary in the solve, with a rigorous error bound.

    With ``c`` the computed ``H^-1 z`` (a Cholesky solve with the factor), ``S`` is evaluated as
    ``f(c) = diag - 2 z^T c + c^T H c`` with ``H`` itself (not the factor): ``f`` is minimal at
    the exact solve, ``f(c) - S = (c - c*)^T H (c - c*) = r^T H^-1 r <= tr(H^-1) ||r||^2`` for
    the solve residual ``r = H c - z`` (computed), so the factor's own backward error enters
    only to second order (``trace``: an upper bound of ``lambda_max(H^-1)``; when not given,
    ``tr(H^-1)`` from :func:`factor_trace`). The remaining terms of the bound:

    * the inputs: each entry ``k`` of a row of ``Z`` within ``z_error[k]`` of the exact one
      (``Design.screening_error``) moves ``S`` by at most ``2 ||c|| ||z_error|| +
      ||z_error||^2 tr(H^-1)``, and ``diag`` by ``diag_error``;
    * rounding of the sums (Higham's ``gamma_n``, eq. 3.5, relative to the sums of absolute
      values, bounded by Cauchy-Schwarz and ``|| |H| |c| || <= ||H||_F ||c||``).

    Cost ``O(M^2 N_B)`` (a Cholesky solve and one product with ``H``) and a few passes over
    ``Z``.
    """
    M = Z.shape[1]
    dt = Z.dtype
    d = fac.d
    # rows c^T = (D z)^T (L L^T)^-1 D: one Cholesky solve on the column-major view of Z
    C = torch.cholesky_solve((Z * d).T, fac.L).T * d
    W = torch.addmm(Z, C, H, beta=-2.0)  # rows: (H c - 2 z)^T
    S = diag + (C * W).sum(1)  # = diag - 2 z^T c + c^T H c
    if trace is None:
        trace = factor_trace(fac)
    H_F = float(torch.linalg.matrix_norm(H)) * (1.0 + rounding_gamma(M * M, dt))
    c_norm = torch.linalg.vector_norm(C, dim=1)
    z_norm = torch.linalg.vector_norm(Z, dim=1)
    r_norm = torch.linalg.vector_norm(W.add_(Z), dim=1)  # W + Z = H c - z
    r_norm += rounding_gamma(M + 2, dt) * (H_F * c_norm + z_norm)
    solve_error = math.sqrt(trace) * r_norm
    ze = float(torch.linalg.vector_norm(z_error))
    S_error = (
        solve_error.square()
        + 2.0 * ze * c_norm
        + ze * ze * trace
        + diag_error
        + rounding_gamma(2 * M + 4, dt) * (diag.abs() + c_norm * (2.0 * z_norm + H_F * c_norm))
    )
    return Screening(S, S_error, C, solve_error, r_norm, c_norm, z_norm, trace)


def factor_trace(fac: _Factor) -> float:
    """Upper bound of ``tr(H^-1)`` (``>= lambda_max(H^-1)``) from the Cholesky factor,
    ``O(M^3)``."""
    d = fac.d
    M = d.numel()
    trace = float((d * d * torch.cholesky_inverse(fac.L).diagonal()).sum())
    return max(trace, 0.0) * (1.0 + rounding_gamma(3 * M, d.dtype))


def gaussian_screened_Q(
    screening: Screening,
    Z: Tensor,
    b_t: Tensor,
    b_t_error: float,
    mu: Tensor,
    gradient: Tensor,
    gradient_error: Tensor,
    z_error: Tensor,
) -> tuple[Tensor, Tensor]:
    """Screening ``Q = b^T t - z^T mu`` (``b^T t`` scaled as ``z``) of the Gaussian model, in
    a form stationary in both solves, with a rigorous error bound.

    With the computed mean ``mu``, its residual ``g = H mu - beta Phi^T t`` (``gradient``,
    computed directly, within ``gradient_error``) and the screening's ``c``,
    ``f = b^T t - z^T mu + c^T g`` equals the exact ``Q`` up to ``(c - c*)^T H (mu - mu*)``,
    at most ``||H^-1/2 r|| tr(H^-1)^1/2 ||g||`` (Cauchy-Schwarz in the ``H`` inner product):
    second order in the solves' errors. Further terms: the inputs (``z`` entries within
    ``z_error``, ``b^T t`` within ``b_t_error``) and rounding of the sums.

    Returns
    -------
    Q, Q_error : Tensor
        ``(N_B,)`` each.
    """
    M = Z.shape[1]
    Q = b_t - Z @ mu + screening.C @ gradient
    g_norm = float(torch.linalg.vector_norm(gradient))
    g_err = float(torch.linalg.vector_norm(gradient_error))
    mu_norm = float(torch.linalg.vector_norm(mu))
    trace = screening.trace
    c_norm = screening.c_norm
    Q_error = (
        screening.solve_error * ((g_norm + g_err) * math.sqrt(trace))
        + b_t_error
        + float(z_error @ mu.abs())
        + float(torch.linalg.vector_norm(z_error)) * trace * (g_norm + g_err)
        + c_norm * g_err
        + rounding_gamma(M + 3, Z.dtype)
        * (b_t.abs() + screening.z_norm * mu_norm + c_norm * g_norm)
    )
    return Q, Q_error


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
    """The best action chosen on exactly recomputed factors (rule 2 of the module).

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
        As in :func:`best_action`.
    exact : callable
        ``idx -> (S_idx, Q_idx)``, the exact factors of the basis columns ``idx``
        (see :func:`exact_factors`).
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

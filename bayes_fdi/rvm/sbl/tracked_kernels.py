r"""Compiled (numba) kernels of the carried screening factors' most frequent updates, a
re-estimation (:func:`reestimate_rows`) and a noise update (:func:`rescale_rows`), and of
their screening (:func:`screen_rows`), on CPU float64 arrays.

:meth:`bayes_fdi.rvm.sbl.tracked_factors.TrackedFactors.reestimate` moves every candidate's
carried ``S_, Q_``, their bounds ``e_S, e_Q``, the residual bound ``rho``, the coefficient norm
bound ``nu`` and the coefficients ``C`` (a rank-one update) by the same formulas for each of the
``P`` rows. Here that is one pass over the rows (the same arithmetic, in the same order, without
fast-math) instead of some thirty ``P``-long torch operations; a noise update
(:meth:`~bayes_fdi.rvm.sbl.tracked_factors.TrackedFactors.rescale`) likewise reads each row of
``C`` once instead of forming ``C o C`` and two products; the scalars of the update (its
``kappa`` and the bounds' factors) are computed by the caller as before. The carried values only
decide which candidates get an exact look (:mod:`~bayes_fdi.rvm.sbl.verification`), so they
change the cost, never the chosen actions.

Imports numba and numpy only. Written by hand: no maintained library carries these bounds.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["reestimate_rows", "rescale_rows", "screen_rows"]


@njit(cache=True, error_model="numpy")
def reestimate_rows(
    C, M, k, s, S, Q, S_err, Q_err, rho, nu, scalars
):  # pragma: no cover - compiled
    """Apply a re-estimation of position ``k`` to every row, in place.

    ``scalars`` holds ``(kappa, kappa_err, kap, e_scale, mk, e_mu, g4, grow, rho_ack, rho_aa,
    rho_nu, s_norm, g2)``: with ``c = C[:, k]``, ``e = e_scale rho``,
    ``S_ += kappa c^2``, ``Q_ += (kappa mk) c``, their bounds as in
    :meth:`~bayes_fdi.rvm.sbl.tracked_factors.TrackedFactors.reestimate`,
    ``C[:, :M] += (-kappa c) s^T``,
    ``rho = rho grow + |c| rho_ack + |a| rho_aa + rho_nu (nu + |a| s_norm)`` and
    ``nu = (nu + |a| s_norm) (1 + g2)``.
    """
    kappa, kappa_err, kap, e_scale, mk, e_mu = (
        scalars[0],
        scalars[1],
        scalars[2],
        scalars[3],
        scalars[4],
        scalars[5],
    )
    g4, grow, rho_ack, rho_aa, rho_nu, s_norm, g2 = (
        scalars[6],
        scalars[7],
        scalars[8],
        scalars[9],
        scalars[10],
        scalars[11],
        scalars[12],
    )
    kmk = kappa * mk
    kerr_mk = kappa_err * abs(mk)
    amk_emu = abs(mk) + e_mu
    for i in range(C.shape[0]):
        ck = C[i, k]
        ack = abs(ck)
        e = e_scale * rho[i]
        dS = kappa * ck * ck
        dQ = kmk * ck
        S[i] += dS
        Q[i] += dQ
        S_err[i] += kappa_err * ck * ck + kap * e * (2.0 * ack + e) + g4 * (abs(S[i]) + abs(dS))
        Q_err[i] += kerr_mk * ack + kap * (e_mu * ack + amk_emu * e) + g4 * (abs(Q[i]) + abs(dQ))
        a = -kappa * ck
        for j in range(M):
            C[i, j] += a * s[j]
        aa = abs(a)
        rho[i] = rho[i] * grow + ack * rho_ack + aa * rho_aa + rho_nu * (nu[i] + aa * s_norm)
        nu[i] = (nu[i] + aa * s_norm) * (1.0 + g2)


@njit(cache=True, error_model="numpy")
def rescale_rows(
    C, M, weights, d_mu, S, Q, S_err, Q_err, rho, nu, scalars
):  # pragma: no cover - compiled
    """Apply a noise update to every row, in place.

    ``weights`` (``(3, M)``) holds ``Delta``, ``Delta^2 / abar`` and ``Delta^2 / abar'``,
    ``d_mu`` is ``Delta mu'``; ``scalars`` holds ``(rho_scale, m_old, psd_new, m_cross, gM,
    d_max, dmu, mu_error_w, d_mu_norm, grow)``. With ``c = C[i, :M]``:
    ``S_ += sum c^2 Delta``, ``Q_ += c^T d_mu`` and the bounds, ``rho`` and ``nu`` as in
    :meth:`~bayes_fdi.rvm.sbl.tracked_factors.TrackedFactors.rescale`.
    """
    rho_scale, m_old, psd_new, m_cross, gM = (
        scalars[0],
        scalars[1],
        scalars[2],
        scalars[3],
        scalars[4],
    )
    d_max, dmu, mu_error_w, d_mu_norm, grow = (
        scalars[5],
        scalars[6],
        scalars[7],
        scalars[8],
        scalars[9],
    )
    for i in range(C.shape[0]):
        dS = 0.0
        p_old = 0.0
        p_new = 0.0
        dQ = 0.0
        for j in range(M):
            c = C[i, j]
            cc = c * c
            dS += cc * weights[0, j]
            p_old += cc * weights[1, j]
            p_new += cc * weights[2, j]
            dQ += c * d_mu[j]
        dc_old = math.sqrt(max(p_old, 0.0)) * (1.0 + gM)
        dc_new = math.sqrt(max(p_new, 0.0)) * (1.0 + gM)
        r = rho[i] * rho_scale
        S[i] += dS
        t = dc_new + m_cross * r
        S_err[i] += (
            r * (2.0 * dc_old + m_old * r)
            + psd_new * t * t
            + gM * (d_max * nu[i] * nu[i] + abs(S[i]))
        )
        Q[i] += dQ
        Q_err[i] += r * dmu + dc_new * mu_error_w + gM * (nu[i] * d_mu_norm + abs(Q[i]))
        rho[i] = rho[i] * grow + dc_new


@njit(cache=True, error_model="numpy")
def screen_rows(
    S, Q, S_err, Q_err, rho, nu, rows, all_rows, beta, scalars
):  # pragma: no cover - compiled
    """``beta S, beta Q`` and their bounds of ``rows`` (every row when ``all_rows``) as
    :meth:`~bayes_fdi.rvm.sbl.tracked_factors.TrackedFactors.screen` computes them, in one pass
    (the same operations in the same order: the same numbers). ``scalars`` holds ``(root_lp,
    two_ze, lam_ze_ze, eps_mu1, bt_error)``: ``S_err + two_ze (nu + root_lp rho) + lam_ze_ze``
    and ``Q_err + eps_mu1 + bt_error``."""
    root_lp, two_ze, lam_ze_ze, eps_mu1, bt_error = (
        scalars[0],
        scalars[1],
        scalars[2],
        scalars[3],
        scalars[4],
    )
    K = S.shape[0] if all_rows else rows.shape[0]
    out = np.empty((4, K))
    for r in range(K):
        i = r if all_rows else rows[r]
        out[0, r] = beta * S[i]
        out[1, r] = beta * Q[i]
        out[2, r] = beta * (S_err[i] + two_ze * (nu[i] + root_lp * rho[i]) + lam_ze_ze)
        out[3, r] = beta * (Q_err[i] + eps_mu1 + bt_error)
    return out

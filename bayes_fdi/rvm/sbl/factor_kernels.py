r"""Compiled (numba) kernels of the fast Gaussian solver's per-iteration posterior work on CPU
float64 arrays: the posterior's bound terms in one pass (:func:`posterior_terms`), the
re-estimation update of the scaled Cholesky factor (:func:`reestimate_factor`) and the
screening factors of a few rows from the fresh factor (:func:`screened_rows`).

:func:`posterior_terms` computes, for
:func:`~bayes_fdi.rvm.sbl.posterior_bounds.posterior_context`, the stored precision
``Hb = (G + G^T) / 2 + diag(abar)``, its squared Frobenius norm, the gradient ``Hb mu - Phi^T t``
and the sums ``|Hb| |mu|`` behind its rounding bound, in one pass over ``G`` instead of some
fifteen ``M x M`` torch operations; :func:`posterior_bounds_terms` adds the rest of that
function's bounds (the same formulas), so that a posterior costs one compiled call. Every value
there is either a bound or feeds one (the
carried screening factors), so its rounding changes the cost of a decision, never the decision.

:func:`reestimate_factor` moves the factor ``L`` of the scaled precision
``I + D G D`` (:class:`~bayes_fdi.rvm.sbl.precision_factor.PrecisionFactor`) to a new prior
precision of one column ``k``: with ``r = d_k' / d_k``,
``I + D' G D' = S (I + D G D) S + (1 - r^2) e_k e_k^T`` (``S`` the identity with ``r`` at
``k``), so row ``k`` of ``L`` is scaled by ``r`` and a rank-one update (``r < 1``) or downdate
(``r > 1``) with ``e_k`` follows; it touches only the trailing block ``L[k:, k:]`` (LINPACK's
``dchud`` / ``dchdd`` rotations, Golub & Van Loan, *Matrix Computations*, sec. 6.5.4). The
kernel also returns the amplification of the update's rounding, ``max_j L_jj / L'_jj`` of a
downdate (1 for an update): the caller refactorises afresh when the accumulated bound says so.

:func:`screened_rows` is the screening of
:func:`~bayes_fdi.rvm.sbl.screening.screened_factors` and
:func:`~bayes_fdi.rvm.sbl.screening.gaussian_screened_Q` for the handful of rows the lazy
verification tightens each iteration (the same formulas and bounds, with exact stored products),
without their twenty-odd torch calls; values and bounds only decide which candidates get an
exact look. :func:`refresh_rows` wraps it for the carried factors: it scales its inputs, gathers
the rows and writes their carried values back in place, in one call.

:func:`reestimate_terms` is the unit solve ``s = Hb^-1 e_k`` and the scalars of a re-estimation
update of the carried factors
(:meth:`~bayes_fdi.rvm.sbl.tracked_factors.TrackedFactors.reestimate`; the same formulas and
bounds), in one call.

Explicit loops, no BLAS, no fast-math: the results do not depend on a BLAS library or a thread
count. Imports numba and numpy only. Written by hand: no maintained library carries these
bounds or updates this scaled factor.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "posterior_bounds_terms",
    "posterior_terms",
    "reestimate_factor",
    "reestimate_terms",
    "refresh_rows",
    "screened_rows",
]


@njit(cache=True, error_model="numpy")
def _solve_upper_transposed(L, y):  # pragma: no cover - compiled
    """``y <- L^-T y`` in place (backward substitution with the lower factor ``L``), in a
    fixed order."""
    M = y.shape[0]
    for i in range(M - 1, -1, -1):
        v = y[i]
        for j in range(i + 1, M):
            v -= L[j, i] * y[j]
        y[i] = v / L[i, i]


@njit(cache=True, error_model="numpy")
def posterior_terms(G, abar, mu, Phi_t, Hb, gradient, abs_product):  # pragma: no cover
    """Fill ``Hb`` (``(M, M)``), ``gradient`` and ``abs_product`` (``(M,)``) and return
    ``||Hb||_F^2``.

    ``Hb = (G + G^T) / 2 + diag(abar)``, ``gradient = Hb mu - Phi_t`` and
    ``abs_product = |Hb| |mu| + |Phi_t|``.
    """
    M = abar.shape[0]
    fro = 0.0
    for i in range(M):
        g = 0.0
        a = 0.0
        for j in range(M):
            h = 0.5 * (G[i, j] + G[j, i])
            if i == j:
                h += abar[i]
            Hb[i, j] = h
            fro += h * h
            g += h * mu[j]
            a += abs(h) * abs(mu[j])
        gradient[i] = g - Phi_t[i]
        abs_product[i] = a + abs(Phi_t[i])
    return fro


@njit(cache=True, error_model="numpy")
def _gamma(n):  # pragma: no cover - compiled
    """Higham's ``gamma_n`` in float64 (``u = 2^-53``), as ``rounding.rounding_gamma``."""
    nu = n * (2.0**-53)
    return nu / (1.0 - nu)


@njit(cache=True, error_model="numpy")
def posterior_bounds_terms(G, alpha, beta, mu, Phi_t, eps):  # pragma: no cover - compiled
    """Everything :func:`~bayes_fdi.rvm.sbl.posterior_bounds.posterior_context` computes, in one
    call: ``(ok, abar, root, Hb, gradient, gradient_error, bounds)`` with ``bounds`` holding
    ``(Hb_F, lam, psd, mu_error_w)``; ``ok`` False where ``||Hb||_F^2`` is not finite or above
    ``1e300`` (the caller then takes the torch operations)."""
    M = alpha.shape[0]
    abar = np.empty(M)
    root = np.empty(M)
    for i in range(M):
        abar[i] = alpha[i] / beta
        root[i] = math.sqrt(abar[i])
    Hb = np.empty((M, M))
    gradient = np.empty(M)
    gradient_error = np.empty(M)
    bounds = np.empty(4)
    fro_sq = posterior_terms(G, abar, mu, Phi_t, Hb, gradient, gradient_error)
    if not (math.isfinite(fro_sq) and fro_sq <= 1e300):
        return False, abar, root, Hb, gradient, gradient_error, bounds
    bounds[0] = math.sqrt(fro_sq) * (1.0 + _gamma(M * M + 1))
    a_min = abar.min()
    low = a_min - M * eps
    gamma2 = _gamma(2)
    if low > 0:
        bounds[1] = (1.0 / low) * (1.0 + gamma2)
        bounds[2] = (a_min / low) * (1.0 + gamma2)
    else:
        bounds[1] = bounds[2] = math.inf
    g_sq = 0.0
    e_sq = 0.0
    gamma_m3 = _gamma(M + 3)
    for i in range(M):
        gradient_error[i] *= gamma_m3  # was |Hb| |mu| + |Phi_t|
        g_sq += (gradient[i] / root[i]) ** 2
        e_sq += (gradient_error[i] / root[i]) ** 2
    g_w = math.sqrt(g_sq) + math.sqrt(e_sq)
    bounds[3] = math.sqrt(bounds[2]) * g_w * (1.0 + _gamma(M + 2))
    return True, abar, root, Hb, gradient, gradient_error, bounds


@njit(cache=True, error_model="numpy")
def reestimate_factor(L, k, r):  # pragma: no cover - compiled
    """Update ``L`` (lower, ``(M, M)``, in place) from ``I + D G D`` to ``I + D' G D'`` where
    only ``d_k`` changed, by ``d_k' = r d_k`` (module docstring).

    Returns the amplification ``max_j L_jj / L'_jj`` of the rounding (1 for an update), or
    ``inf`` when the downdate breaks down (the caller then refactorises afresh).
    """
    M = L.shape[0]
    for j in range(k + 1):
        L[k, j] *= r
    sigma = 1.0 - r * r  # + for an update, - for a downdate
    if sigma == 0.0:
        return 1.0
    sign = 1.0 if sigma > 0.0 else -1.0
    x = np.zeros(M)
    x[k] = math.sqrt(abs(sigma))
    amp = 1.0
    for j in range(k, M):
        ljj = L[j, j]
        xj = x[j]
        rr = ljj * ljj + sign * xj * xj
        if not rr > 0.0:
            return math.inf
        rj = math.sqrt(rr)
        c = rj / ljj
        s = xj / ljj
        L[j, j] = rj
        if sign < 0.0 and ljj / rj > amp:
            amp = ljj / rj
        for i in range(j + 1, M):
            lij = (L[i, j] + sign * s * x[i]) / c
            L[i, j] = lij
            x[i] = c * x[i] - s * lij
    return amp


@njit(cache=True, error_model="numpy")
def screened_rows(L, d, H, Z, diag, bt, mu, grad, scalars, C, out):  # pragma: no cover
    """Screening factors of a few rows from a fresh factor, as
    :func:`~bayes_fdi.rvm.sbl.screening.screened_factors` followed by
    :func:`~bayes_fdi.rvm.sbl.screening.gaussian_screened_Q` with exact stored products
    (``z_error = 0``, ``b^T t`` error 0).

    ``Z`` (``(K, M)``), ``diag``, ``bt``, ``H`` and ``grad`` are in the units of those functions
    (``beta`` times the stored values). ``scalars`` holds ``(trace, H_F, g_norm, g_err,
    mu_norm, gamma_M2, gamma_2M4, gamma_M3)``. Fills ``C`` (``(K, M)``, the solve
    coefficients) and ``out`` (``(K, 5)``: ``S``, its error bound, ``Q``, its error bound, the
    bound of the solve residual ``||H c - z||``) and returns nothing.
    """
    trace, H_F, g_norm, g_err, mu_norm = scalars[0], scalars[1], scalars[2], scalars[3], scalars[4]
    gM2, g2M4, gM3 = scalars[5], scalars[6], scalars[7]
    K, M = Z.shape
    y = np.empty(M)
    root_trace = math.sqrt(trace)
    for r in range(K):
        # c = D (L L^T)^-1 D z: forward, then backward substitution
        for i in range(M):
            v = d[i] * Z[r, i]
            for j in range(i):
                v -= L[i, j] * y[j]
            y[i] = v / L[i, i]
        _solve_upper_transposed(L, y)
        c_sq = 0.0
        z_sq = 0.0
        for i in range(M):
            C[r, i] = y[i] * d[i]
            c_sq += C[r, i] * C[r, i]
            z_sq += Z[r, i] * Z[r, i]
        # S = diag - 2 z^T c + c^T H c (stationary in c), residual H c - z, Q = bt - z^T mu + c^T g
        s = 0.0
        res_sq = 0.0
        q_mu = 0.0
        q_g = 0.0
        for i in range(M):
            hc = 0.0
            for j in range(M):
                hc += H[i, j] * C[r, j]
            w = hc - 2.0 * Z[r, i]
            s += C[r, i] * w
            res_sq += (w + Z[r, i]) * (w + Z[r, i])
            q_mu += Z[r, i] * mu[i]
            q_g += C[r, i] * grad[i]
        c_norm = math.sqrt(c_sq)
        z_norm = math.sqrt(z_sq)
        r_norm = math.sqrt(res_sq) + gM2 * (H_F * c_norm + z_norm)
        solve_error = root_trace * r_norm
        out[r, 0] = diag[r] + s
        out[r, 1] = solve_error * solve_error + g2M4 * (
            abs(diag[r]) + c_norm * (2.0 * z_norm + H_F * c_norm)
        )
        out[r, 2] = bt[r] - q_mu + q_g
        out[r, 3] = (
            solve_error * ((g_norm + g_err) * root_trace)
            + c_norm * g_err
            + gM3 * (abs(bt[r]) + z_norm * mu_norm + c_norm * g_norm)
        )
        out[r, 4] = r_norm


@njit(cache=True, error_model="numpy")
def refresh_rows(
    L, d, Hb, beta, Z, rows, unit, Bt_t, mu, gradient, gradient_error, lam, min_root, carried
):  # pragma: no cover - compiled
    """The carried factors of ``rows`` afresh from the fresh factor, as
    :meth:`~bayes_fdi.rvm.sbl.tracked_factors.TrackedFactors.refresh` of a few rows: the inputs
    of :func:`screened_rows` in ``beta`` units (``H = beta Hb``, the stored products ``Z``
    (``(P, M)``) of ``rows``, ``beta b^T b``, ``beta b^T t``, ``beta`` times the gradient and
    its error bound), then the rows of ``carried = (C, S, Q, S_err, Q_err, rho, nu)`` written in
    place (``S, Q`` and bounds divided by ``beta``, ``rho = ||r|| / (beta min_root)``,
    ``nu = ||c|| (1 + gamma_{M+1})``)."""
    C_all, S, Q, S_err, Q_err, rho, nu = carried
    M = d.shape[0]
    K = rows.shape[0]
    H = np.empty((M, M))
    fro = 0.0
    for i in range(M):
        for j in range(M):
            h = beta * Hb[i, j]
            H[i, j] = h
            fro += h * h
    grad = np.empty(M)
    g_sq = 0.0
    e_sq = 0.0
    m_sq = 0.0
    for i in range(M):
        grad[i] = beta * gradient[i]
        e = beta * gradient_error[i]
        g_sq += grad[i] * grad[i]
        e_sq += e * e
        m_sq += mu[i] * mu[i]
    scalars = np.empty(8)
    scalars[0] = lam / beta
    scalars[1] = math.sqrt(fro) * (1.0 + _gamma(M * M))
    scalars[2] = math.sqrt(g_sq)
    scalars[3] = math.sqrt(e_sq)
    scalars[4] = math.sqrt(m_sq)
    scalars[5] = _gamma(M + 2)
    scalars[6] = _gamma(2 * M + 4)
    scalars[7] = _gamma(M + 3)
    Zr = np.empty((K, M))
    diag = np.empty(K)
    bt = np.empty(K)
    for r in range(K):
        i = rows[r]
        for j in range(M):
            Zr[r, j] = beta * Z[i, j]
        diag[r] = beta * unit[i]
        bt[r] = beta * Bt_t[i]
    C = np.empty((K, M))
    out = np.empty((K, 5))
    screened_rows(L, d, H, Zr, diag, bt, mu, grad, scalars, C, out)
    grow = 1.0 + _gamma(M + 1)
    for r in range(K):
        i = rows[r]
        c_sq = 0.0
        for j in range(M):
            C_all[i, j] = C[r, j]
            c_sq += C[r, j] * C[r, j]
        S[i] = out[r, 0] / beta
        S_err[i] = out[r, 1] / beta
        Q[i] = out[r, 2] / beta
        Q_err[i] = out[r, 3] / beta
        rho[i] = out[r, 4] / (beta * min_root)
        nu[i] = math.sqrt(c_sq) * grow


@njit(cache=True, error_model="numpy")
def reestimate_terms(
    L, d, Hb, root, mu, beta, k, a_old, a_new, Hb_F, psd, mu_error_w
):  # pragma: no cover - compiled
    """``(ok, s, scalars)`` of a re-estimation of position ``k`` from ``abar_k = a_old`` to
    ``a_new``: the computed ``s = Hb^-1 e_k`` (a solve with the factor ``L, d`` of
    ``beta Hb``) and the scalars ``(kappa, kappa_err, kap, e_scale, mk, e_mu, g4, grow, rho_ack,
    rho_aa, rho_nu, s_norm, g2)`` of :func:`~bayes_fdi.rvm.sbl.tracked_kernels.reestimate_rows`,
    by the formulas of
    :meth:`~bayes_fdi.rvm.sbl.tracked_factors.TrackedFactors.reestimate`; ``ok`` False where
    the update's denominator is not bounded away from 0 (the caller then refreshes)."""
    M = d.shape[0]
    y = np.zeros(M)
    for i in range(k, M):  # forward substitution from d_k e_k (zero above k)
        v = d[i] if i == k else 0.0
        for j in range(k, i):
            v -= L[i, j] * y[j]
        y[i] = v / L[i, i]
    _solve_upper_transposed(L, y)
    s = np.empty(M)
    for i in range(M):
        s[i] = beta * (d[i] * y[i])
    gM2 = _gamma(M + 2)
    g2 = _gamma(2)
    g4 = _gamma(4)
    root_new_k = math.sqrt(a_new)
    s_sq = 0.0
    sA_sq = 0.0
    rw_sq = 0.0
    rn_sq = 0.0
    min_root = math.inf
    min_root_new = math.inf
    for i in range(M):
        h = 0.0
        for j in range(M):
            h += Hb[i, j] * s[j]
        r = h - 1.0 if i == k else h
        s_sq += s[i] * s[i]
        sA_sq += (s[i] * root[i]) ** 2
        rw_sq += (r / root[i]) ** 2
        rn = root_new_k if i == k else root[i]
        rn_sq += (r / rn) ** 2
        min_root = min(min_root, root[i])
        min_root_new = min(min_root_new, rn)
    s_norm = math.sqrt(s_sq)
    r_round = gM2 * (Hb_F * s_norm + 1.0)
    r_w = math.sqrt(rw_sq) * (1.0 + gM2) + r_round / min_root
    sA = math.sqrt(sA_sq) * (1.0 + gM2) + math.sqrt(psd) * r_w
    es_k = math.sqrt(psd) * sA * r_w  # |s_k - exact s_k|
    delta = a_new - a_old
    den = 1.0 + delta * s[k]
    den_lo = den - abs(delta) * es_k
    scalars = np.empty(13)
    if not (den_lo > 0 and math.isfinite(den) and math.isfinite(sA)):
        return False, s, scalars
    kappa = delta / den
    kappa_err = delta * delta * es_k / (den * den_lo) + g4 * abs(kappa)
    r_new = math.sqrt(rn_sq) + r_round / min_root_new
    to_w = (Hb_F + abs(delta)) / min_root_new  # ||A'^-1/2 H_'|| bound
    scalars[0] = kappa
    scalars[1] = kappa_err
    scalars[2] = abs(kappa) + kappa_err
    scalars[3] = sA * math.sqrt(psd)  # e = e_scale rho bounds |c_k - exact c_k|
    scalars[4] = mu[k]
    scalars[5] = sA * mu_error_w  # bound of |mu_k - exact mu_k|
    scalars[6] = g4
    scalars[7] = max(1.0, math.sqrt(a_old / a_new))
    scalars[8] = g4 * abs(delta) / root_new_k + abs(kappa) * r_new
    scalars[9] = (2.0**-53) * to_w * s_norm
    scalars[10] = to_w * g2
    scalars[11] = s_norm
    scalars[12] = g2
    return True, s, scalars

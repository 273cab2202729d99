r"""Screening factors of every candidate carried from iteration to iteration, with rigorous
error bounds (:class:`TrackedFactors`), for the fast Gaussian solver.

:func:`bayes_fdi.rvm.sbl.screening.screened_factors` recomputes the screening factors of all
``P`` candidates from a fresh factor at ``O(P M^2)`` per iteration. Here they are *carried*:
each add / re-estimate / delete changes the posterior precision by a rank-one or bordering step,
and the candidates' solve coefficients ``c_m`` follow by one rank-one update of the ``P x M``
matrix ``C`` (``O(P M)``), as in SparseBayes. Unlike SparseBayes, every carried
value comes with a bound of its error that grows with each update:

* ``rho_m >= ||A^-1/2 (H c_m - z_m)||``: the residual of the carried coefficients against the
  *current* precision, weighted by the prior precisions (the updates' exact algebra cancels;
  what remains is the computed solves' residuals and the rounding of the update, both
  bounded). The weights make the bounds independent of the spread of ``alpha``: since
  ``H >= A``, ``|v^T H^-1 r| <= ||A^1/2 H^-1 v|| rho`` and ``||A^1/2 H^-1 A^1/2|| <= 1``;
* ``e_S, e_Q``: bounds of the carried ``S_m, Q_m`` against their exact values for the stored
  products ``z_m``; each update adds the effect of the coefficient error (from ``rho_m``) and
  the update's own rounding (Higham's ``gamma_n``);
* a noise update (``beta``) changes the precision in all ``M`` diagonal entries: the
  coefficients are kept, the factors move by the first-order term computed exactly
  (``c^T Delta c``, ``c^T Delta mu``) and the second-order rest goes into the bounds and into
  ``rho``.

The decisions are still taken on exact factors (:mod:`bayes_fdi.rvm.sbl.verification`): the
carried factors and bounds only decide which candidates need an exact look, so they change the
cost, never the path of actions. Rows that could win are first screened afresh from the fresh
factor (:meth:`TrackedFactors.tighten`, ``O(M^2)`` each); when the bounds have grown so loose
that many rows need it, the solver asks for a full refresh (:meth:`TrackedFactors.refresh`, the
``O(P M^2)`` screening). Everything is kept in ``beta``-free units:
``H_ = diag(alpha / beta) + Phi^T Phi``, ``z_m = Phi^T b_m``; ``S = beta S_``, ``Q = beta Q_``
(the posterior and its bounds: :mod:`bayes_fdi.rvm.sbl.posterior_bounds`).

Imports :mod:`~bayes_fdi.rvm.sbl.capacity`, :mod:`~bayes_fdi.rvm.sbl.posterior_bounds`,
:mod:`~bayes_fdi.rvm.sbl.rounding` and
:mod:`~bayes_fdi.rvm.sbl.screening`. Written by hand: no maintained library implements Tipping &
Faul's solver, nor error bounds for its updates.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from bayes_fdi.rvm.sbl.capacity import grown_capacity
from bayes_fdi.rvm.sbl.posterior_bounds import Posterior
from bayes_fdi.rvm.sbl.rounding import rounding_gamma, thin_matmul
from bayes_fdi.rvm.sbl.screening import gaussian_screened_Q, screened_factors
from bayes_fdi.rvm.sbl.tracked_compiled import (
    reestimate_compiled,
    refresh_rows_compiled,
    rescale_compiled,
    screen_compiled,
)

__all__ = ["COMPILED_UPDATE", "TrackedFactors"]

#: Run the re-estimation update compiled (:mod:`~bayes_fdi.rvm.sbl.tracked_kernels`) on CPU
#: float64; tests clear it to compare with the torch update.
COMPILED_UPDATE = True
#: at most this many rows are refreshed by the compiled kernel (more go through torch's products)
_COMPILED_ROWS = 32
#: the carried bounds are used while the stored Gram matrix's error inflates them by at most
#: this factor (``psd``, see :mod:`bayes_fdi.rvm.sbl.posterior_bounds`); beyond it the solver
#: screens directly
_MAX_PSD = 2.0


class TrackedFactors:
    """Carried ``S_m, Q_m`` of all ``P`` candidates with error bounds (module docstring).

    Parameters
    ----------
    n_basis : int
        ``P``.
    capacity : int
        Initial number of columns of ``C``.
    unit : Tensor
        ``(P,)`` stored ``b_m^T b_m`` of the normalised columns (0 for unusable ones).
    Bt_t : Tensor
        ``(P,)`` stored ``b_m^T t``.
    """

    def __init__(self, n_basis: int, capacity: int, unit: Tensor, Bt_t: Tensor) -> None:
        P = n_basis
        self.unit, self.Bt_t = unit, Bt_t
        self.dtype = unit.dtype
        self.C = unit.new_zeros(P, capacity)
        self.S, self.Q = unit.new_zeros(P), unit.new_zeros(P)
        inf = unit.new_full((P,), math.inf)
        self.S_err, self.Q_err, self.rho, self.nu = inf, inf.clone(), inf.clone(), inf.clone()
        self.needs_refresh = True
        self.stale: set[int] = set()
        self._u = torch.finfo(self.dtype).eps / 2.0
        # CPU float64: the re-estimation update runs compiled (tracked_kernels)
        self._compiled = (
            COMPILED_UPDATE and unit.device.type == "cpu" and self.dtype == torch.float64
        )

    # ----------------------------------------------------------------------- fresh values
    def refresh(self, post: Posterior, Z: Tensor, rows: Tensor | None = None) -> None:
        """Recompute the factors of ``rows`` (all when None) from the fresh factor, with the
        stationary forms of :mod:`~bayes_fdi.rvm.sbl.screening` (``O(K M^2)`` for ``K`` rows).
        ``Z`` is the stored ``P x M`` matrix of products ``B^T Phi``."""
        M = Z.shape[1]
        beta = post.beta
        if (
            rows is not None
            and self._compiled
            and rows.numel() <= _COMPILED_ROWS
            and math.isfinite(post.lam)
        ):
            refresh_rows_compiled(post, Z, rows, self.unit, self.Bt_t, self.carried())
            return
        Zr = Z if rows is None else Z[rows]
        unit = self.unit if rows is None else self.unit[rows]
        Bt_t = self.Bt_t if rows is None else self.Bt_t[rows]
        zero = Zr.new_zeros(M)
        # lambda_max(H^-1) <= lam / beta (screened_factors falls back on tr(H^-1) without it)
        trace = post.lam / beta if math.isfinite(post.lam) else None
        scr = screened_factors(
            post.fac, beta * post.Hb, beta * Zr, beta * unit, z_error=zero, trace=trace
        )
        Q, Q_err = gaussian_screened_Q(
            scr,
            beta * Zr,
            beta * Bt_t,
            0.0,
            post.mu,
            beta * post.gradient,
            beta * post.gradient_error,
            zero,
        )
        rho = scr.residual / (beta * float(post.root.min()))  # ||A^-1/2 r|| <= ||r|| / min root
        nu = scr.c_norm * (1.0 + rounding_gamma(M + 1, self.dtype))
        if rows is None:
            if self.C.shape[1] < M:
                cap = grown_capacity(self.C.shape[1], M, self.C.shape[0])
                self.C = self.C.new_zeros(self.C.shape[0], cap)
            self.C[:, :M] = scr.C
            self.S, self.S_err = scr.S / beta, scr.S_error / beta
            self.Q, self.Q_err = Q / beta, Q_err / beta
            self.rho, self.nu = rho, nu
            self.needs_refresh = False
            self.stale.clear()
        else:
            self.C[rows, :M] = scr.C
            self.S[rows], self.S_err[rows] = scr.S / beta, scr.S_error / beta
            self.Q[rows], self.Q_err[rows] = Q / beta, Q_err / beta
            self.rho[rows], self.nu[rows] = rho, nu

    def carried(self) -> tuple[Tensor, ...]:
        """``(C, S, Q, S_err, Q_err, rho, nu)``, the carried arrays (updated in place by the
        compiled kernels)."""
        return self.C, self.S, self.Q, self.S_err, self.Q_err, self.rho, self.nu

    @staticmethod
    def usable(post: Posterior) -> bool:
        """Whether the carried bounds can be used with this posterior: they rest on
        ``H_ >= A / psd``, which needs every ``alpha / beta`` well above the stored Gram
        matrix's error ``M eps`` (very precise data make some ``alpha / beta`` tiny)."""
        return math.isfinite(post.lam) and post.psd <= _MAX_PSD

    def direct(self, post: Posterior, Z: Tensor, eps: float, bt_error: float) -> tuple[Tensor, ...]:
        """``S, Q`` (``beta`` units) of all rows screened from the fresh factor with the
        complete bounds of :mod:`~bayes_fdi.rvm.sbl.screening` (input errors through
        ``tr(H^-1)``), for a posterior the carried bounds cannot serve (:meth:`usable`); the
        carried values are refreshed at the next usable posterior."""
        M = Z.shape[1]
        beta = post.beta
        z_err = Z.new_full((M,), beta * eps)
        scr = screened_factors(post.fac, beta * post.Hb, beta * Z, beta * self.unit, z_error=z_err)
        Q, Q_err = gaussian_screened_Q(
            scr,
            beta * Z,
            beta * self.Bt_t,
            beta * bt_error,
            post.mu,
            beta * post.gradient,
            beta * post.gradient_error,
            z_err,
        )
        self.needs_refresh = True
        return scr.S, Q, scr.S_error, Q_err

    def prepare(self, post: Posterior, Z: Tensor) -> None:
        """Bring the carried values up to date before a decision: a full refresh when asked
        for, else the stale rows (changed stored products, noise updates) afresh."""
        if self.needs_refresh:
            self.refresh(post, Z)
        elif self.stale:
            rows = torch.tensor(sorted(self.stale), dtype=torch.long, device=Z.device)
            self.refresh(post, Z, rows)
            self.stale.clear()

    def screen(
        self, post: Posterior, eps: float, bt_error: float, rows: Tensor | None = None
    ) -> tuple[Tensor, ...]:
        """``S, Q`` (in ``beta`` units) with bounds of their distance to the exact factors.

        Adds to the carried bounds the effect of the stored products' own error: each entry of
        ``z_m`` within ``eps`` of the exact one moves ``S_`` by at most ``2 ||c*|| ze +
        lam ze^2`` (``ze = sqrt(M) eps``, ``||c* - c|| <= lam^1/2 rho``) and ``Q_`` (linear in
        ``z``) by ``eps ||mu||_1``; ``b^T t`` is within ``bt_error``.
        """
        beta, M = post.beta, post.abar.numel()
        if self._compiled:  # one pass (tracked_compiled), the same numbers
            return screen_compiled(post, eps, bt_error, rows, self.carried())
        S, Q, S_err, Q_err, rho, nu = (
            (v if rows is None else v[rows])
            for v in (self.S, self.Q, self.S_err, self.Q_err, self.rho, self.nu)
        )
        ze = math.sqrt(M) * eps
        c_exact = nu + math.sqrt(post.lam * post.psd) * rho
        S_err = S_err + 2.0 * ze * c_exact + post.lam * ze * ze
        mu_error = math.sqrt(post.lam) * post.mu_error_w
        mu1 = float(post.mu.abs().sum()) + math.sqrt(M) * mu_error
        Q_err = Q_err + eps * mu1 + bt_error
        return beta * S, beta * Q, beta * S_err, beta * Q_err

    def tighten(
        self, post: Posterior, Z: Tensor, rows: Tensor, eps: float, bt_error: float
    ) -> tuple[Tensor, ...]:
        """:meth:`refresh` the ``rows`` (``O(K M^2)``) and :meth:`screen` them: the tight
        bounds of a fresh factor for the few candidates that could win."""
        self.refresh(post, Z, rows)
        return self.screen(post, eps, bt_error, rows)

    # ----------------------------------------------------------------------- updates
    def _unit_solve(self, post: Posterior, k: int) -> tuple[Tensor, Tensor, float, float]:
        """``s = Hb^-1 e_k``, the computed residual ``Hb s - e_k``, a bound of its rounding
        and ``||A^1/2 s*||`` for the exact ``s*`` (upper bound)."""
        M = post.abar.numel()
        e = post.abar.new_zeros(M)
        e[k] = 1.0
        s = post.solve(e)
        r = post.Hb @ s - e
        s_norm = float(torch.linalg.vector_norm(s))
        r_round = rounding_gamma(M + 2, self.dtype) * (post.Hb_F * s_norm + 1.0)
        r_w = post.weighted(r) + r_round / float(post.root.min())
        sA = float(torch.linalg.vector_norm(s * post.root)) * (1.0 + rounding_gamma(M + 2, s.dtype))
        return s, r, r_round, sA + math.sqrt(post.psd) * r_w

    def reestimate(self, post: Posterior, k: int, new_alpha: float) -> None:
        """``alpha_k`` (position ``k``) becomes ``new_alpha``: ``H_' = H_ + delta e_k e_k^T``.

        Exact algebra (``s = H_^-1 e_k``, ``kappa = delta / (1 + delta s_k)``):
        ``c' = c - kappa c_k s``, ``S_' = S_ + kappa c_k^2``, ``Q_' = Q_ + kappa c_k mu_k``.
        """
        if self.needs_refresh:  # the next full refresh rewrites everything
            return
        if self._compiled:  # the scalars, then one pass over the rows (tracked_compiled)
            if not reestimate_compiled(post, k, new_alpha, self.carried()):
                self.needs_refresh = True
            return
        M = post.abar.numel()
        dt = self.dtype
        g2, g4 = rounding_gamma(2, dt), rounding_gamma(4, dt)
        a_old = float(post.abar[k])
        a_new = new_alpha / post.beta
        delta = a_new - a_old
        s, r_s, r_round, sA = self._unit_solve(post, k)
        r_w = post.weighted(r_s) + r_round / float(post.root.min())
        es_k = math.sqrt(post.psd) * sA * r_w  # |s_k - exact s_k|
        sk = float(s[k])
        den = 1.0 + delta * sk
        den_lo = den - abs(delta) * es_k
        if not (den_lo > 0 and math.isfinite(den) and math.isfinite(sA)):
            self.needs_refresh = True
            return
        kappa = delta / den
        kappa_err = delta * delta * es_k / (den * den_lo) + g4 * abs(kappa)
        kap = abs(kappa) + kappa_err
        e_scale = sA * math.sqrt(post.psd)  # e = e_scale rho bounds |c_k - exact c_k|
        mk = float(post.mu[k])
        e_mu = sA * post.mu_error_w  # bound of |mu_k - exact mu_k|
        # residual in the new weights: entry k's weight changes by (a_old / a_new)^1/2
        root_new = post.root.clone()
        root_new[k] = math.sqrt(a_new)
        grow = max(1.0, math.sqrt(a_old / a_new))
        r_new = float(torch.linalg.vector_norm(r_s / root_new)) + r_round / float(root_new.min())
        s_norm = float(torch.linalg.vector_norm(s))
        to_w = (post.Hb_F + abs(delta)) / float(root_new.min())  # ||A'^-1/2 H_'|| bound
        rho_ack = g4 * abs(delta) / math.sqrt(a_new) + abs(kappa) * r_new
        rho_aa = self._u * to_w * s_norm
        rho_nu = to_w * g2
        ck = self.C[:, k].clone()
        ack = ck.abs()
        e = e_scale * self.rho
        dS = kappa * ck * ck
        dQ = (kappa * mk) * ck
        self.S += dS
        self.Q += dQ
        self.S_err += (
            kappa_err * ck * ck + kap * e * (2.0 * ack + e) + g4 * (self.S.abs() + dS.abs())
        )
        self.Q_err += (
            kappa_err * abs(mk) * ack
            + kap * (e_mu * ack + (abs(mk) + e_mu) * e)
            + g4 * (self.Q.abs() + dQ.abs())
        )
        a = -kappa * ck
        self.C[:, :M].addr_(a, s)
        aa = a.abs()
        self.rho = self.rho * grow + ack * rho_ack + aa * rho_aa + rho_nu * (self.nu + aa * s_norm)
        self.nu = (self.nu + aa * s_norm) * (1.0 + g2)

    def delete(self, post: Posterior, k: int) -> None:
        """Remove position ``k``: ``c' = (c - (c_k / s_k) s)`` without entry ``k``,
        ``S_' = S_ + c_k^2 / s_k``, ``Q_' = Q_ + mu_k c_k / s_k`` (``s = H_^-1 e_k``)."""
        if self.needs_refresh:  # the next full refresh rewrites everything
            return
        M = post.abar.numel()
        g2, g4 = rounding_gamma(2, self.dtype), rounding_gamma(4, self.dtype)
        s, r_s, r_round, sA = self._unit_solve(post, k)
        r_w = post.weighted(r_s) + r_round / float(post.root.min())
        es_k = math.sqrt(post.psd) * sA * r_w
        sk = float(s[k])
        sk_lo = sk - es_k
        if not (sk_lo > 0 and math.isfinite(sA)):
            self.needs_refresh = True
            self._drop(k, M)
            return
        ck = self.C[:, k].clone()
        ack = ck.abs()
        e = (sA * math.sqrt(post.psd)) * self.rho
        mk = float(post.mu[k])
        e_mu = sA * post.mu_error_w
        inv_err = es_k / (sk * sk_lo) + g4 / sk  # bound of |1/s_k - 1/exact s_k|
        dS = ck * ck / sk
        dQ = (mk / sk) * ck
        self.S += dS
        self.Q += dQ
        self.S_err += (
            ck * ck * inv_err + e * (2.0 * ack + e) / sk_lo + g4 * (self.S.abs() + dS.abs())
        )
        self.Q_err += (
            ack * abs(mk) * inv_err
            + (e_mu * ack + (abs(mk) + e_mu) * e) / sk_lo
            + g4 * (self.Q.abs() + dQ.abs())
        )
        a = -ck / sk
        self.C[:, :M].addr_(a, s)
        s_norm = float(torch.linalg.vector_norm(s))
        aa = a.abs()
        to_w = post.Hb_F / float(post.root.min())
        col_k = float(torch.linalg.vector_norm(post.Hb[:, k])) / float(post.root.min())
        self.rho = (
            self.rho
            + aa * r_w
            + aa * (self._u * to_w * s_norm)
            + to_w * g2 * (self.nu + aa * s_norm)
            + col_k * 2.0 * g4 * ack
        )
        self.nu = (self.nu + aa * s_norm) * (1.0 + g2)
        self._drop(k, M)

    def _drop(self, k: int, M: int) -> None:
        if k < M - 1:
            self.C[:, k : M - 1] = self.C[:, k + 1 : M].clone()

    def add(
        self,
        post: Posterior,
        h: Tensor,
        d: float,
        new_alpha: float,
        z_new: Tensor,
        bt_t_i: float,
    ) -> None:
        """Append a column with stored Gram entries ``h`` (``(M,)``), ``b_i^T b_i = d``,
        precision ``new_alpha`` and stored products ``z_new`` (``(P,)``, the new column of
        ``B^T Phi``) and stored ``b_i^T t = bt_t_i``. With ``w = H_^-1 h`` and
        ``s_c = alpha_i / beta + d - h^T w``:
        ``xi_m = (z_new_m - h^T c_m) / s_c``, ``c' = [c - xi w, xi]``, ``S_' = S_ - s_c xi^2``,
        ``Q_' = Q_ - xi Q_i`` (``Q_i`` the new column's own factor)."""
        if self.needs_refresh:  # the next full refresh rewrites everything
            return
        M = post.abar.numel()
        dt = self.dtype
        u = self._u
        g2, g4 = rounding_gamma(2, dt), rounding_gamma(4, dt)
        gM = rounding_gamma(M + 3, dt)
        if self.C.shape[1] < M + 1:
            cap = grown_capacity(self.C.shape[1], M + 1, self.C.shape[0])
            self.C = torch.cat(
                [self.C, self.C.new_zeros(self.C.shape[0], cap - self.C.shape[1])], 1
            )
        w = post.solve(h)
        r_w = post.Hb @ w - h
        w_norm = float(torch.linalg.vector_norm(w))
        h_norm = float(torch.linalg.vector_norm(h))
        min_root = float(post.root.min())
        eps_w = post.weighted(r_w) + gM * (post.Hb_F * w_norm + h_norm) / min_root
        wA = float(torch.linalg.vector_norm(w * post.root)) * (1.0 + gM)
        wA += math.sqrt(post.psd) * eps_w  # ||A^1/2 w*||
        abar_i = new_alpha / post.beta
        # stationary in w: s_c = abar_i + d - 2 h^T w + w^T Hb w, within psd eps_w^2
        s_c = abar_i + d - 2.0 * float(h @ w) + float(w @ (post.Hb @ w))
        sc_err = post.psd * eps_w * eps_w + rounding_gamma(2 * M + 4, dt) * (
            abar_i + abs(d) + 2.0 * h_norm * w_norm + post.Hb_F * w_norm * w_norm
        )
        sc_lo = s_c - sc_err
        # the new column's own Q_, stationary in w and mu: within psd eps_w ||gradient||_w
        g_w = post.mu_error_w  # = psd^1/2 ||A^-1/2 gradient|| (rounding included)
        mu_norm = float(torch.linalg.vector_norm(post.mu))
        g_norm = float(torch.linalg.vector_norm(post.gradient))
        g_err = float(torch.linalg.vector_norm(post.gradient_error))
        q_i = bt_t_i - float(h @ post.mu) + float(w @ post.gradient)
        qi_err = (
            math.sqrt(post.psd) * eps_w * g_w
            + w_norm * g_err
            + gM * (abs(bt_t_i) + h_norm * mu_norm + w_norm * g_norm)
        )
        if not (sc_lo > 0 and math.isfinite(s_c) and math.isfinite(wA)):
            self.needs_refresh = True
            self.C[:, M] = 0.0
            return
        Cm = self.C[:, :M]
        num = z_new - Cm @ h
        num_round = gM * (z_new.abs() + h_norm * self.nu)
        num_err = wA * self.rho + num_round
        xi = num / s_c
        axi = xi.abs()
        xi_err = (num_err + axi * sc_err) / sc_lo + u * axi
        self.S -= s_c * xi * xi
        self.S_err += (
            sc_err * xi * xi
            + (s_c + sc_err) * xi_err * (2.0 * axi + xi_err)
            + g4 * (self.S.abs() + s_c * xi * xi)
        )
        self.Q -= q_i * xi
        self.Q_err += (
            xi_err * abs(q_i) + (axi + xi_err) * qi_err + g4 * (self.Q.abs() + abs(q_i) * axi)
        )
        Cm.addr_(-xi, w)
        self.C[:, M] = xi
        to_w = post.Hb_F / min_root
        top = self.rho + axi * eps_w + to_w * g2 * (self.nu + axi * w_norm)
        bottom = (
            num_round
            + u * axi * s_c
            + axi * (w_norm * eps_w * min_root + sc_err)
            + h_norm * g2 * (self.nu + axi * w_norm)
        ) / math.sqrt(abar_i)
        self.rho = top + bottom
        self.nu = (self.nu + axi * w_norm) * (1.0 + g2) + axi

    def rescale(self, old: Posterior, new: Posterior, max_relative: float) -> None:
        """A noise update: ``abar`` moves by ``Delta = abar' - abar`` (all entries). The
        coefficients are kept; ``S_`` moves by ``c^T Delta c`` and ``Q_`` by ``c^T Delta mu'``
        (exact but for ``-c*^T Delta H_'^-1 Delta c*``, at most ``||A'^-1/2 Delta c*||^2``,
        and the coefficient error, both in the bounds), ``rho`` by ``||A'^-1/2 Delta c||``.
        A relative change above ``max_relative`` asks for a refresh instead."""
        if self.needs_refresh:  # the next full refresh rewrites everything
            return
        M = new.abar.numel()
        dt = self.dtype
        Delta = new.abar - old.abar
        rel = float((Delta.abs() / old.abar).max())
        if rel > max_relative or not math.isfinite(new.lam * old.lam):
            self.needs_refresh = True
            return
        gM = rounding_gamma(M + 4, dt)
        if self._compiled:  # one pass over the rows (tracked_kernels)
            rescale_compiled(old, new, Delta, gM, self.carried())
            return
        Cm = self.C[:, :M]
        # one pass over C o C: dS = (C o C) Delta, ||A^-1/2 Delta c||^2, ||A'^-1/2 Delta c||^2
        sq = Delta * Delta
        prods = thin_matmul(Cm * Cm, torch.stack([Delta, sq / old.abar, sq / new.abar], dim=1))
        dS = prods[:, 0]
        dc_old = prods[:, 1].clamp_min(0.0).sqrt() * (1.0 + gM)
        dc_new = prods[:, 2].clamp_min(0.0).sqrt() * (1.0 + gM)
        m_old = float((Delta.abs() / old.abar).max())
        m_cross = float((Delta.abs() / (old.root * new.root)).max())
        d_max = float(Delta.abs().max())
        grow = float((old.root / new.root).max())
        rho = self.rho * math.sqrt(old.psd)  # bounds ||A^1/2 (c - c*)||
        d_mu = Delta * new.mu
        dQ = Cm @ d_mu
        dmu = float(torch.linalg.vector_norm(d_mu / old.root))
        dmu += m_cross * new.mu_error_w  # ||A^-1/2 Delta mu'*||
        d_mu_norm = float(torch.linalg.vector_norm(d_mu))
        self.S += dS
        self.S_err += (
            rho * (2.0 * dc_old + m_old * rho)
            + new.psd * (dc_new + m_cross * rho).square()
            + gM * (d_max * self.nu * self.nu + self.S.abs())
        )
        self.Q += dQ
        self.Q_err += (
            rho * dmu + dc_new * new.mu_error_w + gM * (self.nu * d_mu_norm + self.Q.abs())
        )
        self.rho = self.rho * grow + dc_new

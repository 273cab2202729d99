"""The compiled paths of the carried screening factors' re-estimation and noise updates, fresh
rows and screening (:func:`reestimate_compiled`, :func:`rescale_compiled`,
:func:`refresh_rows_compiled`, :func:`screen_compiled`), on CPU float64.

:class:`~bayes_fdi.rvm.sbl.tracked_factors.TrackedFactors` calls these instead of its torch
operations where its arrays are CPU float64 (``COMPILED_UPDATE``): each prepares the scalars of
the same formulas and hands the carried arrays ``(C, S, Q, S_err, Q_err, rho, nu)`` to one
numba kernel (:func:`~bayes_fdi.rvm.sbl.factor_kernels.refresh_rows`,
:func:`~bayes_fdi.rvm.sbl.tracked_kernels.rescale_rows`; a re-estimation two:
:func:`~bayes_fdi.rvm.sbl.factor_kernels.reestimate_terms` and
:func:`~bayes_fdi.rvm.sbl.tracked_kernels.reestimate_rows`) that updates them in place. The
carried values only decide which candidates get an exact look, so this changes the cost of a
decision, never the decision.

Imports :mod:`~bayes_fdi.rvm.sbl.posterior_bounds` and the two kernel modules. Written by hand:
no maintained library carries these bounds.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import Tensor

from bayes_fdi.rvm.sbl.factor_kernels import reestimate_terms, refresh_rows
from bayes_fdi.rvm.sbl.posterior_bounds import Posterior
from bayes_fdi.rvm.sbl.tracked_kernels import reestimate_rows, rescale_rows, screen_rows

__all__ = [
    "reestimate_compiled",
    "refresh_rows_compiled",
    "rescale_compiled",
    "screen_compiled",
]


def refresh_rows_compiled(
    post: Posterior,
    Z: Tensor,
    rows: Tensor,
    unit: Tensor,
    Bt_t: Tensor,
    carried: tuple[Tensor, ...],
) -> None:
    """``TrackedFactors.refresh`` of a few ``rows`` (stored products ``Z``, ``(P, M)``; stored
    ``b^T b`` and ``b^T t`` of every row) in one compiled call: the same formulas and bounds
    as the torch screening with ``z_error = 0``."""
    L, d = post.fac
    vectors = (post.mu, post.gradient, post.gradient_error)
    refresh_rows(
        L.numpy(),
        d.numpy(),
        post.Hb.numpy(),
        float(post.beta),
        Z.numpy(),
        rows.numpy(),
        unit.numpy(),
        Bt_t.numpy(),
        *(v.numpy() for v in vectors),
        float(post.lam),
        float(post.root.min()),
        tuple(v.numpy() for v in carried),
    )


def rescale_compiled(
    old: Posterior, new: Posterior, Delta: Tensor, gM: float, carried: tuple[Tensor, ...]
) -> None:
    """``TrackedFactors.rescale`` (a noise update moving ``abar`` by ``Delta``) in one pass
    over the rows: the same formulas; ``gM`` is the rounding factor ``gamma_{M+4}``."""
    sq = Delta * Delta
    weights = torch.stack([Delta, sq / old.abar, sq / new.abar])
    d_mu = Delta * new.mu
    m_cross = float((Delta.abs() / (old.root * new.root)).max())
    dmu = float(torch.linalg.vector_norm(d_mu / old.root)) + m_cross * new.mu_error_w
    scalars = [
        math.sqrt(old.psd),
        float((Delta.abs() / old.abar).max()),
        new.psd,
        m_cross,
        gM,
        float(Delta.abs().max()),
        dmu,
        new.mu_error_w,
        float(torch.linalg.vector_norm(d_mu)),
        float((old.root / new.root).max()),
    ]
    C, *vectors = (v.numpy() for v in carried)
    rescale_rows(C, Delta.numel(), weights.numpy(), d_mu.numpy(), *vectors, np.array(scalars))


def reestimate_compiled(
    post: Posterior, k: int, new_alpha: float, carried: tuple[Tensor, ...]
) -> bool:
    """``TrackedFactors.reestimate`` (position ``k`` moves to ``alpha_k = new_alpha``) in two
    compiled calls: the unit solve and the update's scalars, then one pass over the rows.
    Returns False, changing nothing, where the update's denominator is not bounded away from 0
    (the caller then refreshes)."""
    L, d = post.fac
    ok, s, scalars = reestimate_terms(
        L.numpy(),
        d.numpy(),
        post.Hb.numpy(),
        post.root.numpy(),
        post.mu.numpy(),
        float(post.beta),
        k,
        float(post.abar[k]),
        new_alpha / post.beta,
        float(post.Hb_F),
        float(post.psd),
        float(post.mu_error_w),
    )
    if not ok:
        return False
    C, *vectors = (v.numpy() for v in carried)
    reestimate_rows(C, post.abar.numel(), k, s, *vectors, scalars)
    return True


_NO_ROWS = np.empty(0, dtype=np.int64)


def screen_compiled(
    post: Posterior,
    eps: float,
    bt_error: float,
    rows: Tensor | None,
    carried: tuple[Tensor, ...],
) -> tuple[Tensor, ...]:
    """``TrackedFactors.screen`` of ``rows`` (all when None) in one pass
    (:func:`~bayes_fdi.rvm.sbl.tracked_kernels.screen_rows`): the same operations in the same
    order, so the same numbers."""
    M = post.abar.numel()
    ze = math.sqrt(M) * eps
    mu_error = math.sqrt(post.lam) * post.mu_error_w
    mu1 = float(post.mu.abs().sum()) + math.sqrt(M) * mu_error
    scalars = [math.sqrt(post.lam * post.psd), 2.0 * ze, post.lam * ze * ze, eps * mu1, bt_error]
    _, *vectors = (v.numpy() for v in carried)
    out = screen_rows(
        *vectors,
        _NO_ROWS if rows is None else rows.numpy(),
        rows is None,
        float(post.beta),
        np.array(scalars, dtype=np.float64),
    )
    return tuple(torch.from_numpy(out[j]) for j in range(4))

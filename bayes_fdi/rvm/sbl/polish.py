"""Polishing a fast Gaussian fit by a re-estimation restart (:func:`polish_gaussian`).

The evidence of an RBF design has many local optima: Tipping & Faul's sequential solver
(:func:`~bayes_fdi.rvm.sbl.gaussian.fast_gaussian`) builds its basis greedily from one column
and stops at an optimum where no single addition, deletion or re-estimation helps, while
Tipping's re-estimation from the whole basis (:func:`~bayes_fdi.rvm.sbl.reestimation.em_gaussian`,
scikit-learn's ``ARDRegression``) often reaches a different one, nats higher (on 200 to 400
noisy samples of a smooth function with an RBF basis of width 0.5, 0.1 to 6 nats; the two
active sets share half their columns). Moves of one or two columns from the fast optimum
(swaps) did not get there. The polish therefore restarts
the re-estimation from a pool of columns -- the whole basis when it is small, else the fast
fit's basis and the candidates most correlated with its residual -- continues it with the
fast solver (whose decisions are taken on exact factors, and whose every action raises the
evidence), and keeps whichever of the two fits has the higher evidence.

Imports the two Gaussian solvers and the result type. Written by hand on top of the two solvers;
no maintained library combines them.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import Tensor

from bayes_fdi.rvm.sbl.design import Design
from bayes_fdi.rvm.sbl.gaussian import fast_gaussian
from bayes_fdi.rvm.sbl.reestimation import em_gaussian
from bayes_fdi.rvm.sbl.result import SBLResult, unit_columns

__all__ = ["Polish", "polish_gaussian", "restart_pool"]

#: iteration limit of the re-estimation restart (it only has to find the basin: the fast
#: solver takes it from there to its own convergence)
RESTART_MAX_ITER = 1000


class Polish(NamedTuple):
    """What :func:`polish_gaussian` did.

    Attributes
    ----------
    gain : float
        Log evidence of the kept fit minus the given fit's (``>= 0``; 0 when it was kept).
    restart_log_evidence : float
        Log evidence of the continued restart, kept or not.
    pool_size : int
        Number of (usable) columns the restart began with.
    """

    gain: float
    restart_log_evidence: float
    pool_size: int


def restart_pool(design: Design, t: Tensor, fitted: SBLResult, size: int) -> Tensor:
    """The columns a restart begins with, sorted: every usable (non-zero) column when there
    are at most ``size``, else ``fitted``'s basis and the usable candidates of largest
    ``|b_i^T r| / ||b_i||`` (``r = t - Phi mu``, the fit's residual), ``size`` in all (ties to
    the lower index).

    Parameters
    ----------
    design : Design
        The candidate basis.
    t : Tensor
        ``(N,)`` targets.
    fitted : SBLResult
        The fit on ``design`` to polish.
    size : int
        Pool size (``>= 1``); the fit's basis is always in, even when larger.
    """
    if size < 1:
        raise ValueError(f"the pool size must be >= 1, got {size}")
    norms, valid = unit_columns(design)
    if int(valid.sum()) <= size:
        return valid.nonzero().squeeze(1)
    active = fitted.active.to(norms.device)
    resid = t - design.columns(active) @ fitted.mean.to(t)
    score = (design.rmatmul(resid[:, None])[:, 0] / norms).abs()
    score = torch.where(valid, score, -1.0)
    score[active] = torch.inf
    order = torch.sort(-score, stable=True).indices
    n = max(size, active.numel())
    return torch.sort(order[:n]).values


def polish_gaussian(
    design: Design,
    t: Tensor,
    fitted: SBLResult,
    *,
    pool_size: int = 1000,
    max_iter: int = 10000,
    tol: float = 1e-3,
) -> tuple[SBLResult, Polish]:
    """Restart Tipping's re-estimation from a pool of columns, continue it with the fast
    solver, and keep the better of that and ``fitted``.

    Parameters
    ----------
    design : Design
        The candidate basis ``B``.
    t : Tensor
        ``(N,)`` targets.
    fitted : SBLResult
        A fit on ``design`` and ``t`` (usually :func:`fast_gaussian`'s).
    pool_size : int
        Columns the restart begins with (:func:`restart_pool`): the whole basis when it has
        at most this many usable columns. The restart costs ``O(N K^2 + K^3)`` per iteration
        for a pool of ``K`` columns (fewer as columns are pruned).
    max_iter, tol
        The fast continuation's (:func:`fast_gaussian`); the restart stops at ``tol`` too, or
        after :data:`RESTART_MAX_ITER` iterations.

    Returns
    -------
    result : SBLResult
        The kept fit: the continued restart's when its evidence is higher, else ``fitted``.
    polish : Polish
        Its gain over ``fitted`` (``>= 0``), the restart's evidence and pool size.
    """
    columns = restart_pool(design, t, fitted, pool_size)
    restart = em_gaussian(design, t, max_iter=RESTART_MAX_ITER, tol=tol, columns=columns)
    continued = fast_gaussian(design, t, max_iter=max_iter, tol=tol, start=restart)
    kept = continued if continued.log_evidence > fitted.log_evidence else fitted
    return kept, Polish(
        gain=kept.log_evidence - fitted.log_evidence,
        restart_log_evidence=continued.log_evidence,
        pool_size=columns.numel(),
    )

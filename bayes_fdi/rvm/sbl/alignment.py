"""The alignment test of the fast solvers: candidates nearly parallel to an active column are not
added (:class:`Alignment`), decided on exact cosines (:func:`exact_alignment`).

SparseBayes (Tipping & Faul 2003) refuses to add a unit column ``b_i`` with
``|b_i^T phi_j| > 1 - 1e-3`` for an active ``phi_j``, and re-admits it once ``phi_j`` is
deleted. The cosines come from screened products; those within their error bound of the
threshold are recomputed exactly (rule 4 of :mod:`bayes_fdi.rvm.sbl.decisions`).

Imports :mod:`~bayes_fdi.rvm.sbl.design` and :mod:`~bayes_fdi.rvm.sbl.verification`. Written by
hand: a few lines specific to the solver.
"""

from __future__ import annotations

import torch
from torch import Tensor

from bayes_fdi.rvm.sbl.design import Design
from bayes_fdi.rvm.sbl.verification import exact_near_threshold

__all__ = ["ALIGNMENT_MAX", "Alignment", "exact_alignment"]

#: SparseBayes v2: candidates with |cosine| above this to an active column are not added
ALIGNMENT_MAX = 1.0 - 1e-3


class Alignment:
    """How many active columns each candidate is aligned with (``|cosine| > ALIGNMENT_MAX``).

    Parameters
    ----------
    n_basis : int
        Number of candidate columns.
    device : torch.device
        Where the counts live.
    """

    def __init__(self, n_basis: int, device: torch.device) -> None:
        self.count = torch.zeros(n_basis, dtype=torch.long, device=device)

    def add(self, col: Tensor) -> None:
        """Count an added active column, given the cosines ``col`` (``(n_basis,)``) of every
        candidate with it."""
        self.count += (col.abs() > ALIGNMENT_MAX).long()

    def remove(self, col: Tensor) -> None:
        """Uncount a deleted active column (its cosines ``col`` as given to :meth:`add`)."""
        self.count -= (col.abs() > ALIGNMENT_MAX).long()

    @property
    def free(self) -> Tensor:
        """``(n_basis,)`` mask of the candidates aligned with no active column."""
        return self.count == 0


def exact_alignment(BtBi: Tensor, design: Design, norms: Tensor, b_i: Tensor, error: float) -> None:
    """Recompute exactly (in place) the screened cosines ``B^T b_i`` within their error bound
    ``error`` (``Design.screening_error``) of the alignment threshold.

    Parameters
    ----------
    BtBi : Tensor
        ``(N_B,)`` screened cosines of every unit candidate column with the unit column ``b_i``.
    design : Design
        The candidate basis.
    norms : Tensor
        ``(N_B,)`` its column norms.
    b_i : Tensor
        ``(N,)`` the unit column.
    error : float
        Bound of the error of the screened cosines.
    """
    exact_near_threshold(
        BtBi,
        ALIGNMENT_MAX,
        lambda idx: (design.columns(idx) / norms[idx]).T @ b_i,
        relative=2.0 * error / ALIGNMENT_MAX,
    )

"""How many columns the fast Gaussian solver's growing buffers hold (:func:`grown_capacity`).

The buffers ``Phi``, ``B^T Phi`` (:mod:`bayes_fdi.rvm.sbl.gaussian`) and the carried
coefficients ``C`` (:mod:`bayes_fdi.rvm.sbl.tracked_factors`) are ``N x capacity`` float64
arrays. Doubling them when full would, past 256 columns, make each 512 columns wide for a few
more active columns (at ``N = 20 000`` about 80 MB each, held beside the old one while it is
copied), which set the fit's peak memory; from 256 columns on they grow by a quarter instead
(still a geometric growth, so the copies cost ``O(1)`` per added column on average).

Widths stay multiples of 64 columns (up to the number of candidates), so that every row of a
buffer starts on a 64-byte boundary: the width then changes where the columns are stored, not
the numbers computed from them. (Measured: a fit with buffers growing 8 columns at a time is
bit-identical to the default; with widths such as 1, 2, 4, 7 or 10 columns, its precisions move
by rounding, about ``1e-14`` relative, because BLAS takes other code paths on unaligned rows.)

Imports nothing from the package. Written by hand: a growth rule specific to these buffers.
"""

from __future__ import annotations

__all__ = ["grown_capacity"]

#: columns are added in multiples of this
_STEP = 64
#: up to this capacity the buffers double; beyond it they grow by a quarter
_DOUBLING_LIMIT = 256


def grown_capacity(capacity: int, needed: int, limit: int) -> int:
    """The next capacity of a buffer of ``capacity`` columns that must hold ``needed`` columns,
    at most ``limit`` (the number of candidates) unless ``needed`` is larger.

    Parameters
    ----------
    capacity : int
        The present number of columns (>= 1).
    needed : int
        Columns the buffer must hold.
    limit : int
        The most columns it can ever need.

    Examples
    --------
    >>> grown_capacity(64, 65, 10_000), grown_capacity(256, 257, 10_000)
    (128, 320)
    >>> grown_capacity(256, 257, 300)
    300
    """
    cap = max(1, int(capacity))
    while cap < needed:
        if cap < _DOUBLING_LIMIT:
            cap *= 2
        else:
            cap += max(_STEP, cap // 4 // _STEP * _STEP)
    return max(int(needed), min(cap, int(limit)))

"""The screening copy of a symmetric float64 kernel matrix: its upper triangle in 6 bytes an
entry (float32 value plus bfloat16 remainder), row block by row block, with products accumulated
in float64 (:class:`TriangleCopy`).

Written by hand: no maintained library multiplies a symmetric matrix stored in reduced precision
with a float64 vector in float64 arithmetic. BLAS ``ssymv`` / ``sspmv`` accumulate in float32,
whose rounding (``~N`` float32 units, ``1e-3`` at ``N = 20000``) hides a smooth kernel's small
factors. Here each stored block is converted into a cache-sized float64 buffer and multiplied
there: a product reads 6 bytes per stored entry, the copy holds ``~N^2 / 2`` entries (37.5 % of
the float64 matrix), and nothing is recomputed.

Error. An entry ``K`` is stored as ``hi = fl32(K)`` and ``lo = bf16(K - hi)``: ``hi + lo`` is
within ``delta |K| + eta`` of ``K`` with ``delta = 2^-33`` (bfloat16 keeps 8 of the remainder's
bits, the remainder is at most ``2^-24 |K|``) and ``eta = 2^-133`` (the subnormal ranges of both
formats); ``hi + lo`` is exact in float64. Each product entry is a sum of ``N`` float64 terms in
some order, so
(Higham, *Accuracy and Stability of Numerical Algorithms*, eq. 3.5)
``|computed (K v)_i - (K v)_i| <= (delta' + gamma_{N+4} (1 + delta')) sum_j |K_ij v_j| +
eta ||v||_1`` with ``delta' = (1 + delta)^2 (1 + u) - 1``, which also covers the squared entries
of :meth:`TriangleCopy.square_matmul`: :meth:`TriangleCopy.error` turns it into a bound relative
to ``||b_i|| ||v||``.

Imports :mod:`bayes_fdi.rvm.kernels` only.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from bayes_fdi.rvm.kernels import Kernel

__all__ = ["CHUNK_BYTES", "ENTRY_BYTES", "TriangleCopy", "triangle_bytes"]

#: bytes of one float64 block of rows (converted from the store for each product): small
#: enough to stay in a core's cache, large enough that the per-block overhead is small
CHUNK_BYTES = 4_000_000
#: bytes per stored entry (float32 value + bfloat16 remainder)
ENTRY_BYTES = 6
_DELTA = 2.0**-33  # relative error of hi + lo
_ETA = 2.0**-133  # absolute error of hi + lo (subnormal ranges)


def triangle_bytes(n: int, rows: int) -> int:
    """Bytes of the copy of an ``n x n`` matrix stored in blocks of ``rows`` rows (each block
    keeps its columns from its first row on)."""
    total = 0
    for start in range(0, n, rows):
        total += min(rows, n - start) * (n - start)
    return ENTRY_BYTES * total


class TriangleCopy:
    """Upper triangle of ``K = kernel(X, X)`` in blocks ``K[s:e, s:]`` (``hi`` float32 and
    ``lo`` bfloat16, ``K ~ hi + lo``; module docstring).

    Built in one pass over the kernel rows, which also gives the exact (float64) column norms
    and ``K^T rhs`` (``K`` is symmetric, so row and column sums agree).

    Parameters
    ----------
    kernel : Kernel
        A symmetric kernel.
    X : Tensor
        ``(N, d)`` float64 training inputs.
    rows : int
        Rows per stored block (see :meth:`rows_for`).
    rhs : Tensor or None
        ``(N,)`` or ``(N, k)``: compute ``K^T rhs`` exactly during the build.

    Raises
    ------
    OverflowError
        If a kernel value exceeds the float32 range.
    """

    def __init__(self, kernel: Kernel, X: Tensor, *, rows: int, rhs: Tensor | None = None):
        if X.dtype != torch.float64:
            raise TypeError(f"the screening copy is for float64 designs, got {X.dtype}")
        n = X.shape[0]
        self.n, self.rows = n, max(1, min(int(rows), n))
        self.dtype, self.device = X.dtype, X.device
        self.his: list[Tensor] = []
        self.los: list[Tensor] = []
        sq = torch.zeros(n, dtype=self.dtype, device=self.device)
        R = None if rhs is None else rhs.reshape(n, -1).to(self.dtype)
        prod = None if R is None else R.new_zeros(n, R.shape[1])
        big = torch.finfo(torch.float32).max
        for s in range(0, n, self.rows):
            e = min(s + self.rows, n)
            block = kernel(X[s:e], X[s:])  # K[s:e, s:] in float64
            if not bool(block.abs().max() <= big):
                raise OverflowError("kernel values exceed the float32 range of the copy")
            if prod is not None and R is not None:
                prod[s:e] += block @ R[s:]
                prod[e:] += block[:, e - s :].T @ R[s:e]
            hi = block.to(torch.float32)
            self.his.append(hi)
            self.los.append((block - hi.to(self.dtype)).to(torch.bfloat16))
            block.square_()
            sq[s:e] += block.sum(1)
            sq[e:] += block[:, e - s :].sum(0)
        self.norms = sq.sqrt()
        self.rhs_product = prod

    @staticmethod
    def rows_for(n: int) -> int:
        """Rows of a block whose float64 conversion takes about :data:`CHUNK_BYTES`."""
        return max(1, CHUNK_BYTES // max(1, 8 * n))

    @property
    def nbytes(self) -> int:
        """Bytes held by the stored blocks."""
        return sum(b.numel() * b.element_size() for b in (*self.his, *self.los))

    def error(self, min_norm: float) -> float:
        """Bound of ``|computed (K v)_i - (K v)_i| / (||b_i|| ||v||)`` for columns of norm at least
        ``min_norm``, and of ``|computed ((K o K) w)_i - ((K o K) w)_i| / (||b_i||^2 max|w|)``
        (module docstring; ``|K_ij| <= ||b_i||`` for a symmetric ``K``)."""
        u = torch.finfo(self.dtype).eps / 2.0
        m = self.n + 4
        gamma = m * u / (1.0 - m * u)
        store = (1.0 + _DELTA) ** 2 * (1.0 + u) - 1.0
        rel = store + gamma * (1.0 + store)
        if not min_norm > 0:
            return math.inf
        # eta ||v||_1 <= eta sqrt(N) ||v||; the squares: |(K + d)^2 - K^2| <= ... + eta (2 (1 +
        # delta) |K| + eta), summed over N entries
        absolute = max(
            _ETA * math.sqrt(self.n) / min_norm,
            self.n * (2.0 * (1.0 + _DELTA) * _ETA / min_norm + (_ETA / min_norm) ** 2),
        )
        return rel + absolute * (1.0 + gamma)

    def _products(self, V: Tensor, square: bool) -> Tensor:
        n = self.n
        V = V.to(self.dtype)
        out = V.new_zeros(n, V.shape[1])
        buf = V.new_empty(2, self.rows, n)
        s = 0
        for hi, lo in zip(self.his, self.los, strict=True):
            r = hi.shape[0]
            e = s + r
            b = buf[0, :r, : n - s]
            b.copy_(hi)
            # hi + lo is exact in float64 (lo holds the bits below hi's)
            b.add_(buf[1, :r, : n - s].copy_(lo))
            if square:
                b.square_()
            out[s:e].addmm_(b, V[s:])
            if e < n:
                out[e:].addmm_(b[:, r:].T, V[s:e])
            s = e
        return out

    def matmul(self, V: Tensor) -> Tensor:
        """``K V`` (``= K^T V``) for an ``(N, k)`` matrix, accumulated in float64."""
        return self._products(V, square=False)

    def square_matmul(self, V: Tensor) -> Tensor:
        """``(K o K) V`` for an ``(N, k)`` matrix."""
        return self._products(V, square=True)

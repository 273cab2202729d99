"""Candidate basis ("design matrix") providers for the sparse Bayesian solvers.

The solvers never need the full ``N x N_B`` candidate basis ``B`` itself, only

* columns ``B[:, idx]`` (the active basis ``Phi``),
* products ``B^T V`` with thin ``N x k`` matrices (new cache columns, ``Q`` factors),
* ``(B * B)^T w`` (the ``S`` factors of the Bernoulli model; column norms).

:class:`Design` provides these for ``B = [1 | F]`` (the optional bias column first),
where ``F`` is either a dense matrix or the symmetric training kernel matrix
``kernel(X, X)``.  The kernel matrix is materialised only when it fits the memory
budget ``max_bytes``; otherwise it is recomputed in row blocks, so memory grows like
``N x (block + active set)`` instead of ``N^2``.

Screening copy.  A float64 kernel design may keep, instead of the matrix, only its upper
triangle in 6 bytes an entry (a float32 value and a bfloat16 remainder:
:class:`~bayes_fdi.rvm.sbl.screening_copy.TriangleCopy`, 37.5 % of the float64 matrix's memory),
used by ``rmatmul(V, exact=False)``: the ``B^T b_i`` products that screen candidate columns in
the fast solvers.  The products are accumulated in float64 from cache-sized blocks converted
on the fly, so their error is the stored entries' (relative ``2^-33``) plus float64
accumulation -- about ``2.3e-10`` of ``||b_i|| ||v||``, against ``~N 2^-24`` (``1e-3`` at
``N = 20000``) had they been float32 products.  Everything that enters the model -- active
columns, ``B^T t``, column norms and the Gram entries between active columns -- stays exact
float64, and the solvers decide every action on exact factors within the rigorous error bound of
those products (:meth:`Design.screening_error`), so the fit is the same as with the float64
matrix.  With ``screen=None`` (the default) a design on the CPU keeps the copy when the float64
matrix exceeds ``max_bytes`` and the copy fits it (``N`` from about 15 800 to 25 800 at the
default 2 GB); recomputing the kernel rows for every product instead made the smooth benchmark
fit at ``N = 20000`` ten times slower (``docs/rvm-benchmark.md``).  On other devices the rows
are recomputed there, which is cheap.

Imports :mod:`bayes_fdi.rvm.kernels` and :mod:`~bayes_fdi.rvm.sbl.screening_copy` only. Written
by hand: no maintained library serves a kernel design in blocks or from a reduced-precision copy
with a bound of the products' error.
"""

from __future__ import annotations

import torch
from scipy.linalg.blas import dsymv
from torch import Tensor

from bayes_fdi.rvm.kernels import Kernel
from bayes_fdi.rvm.sbl.screening_copy import TriangleCopy, triangle_bytes

__all__ = ["DEFAULT_MAX_BYTES", "Design"]

#: default memory budget (bytes) for materialising a kernel matrix
DEFAULT_MAX_BYTES = 2_000_000_000
#: bytes per row block when the kernel matrix is computed on the fly
_BLOCK_BYTES = 64_000_000


class Design:
    """The full candidate basis ``B = [1 | F]`` (bias column first when ``bias``).

    Parameters
    ----------
    matrix : Tensor, optional
        A dense ``(N, p)`` matrix ``F``.  Exactly one of ``matrix`` and ``kernel`` is given.
    kernel : Kernel, optional
        With ``X``: ``F = kernel(X, X)`` (``N x N``, symmetric).
    X : Tensor, optional
        Training inputs ``(N, d)`` for ``kernel``.
    bias : bool
        Prepend a constant column of ones.
    max_bytes : int
        Materialise ``kernel(X, X)`` only if it needs at most this many bytes.
    rhs : Tensor, optional
        A right-hand side whose exact ``B^T rhs`` is computed during construction (from the
        same kernel rows) and returned by :meth:`rhs_product`.
    screen : bool or None
        ``True``: keep the screening copy (float64 designs, if it fits ``max_bytes``) instead
        of the float64 matrix; ``False``: never; ``None``: keep it on the CPU when the float64
        matrix does not fit and the copy does (module docstring).
    """

    def __init__(
        self,
        *,
        matrix: Tensor | None = None,
        kernel: Kernel | None = None,
        X: Tensor | None = None,
        bias: bool = True,
        max_bytes: int = DEFAULT_MAX_BYTES,
        rhs: Tensor | None = None,
        screen: bool | None = None,
    ) -> None:
        if (matrix is None) == (kernel is None):
            raise ValueError("give exactly one of `matrix` and `kernel`")
        self.bias = bool(bias)
        self.offset = 1 if self.bias else 0
        self.kernel = kernel
        self.X = X
        self.F: Tensor | None = None
        self.screen_copy: TriangleCopy | None = None
        self._rhs = rhs
        self._rhs_product: Tensor | None = None
        self._norms: Tensor | None = None
        if matrix is not None:
            self.F = matrix
            ref = matrix
        else:
            if X is None:
                raise ValueError("`kernel` needs the training inputs `X`")
            ref = X
        self.n_samples = ref.shape[0]
        self.dtype = ref.dtype
        self.device = ref.device
        itemsize = torch.empty((), dtype=self.dtype).element_size()
        self._block = max(1, _BLOCK_BYTES // max(1, self.n_samples * itemsize))
        self._F_sq: Tensor | None = None
        if kernel is not None:
            n = self.n_samples
            rows = TriangleCopy.rows_for(n)
            copy_fits = self.dtype == torch.float64 and triangle_bytes(n, rows) <= max_bytes
            full_fits = n * n * itemsize <= max_bytes
            if screen is None:
                screen = not full_fits and self.device.type == "cpu"
            if screen and copy_fits:
                assert X is not None
                try:
                    self.screen_copy = TriangleCopy(kernel, X, rows=rows, rhs=rhs)
                except OverflowError:  # kernel values beyond float32: no copy
                    self.screen_copy = None
            if self.screen_copy is not None:
                norms = self.screen_copy.norms
                if self.bias:
                    norms = torch.cat([norms.new_full((1,), float(n) ** 0.5), norms])
                self._norms = norms
                if rhs is not None:
                    prod = self.screen_copy.rhs_product
                    assert prod is not None
                    if self.bias:
                        head = rhs.reshape(n, -1).to(self.dtype).sum(0, keepdim=True)
                        prod = torch.cat([head, prod], dim=0)
                    self._rhs_product = prod
            elif full_fits:
                self.F = kernel(X, X)
        self.n_features = self.F.shape[1] if self.F is not None else self.n_samples
        self.n_basis = self.n_features + self.offset

    @property
    def materialised(self) -> bool:
        """Whether ``F`` (or its screening copy) is held in memory."""
        return self.F is not None or self.screen_copy is not None

    def rhs_product(self, rhs: Tensor) -> Tensor:
        """Exact ``B^T rhs`` (``(N_B,)`` or ``(N_B, k)``), cached at construction if possible."""
        if self._rhs_product is not None and rhs is self._rhs:
            out = self._rhs_product
        else:
            out = self.rmatmul(rhs.reshape(self.n_samples, -1))
        return out[:, 0] if rhs.ndim == 1 else out

    def _kernel_rows(self, start: int, stop: int) -> Tensor:
        assert self.kernel is not None and self.X is not None
        return self.kernel(self.X[start:stop], self.X)

    def columns(self, idx: Tensor | list[int]) -> Tensor:
        """Columns ``B[:, idx]`` as an ``(N, len(idx))`` tensor."""
        idx = torch.as_tensor(idx, dtype=torch.long, device="cpu").reshape(-1)
        out = torch.empty(self.n_samples, idx.numel(), dtype=self.dtype, device=self.device)
        is_bias = idx < self.offset
        if bool(is_bias.any()):
            out[:, is_bias.to(self.device)] = 1.0
        feat = idx[~is_bias] - self.offset
        if feat.numel():
            if self.F is not None:
                cols = self.F[:, feat.to(self.device)]
            else:
                assert self.kernel is not None and self.X is not None
                cols = self.kernel(self.X, self.X[feat.to(self.device)])
            out[:, (~is_bias).to(self.device)] = cols
        return out

    def rmatmul(self, V: Tensor, *, exact: bool = True) -> Tensor:
        """``B^T V`` for an ``(N, k)`` matrix ``V``; returns ``(N_B, k)``.

        ``exact=False`` may use the screening copy (error :meth:`screening_error`).
        """
        out = torch.empty(self.n_basis, V.shape[1], dtype=self.dtype, device=self.device)
        if self.bias:
            out[0] = V.sum(0)
        if self.F is not None:
            F = self.F
            if (
                self.kernel is not None
                and F.device.type == "cpu"
                and V.shape[1] == 1
                and (F.dtype == V.dtype == torch.float64)
            ):
                # symmetric kernel matrix: BLAS dsymv reads one triangle (a product is memory
                # bound: ~1.7x faster than the general one); F.numpy().T is the column-major
                # view of F^T = F, no copy
                v = V[:, 0].detach().contiguous().numpy()
                out[self.offset :, 0] = torch.from_numpy(dsymv(1.0, F.numpy().T, v, lower=1))
            else:
                torch.matmul(F.T, V, out=out[self.offset :])
        elif self.screen_copy is not None and not exact:
            out[self.offset :] = self.screen_copy.matmul(V)  # K symmetric
        else:  # symmetric kernel matrix: K^T V = K V, row block by row block
            for start in range(0, self.n_samples, self._block):
                stop = min(start + self._block, self.n_samples)
                out[self.offset + start : self.offset + stop] = self._kernel_rows(start, stop) @ V
        return out

    def sq_rmatmul(self, w: Tensor, *, exact: bool = True) -> Tensor:
        """``(B * B)^T w`` for a length-``N`` vector ``w``; returns ``(N_B,)``.

        ``exact=False`` may use the screening copy (error :meth:`screening_error`).
        """
        out = torch.empty(self.n_basis, dtype=self.dtype, device=self.device)
        if self.bias:
            out[0] = w.sum()
        if self.F is not None:
            if self._F_sq is None:
                self._F_sq = self.F.square()
            out[self.offset :] = self._F_sq.T @ w
        elif self.screen_copy is not None and not exact:
            out[self.offset :] = self.screen_copy.square_matmul(w[:, None])[:, 0]
        else:
            for start in range(0, self.n_samples, self._block):
                stop = min(start + self._block, self.n_samples)
                rows = self._kernel_rows(start, stop)
                out[self.offset + start : self.offset + stop] = rows.square_() @ w
        return out

    def product_error(self) -> float:
        """Bound on the error of ``b_i^T v / ||b_i||`` for a unit vector ``v`` when both are
        exact columns in the working precision (``columns``: the Gram entries among active
        columns), and of ``rmatmul`` from a matrix held in that precision.

        A dot product of ``N`` terms in a precision of unit roundoff ``u`` is within
        ``N u / (1 - N u) * sum |b_ij v_j| <= N u / (1 - N u) * ||b_i|| ||v||`` of the exact one,
        whatever the summation order (Higham, *Accuracy and Stability of Numerical Algorithms*,
        eq. 3.5): blocked, threaded and vectorised BLAS kernels all satisfy it. A few more
        roundings cover storing ``v`` and evaluating the kernel rows and columns separately.
        """
        u = torch.finfo(self.dtype).eps / 2.0
        n = self.n_samples + 8
        return n * u / (1.0 - n * u)

    def screening_error(self) -> float:
        """Bound on the error of ``rmatmul(v, exact=False)[i] / ||b_i||`` for a unit vector ``v``
        (and of ``sq_rmatmul(w, exact=False)[i]`` relative to ``sum_j b_ij^2 |w_j|``): that of
        :meth:`product_error`, plus with the screening copy the rounding of its stored entries
        (:meth:`TriangleCopy.error <bayes_fdi.rvm.sbl.screening_copy.TriangleCopy.error>`).
        """
        if self.screen_copy is None:
            return self.product_error()
        norms = self.screen_copy.norms
        usable = norms[norms > 0]
        min_norm = float(usable.min()) if usable.numel() else 1.0
        return self.screen_copy.error(min_norm) + self.product_error()

    def column_norms(self) -> Tensor:
        """Exact Euclidean norms of all ``N_B`` columns."""
        if self._norms is not None:
            return self._norms
        if self.F is not None:
            norms = torch.linalg.vector_norm(self.F, dim=0)
            if self.bias:
                norms = torch.cat([norms.new_full((1,), float(self.n_samples) ** 0.5), norms])
        else:
            ones = torch.ones(self.n_samples, dtype=self.dtype, device=self.device)
            norms = self.sq_rmatmul(ones).sqrt()
        self._norms = norms
        return norms

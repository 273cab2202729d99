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

Screening copy.  With ``screen=True`` a float64 kernel design keeps only a *float32* copy of
the kernel matrix (half the memory), used by ``rmatmul(V, exact=False)``: the ``B^T b_i``
products that screen candidate columns in the fast solvers.  Everything that enters the model
-- active columns, ``B^T t``, column norms and the Gram entries between active columns -- stays
exact float64, and the solvers decide every action on exact factors within the rigorous error
bound of those products (:meth:`Design.screening_error`), so the fit is the same as with the
float64 matrix.  It is not the default: on smooth kernels float32 products cannot resolve most
candidates' factors (``S`` near 1e-6 of the noise precision against a float32 error bound of
~1e-4), and the solver then has to recompute nearly every candidate exactly (two 2400-sample
normal models: 1.6 s and 84 s against 0.20 s and 2.1 s with the float64 matrix).
"""

from __future__ import annotations

import torch
from scipy.linalg.blas import ssymv
from torch import Tensor

from bayes_fdi.rvm.kernels import Kernel

__all__ = ["DEFAULT_MAX_BYTES", "Design"]

#: default memory budget (bytes) for materialising a kernel matrix
DEFAULT_MAX_BYTES = 2_000_000_000
#: bytes per row block when the kernel matrix is computed on the fly
_BLOCK_BYTES = 64_000_000


def _symv(F: Tensor, v: Tensor) -> Tensor:
    """``F v`` for a symmetric float32 CPU matrix ``F`` by BLAS ``ssymv``.

    Reads one triangle only (the upper one of the row-major ``F``): a matrix-vector
    product is memory bound, so this is ~1.5x faster than a general ``F @ v``.
    """
    x = v.detach().to(dtype=torch.float32, device="cpu").contiguous().numpy()
    # F.numpy().T is the column-major view of F^T = F: no copy
    return torch.from_numpy(ssymv(1.0, F.numpy().T, x, lower=1))


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
        self.F_screen: Tensor | None = None
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
            if screen is None:
                screen = False
            if screen and n * n * 4 <= max_bytes:
                self._build_screening()
            elif not screen and n * n * itemsize <= max_bytes:
                self.F = kernel(X, X)
        self.n_features = self.F.shape[1] if self.F is not None else self.n_samples
        self.n_basis = self.n_features + self.offset

    def _build_screening(self) -> None:
        """One blockwise pass: float32 copy, exact column norms and exact ``K^T rhs``."""
        n = self.n_samples
        self.F_screen = torch.empty(n, n, dtype=torch.float32, device=self.device)
        sq = torch.zeros(n, dtype=self.dtype, device=self.device)
        prod = None
        if self._rhs is not None:
            rhs = self._rhs.reshape(n, -1).to(self.dtype)
            prod = torch.empty(n, rhs.shape[1], dtype=self.dtype, device=self.device)
        for start in range(0, n, self._block):
            stop = min(start + self._block, n)
            rows = self._kernel_rows(start, stop)
            self.F_screen[start:stop] = rows
            if prod is not None:
                prod[start:stop] = rows @ rhs  # K symmetric: (K^T rhs) rows
            sq += rows.square_().sum(0)
        norms = sq.sqrt()
        if self.bias:
            norms = torch.cat([norms.new_full((1,), float(n) ** 0.5), norms])
        self._norms = norms
        if prod is not None:
            assert self._rhs is not None
            head = (
                [self._rhs.reshape(n, -1).to(self.dtype).sum(0, keepdim=True)] if self.bias else []
            )
            self._rhs_product = torch.cat([*head, prod], dim=0)

    @property
    def materialised(self) -> bool:
        """Whether ``F`` (or its float32 screening copy) is held in memory."""
        return self.F is not None or self.F_screen is not None

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

        ``exact=False`` may use the float32 screening copy (relative error ~1e-6).
        """
        out = torch.empty(self.n_basis, V.shape[1], dtype=self.dtype, device=self.device)
        if self.bias:
            out[0] = V.sum(0)
        if self.F is not None:
            torch.matmul(self.F.T, V, out=out[self.offset :])
        elif self.F_screen is not None and not exact:
            if V.shape[1] == 1 and self.F_screen.device.type == "cpu":
                out[self.offset :, 0] = _symv(self.F_screen, V[:, 0])
            else:
                out[self.offset :] = self.F_screen @ V.to(torch.float32)  # K symmetric
        else:  # symmetric kernel matrix: K^T V = K V, row block by row block
            for start in range(0, self.n_samples, self._block):
                stop = min(start + self._block, self.n_samples)
                out[self.offset + start : self.offset + stop] = self._kernel_rows(start, stop) @ V
        return out

    def sq_rmatmul(self, w: Tensor, *, exact: bool = True) -> Tensor:
        """``(B * B)^T w`` for a length-``N`` vector ``w``; returns ``(N_B,)``.

        ``exact=False`` may use the float32 screening copy.
        """
        out = torch.empty(self.n_basis, dtype=self.dtype, device=self.device)
        if self.bias:
            out[0] = w.sum()
        if self.F is not None or (self.F_screen is not None and not exact):
            if self._F_sq is None:
                self._F_sq = self.F.square() if self.F is not None else self.F_screen.square()
            out[self.offset :] = self._F_sq.T @ w.to(self._F_sq.dtype)
        else:
            for start in range(0, self.n_samples, self._block):
                stop = min(start + self._block, self.n_samples)
                rows = self._kernel_rows(start, stop)
                out[self.offset + start : self.offset + stop] = rows.square_() @ w
        return out

    def screening_error(self) -> float:
        """Bound on the error of ``rmatmul(v, exact=False)[i] / ||b_i||`` for a unit vector ``v``.

        A dot product of ``N`` terms in a precision of unit roundoff ``u`` is within
        ``N u / (1 - N u) * sum |b_ij v_j| <= N u / (1 - N u) * ||b_i|| ||v||`` of the exact one,
        whatever the summation order (Higham, *Accuracy and Stability of Numerical Algorithms*,
        eq. 3.5): blocked, threaded and vectorised BLAS kernels all satisfy it. ``u`` is that of
        float32 for the screening copy, of the design's dtype otherwise; a few more roundings
        cover storing the entries and ``v`` in that precision and evaluating the kernel rows and
        columns separately.
        """
        low = torch.float32 if self.F_screen is not None else self.dtype
        u = torch.finfo(low).eps / 2.0
        n = self.n_samples + 8
        return n * u / (1.0 - n * u)

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

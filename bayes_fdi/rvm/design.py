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
"""

from __future__ import annotations

import torch
from torch import Tensor

from bayes_fdi.rvm.kernels import Kernel

__all__ = ["DEFAULT_MAX_BYTES", "Design"]

#: default memory budget (bytes) for materialising a kernel matrix
DEFAULT_MAX_BYTES = 1_500_000_000
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
    """

    def __init__(
        self,
        *,
        matrix: Tensor | None = None,
        kernel: Kernel | None = None,
        X: Tensor | None = None,
        bias: bool = True,
        max_bytes: int = DEFAULT_MAX_BYTES,
    ) -> None:
        if (matrix is None) == (kernel is None):
            raise ValueError("give exactly one of `matrix` and `kernel`")
        self.bias = bool(bias)
        self.offset = 1 if self.bias else 0
        self.kernel = kernel
        self.X = X
        if matrix is not None:
            self.F: Tensor | None = matrix
            ref = matrix
        else:
            if X is None:
                raise ValueError("`kernel` needs the training inputs `X`")
            ref = X
            n = X.shape[0]
            itemsize = torch.empty((), dtype=X.dtype).element_size()
            self.F = kernel(X, X) if n * n * itemsize <= max_bytes else None
        self.n_samples = ref.shape[0]
        self.n_features = self.F.shape[1] if self.F is not None else self.n_samples
        self.n_basis = self.n_features + self.offset
        self.dtype = ref.dtype
        self.device = ref.device
        itemsize = torch.empty((), dtype=self.dtype).element_size()
        self._block = max(1, _BLOCK_BYTES // max(1, self.n_samples * itemsize))
        self._F_sq: Tensor | None = None

    @property
    def materialised(self) -> bool:
        """Whether ``F`` is held in memory (``False``: computed in row blocks)."""
        return self.F is not None

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

    def rmatmul(self, V: Tensor) -> Tensor:
        """``B^T V`` for an ``(N, k)`` matrix ``V``; returns ``(N_B, k)``."""
        out = torch.empty(self.n_basis, V.shape[1], dtype=self.dtype, device=self.device)
        if self.bias:
            out[0] = V.sum(0)
        if self.F is not None:
            torch.matmul(self.F.T, V, out=out[self.offset :])
        else:  # symmetric kernel matrix: K^T V = K V, row block by row block
            for start in range(0, self.n_samples, self._block):
                stop = min(start + self._block, self.n_samples)
                out[self.offset + start : self.offset + stop] = self._kernel_rows(start, stop) @ V
        return out

    def sq_rmatmul(self, w: Tensor) -> Tensor:
        """``(B * B)^T w`` for a length-``N`` vector ``w``; returns ``(N_B,)``."""
        out = torch.empty(self.n_basis, dtype=self.dtype, device=self.device)
        if self.bias:
            out[0] = w.sum()
        if self.F is not None:
            if self._F_sq is None:
                self._F_sq = self.F * self.F
            out[self.offset :] = self._F_sq.T @ w
        else:
            for start in range(0, self.n_samples, self._block):
                stop = min(start + self._block, self.n_samples)
                rows = self._kernel_rows(start, stop)
                out[self.offset + start : self.offset + stop] = rows.square_() @ w
        return out

    def column_norms(self) -> Tensor:
        """Euclidean norms of all ``N_B`` columns."""
        if self.F is not None:
            norms = torch.linalg.vector_norm(self.F, dim=0)
            if self.bias:
                norms = torch.cat([norms.new_full((1,), float(self.n_samples) ** 0.5), norms])
            return norms
        return self.sq_rmatmul(
            torch.ones(self.n_samples, dtype=self.dtype, device=self.device)
        ).sqrt()

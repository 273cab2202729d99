"""Potentials in numpy, differentiable in torch: validated inputs, Cholesky with jitter, bridge.

The NUTS potentials of the sparse Bayesian models are small ``M x M`` algebra with closed-form
gradients; numpy evaluates them far below torch's per-operation overhead, and
:class:`NumpyFunction` hands value and gradient to torch autograd (so Pyro's NUTS can use them).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

DTYPE = torch.float64
LOG_2PI = math.log(2.0 * math.pi)


def as_tensor(x: Any, name: str, ndim: int) -> torch.Tensor:
    """``x`` as a finite float64 CPU tensor with ``ndim`` dimensions, or a ``ValueError``."""
    if isinstance(x, torch.Tensor):
        out = x.detach().to(device="cpu", dtype=DTYPE)
    else:
        try:
            out = torch.as_tensor(np.asarray(x, dtype=np.float64), dtype=DTYPE)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{name} must be numeric array-like: {exc}") from exc
    if out.ndim != ndim:
        raise ValueError(f"{name} must be {ndim}-D, got shape {tuple(out.shape)}")
    if not torch.isfinite(out).all():
        raise ValueError(f"{name} contains NaN or inf")
    return out


def design_and_targets(Phi: Any, t: Any) -> tuple[torch.Tensor, torch.Tensor]:
    """Validated ``(Phi, t)``: finite ``(n, m)`` design (``n >= 2``, ``m >= 1``) and n targets."""
    Phi_t, t_t = as_tensor(Phi, "Phi", 2), as_tensor(t, "t", 1)
    n, m = Phi_t.shape
    if t_t.shape[0] != n:
        raise ValueError(f"Phi has {n} rows but t has {t_t.shape[0]} entries")
    if n < 2 or m < 1:
        raise ValueError(f"need at least 2 rows and 1 basis column, got Phi shape {(n, m)}")
    return Phi_t, t_t


def np_cholesky(H: np.ndarray) -> np.ndarray:
    """Cholesky factor of a batch of SPD matrices, adding diagonal jitter only if needed."""
    try:
        return np.linalg.cholesky(H)
    except np.linalg.LinAlgError:
        pass
    eye = np.eye(H.shape[-1])
    scale = np.abs(np.diagonal(H, axis1=-2, axis2=-1)).mean(-1)[..., None, None]
    for jitter in (1e-12, 1e-10, 1e-8, 1e-6):
        try:
            return np.linalg.cholesky(H + jitter * scale * eye)
        except np.linalg.LinAlgError:
            continue
    raise ValueError("posterior precision matrix A + beta Phi^T Phi is not positive definite")


def as_pair(x: Any, y: Any) -> tuple[torch.Tensor, torch.Tensor]:
    """Two float64 tensors (no copy when already float64 tensors)."""
    return torch.as_tensor(x, dtype=DTYPE), torch.as_tensor(y, dtype=DTYPE)


class NumpyFunction(torch.autograd.Function):
    """Bridge: ``fn(*arrays) -> (value, grads)`` computed in numpy, differentiable in torch."""

    @staticmethod
    def forward(ctx, fn, *inputs):  # type: ignore[override]
        value, grads = fn(*(x.detach().cpu().numpy() for x in inputs))
        ctx.save_for_backward(*(torch.as_tensor(g, dtype=DTYPE) for g in grads))
        return torch.as_tensor(value, dtype=DTYPE)

    @staticmethod
    def backward(ctx, grad_output):  # type: ignore[override]
        out = []
        for g in ctx.saved_tensors:
            go = grad_output.reshape(grad_output.shape + (1,) * (g.ndim - grad_output.ndim))
            out.append(go * g)
        return (None, *out)

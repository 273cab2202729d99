"""Kernels (basis-function generators) for the RVM, as small composable objects.

A kernel is called as ``kernel(X, Z)`` on two 2-D torch tensors and returns the
``(len(X), len(Z))`` matrix of ``k(x_i, z_j)`` in the dtype and on the device of
``X``.  Kernels compose with ``+`` and ``*`` (with each other or with a positive
scalar), in the manner of GPyTorch kernels.  Every kernel has a JSON-serialisable
:meth:`Kernel.to_dict` and :func:`kernel_from_dict` rebuilds it (used by
:mod:`bayes_fdi.rvm.persistence`).

Imports torch only.
"""

from __future__ import annotations

import math
from typing import Any

import torch
from torch import Tensor

__all__ = [
    "RBF",
    "Kernel",
    "Linear",
    "Polynomial",
    "Product",
    "Scaled",
    "Sum",
    "kernel_from_dict",
]


class Kernel:
    """Base class of the kernels: ``__call__(X, Z) -> Tensor`` of shape ``(n, m)``."""

    def __call__(self, X: Tensor, Z: Tensor | None = None) -> Tensor:
        Z = X if Z is None else Z
        if X.ndim != 2 or Z.ndim != 2:
            raise ValueError(
                f"kernel inputs must be 2-D, got shapes {tuple(X.shape)}, {tuple(Z.shape)}"
            )
        if X.shape[1] != Z.shape[1]:
            raise ValueError(
                f"kernel inputs have {X.shape[1]} and {Z.shape[1]} features; they must agree"
            )
        return self.forward(X, Z.to(dtype=X.dtype, device=X.device))

    def forward(self, X: Tensor, Z: Tensor) -> Tensor:  # pragma: no cover - abstract
        """Compute the kernel matrix of validated, same-dtype inputs."""
        raise NotImplementedError

    def to_dict(self) -> dict[str, Any]:  # pragma: no cover - abstract
        """A JSON-serialisable description; :func:`kernel_from_dict` inverts it."""
        raise NotImplementedError

    def __add__(self, other: Kernel) -> Kernel:
        if not isinstance(other, Kernel):
            return NotImplemented
        return Sum(self, other)

    def __mul__(self, other: Kernel | float) -> Kernel:
        if isinstance(other, Kernel):
            return Product(self, other)
        if isinstance(other, int | float) and not isinstance(other, bool):
            return Scaled(self, float(other))
        return NotImplemented

    __rmul__ = __mul__

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Kernel) and self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash(repr(self.to_dict()))


#: at most this many ``Z`` entries: squared distances by direct differences
_DIRECT_MAX = 16
#: direct differences are computed for at most this many (pair x feature) entries at a time
_DIRECT_CHUNK = 1 << 22


def _direct_squared_distances(X: Tensor, Z: Tensor) -> Tensor:
    """``sum_k (x_k - z_k)^2`` for all pairs, in row blocks of bounded memory (exact)."""
    out = torch.empty(X.shape[0], Z.shape[0], dtype=X.dtype, device=X.device)
    rows = max(1, _DIRECT_CHUNK // max(1, Z.shape[0] * X.shape[1]))
    for start in range(0, X.shape[0], rows):
        block = X[start : start + rows, None, :] - Z[None, :, :]
        out[start : start + rows] = block.square_().sum(-1)
    return out


def _squared_distances(X: Tensor, Z: Tensor) -> Tensor:
    """Pairwise squared Euclidean distances, accurate to ~``sqrt(eps)`` relative or better.

    Computed as ``|x|^2 + |z|^2 - 2 x.z`` on inputs centred at the mean of ``X``, allocating a
    single ``(n, m)`` result. That expansion has an absolute rounding error of at most
    ``~(d + 3) eps (max|x| + max|z|)^2`` (centred norms, ``d`` features); every entry
    smaller than that bound over ``sqrt(eps)`` -- where the expansion cancels (near pairs,
    data far from its mean) -- is recomputed by direct differences ``sum_k (x_k - z_k)^2``,
    which carry only relative rounding. A few columns ``Z`` are computed directly throughout.
    """
    if Z.shape[0] * Z.shape[1] <= _DIRECT_MAX:
        return (X[:, None, :] - Z[None, :, :]).square_().sum(-1)
    centre = X.mean(dim=0, keepdim=True) if X.shape[0] else 0.0
    Xc = X - centre
    Zc = Z - centre
    nx = (Xc * Xc).sum(1)
    nz = (Zc * Zc).sum(1)
    d2 = nx[:, None] + nz[None, :]
    d2.addmm_(Xc, Zc.T, alpha=-2.0)
    if d2.numel() == 0:
        return d2
    eps = torch.finfo(X.dtype).eps
    reach = float(nx.max().sqrt() + nz.max().sqrt())
    bound = (X.shape[1] + 3.0) * eps * reach * reach / math.sqrt(eps)
    if not math.isfinite(bound):  # (inputs near the float range) everything directly
        return _direct_squared_distances(X, Z)
    if not float(d2.min()) <= bound:  # (one reduction; NaN inputs propagate as they are)
        return d2.clamp_min_(0.0)
    ij = (d2 <= bound).nonzero()
    if ij.shape[0] > d2.numel() // 8:  # widespread cancellation: all pairs directly
        return _direct_squared_distances(X, Z)
    step = max(1, _DIRECT_CHUNK // max(1, X.shape[1]))
    for start in range(0, ij.shape[0], step):
        i, j = ij[start : start + step].unbind(1)
        d2[i, j] = (X[i] - Z[j]).square_().sum(1)
    return d2.clamp_min_(0.0)


class RBF(Kernel):
    r"""Gaussian kernel :math:`k(x, z) = \exp(-\lVert x - z\rVert^2 / (2\sigma^2))`.

    Parameters
    ----------
    width : float
        :math:`\sigma > 0`, the paper's parametrisation (its GA-tuned 0.0305).
    """

    def __init__(self, width: float = 1.0) -> None:
        width = float(width)
        if not math.isfinite(width) or width <= 0:
            raise ValueError(f"RBF width must be a finite positive number, got {width!r}")
        self.width = width

    def forward(self, X: Tensor, Z: Tensor) -> Tensor:
        d2 = _squared_distances(X, Z)
        if Z is X:  # exact zeros on the diagonal of a Gram matrix
            d2.fill_diagonal_(0.0)
        # -d2 / (2 width^2); for widths whose square leaves the float range (beyond ~1e+-154)
        # as two factors, never width^2 (which over- or underflows, and 0 * inf = NaN): a
        # zero distance stays exactly zero for every width
        w2 = self.width * self.width
        if 1e-300 < w2 < 1e300:
            d2.mul_(-0.5 / w2)
        elif math.isfinite(1.0 / self.width):
            d2.mul_(-0.5 / self.width).mul_(1.0 / self.width)
        else:  # (subnormal width)
            d2.div_(self.width).div_(self.width).mul_(-0.5)
        return torch.exp_(d2)

    def to_dict(self) -> dict[str, Any]:
        return {"type": "rbf", "width": self.width}

    def __repr__(self) -> str:
        return f"RBF(width={self.width!r})"


class Linear(Kernel):
    r"""Linear kernel :math:`k(x, z) = x^\top z + c`.

    Parameters
    ----------
    offset : float
        Constant ``c >= 0`` added to the inner product.
    """

    def __init__(self, offset: float = 0.0) -> None:
        offset = float(offset)
        if not math.isfinite(offset) or offset < 0:
            raise ValueError(f"Linear offset must be finite and >= 0, got {offset!r}")
        self.offset = offset

    def forward(self, X: Tensor, Z: Tensor) -> Tensor:
        return X @ Z.T + self.offset

    def to_dict(self) -> dict[str, Any]:
        return {"type": "linear", "offset": self.offset}

    def __repr__(self) -> str:
        return f"Linear(offset={self.offset!r})"


class Polynomial(Kernel):
    r"""Polynomial kernel :math:`k(x, z) = (\gamma\, x^\top z + c_0)^{d}`.

    Parameters
    ----------
    degree : int
        Positive integer degree ``d``.
    gamma : float
        Scale of the inner product (``> 0``).
    coef0 : float
        Constant ``c_0``.
    """

    def __init__(self, degree: int = 3, gamma: float = 1.0, coef0: float = 1.0) -> None:
        if int(degree) != degree or degree < 1:
            raise ValueError(f"Polynomial degree must be a positive integer, got {degree!r}")
        if not math.isfinite(float(gamma)) or gamma <= 0:
            raise ValueError(f"Polynomial gamma must be finite and > 0, got {gamma!r}")
        if not math.isfinite(float(coef0)):
            raise ValueError(f"Polynomial coef0 must be finite, got {coef0!r}")
        self.degree = int(degree)
        self.gamma = float(gamma)
        self.coef0 = float(coef0)

    def forward(self, X: Tensor, Z: Tensor) -> Tensor:
        return (self.gamma * (X @ Z.T) + self.coef0) ** self.degree

    def to_dict(self) -> dict[str, Any]:
        return {
            "type": "polynomial",
            "degree": self.degree,
            "gamma": self.gamma,
            "coef0": self.coef0,
        }

    def __repr__(self) -> str:
        return f"Polynomial(degree={self.degree}, gamma={self.gamma!r}, coef0={self.coef0!r})"


class Sum(Kernel):
    """Sum of two kernels."""

    def __init__(self, left: Kernel, right: Kernel) -> None:
        self.left, self.right = left, right

    def forward(self, X: Tensor, Z: Tensor) -> Tensor:
        return self.left.forward(X, Z) + self.right.forward(X, Z)

    def to_dict(self) -> dict[str, Any]:
        return {"type": "sum", "left": self.left.to_dict(), "right": self.right.to_dict()}

    def __repr__(self) -> str:
        return f"({self.left!r} + {self.right!r})"


class Product(Kernel):
    """Element-wise product of two kernels."""

    def __init__(self, left: Kernel, right: Kernel) -> None:
        self.left, self.right = left, right

    def forward(self, X: Tensor, Z: Tensor) -> Tensor:
        return self.left.forward(X, Z) * self.right.forward(X, Z)

    def to_dict(self) -> dict[str, Any]:
        return {"type": "product", "left": self.left.to_dict(), "right": self.right.to_dict()}

    def __repr__(self) -> str:
        return f"({self.left!r} * {self.right!r})"


class Scaled(Kernel):
    """A kernel times a positive constant."""

    def __init__(self, kernel: Kernel, scale: float) -> None:
        scale = float(scale)
        if not math.isfinite(scale) or scale <= 0:
            raise ValueError(f"kernel scale must be finite and > 0, got {scale!r}")
        self.kernel, self.scale = kernel, scale

    def forward(self, X: Tensor, Z: Tensor) -> Tensor:
        return self.scale * self.kernel.forward(X, Z)

    def to_dict(self) -> dict[str, Any]:
        return {"type": "scaled", "scale": self.scale, "kernel": self.kernel.to_dict()}

    def __repr__(self) -> str:
        return f"{self.scale!r} * {self.kernel!r}"


def kernel_from_dict(spec: dict[str, Any]) -> Kernel:
    """Rebuild a kernel from :meth:`Kernel.to_dict` output.

    Raises
    ------
    ValueError
        If the description is malformed or names an unknown kernel type.
    """
    try:
        kind = spec["type"]
        if kind == "rbf":
            return RBF(spec["width"])
        if kind == "linear":
            return Linear(spec["offset"])
        if kind == "polynomial":
            return Polynomial(spec["degree"], spec["gamma"], spec["coef0"])
        if kind == "sum":
            return Sum(kernel_from_dict(spec["left"]), kernel_from_dict(spec["right"]))
        if kind == "product":
            return Product(kernel_from_dict(spec["left"]), kernel_from_dict(spec["right"]))
        if kind == "scaled":
            return Scaled(kernel_from_dict(spec["kernel"]), spec["scale"])
    except (KeyError, TypeError) as exc:
        raise ValueError(f"malformed kernel description {spec!r}: {exc}") from exc
    raise ValueError(f"unknown kernel type {spec.get('type')!r} in {spec!r}")

"""Exact rescaling of the RVM estimators' data: powers of two, and kernels that follow them.

Data far from unit scale are divided by a power of two (`power_of_two_scale`), which rounds
nothing. A kernel follows its inputs exactly: the RBF kernel at the width divided by the same
power (`~bayes_fdi.rvm.base`), the linear kernel ``x.z + c`` on inputs divided by ``s`` as
``x.z + c / s^2`` and the polynomial kernel ``(gamma x.z + c0)^d`` as ``(gamma x.z + c0 /
s^2)^d`` (`rescaled_kernel`): the caller's kernel divided by ``s^2`` or ``s^(2d)``
(`kernel_factor`), so every kernel column changes by one power of two and the solvers, which
work on unit-norm columns, fit the same model. A kernel with an offset is never scaled up (its
offset would overflow; its values, near the offset, do not). `check_kernel_range` refuses
inputs whose linear or polynomial kernel values would still overflow.

Imports torch and :mod:`~bayes_fdi.rvm.kernels` only. Written by hand: a few lines of float
bookkeeping specific to these estimators.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import torch
from torch import Tensor

from bayes_fdi.rvm.kernels import Kernel, Linear, Polynomial

__all__ = [
    "MAX_SCALED_WIDTH",
    "MIN_SCALED_WIDTH",
    "SCALE_EXPONENT",
    "check_kernel_range",
    "has_offset",
    "kernel_factor",
    "power_of_two_scale",
    "rescaled_kernel",
]

#: data whose largest magnitude lies in [2^-SCALE_EXPONENT, 2^SCALE_EXPONENT] are not rescaled
SCALE_EXPONENT = 32
#: RBF widths are clamped to [2^-500, 2^500]: the square stays a normal float64, and outside
#: that range the kernel of (rescaled, hence at most ~2^33 apart) rows is the same in float64
#: (below: 0 between distinct rows, 1 between equal ones; above: 1 everywhere)
MIN_SCALED_WIDTH = 2.0**-500
MAX_SCALED_WIDTH = 2.0**500


def power_of_two_scale(values: Tensor) -> float:
    """A power of two near ``max|values|`` when that lies outside ``[2^-32, 2^32]``, else 1.0.

    Dividing by it is exact (no rounding), so rescaled data hold the same information.
    """
    if values.numel() == 0:
        return 1.0
    top = float(values.detach().abs().max())
    if not (math.isfinite(top) and top > 0):
        return 1.0
    exponent = math.floor(math.log2(top))
    if abs(exponent) <= SCALE_EXPONENT:
        return 1.0
    return math.ldexp(1.0, exponent)


def check_kernel_range(
    kern: Kernel,
    X: Tensor,
    *,
    x_scale: float = 1.0,
    shown: Callable[[], Kernel] | None = None,
) -> None:
    """Refuse inputs whose linear or polynomial kernel values overflow the float type: its
    largest values lie on the diagonal (Cauchy-Schwarz), ``offset + |x|^2`` or
    ``(gamma |x|^2 + coef0)^degree``. (The RBF kernel is bounded by 1.) ``X`` and ``kern``
    are in rescaled units (inputs divided by ``x_scale``); the message names the caller's
    kernel (``shown()``, built only for the message) and inputs."""
    if not isinstance(kern, (Linear, Polynomial)):
        return
    sq = (X * X).sum(dim=1)
    diag = sq + kern.offset if isinstance(kern, Linear) else (kern.gamma * sq + kern.coef0)
    if isinstance(kern, Polynomial):
        diag = diag**kern.degree
    if not bool(torch.isfinite(diag).all()):
        top, dtype = float(X.abs().max()) * x_scale, str(X.dtype).removeprefix("torch.")
        name = repr(shown() if shown is not None else kern)
        raise ValueError(
            f"the {name} kernel overflows {dtype} on these inputs (largest |x| {top:.3g}): "
            "standardise the inputs, or use the RBF kernel, whose fits are scale-invariant"
        )


def rescaled_kernel(kern: Kernel, x_scale: float) -> Kernel:
    """The linear or polynomial kernel ``kern`` on inputs divided by the power of two
    ``x_scale``: ``kern`` divided by `kernel_factor` (other kernels are returned as they are)."""
    if x_scale == 1.0:
        return kern
    sq = x_scale * x_scale  # a kernel with an offset is only scaled down: no overflow

    def scaled(offset: float) -> float:
        return offset / sq if offset else 0.0

    if isinstance(kern, Linear):
        return Linear(scaled(kern.offset))
    if isinstance(kern, Polynomial):
        return Polynomial(kern.degree, kern.gamma, scaled(kern.coef0))
    return kern


def kernel_factor(kern: Kernel, x_scale: float) -> float:
    """``kern`` over `rescaled_kernel` ``(kern, x_scale)``: ``x_scale^2`` (linear),
    ``x_scale^(2 degree)`` (polynomial), 1 otherwise; ``inf`` or 0 where that leaves float64."""
    if x_scale == 1.0 or not isinstance(kern, (Linear, Polynomial)):
        return 1.0
    power = 2 * kern.degree if isinstance(kern, Polynomial) else 2
    with np.errstate(over="ignore", under="ignore"):
        return float(np.float64(x_scale) ** power)


def has_offset(kern: Kernel | None) -> bool:
    """Whether ``kern`` is a linear or polynomial kernel with a non-zero additive constant:
    its tiny inputs are left unscaled (the constant would grow by ``1 / x_scale^2``)."""
    if isinstance(kern, Linear):
        return kern.offset != 0.0
    return isinstance(kern, Polynomial) and kern.coef0 != 0.0

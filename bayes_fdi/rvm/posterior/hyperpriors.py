"""Gamma hyperpriors on the ARD weight precisions and the noise precision.

Why the defaults are not Tipping's ``1e-6`` is explained in :class:`Hyperpriors` and in the
package docstring of :mod:`bayes_fdi.rvm.posterior`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import torch

__all__ = ["Hyperpriors"]


class Hyperpriors(NamedTuple):
    """Gamma hyperpriors (shape ``a``, rate ``b``) on the weight precisions and noise precision.

    Construct as ``Hyperpriors(a_alpha=0.5, b_alpha=5e-5, a_beta=1e-6, b_beta=1e-6,
    relative=True)`` (an immutable named tuple).

    Attributes
    ----------
    a_alpha, b_alpha : float
        Shape and rate of ``alpha_i ~ Gamma(a_alpha, b_alpha)`` for every basis function.
    a_beta, b_beta : float
        Shape and rate of ``beta ~ Gamma(a_beta, b_beta)`` (regression noise precision).
    relative : bool
        If True (default) the rates are in units of the target variance: the model uses
        ``b * var(t)``, which makes the prior invariant to rescaling the targets (``alpha`` and
        ``beta`` both scale as ``1 / var(t)``). Classification targets are on the logit scale
        and use a scale of 1. Set False to give absolute rates.

    Notes
    -----
    On the log scale (where NUTS samples) the Gamma prior has density
    ``exp(a u - b e^u)`` for ``u = log alpha``: almost flat for small ``a`` below ``u ~ log(1/b)``
    and falling off doubly-exponentially above. The defaults ``a_alpha = 1/2``,
    ``b_alpha = 5e-5`` make the implied marginal prior of each weight a Cauchy distribution with
    scale ``sqrt(b/a) = 1%`` of the target standard deviation (see :mod:`bayes_fdi.rvm.posterior`).
    """

    a_alpha: float = 0.5
    b_alpha: float = 5e-5
    a_beta: float = 1e-6
    b_beta: float = 1e-6
    relative: bool = True

    def resolve(self, scale: float) -> Hyperpriors:
        """Absolute hyperpriors for targets of variance ``scale`` (no-op when not relative)."""
        for name in ("a_alpha", "b_alpha", "a_beta", "b_beta"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(
                    f"hyperprior {name} must be a positive finite number, got {value!r}"
                )
        if not self.relative:
            return self
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"hyperprior scale must be positive and finite, got {scale!r}")
        return Hyperpriors(
            self.a_alpha, self.b_alpha * scale, self.a_beta, self.b_beta * scale, relative=False
        )


def log_gamma_on_log_scale(u: torch.Tensor, a: float, b: float) -> torch.Tensor:
    """Elementwise log density of ``u = log x`` for ``x ~ Gamma(a, b)`` (Jacobian included)."""
    return a * math.log(b) - math.lgamma(a) + a * u - b * torch.exp(u)


def np_log_gamma_on_log_scale(u: np.ndarray, a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
    """Value and derivative of the log density of ``u = log x``, ``x ~ Gamma(a, b)`` (numpy)."""
    bx = b * np.exp(u)
    return a * math.log(b) - math.lgamma(a) + a * u - bx, a - bx

"""Priors of the digital twin: each fitted parameter is logit-normal on a stated physical interval.

A parameter ``theta`` with prior interval ``[low, high]`` is ``theta = low + (high - low)
sigmoid(z)`` with ``z ~ Normal(logit((nominal - low) / (high - low)), spread)``: its median is
the nominal value, it never leaves its interval, and ``z`` (unconstrained) is what the sampler
and the Laplace approximation work in. :data:`DEFAULT_PRIORS` gives the priors of the
parameters a valve's healthy data can identify (see ``docs/twin.md``); the intervals lie inside
the physical bounds of `bayes_fdi.actuator.PARAMETER_INFO`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import NamedTuple

import numpy as np

from bayes_fdi.actuator import NOMINAL, PARAMETER_INFO

__all__ = [
    "DEFAULT_PRIORS",
    "NOISE_PRIOR",
    "NoisePrior",
    "ParameterPrior",
    "check_priors",
]


class ParameterPrior(NamedTuple):
    """Logit-normal prior of one parameter: median ``nominal``, support ``(low, high)``.

    ``spread`` is the standard deviation of ``logit((theta - low) / (high - low))``: 1 puts 90 %
    of the prior mass between ``sigmoid(logit(q) -+ 1.645)`` of the interval, ``q`` being the
    nominal value's position in it.
    """

    nominal: float
    low: float
    high: float
    spread: float = 1.0

    def loc(self) -> float:
        """The prior mean of the unconstrained ``z``."""
        return self.to_latent(self.nominal)

    def to_latent(self, value: float) -> float:
        """``logit((value - low) / (high - low))``, the inverse of `to_value`; a value at or
        beyond the support's ends is taken ``1e-9`` of the interval inside them."""
        q = min(max((float(value) - self.low) / (self.high - self.low), 1e-9), 1.0 - 1e-9)
        return math.log(q / (1.0 - q))

    def to_value(self, z):
        """``low + (high - low) sigmoid(z)`` (numpy or torch, elementwise)."""
        if isinstance(z, np.ndarray | float | int):
            return self.low + (self.high - self.low) / (1.0 + np.exp(-np.asarray(z, float)))
        return self.low + (self.high - self.low) * z.sigmoid()


class NoisePrior(NamedTuple):
    """Prior of the AR(1) residual model of each channel.

    ``log(sigma) ~ Normal(log(sigma_median), sigma_spread)`` (``sigma``: standard deviation of
    the innovations, full-scale units) and ``atanh(phi) ~ Normal(0, phi_spread)`` (``phi``: the
    lag-1 coefficient, in ``(-1, 1)``), for X and F alike; and
    ``log(kappa) ~ Normal(log(kappa_median), kappa_spread)``: ``kappa`` is the standard
    deviation of the recorded pressure drop's error (full scale of the pressure transmitters),
    which adds ``kappa (F' - o) / (2 (P1 - P2))`` to the flow's innovation scale
    (`bayes_fdi.twin.likelihood.flow_innovation_scale`).
    """

    sigma_median: float = 0.02
    sigma_spread: float = 1.5
    phi_spread: float = 1.0
    kappa_median: float = 0.002
    kappa_spread: float = 1.5


#: The noise prior of X and F: innovations around 2 % of full scale (a factor of 4.5 either way
#: at one standard deviation), lag-1 correlation centred on 0; the pressure drop read with an
#: error around 0.2 % of the transmitters' full scale (two readings with DAMADICS' 0.14 % white
#: noise each; a factor of 4.5 either way at one standard deviation).
NOISE_PRIOR = NoisePrior()


def _prior(name: str, low: float, high: float, spread: float = 1.0) -> ParameterPrior:
    return ParameterPrior(float(getattr(NOMINAL, name)), low, high, spread)


#: Priors of the parameters fitted by default: the valve's flow coefficient and characteristic,
#: the F' transmitter's zero, the X' transmitter's zero and span, the positioner's air capacity
#: and set-point lag, and the friction (backlash).
DEFAULT_PRIORS: dict[str, ParameterPrior] = {
    "kv": _prior("kv", 30.0, 480.0),
    "characteristic": _prior("characteristic", 2.0, 10.0),
    "f_offset": _prior("f_offset", -0.1, 0.1),
    "x_offset": _prior("x_offset", -0.1, 0.1),
    "x_gain": _prior("x_gain", 0.8, 1.2),
    "inflow_coefficient": _prior("inflow_coefficient", 0.5e-6, 12.5e-6),
    "setpoint_lag": _prior("setpoint_lag", 0.05, 2.0),
    "backlash": _prior("backlash", 0.0, 0.1),
}


def check_priors(priors: Mapping[str, ParameterPrior]) -> dict[str, ParameterPrior]:
    """Validate priors against the physical bounds of `PARAMETER_INFO`; return a copy.

    Raises ``ValueError`` naming the parameter: unknown name, an interval outside the physical
    bounds or not containing its nominal value, a spread that is not positive.
    """
    if not isinstance(priors, Mapping) or not priors:
        raise ValueError("priors must be a non-empty mapping of parameter name -> ParameterPrior")
    out = {}
    for name, prior in priors.items():
        if name not in PARAMETER_INFO:
            raise ValueError(f"unknown parameter {name!r}; parameters are {list(PARAMETER_INFO)}")
        if not isinstance(prior, ParameterPrior):
            raise ValueError(f"prior of {name} must be a ParameterPrior, got {prior!r}")
        info = PARAMETER_INFO[name]
        values = [float(v) for v in prior]
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f"prior of {name}: values must be finite, got {prior!r}")
        if not info.low <= prior.low < prior.high <= info.high:
            raise ValueError(
                f"prior of {name}: interval [{prior.low:g}, {prior.high:g}] must be increasing "
                f"and inside the physical bounds [{info.low:g}, {info.high:g}] {info.unit}"
            )
        if not prior.low < prior.nominal < prior.high:
            raise ValueError(
                f"prior of {name}: nominal {prior.nominal:g} must lie strictly inside "
                f"[{prior.low:g}, {prior.high:g}]"
            )
        if prior.spread <= 0:
            raise ValueError(f"prior of {name}: spread must be > 0, got {prior.spread!r}")
        out[name] = ParameterPrior(*values)
    return out

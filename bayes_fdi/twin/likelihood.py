"""The twin's residual model: an AR(1) process per channel with a time-varying innovation scale.

What the model does not explain of a healthy recording is mostly loop motion at the 1 Hz
sampling rate (lag-1 correlation about 0.4 on the real hour), not white measurement noise, so
the residual ``e = y - model`` of each channel is an AR(1) process:
``e_0 ~ N(0, sigma_0^2 / (1 - phi^2))``, ``e_t = phi e_(t-1) + sigma_t eps_t``. The innovation
scale ``sigma_t`` may change with time: the flow's grows with the flow over the pressure drop
(:func:`flow_innovation_scale`), because the recorded pressures that drive the model are noisy
and ``dF / F = d(P1 - P2) / (2 (P1 - P2))``. With a constant scale the process is stationary.
Written by hand: Pyro's Gaussian HMMs need an observation noise, which an exactly observed AR(1)
process has not. A mask selects contiguous samples of each series (the samples after a window's
settling time and before its padding); the first selected sample of a series takes the
stationary density of its own scale.
"""

from __future__ import annotations

import math

import numpy as np
import pyro.distributions as dist
import torch
from scipy.signal import lfilter
from torch.distributions import constraints

__all__ = ["StationaryAR1", "ar1_from_innovations", "ar1_paths", "flow_innovation_scale"]


def flow_innovation_scale(sigma, kappa, ratio):
    """The flow residual's innovation scale ``sqrt(sigma^2 + (kappa * ratio)^2)`` (torch).

    ``ratio`` is the model's flow reading above the F' zero over twice the pressure drop,
    ``(F' - o) / (2 (P1 - P2))`` (`bayes_fdi.twin.model.flow_ratio`); ``kappa`` is the standard
    deviation of the recorded pressure drop's error, in the pressure transmitters' full scale:
    a drop read ``d(P1 - P2)`` wrong moves the model's flow by ``F d(P1 - P2) / (2 (P1 - P2))``.
    """
    return torch.sqrt(sigma**2 + (kappa * ratio) ** 2)


class StationaryAR1(dist.TorchDistribution):
    """Series ``loc + e`` with ``e`` an AR(1) process (event: the last dimension).

    Parameters
    ----------
    loc
        Mean of each series, shape ``batch + (T,)``.
    sigma
        Standard deviation of the innovations (> 0), broadcastable to ``batch + (T,)``: one
        value per series (shape ``batch + (1,)``, or a scalar) gives a stationary process;
        ``sigma[..., t]`` is the scale of ``eps_t``, and the first counted sample of a series
        has the stationary variance ``sigma_t^2 / (1 - phi^2)`` of its own ``t``.
    phi
        Lag-1 coefficient in ``(-1, 1)``, broadcastable to ``batch``.
    mask
        Boolean, shape of ``loc``: the samples that count (contiguous in each series); None:
        all.
    """

    arg_constraints = {"loc": constraints.real, "sigma": constraints.positive}  # noqa: RUF012
    support = constraints.real_vector
    has_rsample = False

    def __init__(self, loc, sigma, phi, mask=None, validate_args=None):
        self.loc = loc
        batch = loc.shape[:-1]
        self.sigma = torch.as_tensor(sigma, dtype=loc.dtype).expand(loc.shape)
        self.phi = torch.as_tensor(phi, dtype=loc.dtype).expand(batch)
        self.mask = torch.ones_like(loc, dtype=torch.bool) if mask is None else mask
        super().__init__(batch, loc.shape[-1:], validate_args=validate_args)

    def log_prob(self, value):
        e = value - self.loc
        sigma = self.sigma
        phi = self.phi.unsqueeze(-1)
        prev = torch.zeros_like(self.mask)
        prev[..., 1:] = self.mask[..., :-1]
        first = self.mask & ~prev
        cont = (self.mask & prev)[..., 1:]
        var0 = sigma**2 / (1.0 - phi**2)
        lp_first = -0.5 * (e**2 / var0 + torch.log(2.0 * math.pi * var0))
        innov = e[..., 1:] - phi * e[..., :-1]
        now = sigma[..., 1:]
        lp_cont = -0.5 * ((innov / now) ** 2 + math.log(2.0 * math.pi)) - torch.log(now)
        zero = torch.zeros((), dtype=e.dtype)
        return torch.where(first, lp_first, zero).sum(-1) + torch.where(cont, lp_cont, zero).sum(-1)

    def sample(self, sample_shape=()):
        shape = torch.Size(sample_shape) + self.batch_shape + self.event_shape
        eps = torch.randn(shape, dtype=self.loc.dtype)
        sigma = self.sigma.expand(shape).detach().numpy()
        phi = self.phi.expand(shape[:-1]).detach().numpy()
        paths = ar1_from_innovations(eps.numpy(), sigma, phi)
        return self.loc.detach() + torch.as_tensor(paths, dtype=self.loc.dtype)


def ar1_from_innovations(eps: np.ndarray, sigma: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """AR(1) paths (last axis: time) from standard normal innovations ``eps``.

    ``sigma``: one innovation scale per path (shape ``eps.shape[:-1]``, broadcastable; a
    stationary path) or one per sample (shape ``eps.shape``); ``phi``: one per path. The first
    sample has the stationary variance ``sigma_0^2 / (1 - phi^2)``.
    """
    eps = np.asarray(eps, dtype=np.float64)
    sigma = np.asarray(sigma, dtype=np.float64)
    per_sample = sigma.ndim == eps.ndim
    sigma = np.broadcast_to(sigma, eps.shape if per_sample else eps.shape[:-1])
    phi = np.broadcast_to(np.asarray(phi, dtype=np.float64), eps.shape[:-1])
    out = np.empty_like(eps)
    n_t = eps.shape[-1]
    flat_eps = eps.reshape(-1, n_t)
    flat_out = out.reshape(-1, n_t)
    flat_sigma = sigma.reshape(-1, n_t) if per_sample else sigma.reshape(-1, 1)
    for k, p in enumerate(phi.ravel()):
        s = flat_sigma[k]
        e0 = flat_eps[k, 0] * s[0] / math.sqrt(1.0 - p * p)
        flat_out[k, 0] = e0
        if n_t > 1:
            if per_sample:
                drive = s[1:] * flat_eps[k, 1:]
                flat_out[k, 1:] = lfilter([1.0], [1.0, -p], drive, zi=[p * e0])[0]
            else:
                flat_out[k, 1:] = lfilter([s[0]], [1.0, -p], flat_eps[k, 1:], zi=[p * e0])[0]
    return out


def ar1_paths(
    rng: np.random.Generator, sigma: np.ndarray, phi: np.ndarray, n_times: int
) -> np.ndarray:
    """Stationary AR(1) paths, shape ``sigma.shape + (n_times,)``, drawn from ``rng``."""
    sigma = np.asarray(sigma, dtype=np.float64)
    eps = rng.standard_normal((*sigma.shape, int(n_times)))
    return ar1_from_innovations(eps, sigma, np.asarray(phi, dtype=np.float64))

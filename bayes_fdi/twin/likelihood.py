"""The twin's residual model: a stationary AR(1) process per channel, as a Pyro distribution.

What the model does not explain of a healthy recording is mostly loop motion at the 1 Hz
sampling rate (lag-1 correlation about 0.4 on the real hour), not white measurement noise, so
the residual ``e = y - model`` of each channel is a stationary AR(1) process:
``e_0 ~ N(0, sigma^2 / (1 - phi^2))``, ``e_t = phi e_(t-1) + sigma eps_t``. Written by hand:
Pyro's Gaussian HMMs need an observation noise, which an exactly observed AR(1) process has
not. A mask selects contiguous samples of each series (the samples after a window's settling
time and before its padding); the first selected sample of a series takes the stationary
density.
"""

from __future__ import annotations

import math

import numpy as np
import pyro.distributions as dist
import torch
from scipy.signal import lfilter
from torch.distributions import constraints

__all__ = ["StationaryAR1", "ar1_paths"]


class StationaryAR1(dist.TorchDistribution):
    """Series ``loc + e`` with ``e`` a stationary AR(1) process (event: the last dimension).

    Parameters
    ----------
    loc
        Mean of each series, shape ``batch + (T,)``.
    sigma
        Standard deviation of the innovations (> 0), broadcastable to ``batch``.
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
        self.sigma = torch.as_tensor(sigma, dtype=loc.dtype).expand(batch)
        self.phi = torch.as_tensor(phi, dtype=loc.dtype).expand(batch)
        self.mask = torch.ones_like(loc, dtype=torch.bool) if mask is None else mask
        super().__init__(batch, loc.shape[-1:], validate_args=validate_args)

    def log_prob(self, value):
        e = value - self.loc
        sigma = self.sigma.unsqueeze(-1)
        phi = self.phi.unsqueeze(-1)
        prev = torch.zeros_like(self.mask)
        prev[..., 1:] = self.mask[..., :-1]
        first = self.mask & ~prev
        cont = (self.mask & prev)[..., 1:]
        var0 = sigma**2 / (1.0 - phi**2)
        lp_first = -0.5 * (e**2 / var0 + torch.log(2.0 * math.pi * var0))
        innov = e[..., 1:] - phi * e[..., :-1]
        lp_cont = -0.5 * ((innov / sigma) ** 2 + math.log(2.0 * math.pi)) - torch.log(sigma)
        zero = torch.zeros((), dtype=e.dtype)
        return torch.where(first, lp_first, zero).sum(-1) + torch.where(cont, lp_cont, zero).sum(-1)

    def sample(self, sample_shape=()):
        shape = torch.Size(sample_shape) + self.batch_shape + self.event_shape
        eps = torch.randn(shape, dtype=self.loc.dtype)
        sigma = self.sigma.expand(shape[:-1]).detach().numpy()
        phi = self.phi.expand(shape[:-1]).detach().numpy()
        paths = ar1_from_innovations(eps.numpy(), sigma, phi)
        return self.loc.detach() + torch.as_tensor(paths, dtype=self.loc.dtype)


def ar1_from_innovations(eps: np.ndarray, sigma: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Stationary AR(1) paths (last axis: time) from standard normal innovations ``eps``."""
    eps = np.asarray(eps, dtype=np.float64)
    sigma = np.broadcast_to(np.asarray(sigma, dtype=np.float64), eps.shape[:-1])
    phi = np.broadcast_to(np.asarray(phi, dtype=np.float64), eps.shape[:-1])
    out = np.empty_like(eps)
    flat_eps = eps.reshape(-1, eps.shape[-1])
    flat_out = out.reshape(-1, eps.shape[-1])
    for k, (s, p) in enumerate(zip(sigma.ravel(), phi.ravel(), strict=True)):
        e0 = flat_eps[k, 0] * s / math.sqrt(1.0 - p * p)
        flat_out[k, 0] = e0
        if flat_eps.shape[1] > 1:
            flat_out[k, 1:] = lfilter([s], [1.0, -p], flat_eps[k, 1:], zi=[p * e0])[0]
    return out


def ar1_paths(
    rng: np.random.Generator, sigma: np.ndarray, phi: np.ndarray, n_times: int
) -> np.ndarray:
    """Stationary AR(1) paths, shape ``sigma.shape + (n_times,)``, drawn from ``rng``."""
    sigma = np.asarray(sigma, dtype=np.float64)
    eps = rng.standard_normal((*sigma.shape, int(n_times)))
    return ar1_from_innovations(eps, sigma, np.asarray(phi, dtype=np.float64))

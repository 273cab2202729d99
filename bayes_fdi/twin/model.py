"""The twin's Bayesian model, written in Pyro.

Latent variables (all unconstrained): ``z`` (one per fitted parameter, logit-normal priors of
`bayes_fdi.twin.priors`), ``log_sigma`` and ``atanh_phi`` (the AR(1) residual model of X and
F). Given them, the simulator (`bayes_fdi.twin.simulator`) runs the recording's windows with the
recording's own inputs, and the recorded X and F are AR(1) series around its outputs
(`bayes_fdi.twin.likelihood.StationaryAR1`). :func:`log_joint` evaluates the model's log density
for a batch of latent vectors by tracing it with Pyro.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pyro
import pyro.distributions as dist
import torch
from pyro import poutine

from bayes_fdi.twin.likelihood import StationaryAR1
from bayes_fdi.twin.priors import NoisePrior, ParameterPrior
from bayes_fdi.twin.simulator import OUTPUTS, WindowSimulator, simulated_outputs

__all__ = ["TwinProblem", "log_joint", "noise_estimate", "score", "split_latent", "twin_model"]


def noise_estimate(residual: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Least-squares AR(1) fit of residuals ``(..., W, T, 2)``: ``(..., 4)`` latent noise values
    (``log sigma`` of X and F, then ``atanh phi``), the conditional mode up to the priors and
    the first samples' terms."""
    pairs = mask[:, 1:] & mask[:, :-1]
    out = []
    for c in range(residual.shape[-1]):
        now = residual[..., 1:, c][..., pairs]
        before = residual[..., :-1, c][..., pairs]
        phi = np.sum(now * before, axis=-1) / np.maximum(np.sum(before**2, axis=-1), 1e-300)
        phi = np.clip(phi, -0.99, 0.99)
        var = np.mean((now - phi[..., None] * before) ** 2, axis=-1)
        out.append((0.5 * np.log(np.maximum(var, 1e-300)), np.arctanh(phi)))
    return np.stack([out[0][0], out[1][0], out[0][1], out[1][1]], axis=-1)


class TwinProblem(NamedTuple):
    """Everything the model conditions on: simulator, priors, recorded data, difference steps."""

    simulator: WindowSimulator
    priors: tuple[ParameterPrior, ...]
    noise: NoisePrior
    observed: torch.Tensor  # (W, T, 2) recorded X, F
    mask: torch.Tensor  # (W, T) samples that count
    steps: np.ndarray  # (p,) finite-difference steps of the physical parameters

    @property
    def n_parameters(self) -> int:
        return len(self.priors)

    @property
    def n_latent(self) -> int:
        return len(self.priors) + 2 * len(OUTPUTS)

    def prior_loc(self) -> torch.Tensor:
        return torch.tensor([p.loc() for p in self.priors], dtype=torch.float64)

    def prior_spread(self) -> torch.Tensor:
        return torch.tensor([p.spread for p in self.priors], dtype=torch.float64)

    def physical(self, z: torch.Tensor) -> torch.Tensor:
        """Physical parameter values ``(..., p)`` of unconstrained ``z`` ``(..., p)``."""
        low = torch.tensor([p.low for p in self.priors], dtype=z.dtype)
        high = torch.tensor([p.high for p in self.priors], dtype=z.dtype)
        return low + (high - low) * torch.sigmoid(z)


def twin_model(problem: TwinProblem, outputs: torch.Tensor | None = None) -> None:
    """The Pyro model; batch the latents along a leading dimension to score several at once.

    ``outputs``: the simulator's outputs at the latent parameters when already known (the
    model then does not run the simulator again).
    """
    n_out = len(OUTPUTS)
    z = pyro.sample("z", dist.Normal(problem.prior_loc(), problem.prior_spread()).to_event(1))
    noise = problem.noise
    log_sigma = pyro.sample(
        "log_sigma",
        dist.Normal(
            torch.full((n_out,), float(np.log(noise.sigma_median)), dtype=torch.float64),
            torch.full((n_out,), noise.sigma_spread, dtype=torch.float64),
        ).to_event(1),
    )
    atanh_phi = pyro.sample(
        "atanh_phi",
        dist.Normal(
            torch.zeros(n_out, dtype=torch.float64),
            torch.full((n_out,), noise.phi_spread, dtype=torch.float64),
        ).to_event(1),
    )
    theta = problem.physical(z)
    if outputs is None:
        outputs = simulated_outputs(theta, problem.simulator, problem.steps)
    sigma = log_sigma.exp()
    phi = atanh_phi.tanh()
    for c, name in enumerate(OUTPUTS):
        batch = outputs.shape[:-3]
        pyro.sample(
            f"obs_{name}",
            StationaryAR1(
                outputs[..., c],
                sigma[..., c, None].expand(*batch, problem.mask.shape[0]),
                phi[..., c, None].expand(*batch, problem.mask.shape[0]),
                mask=problem.mask.expand(*batch, *problem.mask.shape),
            ).to_event(1),
            obs=problem.observed[..., c],
        )


def split_latent(v: torch.Tensor, n_parameters: int) -> dict[str, torch.Tensor]:
    """The latent vector(s) ``(..., p + 4)`` as the model's sites ``z``, ``log_sigma``,
    ``atanh_phi``."""
    p = n_parameters
    return {"z": v[..., :p], "log_sigma": v[..., p : p + 2], "atanh_phi": v[..., p + 2 : p + 4]}


def log_joint(problem: TwinProblem, v: torch.Tensor) -> torch.Tensor:
    """Log density of the model (prior plus likelihood) at latent vectors ``v`` ``(B, p + 4)``.

    Returns a tensor ``(B,)``; differentiable in ``v`` when ``B == 1``.
    """
    return score(problem, v)[0]


def score(
    problem: TwinProblem, v: torch.Tensor, outputs: torch.Tensor | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """`log_joint` and the simulator's outputs ``(B, W, T, 2)`` at each latent vector
    (``outputs``: those outputs when already simulated)."""
    if v.ndim != 2 or v.shape[1] != problem.n_latent:
        raise ValueError(f"latent vectors must have shape (B, {problem.n_latent}), got {v.shape}")
    conditioned = poutine.condition(twin_model, data=split_latent(v, problem.n_parameters))
    trace = poutine.trace(conditioned).get_trace(problem, outputs)
    total = torch.zeros(v.shape[0], dtype=v.dtype)
    for site in trace.nodes.values():
        if site["type"] != "sample":
            continue
        lp = site["fn"].log_prob(site["value"])
        total = total + lp.reshape(v.shape[0], -1).sum(-1)
    outputs = torch.stack(
        [trace.nodes[f"obs_{name}"]["fn"].base_dist.loc for name in OUTPUTS], dim=-1
    )
    return total, outputs

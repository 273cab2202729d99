"""The twin's Bayesian model, written in Pyro.

Latent variables (all unconstrained): ``z`` (one per fitted parameter, logit-normal priors of
`bayes_fdi.twin.priors`), ``log_sigma`` and ``atanh_phi`` (the AR(1) residual model of X and
F) and ``log_kappa`` (the recorded pressure drop's error, which scales the flow residual with
the flow over the pressure drop: :func:`flow_ratio`). Given them, the simulator
(`bayes_fdi.twin.simulator`) runs the recording's windows with the recording's own inputs, and
the recorded X and F are AR(1) series around its outputs
(`bayes_fdi.twin.likelihood.StationaryAR1`), X's with one innovation scale ``sigma_X``, F's with
``sqrt(sigma_F^2 + (kappa ratio_t)^2)``. :func:`log_joint` evaluates the model's log density
for a batch of latent vectors by tracing it with Pyro.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import pyro
import pyro.distributions as dist
import torch
from pyro import poutine

from bayes_fdi.actuator import ActuatorParameters
from bayes_fdi.twin.likelihood import StationaryAR1, ar1_from_innovations, flow_innovation_scale
from bayes_fdi.twin.priors import NoisePrior, ParameterPrior
from bayes_fdi.twin.simulator import OUTPUTS, WindowSimulator, simulated_outputs

__all__ = [
    "MIN_PRESSURE_DROP",
    "N_NOISE",
    "TwinProblem",
    "flow_ratio",
    "log_joint",
    "noise_estimate",
    "noise_values",
    "residual_paths",
    "score",
    "split_latent",
    "twin_model",
]

#: Noise latents after the fitted parameters: log sigma (X, F), atanh phi (X, F), log kappa.
N_NOISE = 5
#: Floor of the pressure drop in :func:`flow_ratio` (full scale of the pressure transmitters:
#: 20 kPa). The flow's error ``F d(P1 - P2) / (2 (P1 - P2))`` is a linearisation for an error
#: small against the drop; below a few times the readings' noise the error is of the order of
#: the flow itself, which the floor keeps it at.
MIN_PRESSURE_DROP = 0.005


def flow_ratio(
    flow: torch.Tensor,
    theta: torch.Tensor,
    names: Sequence[str],
    base: ActuatorParameters,
    pressures: torch.Tensor,
) -> torch.Tensor:
    """``(F' - o) / (2 (P1 - P2))``: the model's flow reading above the F' zero ``o`` over twice
    the pressure drop that drove it, clipped below at 0 and with the drop floored at
    `MIN_PRESSURE_DROP` (full-scale units of F' and of the pressure transmitters).

    ``flow``: the model's F' ``(..., W, T)``; ``theta``: the fitted parameters ``(..., p)`` in
    the order of ``names`` (the F' zero and the pressure transmitters' calibration come from
    ``theta`` when fitted, else from ``base``); ``pressures``: the recorded P1', P2'
    ``(W, T, 2)``, read back through the calibration as the simulator reads them.
    """
    names = list(names)

    def field(name: str):
        if name in names:
            return theta[..., names.index(name), None, None]
        return float(getattr(base, name))

    p1 = (pressures[..., 0] - field("p1_offset")) / field("p1_gain")
    p2 = (pressures[..., 1] - field("p2_offset")) / field("p2_gain")
    drop = (p1 - p2).clamp(min=MIN_PRESSURE_DROP)
    return (flow - field("f_offset")).clamp(min=0.0) / (2.0 * drop)


def noise_values(latent: np.ndarray, n_parameters: int) -> tuple[np.ndarray, ...]:
    """``sigma (..., 2)``, ``phi (..., 2)`` (X, F) and ``kappa (...)`` of latent vector(s)."""
    latent = np.asarray(latent)
    p = n_parameters
    sigma = np.exp(latent[..., p : p + 2])
    phi = np.tanh(latent[..., p + 2 : p + 4])
    return sigma, phi, np.exp(latent[..., p + 4])


def residual_paths(
    rng: np.random.Generator,
    latent: np.ndarray,
    thetas: np.ndarray,
    model: np.ndarray,
    names: Sequence[str],
    base: ActuatorParameters,
    pressures: np.ndarray,
) -> np.ndarray:
    """AR(1) residual paths ``(draw, W, T, 2)`` of X and F for latent draws ``(draw, p + 5)``,
    their parameters ``thetas`` ``(draw, p)``, their simulated outputs ``model``
    ``(draw, W, T, 2)`` and the recorded P1', P2' ``pressures`` ``(W, T, 2)``: X's with one
    innovation scale per draw, F's with the scale that grows with the flow over the pressure
    drop. ``rng`` draws the standard normal innovations, X's then F's."""
    sigma, phi, kappa = noise_values(latent, len(names))
    n, n_w, n_t = model.shape[:3]
    with torch.no_grad():
        ratio = flow_ratio(
            torch.as_tensor(model[..., 1]), torch.as_tensor(thetas), names, base,
            torch.as_tensor(pressures),
        )  # fmt: skip
        scale_f = flow_innovation_scale(
            torch.as_tensor(sigma[:, 1, None, None]), torch.as_tensor(kappa[:, None, None]), ratio
        ).numpy()
    scales = {"X": np.broadcast_to(sigma[:, 0, None], (n, n_w)), "F": scale_f}
    paths = np.empty(model.shape)
    for c, name in enumerate(OUTPUTS):
        eps = rng.standard_normal((n, n_w, n_t))
        paths[..., c] = ar1_from_innovations(
            eps, scales[name], np.broadcast_to(phi[:, c, None], (n, n_w))
        )
    return paths


def _variance_fit(u2: np.ndarray, q2: np.ndarray, floors: tuple[float, float]) -> np.ndarray:
    """``(a, b)`` of ``E u2 = a + b q2`` (both >= their floors) by iteratively reweighted least
    squares with weights ``1 / (a + b q2)^2``: at its fixed point, the maximum-likelihood
    variances of zero-mean Gaussian ``u``. The 2 x 2 normal equations are solved in closed form
    from numpy's sums (no LAPACK: the same bits on every machine)."""
    weights = np.ones_like(u2)
    ab = np.array(floors, dtype=np.float64)
    for _ in range(4):
        s0, s1, s2 = np.sum(weights), np.sum(weights * q2), np.sum(weights * q2**2)
        t0, t1 = np.sum(weights * u2), np.sum(weights * q2 * u2)
        det = s0 * s2 - s1 * s1
        b = (s0 * t1 - s1 * t0) / det if det > 0 else -math.inf
        ab = np.array([(t0 - b * s1) / s0, b])
        if not ab[1] >= floors[1]:  # the flow term is not supported: the constant alone
            ab = np.array([np.sum(weights * (u2 - floors[1] * q2)) / s0, floors[1]])
        ab = np.maximum(ab, floors)
        weights = 1.0 / (ab[0] + ab[1] * q2) ** 2
    return ab


def noise_estimate(
    residual: np.ndarray, mask: np.ndarray, ratio: np.ndarray, kappa_floor: float = 1e-5
) -> np.ndarray:
    """Least-squares fit of the AR(1) residual model to residuals ``(W, T, 2)``: the ``(5,)``
    latent noise values (``log sigma`` of X and F, ``atanh phi`` of X and F, ``log kappa``),
    the conditional mode up to the priors and the first samples' terms.

    ``ratio`` ``(W, T)``: :func:`flow_ratio` at the residual's parameters. X's innovations have
    one variance; F's variance ``sigma^2 + kappa^2 ratio_t^2`` is fitted to the squared
    innovations (``kappa`` at least ``kappa_floor``), and ``phi_F`` again by weighted least
    squares with those variances.
    """
    pairs = mask[:, 1:] & mask[:, :-1]
    q2 = (ratio[:, 1:][pairs]) ** 2
    log_sigma, atanh_phi = [], []
    for c, name in enumerate(OUTPUTS):
        now = residual[:, 1:, c][pairs]
        before = residual[:, :-1, c][pairs]
        if name != "F":
            phi = _lag_one(now, before, np.ones_like(now))
            var = max(float(np.mean((now - phi * before) ** 2)), 1e-300)
        else:
            weights = np.ones_like(now)
            for _ in range(2):  # phi, then the variances, then phi again with them
                phi = _lag_one(now, before, weights)
                u2 = (now - phi * before) ** 2
                floor = max(1e-12 * float(np.mean(u2)), 1e-300)
                var, kappa2 = _variance_fit(u2, q2, (floor, kappa_floor**2))
                weights = 1.0 / (var + kappa2 * q2)
        log_sigma.append(0.5 * np.log(var))
        atanh_phi.append(np.arctanh(phi))
    return np.array([*log_sigma, *atanh_phi, np.log(np.sqrt(kappa2))])


def _lag_one(now: np.ndarray, before: np.ndarray, weights: np.ndarray) -> float:
    """Weighted least-squares lag-1 coefficient of ``now`` on ``before``, clipped to 0.99."""
    phi = np.sum(weights * now * before) / max(np.sum(weights * before**2), 1e-300)
    return float(np.clip(phi, -0.99, 0.99))


class TwinProblem(NamedTuple):
    """Everything the model conditions on: simulator, priors, recorded data, difference steps."""

    simulator: WindowSimulator
    priors: tuple[ParameterPrior, ...]
    noise: NoisePrior
    observed: torch.Tensor  # (W, T, 2) recorded X, F
    mask: torch.Tensor  # (W, T) samples that count
    steps: np.ndarray  # (p,) finite-difference steps of the physical parameters
    pressures: torch.Tensor  # (W, T, 2) recorded P1', P2'

    @property
    def n_parameters(self) -> int:
        return len(self.priors)

    @property
    def n_latent(self) -> int:
        return len(self.priors) + N_NOISE

    def prior_loc(self) -> torch.Tensor:
        return torch.tensor([p.loc() for p in self.priors], dtype=torch.float64)

    def prior_spread(self) -> torch.Tensor:
        return torch.tensor([p.spread for p in self.priors], dtype=torch.float64)

    def physical(self, z: torch.Tensor) -> torch.Tensor:
        """Physical parameter values ``(..., p)`` of unconstrained ``z`` ``(..., p)``."""
        low = torch.tensor([p.low for p in self.priors], dtype=z.dtype)
        high = torch.tensor([p.high for p in self.priors], dtype=z.dtype)
        return low + (high - low) * torch.sigmoid(z)

    def flow_ratio(self, theta: torch.Tensor, flow: torch.Tensor) -> torch.Tensor:
        """:func:`flow_ratio` of the windows for parameters ``theta`` and model flow ``flow``."""
        sim = self.simulator
        return flow_ratio(flow, theta, sim.names, sim.base, self.pressures)


def _normal(median: float, spread: float, n: int) -> dist.Distribution:
    loc = torch.full((n,), float(np.log(median)), dtype=torch.float64)
    return dist.Normal(loc, torch.full((n,), float(spread), dtype=torch.float64)).to_event(1)


def twin_model(problem: TwinProblem, outputs: torch.Tensor | None = None) -> None:
    """The Pyro model; batch the latents along a leading dimension to score several at once.

    ``outputs``: the simulator's outputs at the latent parameters when already known (the
    model then does not run the simulator again).
    """
    n_out = len(OUTPUTS)
    z = pyro.sample("z", dist.Normal(problem.prior_loc(), problem.prior_spread()).to_event(1))
    noise = problem.noise
    log_sigma = pyro.sample("log_sigma", _normal(noise.sigma_median, noise.sigma_spread, n_out))
    atanh_phi = pyro.sample(
        "atanh_phi",
        dist.Normal(
            torch.zeros(n_out, dtype=torch.float64),
            torch.full((n_out,), noise.phi_spread, dtype=torch.float64),
        ).to_event(1),
    )
    log_kappa = pyro.sample("log_kappa", _normal(noise.kappa_median, noise.kappa_spread, 1))
    theta = problem.physical(z)
    if outputs is None:
        outputs = simulated_outputs(theta, problem.simulator, problem.steps)
    sigma = log_sigma.exp()[..., None, None, :]  # (..., 1, 1, 2): per channel
    phi = atanh_phi.tanh()[..., None, :]  # (..., 1, 2)
    kappa = log_kappa.exp()[..., None, :]  # (..., 1, 1)
    batch = outputs.shape[:-3]
    n_windows = problem.mask.shape[0]
    for c, name in enumerate(OUTPUTS):
        scale = sigma[..., c]
        if name == "F":
            ratio = problem.flow_ratio(theta, outputs[..., c])
            scale = flow_innovation_scale(scale, kappa, ratio)
        pyro.sample(
            f"obs_{name}",
            StationaryAR1(
                outputs[..., c],
                scale.expand(*batch, *problem.mask.shape),
                phi[..., c].expand(*batch, n_windows),
                mask=problem.mask.expand(*batch, *problem.mask.shape),
            ).to_event(1),
            obs=problem.observed[..., c],
        )


def split_latent(v: torch.Tensor, n_parameters: int) -> dict[str, torch.Tensor]:
    """The latent vector(s) ``(..., p + 5)`` as the model's sites ``z``, ``log_sigma``,
    ``atanh_phi``, ``log_kappa``."""
    p = n_parameters
    return {
        "z": v[..., :p],
        "log_sigma": v[..., p : p + 2],
        "atanh_phi": v[..., p + 2 : p + 4],
        "log_kappa": v[..., p + 4 : p + 5],
    }


def log_joint(problem: TwinProblem, v: torch.Tensor) -> torch.Tensor:
    """Log density of the model (prior plus likelihood) at latent vectors ``v`` ``(B, p + 5)``.

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

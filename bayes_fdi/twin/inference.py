"""The twin's posterior as ArviZ ``InferenceData``, and what it says the data identify.

:func:`inference_data` gathers the fit: ``posterior`` (Laplace draws of the fitted parameters in
their physical units and of the residual model's ``sigma_X, sigma_F, phi_X, phi_F, kappa_F``),
``sample_stats`` (each draw's Pareto-smoothed log importance weight against the exact
posterior), ``prior`` (draws from the priors), ``observed_data`` (the fitted X, F per window),
``constant_data`` (the windows' inputs and which samples were fitted) and
``posterior_predictive`` (X, F: the simulator at each draw plus an AR(1) path, F's with the
innovation scale that grows with the flow over the pressure drop).
:func:`identification` tabulates prior and posterior widths and the posterior correlations.
"""

from __future__ import annotations

from typing import NamedTuple

import arviz as az
import numpy as np
import torch

from bayes_fdi.datasets import INPUT_CHANNELS
from bayes_fdi.twin.laplace import ImportanceCheck, LaplaceFit
from bayes_fdi.twin.model import TwinProblem, residual_paths
from bayes_fdi.twin.simulator import OUTPUTS, FitWindows

__all__ = ["ParameterIdentification", "identification", "inference_data", "latent_names"]


def latent_names(names: tuple[str, ...]) -> tuple[str, ...]:
    """Names of the posterior's variables: the fitted parameters, then the noise parameters."""
    noise = tuple(f"sigma_{c}" for c in OUTPUTS) + tuple(f"phi_{c}" for c in OUTPUTS)
    return (*names, *noise, "kappa_F")


def _physical(problem: TwinProblem, latent: np.ndarray) -> np.ndarray:
    """Latent draws ``(n, p + 5)`` in the posterior's units (parameters, sigma, phi, kappa)."""
    p = problem.n_parameters
    out = np.empty_like(latent)
    out[:, :p] = problem.physical(torch.as_tensor(latent[:, :p])).numpy()
    out[:, p : p + 2] = np.exp(latent[:, p : p + 2])
    out[:, p + 2 : p + 4] = np.tanh(latent[:, p + 2 : p + 4])
    out[:, p + 4] = np.exp(latent[:, p + 4])
    return out


def _prior_latent(problem: TwinProblem, n: int, rng: np.random.Generator) -> np.ndarray:
    noise = problem.noise
    z = problem.prior_loc().numpy() + problem.prior_spread().numpy() * rng.standard_normal(
        (n, problem.n_parameters)
    )
    log_sigma = np.log(noise.sigma_median) + noise.sigma_spread * rng.standard_normal((n, 2))
    atanh_phi = noise.phi_spread * rng.standard_normal((n, 2))
    log_kappa = np.log(noise.kappa_median) + noise.kappa_spread * rng.standard_normal((n, 1))
    return np.concatenate([z, log_sigma, atanh_phi, log_kappa], axis=1)


def inference_data(
    problem: TwinProblem,
    windows: FitWindows,
    laplace: LaplaceFit,
    check: ImportanceCheck,
    rng: np.random.Generator,
) -> az.InferenceData:
    """The fit as ``InferenceData`` (one chain; ``rng`` draws the prior and predictive noise)."""
    names = latent_names(problem.simulator.names)
    n = check.draws.shape[0]
    post = _physical(problem, check.draws)
    prior = _physical(problem, _prior_latent(problem, n, rng))
    p = problem.n_parameters
    predictive = check.outputs.copy()  # (draw, window, time, 2)
    n_windows, n_t = predictive.shape[1:3]
    sim = problem.simulator
    predictive += residual_paths(
        rng, check.draws, post[:, :p], check.outputs, sim.names, sim.base,
        problem.pressures.numpy(),
    )  # fmt: skip
    observed = windows.observed
    constant = {c: windows.inputs[c].transpose("run", "time").values for c in INPUT_CHANNELS}
    constant["fitted"] = windows.mask.astype(np.int8)
    window_dims = ["window", "time"]
    dims = {c: window_dims for c in (*OUTPUTS, *INPUT_CHANNELS, "fitted")}
    coords = {"window": np.arange(n_windows), "time": np.arange(n_t, dtype=np.float64)}
    attrs = {
        "method": "Laplace approximation at the posterior mode (Gauss-Newton curvature of the "
        "simulator by central finite differences), checked by Pareto-smoothed importance sampling",
        "pareto_k": check.pareto_k,
        "importance_ess": check.ess,
        "mode_iterations": laplace.iterations,
        "mode_converged": int(laplace.converged),
        "newton_decrement": laplace.newton_decrement,
        "window_origin_run": [r for r, _ in windows.origin],
        "window_origin_time": [t for _, t in windows.origin],
    }
    return az.from_dict(
        posterior={name: post[None, :, i] for i, name in enumerate(names)},
        sample_stats={"log_weight": check.log_weights[None]},
        prior={name: prior[None, :, i] for i, name in enumerate(names)},
        observed_data={c: observed[..., i] for i, c in enumerate(OUTPUTS)},
        posterior_predictive={c: predictive[None, ..., i] for i, c in enumerate(OUTPUTS)},
        constant_data=constant,
        coords=coords,
        dims=dims,
        attrs=attrs,
    )


class ParameterIdentification(NamedTuple):
    """What the data say about one parameter, in its physical unit.

    ``ratio`` is the posterior over the prior standard deviation (small: identified); the
    ``weighted_`` moments are those of the Laplace draws under their Pareto-smoothed importance
    weights, i.e. estimates of the exact posterior's (trust them when ``pareto_k < 0.7``).
    """

    name: str
    prior_mean: float
    prior_sd: float
    posterior_mean: float
    posterior_sd: float
    ratio: float
    weighted_mean: float
    weighted_sd: float


def identification(
    idata: az.InferenceData,
) -> tuple[list[ParameterIdentification], tuple[str, ...], np.ndarray]:
    """Prior and posterior widths of every posterior variable, and their posterior correlations.

    Returns the table, the variables' names and the correlation matrix of the posterior draws.
    """
    names = tuple(idata.posterior.data_vars)
    weights = np.exp(idata.sample_stats["log_weight"].values.ravel())
    weights = weights / weights.sum()
    table = []
    for name in names:
        prior = idata.prior[name].values.ravel()
        post = idata.posterior[name].values.ravel()
        prior_sd, post_sd = float(prior.std()), float(post.std())
        w_mean = float(np.sum(weights * post))
        w_sd = float(np.sqrt(np.sum(weights * (post - w_mean) ** 2)))
        row = (float(prior.mean()), prior_sd, float(post.mean()), post_sd, post_sd / prior_sd)
        table.append(ParameterIdentification(name, *row, w_mean, w_sd))
    draws = np.stack([idata.posterior[n].values.ravel() for n in names], axis=1)
    return table, names, np.corrcoef(draws, rowvar=False)

"""The samplers: seeded sequential NUTS chains on a model's potential, and full-rank Gaussian SVI.

Both are Pyro's (``pyro.infer.NUTS`` / ``MCMC``, ``SVI`` with ``AutoMultivariateNormal``); this
module seeds them, starts them from given values and returns numpy draws ``(chains, draws, ...)``.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np
import pyro
import torch
from pyro.infer import MCMC, NUTS, SVI, JitTrace_ELBO, Trace_ELBO
from pyro.infer.autoguide import AutoMultivariateNormal
from pyro.infer.autoguide.initialization import init_to_value

from bayes_fdi.rvm.posterior.classification_model import SparseBayesClassificationModel
from bayes_fdi.rvm.posterior.numpy_bridge import DTYPE
from bayes_fdi.rvm.posterior.regression_model import SparseBayesRegressionModel

Model = SparseBayesRegressionModel | SparseBayesClassificationModel


def chain_seeds(seed: int, n: int) -> list[int]:
    """``n`` independent integer seeds spawned from ``numpy.random.SeedSequence(seed)``."""
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(seed).spawn(n)]


def check_int(name: str, value: Any, minimum: int) -> int:
    """``value`` as an ``int >= minimum`` (bools rejected), or a ``ValueError`` naming it."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def check_init(model: Model, init: Mapping[str, Any] | None) -> dict[str, torch.Tensor]:
    """Validate start values; classification accepts weights ``w`` or ``z`` for either form."""
    default = model.default_init()
    if init is None:
        return default
    given = {}
    for name, value in init.items():
        value = torch.as_tensor(np.asarray(value, dtype=np.float64), dtype=DTYPE)
        if not torch.isfinite(value).all():
            raise ValueError(f"init[{name!r}] contains NaN or inf")
        given[name] = value
    if model.kind == "classification" and "log_alpha" in given and "v" not in given:
        if "z" in given:
            given["w"] = given["z"] * torch.exp(-0.5 * given["log_alpha"])
        if "w" in given:
            given["v"] = model.latent_from_weights(given["log_alpha"], given["w"])
    out = {}
    for name, ref in default.items():
        if name not in given:
            raise ValueError(f"init is missing {name!r} (needs {sorted(default)})")
        if given[name].shape != ref.shape:
            raise ValueError(
                f"init[{name!r}] must have shape {tuple(ref.shape)}, got {tuple(given[name].shape)}"
            )
        out[name] = given[name]
    return out


def run_nuts(
    model: Model,
    init: dict[str, torch.Tensor],
    *,
    num_samples: int,
    warmup_steps: int,
    num_chains: int,
    seed: int,
    target_accept_prob: float,
    max_tree_depth: int,
    full_mass: bool,
    init_jitter: float,
    progress: bool,
) -> tuple[dict[str, np.ndarray], dict[str, list[Any]]]:
    """Sequential seeded NUTS chains on ``model.potential``; returns (C, S, ...) draws + stats."""
    draws: dict[str, list[np.ndarray]] = {name: [] for name in init}
    stats: dict[str, list[Any]] = {"divergent_draws": [], "acceptance_rate": [], "step_size": []}
    for chain_seed in chain_seeds(seed, num_chains):
        pyro.set_rng_seed(chain_seed)
        gen = torch.Generator().manual_seed(chain_seed)
        start = {
            k: v + init_jitter * torch.randn(v.shape, generator=gen, dtype=DTYPE)
            for k, v in init.items()
        }
        kernel = NUTS(
            potential_fn=model.potential,
            target_accept_prob=target_accept_prob,
            max_tree_depth=max_tree_depth,
            full_mass=full_mass,
        )
        mcmc = MCMC(
            kernel,
            num_samples=num_samples,
            warmup_steps=warmup_steps,
            initial_params=start,
            disable_progbar=not progress,
        )
        mcmc.run()
        for name, value in mcmc.get_samples().items():
            draws[name].append(value.detach().cpu().numpy())
        diag = mcmc.diagnostics()
        stats["divergent_draws"].append(tuple(int(i) for i in diag["divergences"]["chain 0"]))
        stats["acceptance_rate"].append(float(diag["acceptance rate"]["chain 0"]))
        stats["step_size"].append(float(kernel.step_size))
    return {k: np.stack(v, 0) for k, v in draws.items()}, stats


def run_svi(
    model: Model,
    init: dict[str, torch.Tensor],
    *,
    steps: int,
    lr: float,
    particles: int,
    num_draws: int,
    seed: int,
    jit: bool,
    progress: bool,
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Full-rank Gaussian SVI on the non-centred model; returns (1, S, ...) draws + ELBO trace."""
    fn = model.noncentred_model
    values = {"alpha": torch.exp(init["log_alpha"])}
    if "log_beta" in init:
        values["beta"] = torch.exp(init["log_beta"])
        # start z at the conditional posterior mean weights, w = z / sqrt(alpha)
        mu, _ = model.weight_posterior(init["log_alpha"], init["log_beta"])
        values["z"] = mu * torch.exp(0.5 * init["log_alpha"])
    else:
        w = model.weights_from_latent(init["log_alpha"], init["v"])
        values["z"] = w * torch.exp(0.5 * init["log_alpha"])
    options = {"num_particles": particles, "vectorize_particles": True, "max_plate_nesting": 1}

    def build(use_jit: bool) -> tuple[AutoMultivariateNormal, SVI]:
        pyro.set_rng_seed(seed)
        pyro.clear_param_store()
        guide = AutoMultivariateNormal(
            fn, init_loc_fn=init_to_value(values=values), init_scale=0.01
        )
        optim = pyro.optim.ClippedAdam({"lr": lr, "lrd": 0.05 ** (1.0 / steps), "clip_norm": 10.0})
        loss = (
            JitTrace_ELBO(ignore_jit_warnings=True, **options) if use_jit else Trace_ELBO(**options)
        )
        return guide, SVI(fn, guide, optim, loss)

    losses = np.empty(steps)
    with warnings.catch_warnings():
        # JitTrace_ELBO relies on torch.jit.trace, deprecated (not removed) in recent torch
        warnings.filterwarnings(
            "ignore", message=".*torch.jit.trace.*", category=DeprecationWarning
        )
        guide, svi = build(jit)
        try:
            losses[0] = svi.step()
        except (RuntimeError, TypeError, NotImplementedError) as exc:
            if not jit:
                raise
            warnings.warn(
                f"JitTrace_ELBO failed ({exc}); falling back to Trace_ELBO",
                RuntimeWarning,
                stacklevel=3,
            )
            guide, svi = build(False)
            losses[0] = svi.step()
        for i in range(1, steps):
            losses[i] = svi.step()
            if progress and (i + 1) % max(1, steps // 10) == 0:
                print(f"SVI step {i + 1}/{steps}: loss {losses[i]:.4g}")
    predictive = pyro.infer.Predictive(
        fn,
        guide=guide,
        num_samples=num_draws,
        parallel=True,
        return_sites=["alpha", "beta", "weights"],
    )
    with torch.no_grad():
        samples = predictive()
    m = model.n_basis
    out = {
        "log_alpha": samples["alpha"].reshape(1, num_draws, m).log().numpy(),
        "weights": samples["weights"].reshape(1, num_draws, m).numpy(),
    }
    if "beta" in samples:
        out["log_beta"] = samples["beta"].reshape(1, num_draws).log().numpy()
    return out, -losses

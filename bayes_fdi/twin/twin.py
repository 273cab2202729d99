"""`ActuatorTwin`: a Bayesian digital twin of one actuator, calibrated on its healthy data.

``ActuatorTwin().fit(healthy)`` learns the posterior of the actuator parameters that a healthy
recording identifies, given the recording's own inputs (CV, P1, P2, T1) and outputs (X, F):
the Pyro model of `bayes_fdi.twin.model` (logit-normal priors around DABLib's nominal values,
the simulator, an AR(1) residual per channel), its Laplace approximation at the posterior mode
(`bayes_fdi.twin.laplace`), checked by Pareto-smoothed importance sampling. After `fit`,
``noise_`` holds each channel's ``(sigma, phi)`` at the mode and ``kappa_`` the pressure
drop's reading error (F's innovation scale is
``sqrt(sigma_F^2 + (kappa (F' - o) / (2 dP))^2)``). The result is an ArviZ
``InferenceData`` (`bayes_fdi.twin.inference`); `sample_parameters` draws actuator parameter
records from the posterior, `predict` gives the posterior predictive of X and F for any
inputs, `check` scores it on held-out healthy data. See ``docs/twin.md``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
import xarray as xr
from sklearn.base import BaseEstimator

from bayes_fdi.actuator import NOMINAL, ActuatorParameters
from bayes_fdi.rvm.threads import limit_fit_threads
from bayes_fdi.twin.checks import TwinCheck, predictive_check
from bayes_fdi.twin.fixed_order import cholesky, matvec
from bayes_fdi.twin.flow_start import flow_law_start
from bayes_fdi.twin.inference import inference_data
from bayes_fdi.twin.laplace import fit_laplace, importance_check
from bayes_fdi.twin.model import TwinProblem, noise_estimate, noise_values, residual_paths
from bayes_fdi.twin.priors import (
    DEFAULT_PRIORS,
    NOISE_PRIOR,
    NoisePrior,
    ParameterPrior,
    check_priors,
)
from bayes_fdi.twin.simulator import OUTPUTS, WindowSimulator, cut_windows

__all__ = ["ActuatorTwin"]

#: independent random streams of one seed: ``default_rng([seed, stream])``
STREAM_FIT, STREAM_PREDICT = 0, 1


class ActuatorTwin(BaseEstimator):
    """Bayesian digital twin of an actuator: a posterior over its identifiable parameters.

    Parameters
    ----------
    priors
        Parameter name -> `ParameterPrior` of the fitted parameters (default
        `DEFAULT_PRIORS`: Kv, the characteristic's exponent, the F' zero, the X' zero and span,
        the positioner's air capacity and set-point lag, the backlash).
    noise_prior
        Prior of the AR(1) residual model of X and F, and of ``kappa``, the recorded pressure
        drop's error, which makes F's innovation scale grow with the flow over the pressure
        drop (`bayes_fdi.twin.likelihood.flow_innovation_scale`).
    base
        Values of the parameters not fitted (default: nominal).
    window, settle
        The recording is fitted in gap-free windows of ``window`` s, each simulated from its
        first sample; its first ``settle`` s are simulated but not fitted.
    max_fit_seconds
        Longer recordings are fitted on evenly spaced windows holding about this many seconds
        (`bayes_fdi.twin.simulator.cut_windows`); None fits everything.
    n_draws
        Posterior draws (Laplace draws, importance-checked) kept in ``inference_data_``.
    fd_fraction
        Finite-difference step of each parameter, as a fraction of its prior interval.
    max_iter, tol
        Levenberg-Marquardt steps and the convergence tolerance (nats) of the mode search.
    integrator, hold, warmup
        As in `bayes_fdi.actuator.simulate`.
    flow_law_start
        Search the mode also from the flow law fitted to the recorded flow
        (`bayes_fdi.twin.flow_start.flow_law_start`) besides the priors' medians, and keep the
        mode of higher posterior density (the search is local; this doubles its cost).
    random_state
        Seed of the posterior and prior draws (the fit itself is deterministic).
    """

    def __init__(
        self,
        priors: Mapping[str, ParameterPrior] | None = None,
        *,
        noise_prior: NoisePrior = NOISE_PRIOR,
        base: ActuatorParameters = NOMINAL,
        window: int = 900,
        settle: int = 10,
        max_fit_seconds: int | None = 3600,
        n_draws: int = 400,
        fd_fraction: float = 0.01,
        max_iter: int = 40,
        tol: float = 0.01,
        integrator: str = "fast",
        hold: str = "linear",
        warmup: int = 30,
        flow_law_start: bool = True,
        random_state: int = 0,
    ) -> None:
        self.priors = priors
        self.noise_prior = noise_prior
        self.base = base
        self.window = window
        self.settle = settle
        self.max_fit_seconds = max_fit_seconds
        self.n_draws = n_draws
        self.fd_fraction = fd_fraction
        self.max_iter = max_iter
        self.tol = tol
        self.integrator = integrator
        self.hold = hold
        self.warmup = warmup
        self.flow_law_start = flow_law_start
        self.random_state = random_state

    # ------------------------------------------------------------------ fitting
    def _check_settings(self) -> dict[str, ParameterPrior]:
        priors = check_priors(DEFAULT_PRIORS if self.priors is None else self.priors)
        if not isinstance(self.base, ActuatorParameters):
            raise ValueError(f"base must be an ActuatorParameters, got {self.base!r}")
        self.base.validated()
        if not isinstance(self.noise_prior, NoisePrior):
            raise ValueError(f"noise_prior must be a NoisePrior, got {self.noise_prior!r}")
        for name, value in self.noise_prior._asdict().items():
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"noise_prior.{name} must be a finite number > 0, got {value!r}")
        for name in ("window", "settle", "n_draws", "max_iter", "warmup", "random_state"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
                raise ValueError(f"{name} must be an integer >= 0, got {value!r}")
        if not isinstance(self.flow_law_start, bool | np.bool_):
            raise ValueError(f"flow_law_start must be True or False, got {self.flow_law_start!r}")
        if self.n_draws < 20:
            raise ValueError(f"n_draws must be at least 20, got {self.n_draws}")
        if not 0.0 < float(self.fd_fraction) < 0.1:
            raise ValueError(f"fd_fraction must lie in (0, 0.1), got {self.fd_fraction!r}")
        if self.max_fit_seconds is not None and self.max_fit_seconds < self.window:
            raise ValueError("max_fit_seconds must be None or at least one window")
        return priors

    def _simulate_options(self) -> dict[str, Any]:
        return {"integrator": self.integrator, "hold": self.hold, "warmup": self.warmup}

    @limit_fit_threads
    def fit(self, healthy: xr.Dataset) -> ActuatorTwin:
        """Fit the posterior on a healthy recording (channels CV, P1, P2, T1, X, F; NaN gaps are
        cut out). Returns ``self``.

        torch and the BLAS libraries run on `bayes_fdi.rvm.threads.get_fit_threads` threads
        (default 1: the same numbers whatever the caller's thread settings); the simulations
        run on numba's threads, one run each.
        """
        t_start = time.perf_counter()
        priors = self._check_settings()
        if "state" in healthy.coords:
            faulty = sorted(set(map(str, healthy["state"].values)) - {"fn"})
            if faulty:
                raise ValueError(f"the twin is fitted on healthy runs only; found states {faulty}")
        names = tuple(priors)
        windows = cut_windows(
            healthy, window=int(self.window), settle=int(self.settle),
            max_seconds=self.max_fit_seconds,
        )  # fmt: skip
        simulator = WindowSimulator(windows.inputs, self.base, names, **self._simulate_options())
        steps = np.array([self.fd_fraction * (p.high - p.low) for p in priors.values()])
        problem = TwinProblem(
            simulator, tuple(priors.values()), self.noise_prior,
            torch.as_tensor(windows.observed), torch.as_tensor(windows.mask), steps,
            torch.as_tensor(_pressures(windows.inputs)),
        )  # fmt: skip
        starts = {"prior medians": _start(problem, windows)}
        flow_law = flow_law_start(windows, self.base, priors) if self.flow_law_start else None
        if flow_law is not None:
            starts["flow law"] = _start(problem, windows, flow_law)
        fits = {
            name: fit_laplace(problem, start, max_iter=int(self.max_iter), tol=float(self.tol))
            for name, start in starts.items()
        }
        # the higher log density; on a tie the priors' medians (the first start)
        self.start_ = max(fits, key=lambda name: fits[name].log_joint)
        self.start_log_joints_ = {name: float(fit.log_joint) for name, fit in fits.items()}
        laplace = fits[self.start_]
        rng = np.random.default_rng([int(self.random_state), STREAM_FIT])
        check = importance_check(problem, laplace, int(self.n_draws), rng)
        self.names_ = names
        self.priors_ = priors
        self.laplace_ = laplace
        self.pareto_k_ = check.pareto_k
        self.importance_ess_ = check.ess
        self.windows_ = windows.origin
        mode = problem.physical(torch.as_tensor(laplace.mode[: len(names)])).numpy()
        self.parameters_ = self.base._replace(**dict(zip(names, map(float, mode), strict=True)))
        sigma, phi, kappa = noise_values(laplace.mode, len(names))
        self.noise_ = {c: (float(sigma[i]), float(phi[i])) for i, c in enumerate(OUTPUTS)}
        self.kappa_ = float(kappa)
        self.inference_data_ = inference_data(problem, windows, laplace, check, rng)
        self.fit_seconds_ = time.perf_counter() - t_start
        self.inference_data_.attrs["fit_seconds"] = self.fit_seconds_
        self.inference_data_.attrs["mode_start"] = self.start_
        return self

    def _check_fitted(self) -> None:
        if not hasattr(self, "laplace_"):
            raise ValueError("ActuatorTwin is not fitted; call fit(healthy) first")

    # ------------------------------------------------------------------ draws
    def sample_latent(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` draws ``(n, p + 5)`` of the latent vector from the Laplace posterior."""
        self._check_fitted()
        chol = cholesky(self.laplace_.covariance)
        return self.laplace_.mode + matvec(chol, rng.standard_normal((int(n), chol.shape[0])))

    def latent_to_parameters(self, latent: np.ndarray) -> list[ActuatorParameters]:
        """Parameter records of latent vectors ``(n, p + 5)`` (unfitted fields from ``base``)."""
        self._check_fitted()
        latent = np.atleast_2d(latent)
        out = []
        for row in latent:
            values = {
                name: float(prior.to_value(row[i]))
                for i, (name, prior) in enumerate(self.priors_.items())
            }
            out.append(self.base._replace(**values))
        return out

    def sample_parameters(self, n: int, seed: int) -> list[ActuatorParameters]:
        """``n`` actuator parameter records drawn from the posterior with stream ``seed``.

        Draw ``k`` of seed ``s`` is the ``k``-th row of ``default_rng([s, 2])``'s Gaussian
        draws, so different seeds give independent draws (disjoint with probability one) and
        the same seed the same records.
        """
        rng = np.random.default_rng([int(seed), 2])
        return self.latent_to_parameters(self.sample_latent(n, rng))

    # ------------------------------------------------------------------ prediction
    def predict(self, inputs: xr.Dataset, *, n_draws: int = 200, seed: int = 0) -> xr.Dataset:
        """Posterior predictive of X and F for the inputs of every run of a dataset.

        Each draw takes actuator and noise parameters from the posterior and simulates every run
        from its first sample (``X_model``, ``F_model``: the simulated X', F'); ``X``, ``F`` add
        an AR(1) path of the draw's noise parameters (F's innovation scale growing with the
        draw's flow over the inputs' pressure drop). Returns a dataset of dims
        ``(draw, run, time)``. The random stream is ``default_rng([seed, 1])``.
        """
        self._check_fitted()
        if isinstance(n_draws, bool) or not isinstance(n_draws, int) or n_draws < 1:
            raise ValueError(f"n_draws must be a positive integer, got {n_draws!r}")
        rng = np.random.default_rng([int(seed), STREAM_PREDICT])
        latent = self.sample_latent(n_draws, rng)
        simulator = WindowSimulator(inputs, self.base, self.names_, **self._simulate_options())
        records = self.latent_to_parameters(latent)
        thetas = np.array([[getattr(p, n) for n in self.names_] for p in records])
        model = simulator.outputs(thetas)  # (draw, run, time, 2)
        noise = residual_paths(rng, latent, thetas, model, self.names_, self.base,
                               _pressures(inputs))  # fmt: skip
        dims = ("draw", "run", "time")
        data = {}
        for c, name in enumerate(OUTPUTS):
            data[name] = (dims, model[..., c] + noise[..., c])
            data[f"{name}_model"] = (dims, model[..., c])
        coords = {"draw": np.arange(n_draws), "run": inputs["run"].values,
                  "time": inputs["time"].values}  # fmt: skip
        return xr.Dataset(data, coords=coords, attrs={"seed": int(seed)})

    def check(
        self, heldout: xr.Dataset, *, n_draws: int = 200, seed: int = 0, level: float = 0.95
    ) -> TwinCheck:
        """Score the posterior predictive on held-out healthy data (`predictive_check`)."""
        self._check_fitted()
        return predictive_check(self, heldout, n_draws=n_draws, seed=seed, level=level)


def _pressures(inputs: xr.Dataset) -> np.ndarray:
    """The recorded P1', P2' of every run ``(run, time, 2)``."""
    return np.stack([inputs[c].transpose("run", "time").values for c in ("P1", "P2")], axis=-1)


def _start(problem: TwinProblem, windows, values: Mapping[str, float] | None = None) -> np.ndarray:
    """A start of the mode search: the priors' medians, with the physical ``values`` given
    replacing theirs; the noise parameters of the AR(1) model of the residual there."""
    z = problem.prior_loc().numpy()
    names = list(problem.simulator.names)
    for name, value in (values or {}).items():
        z[names.index(name)] = problem.priors[names.index(name)].to_latent(value)
    theta = problem.physical(torch.as_tensor(z))
    outputs = problem.simulator.outputs(theta.numpy()[None])[0]
    ratio = problem.flow_ratio(theta, torch.as_tensor(outputs[..., 1])).numpy()
    return np.concatenate([z, noise_estimate(windows.observed - outputs, windows.mask, ratio)])

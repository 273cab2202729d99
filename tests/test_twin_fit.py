"""The twin's calibration against things known independently.

A simulated plant with known, perturbed parameters (its posterior must cover them), the exact
slope of the flow in Kv (F' is proportional to Kv), a flow offset whose posterior is the
generalised-least-squares posterior of a linear model with AR(1) noise (closed form), and the
same numbers from the same seed.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from bayes_fdi.actuator import NOISE_STD, NOMINAL, simulate
from bayes_fdi.datasets import load_lublin_example
from bayes_fdi.twin import ActuatorTwin, ParameterPrior, identification
from bayes_fdi.twin.likelihood import ar1_paths
from bayes_fdi.twin.model import flow_ratio
from bayes_fdi.twin.simulator import WindowSimulator, cut_windows, simulated_outputs

TRUE = NOMINAL._replace(
    kv=110.0, characteristic=5.3, f_offset=0.01, x_offset=-0.01, x_gain=1.03,
    inflow_coefficient=3e-6, setpoint_lag=0.35, backlash=0.015,
)  # fmt: skip


@pytest.fixture(scope="module")
def hour():
    return load_lublin_example()


def _plant(inputs, parameters, seed):
    """The real hour's inputs driving a simulated plant; the input readings stay noise-free
    (noise on P1, P2 moves the simulated stem: an errors-in-variables effect, see the docs)."""
    plant = simulate(inputs, parameters=parameters, seed=seed)
    for c in ("P1", "P2", "T1"):
        plant[c] = inputs[c]
    return plant


@pytest.fixture(scope="module")
def simulated_fit(hour):
    plant = _plant(hour.isel(time=slice(0, 900)), TRUE, seed=3)
    twin = ActuatorTwin(window=300, n_draws=120, random_state=1).fit(plant.isel(time=slice(0, 600)))
    return twin, plant


def test_the_posterior_covers_a_simulated_plants_true_parameters(simulated_fit):
    twin, _ = simulated_fit
    table, names, corr = identification(twin.inference_data_)
    rows = {r.name: r for r in table}
    for name in twin.names_:
        row = rows[name]
        z = (row.posterior_mean - getattr(TRUE, name)) / row.posterior_sd
        assert abs(z) < 3.5, (name, row)
        assert row.ratio < 0.5, (name, row)  # every default parameter is identified here
    for channel in ("X", "F"):
        sigma = rows[f"sigma_{channel}"]
        assert abs(sigma.posterior_mean - NOISE_STD) < 4 * sigma.posterior_sd + 1e-4
        assert abs(rows[f"phi_{channel}"].posterior_mean) < 4 * rows[f"phi_{channel}"].posterior_sd
    assert corr.shape == (len(names), len(names))
    assert twin.laplace_.converged
    assert twin.pareto_k_ < 0.7


def test_the_inference_data_holds_prior_posterior_data_and_predictive(simulated_fit):
    twin, plant = simulated_fit
    idata = twin.inference_data_
    for group in ("posterior", "prior", "observed_data", "posterior_predictive", "sample_stats"):
        assert group in idata.groups()
    assert idata.posterior["kv"].shape == (1, 120)
    prior = twin.priors_["kv"]
    assert prior.low < float(idata.prior["kv"].min()) < float(idata.prior["kv"].max()) < prior.high
    np.testing.assert_array_equal(idata.observed_data["X"].values[0], plant.X.values[0, :300])
    assert idata.posterior_predictive["F"].shape == (1, 120, 2, 300)
    assert np.isclose(np.exp(idata.sample_stats["log_weight"].values).sum(), 1.0)


def test_held_out_simulated_data_are_covered_at_the_stated_level(simulated_fit):
    twin, plant = simulated_fit
    check = twin.check(plant.isel(time=slice(600, 900)), n_draws=100, seed=2)
    for channel in ("X", "F"):
        assert 0.9 <= check.coverage[channel] <= 0.99, check
        assert check.rms[channel] < 2 * NOISE_STD


def test_the_simulator_slope_in_kv_is_the_closed_form(hour):
    windows = cut_windows(hour.isel(time=slice(100, 400)), window=150, settle=10, max_seconds=None)
    simulator = WindowSimulator(windows.inputs, NOMINAL, ("kv", "f_offset"), warmup=30)
    theta = torch.tensor([120.0, 0.01], dtype=torch.float64, requires_grad=True)
    out = simulated_outputs(theta, simulator, np.array([1.0, 0.001]))
    weights = torch.tensor(np.random.default_rng(0).normal(size=out.shape))
    (grad,) = torch.autograd.grad((weights * out).sum(), theta)
    f = out[..., 1].detach().numpy()
    assert 0.0 < f.min() and f.max() < 1.0  # not clipped
    # F' = kv * g(X, P) + offset and X' does not depend on kv: dF'/dkv = (F' - offset) / kv
    w = weights.numpy()
    assert float(grad[0]) == pytest.approx(np.sum(w[..., 1] * (f - 0.01) / 120.0), rel=1e-6)
    assert float(grad[1]) == pytest.approx(np.sum(w[..., 1]), rel=1e-9)


def _gls(residual: np.ndarray, scale: np.ndarray, phi: float) -> tuple[float, float]:
    """``1' P r`` and ``1' P 1`` of a constant under AR(1) noise with innovation scales
    ``scale[t]`` (flat prior): the precision ``P = L' D^-1 L``, ``L`` the AR(1) differencing,
    ``D`` the innovations' variances (the first sample's stationary)."""
    n = residual.size
    ell = np.eye(n) - phi * np.eye(n, k=-1)
    variances = np.r_[scale[0] ** 2 / (1.0 - phi**2), scale[1:] ** 2]
    prec = ell.T @ np.diag(1.0 / variances) @ ell
    ones = np.ones(n)
    return float(ones @ prec @ residual), float(ones @ prec @ ones)


def test_an_offsets_posterior_is_the_generalised_least_squares_posterior(hour):
    inputs = hour.isel(time=slice(0, 600))
    clean = simulate(inputs, noise=False, parameters=NOMINAL._replace(f_offset=0.02))
    rng = np.random.default_rng(7)
    data = clean.copy(deep=True)
    data["X"] = clean.X + ar1_paths(rng, np.array([0.004]), np.array([0.5]), 600)
    data["F"] = clean.F + ar1_paths(rng, np.array([0.01]), np.array([0.4]), 600)
    prior = {"f_offset": ParameterPrior(0.0, -0.1, 0.1)}
    twin = ActuatorTwin(prior, window=300, n_draws=400, random_state=0).fit(data)
    sigma, phi = twin.noise_["F"]
    numerator, precision = 0.0, 0.0
    for start in (0, 300):
        # the twin simulates each window from its first sample
        window = inputs.isel(time=slice(start, start + 300))
        base = simulate(window, noise=False).F.values[0]
        e = (data.F.values[0, start : start + 300] - base)[twin.settle :]
        # the flow's innovation scale at the mode: F' - o does not depend on the offset o
        pressures = np.stack([window.P1.values[0], window.P2.values[0]], axis=-1)
        ratio = flow_ratio(
            torch.as_tensor(base), torch.tensor([0.0]), ("f_offset",), NOMINAL,
            torch.as_tensor(pressures),
        ).numpy()[0, twin.settle :]  # fmt: skip
        scale = np.sqrt(sigma**2 + (twin.kappa_ * ratio) ** 2)
        num, prec = _gls(e, scale, phi)
        numerator += num
        precision += prec
    mean, sd = numerator / precision, precision**-0.5
    post = twin.inference_data_.posterior["f_offset"].values.ravel()
    # the mode search stops when it promises less than tol = 0.01 nats: within 0.14 sd
    assert twin.parameters_.f_offset == pytest.approx(mean, abs=0.15 * sd)
    assert post.std() == pytest.approx(sd, rel=0.1)  # 400 draws: +-4 % sampling error
    assert abs(mean - 0.02) < 4 * sd


def test_the_same_seed_gives_the_same_posterior(hour):
    data = _plant(hour.isel(time=slice(0, 300)), TRUE, seed=4)
    fits = [
        ActuatorTwin(window=300, n_draws=30, random_state=s, max_iter=8).fit(data)
        for s in (5, 5, 6)
    ]
    a, b, c = (f.inference_data_.posterior for f in fits)
    for name in a.data_vars:
        np.testing.assert_array_equal(a[name].values, b[name].values)
    np.testing.assert_array_equal(fits[0].laplace_.mode, fits[2].laplace_.mode)
    assert not np.array_equal(a["kv"].values, c["kv"].values)
    draws = fits[0].sample_parameters(3, seed=9)
    assert draws == fits[1].sample_parameters(3, seed=9)
    assert draws != fits[0].sample_parameters(3, seed=10)


def test_an_unfitted_twin_and_bad_settings_are_refused(hour):
    with pytest.raises(ValueError, match="not fitted"):
        ActuatorTwin().sample_parameters(2, seed=0)
    with pytest.raises(ValueError, match="n_draws must be at least 20"):
        ActuatorTwin(n_draws=5).fit(hour)
    with pytest.raises(ValueError, match="window must be at least"):
        ActuatorTwin(window=30).fit(hour)
    faulty = hour.assign_coords(state=("run", ["f1"]))
    with pytest.raises(ValueError, match=r"healthy runs only; found states \['f1'\]"):
        ActuatorTwin().fit(faulty)
    with pytest.raises(ValueError, match="no gap-free stretch"):
        ActuatorTwin(window=300).fit(hour.isel(time=slice(0, 50)))


def test_windows_avoid_gaps_and_long_recordings_keep_evenly_spaced_windows(hour):
    gappy = hour.copy(deep=True)
    gappy["F"][0, 1000:1010] = np.nan
    windows = cut_windows(gappy, window=600, settle=10, max_seconds=None)
    starts = [t for _, t in windows.origin]
    assert starts == [0.0, 600.0, 1010.0, 1610.0, 2210.0, 2810.0, 3410.0]
    assert np.all(np.isfinite(windows.observed))
    # the window before the gap holds 400 samples: padded, not fitted beyond them
    assert windows.mask[1].sum() == 400 - 10 and not windows.mask[1, 400:].any()
    assert windows.mask[6].sum() == 190 - 10
    day = hour.isel(run=[0] * 24).assign_coords(run=np.arange(24))
    kept = cut_windows(day, window=900, settle=10, max_seconds=3600)
    assert [r for r, _ in kept.origin] == [0, 8, 15, 23]
    assert [t for _, t in kept.origin] == [0.0, 0.0, 2700.0, 2700.0]

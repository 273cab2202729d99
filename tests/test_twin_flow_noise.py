"""The flow residual that grows with the flow over the pressure drop, on a simulated valve.

A valve driven at a small pressure drop (20-140 kPa) reads F' with an error whose scale is
``sqrt(sigma^2 + (kappa (F' - o) / (2 (P1 - P2)))^2)``, the error a pressure drop read ``kappa``
wrong gives the model's flow: the twin must recover ``kappa`` and cover held-out data at the
stated level, where one innovation scale for the whole flow range could not.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from bayes_fdi.actuator import NOISE_STD, NOMINAL, simulate
from bayes_fdi.datasets import load_lublin_example
from bayes_fdi.twin import ActuatorTwin, identification
from bayes_fdi.twin.likelihood import ar1_from_innovations
from bayes_fdi.twin.model import flow_ratio

TRUE = NOMINAL._replace(kv=110.0, f_offset=0.01, inflow_coefficient=3e-6, backlash=0.015)
KAPPA, SIGMA_F, PHI_F = 0.003, NOISE_STD, 0.3


@pytest.fixture(scope="module")
def valve():
    """The real hour's CV and T1; P2' a drop below the recorded P1' that swings between 0.5 %
    and 3.5 % of the transmitters' full scale (20-140 kPa) over about 7 min."""
    inputs = load_lublin_example().isel(time=slice(0, 900)).copy(deep=True)
    t = np.arange(inputs.sizes["time"])
    drop = 0.02 + 0.015 * np.sin(2.0 * np.pi * t / 420.0)
    inputs["P2"] = inputs["P1"] - drop[None]
    clean = simulate(inputs, noise=False, parameters=TRUE)
    pressures = np.stack([inputs["P1"].values[0], inputs["P2"].values[0]], axis=-1)
    ratio = flow_ratio(
        torch.as_tensor(clean.F.values), torch.tensor([]), (), TRUE, torch.as_tensor(pressures)
    ).numpy()
    rng = np.random.default_rng(12)
    scale = np.sqrt(SIGMA_F**2 + (KAPPA * ratio) ** 2)
    data = clean.copy(deep=True)
    data["X"] = clean.X + NOISE_STD * rng.standard_normal(clean.X.shape)
    data["F"] = clean.F + ar1_from_innovations(rng.standard_normal(scale.shape), scale, [PHI_F])
    twin = ActuatorTwin(window=300, n_draws=200, random_state=3).fit(data.isel(time=slice(0, 600)))
    return twin, data, ratio


def test_the_valve_flows_far_above_its_pressure_drop(valve):
    _, data, ratio = valve
    # the flow term's share of the innovation variance: the case the constant scale misses
    assert np.quantile(KAPPA * ratio, 0.1) > SIGMA_F
    assert np.quantile(ratio, 0.9) > 2.5 * np.quantile(ratio, 0.1)
    assert 0.02 < float(data.F.min()) and float(data.F.max()) < 0.98  # never clipped


def test_the_twin_recovers_the_pressure_drops_error(valve):
    twin, _, _ = valve
    rows = {r.name: r for r in identification(twin.inference_data_)[0]}
    kappa = rows["kappa_F"]
    # 590 fitted samples in which the flow term dominates: kappa's relative posterior sd is
    # about 1 / sqrt(2 * 590) = 3 %; the mode and the draws must agree with the truth at that
    # scale (3.5 posterior sd, as for the actuator parameters) and the sd must be that small
    assert kappa.posterior_sd < 0.1 * KAPPA
    assert abs(kappa.posterior_mean - KAPPA) < 3.5 * kappa.posterior_sd, kappa
    assert abs(rows["phi_F"].posterior_mean - PHI_F) < 3.5 * rows["phi_F"].posterior_sd
    assert twin.kappa_ == pytest.approx(kappa.posterior_mean, rel=0.1)
    for name in ("kv", "f_offset"):
        z = (rows[name].posterior_mean - getattr(TRUE, name)) / rows[name].posterior_sd
        assert abs(z) < 3.5, rows[name]


def test_held_out_data_are_covered_at_the_stated_level_across_the_flows(valve):
    twin, data, ratio = valve
    check = twin.check(data.isel(time=slice(600, 900)), n_draws=200, seed=4)
    for channel in ("X", "F"):
        assert 0.9 <= check.coverage[channel] <= 0.98, check
    # the interval follows the flow over the pressure drop: wider where it is high
    pred = twin.predict(data.isel(time=slice(600, 900)), n_draws=200, seed=4)
    low, high = np.quantile(pred["F"].values, [0.025, 0.975], axis=0)
    width = (high - low)[0, twin.settle :]
    q = ratio[0, 600 + twin.settle :]
    assert np.corrcoef(width, q)[0, 1] > 0.9


@pytest.mark.parametrize("field", ["kappa_median", "kappa_spread", "sigma_median"])
def test_a_noise_prior_that_is_not_positive_is_refused_by_name(field):
    from bayes_fdi.twin import NoisePrior

    hour = load_lublin_example()
    with pytest.raises(ValueError, match=f"noise_prior.{field} must be a finite number > 0"):
        ActuatorTwin(noise_prior=NoisePrior(**{field: 0.0})).fit(hour)

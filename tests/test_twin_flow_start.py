"""The twin's second start: the flow law fitted to the recorded flow alone.

Checked on a simulated valve far from nominal (Kv 0.6x, characteristic 1.25x): the grid finds
its flow law within the grid's resolution, leaves readings at the ends of F's range out, and the
twin keeps the mode of higher posterior density of its two starts.
"""

from __future__ import annotations

import numpy as np
import pytest

from bayes_fdi.actuator import NOMINAL, simulate
from bayes_fdi.datasets import load_lublin_example
from bayes_fdi.twin import ActuatorTwin
from bayes_fdi.twin.flow_start import flow_law_start
from bayes_fdi.twin.priors import DEFAULT_PRIORS
from bayes_fdi.twin.simulator import cut_windows

FAR = NOMINAL._replace(kv=84.0, characteristic=6.3, f_offset=0.015)


@pytest.fixture(scope="module")
def far_plant():
    inputs = load_lublin_example().isel(time=slice(0, 900))
    plant = simulate(inputs, parameters=FAR, seed=5)
    for c in ("P1", "P2", "T1"):
        plant[c] = inputs[c]
    return plant


def _grid_step(name: str) -> float:
    """The grid's spacing in the physical value, at the true value (41 points over 6 sd)."""
    prior = DEFAULT_PRIORS[name]
    value = getattr(FAR, name)
    q = (value - prior.low) / (prior.high - prior.low)
    return (prior.high - prior.low) * q * (1 - q) * prior.spread * 6.0 / 40


def test_the_grid_finds_the_flow_law_of_a_valve_far_from_nominal(far_plant):
    windows = cut_windows(far_plant, window=300, settle=10, max_seconds=None)
    start = flow_law_start(windows, NOMINAL, DEFAULT_PRIORS)
    for name in ("kv", "characteristic"):
        # the least-squares grid point is a neighbour of the truth (noise moves it by less)
        assert abs(start[name] - getattr(FAR, name)) <= 1.5 * _grid_step(name), (name, start)
    # the F' zero at its least-squares value: within the flow noise's reach of the truth
    assert abs(start["f_offset"] - FAR.f_offset) < 0.01


def test_readings_at_the_ends_of_the_range_are_left_out(far_plant):
    windows = cut_windows(far_plant, window=300, settle=10, max_seconds=None)
    base = flow_law_start(windows, NOMINAL, DEFAULT_PRIORS)
    observed = windows.observed.copy()
    observed[0, 100:160, 1] = 1.0  # a minute at the top of the range
    observed[1, 100:130, 1] = 0.0  # half a minute at the bottom
    saturated = windows._replace(observed=observed)
    inside = (observed[..., 1] > 0.005) & (observed[..., 1] < 0.995)
    left_out = windows._replace(mask=windows.mask & inside)
    assert flow_law_start(saturated, NOMINAL, DEFAULT_PRIORS) == flow_law_start(
        left_out, NOMINAL, DEFAULT_PRIORS
    )
    assert base is not None


def test_without_kv_and_characteristic_there_is_no_flow_law_start(far_plant):
    windows = cut_windows(far_plant, window=300, settle=10, max_seconds=None)
    priors = {k: v for k, v in DEFAULT_PRIORS.items() if k != "kv"}
    assert flow_law_start(windows, NOMINAL, priors) is None


def test_the_twin_keeps_the_mode_of_higher_density_and_covers_the_valve(far_plant):
    twin = ActuatorTwin(window=300, n_draws=60, random_state=2).fit(
        far_plant.isel(time=slice(0, 600))
    )
    assert set(twin.start_log_joints_) == {"prior medians", "flow law"}
    assert twin.laplace_.log_joint == max(twin.start_log_joints_.values())
    assert twin.start_log_joints_[twin.start_] == twin.laplace_.log_joint
    assert twin.inference_data_.attrs["mode_start"] == twin.start_
    mode = twin.parameters_
    sd = np.sqrt(np.diag(twin.laplace_.covariance))
    assert np.all(np.isfinite(sd))
    for name in ("kv", "characteristic"):
        assert abs(getattr(mode, name) / getattr(FAR, name) - 1.0) < 0.1, (name, mode)
    one = ActuatorTwin(window=300, n_draws=60, random_state=2, flow_law_start=False)
    with pytest.raises(ValueError, match="flow_law_start"):
        ActuatorTwin(flow_law_start="yes").fit(far_plant)
    assert one.get_params()["flow_law_start"] is False

"""Physical laws the actuator model must obey (closed forms and water tables)."""

import numpy as np
import pytest

from bayes_fdi.actuator import (
    FAULT_NAMES,
    SIGNED_FAULTS,
    Fault,
    benchmark_inputs,
    flow_rate,
    simulate,
    vapour_pressure,
    water_density,
)
from bayes_fdi.actuator.model import PARAMETERS

P1, P2, T1 = 3.5e6, 2.6e6, 43.0


def test_flow_falls_monotonically_as_the_valve_closes_and_is_zero_when_closed():
    x = np.linspace(0.0, 1.0, 2001)
    flow = flow_rate(x, P1, P2, T1)
    assert np.all(np.diff(flow) < 0.0)
    assert flow[-1] == 0.0
    # fully open: Q = Kv sqrt(dp[bar] / (rho/1000)) with Kv = 120 m3/h (not choked at X = 0)
    rho = water_density(T1, P1)
    q = 120.0 * np.sqrt((P1 - P2) / 1e5 / (rho / 1000.0))
    assert flow[0] == pytest.approx(q * rho / 1000.0, rel=1e-12)


def test_equal_percentage_characteristic():
    # not choked: the flow ratio between two openings is exp(-5 dX) (Kv ~ e^(-5X))
    f = flow_rate(np.array([0.3, 0.5]), P1, P2, T1)
    assert f[1] / f[0] == pytest.approx(np.exp(-5 * 0.2), rel=1e-12)


def test_choked_flow_caps_the_flow():
    # lowering P2 raises the flow until the pressure drop reaches the choking limit
    # Km (P1 - rc pv); below that P2 the flow stays at the cap
    x = 0.6
    p2 = np.linspace(3.4e6, 0.0, 400)
    flow = flow_rate(np.full_like(p2, x), P1, p2, T1)
    assert np.all(np.diff(flow) >= -1e-12)
    km = np.interp(60.0, [50.0, 60.0, 70.0], [0.725, 0.67, 0.61])
    pv = vapour_pressure(T1)
    rc = np.interp(P1 / 1e6, [3.448, 6.895], [0.84, 0.79])
    dp_cap = km * (P1 - rc * pv)
    choked = p2 < P1 - dp_cap
    assert choked.sum() > 50
    np.testing.assert_allclose(flow[choked], flow[choked][0], rtol=1e-12)
    assert flow[~choked].max() <= flow[choked][0] + 1e-9


def test_bypass_adds_flow_even_when_the_valve_is_closed():
    closed = flow_rate(1.0, P1, P2, T1, faults={"f18": 1.0})
    q_bypass = 100.0 * 19.75 * np.sqrt((P1 - P2) / 1e6 / 1000.0)  # bypass fully open, Km = 0.45
    assert closed == pytest.approx(q_bypass, rel=1e-12)


def test_water_properties_against_steam_tables():
    # IAPWS saturated-liquid densities (kg/m3) at 0.1 MPa-ish pressures
    for t, rho in ((20.0, 998.2), (43.0, 991.0), (80.0, 971.8), (100.0, 958.4)):
        assert water_density(t, 1e5) == pytest.approx(rho, abs=0.6)
    # saturation pressure of water: 100 C -> 101.3 kPa, 43 C -> 8.65 kPa (model's Antoine law
    # is a fit, within 7 %)
    assert vapour_pressure(100.0) == pytest.approx(101.325e3, rel=0.07)
    assert vapour_pressure(43.0) == pytest.approx(8.65e3, rel=0.07)


def test_parameters_table_is_the_reference_values():
    assert PARAMETERS["X0"][0] == 0.0381
    assert PARAMETERS["k"][0] == 60892.0
    assert PARAMETERS["Ae"][0] == 0.029
    assert PARAMETERS["c"][0] == 1500.0


@pytest.fixture(scope="module")
def all_faults_run():
    inputs = benchmark_inputs(n_runs=20, duration=200, vary=True, seed=3)
    faults = [None] + [
        Fault(n, -1.0 if n in SIGNED_FAULTS and i % 2 else 1.0, onset=50.0)
        for i, n in enumerate(FAULT_NAMES)
    ]
    return simulate(inputs, faults, seed=0, return_states=True)


def test_stem_stays_within_its_stops(all_faults_run):
    ds, states = all_faults_run
    x = states["X_true"].values
    assert np.isfinite(x).all()
    assert x.min() >= 0.0
    # upper stop Hb = X0 (1 - 0.2 f2)(1 - f1)(1 + 0.1 f3) <= 1.1 X0
    assert x.max() <= 1.1 + 1e-12
    f1_run = list(ds.state.values).index("f1")
    assert x[f1_run, 50:].max() == 0.0  # f1 = 1: the stem cannot close at all
    for name in ("X", "F", "P1", "P2", "T1"):
        v = ds[name].values
        assert v.min() >= 0.0 and v.max() <= 1.0


def test_f1_caps_the_stem_at_its_clogged_position():
    inputs = benchmark_inputs(n_runs=1, duration=300)
    _, states = simulate(inputs, Fault("f1", 0.6, onset=10.0), return_states=True)
    x = states["X_true"].values[0]
    assert x[12:].max() <= 0.4 + 1e-12
    assert x[12:].max() > 0.39  # the controller pushes it against the stop at CV = 0.75


@pytest.mark.parametrize("name", FAULT_NAMES)
def test_strength_zero_is_bit_for_bit_nominal(name):
    inputs = benchmark_inputs(n_runs=2, duration=120, vary=True, seed=1)
    nominal = simulate(inputs, None, seed=4)
    for profile, ramp in (("abrupt", 0.0), ("incipient", 30.0)):
        zero = simulate(inputs, Fault(name, 0.0, onset=20.0, profile=profile, ramp=ramp), seed=4)
        for channel in ("X", "F", "P1", "P2", "T1"):
            np.testing.assert_array_equal(zero[channel].values, nominal[channel].values)

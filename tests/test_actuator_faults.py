"""The Fault record, the fault table and FGen's time law."""

import numpy as np
import pytest

from bayes_fdi.actuator import FAULT_NAMES, FAULT_TABLE, SIGNED_FAULTS, Fault
from bayes_fdi.actuator.faults import fault_value
from bayes_fdi.datasets import STATES


def test_fault_table_covers_the_benchmark_states():
    assert FAULT_NAMES == STATES[1:]
    assert set(FAULT_TABLE) == {f"f{i}" for i in range(1, 20)}
    # the benchmark's fault vector allows negative values for exactly these faults
    assert {"f4", "f12", "f13", "f14", "f17", "f19"} == SIGNED_FAULTS


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"name": "f20", "strength": 0.5}, "name"),
        ({"name": "fn", "strength": 0.5}, "name"),
        ({"name": "f1", "strength": -0.5}, "strength"),
        ({"name": "f1", "strength": 1.5}, "strength"),
        ({"name": "f17", "strength": -1.5}, "strength"),
        ({"name": "f1", "strength": float("nan")}, "strength"),
        ({"name": "f1", "strength": "big"}, "strength"),
        ({"name": "f1", "strength": 0.5, "onset": -1.0}, "onset"),
        ({"name": "f1", "strength": 0.5, "onset": float("inf")}, "onset"),
        ({"name": "f1", "strength": 0.5, "profile": "sudden"}, "profile"),
        ({"name": "f1", "strength": 0.5, "profile": "incipient", "ramp": 0.0}, "ramp"),
        ({"name": "f1", "strength": 0.5, "profile": "abrupt", "ramp": 10.0}, "ramp"),
    ],
)
def test_invalid_fault_names_the_field(kwargs, field):
    with pytest.raises(ValueError, match=rf"Fault\.{field}"):
        Fault(**kwargs).validated()


@pytest.mark.parametrize("name", sorted(SIGNED_FAULTS))
def test_signed_faults_accept_negative_strength(name):
    assert Fault(name, -1.0).validated().strength == -1.0


def test_fault_is_immutable():
    fault = Fault("f1", 0.5)
    with pytest.raises(AttributeError):
        fault.strength = 0.7  # type: ignore[misc]


def test_fgen_law_abrupt_and_incipient_closed_form(rng):
    t = np.sort(rng.uniform(0.0, 400.0, 200))
    abrupt = Fault("f1", 0.75, onset=100.0)
    np.testing.assert_array_equal(abrupt.value_at(t), np.where(t >= 100.0, 0.75, 0.0))
    ramp = Fault("f17", -0.5, onset=50.0, profile="incipient", ramp=200.0)
    expected = np.where(t < 50.0, 0.0, -0.5 * np.minimum(1.0, (t - 50.0) / 200.0))
    np.testing.assert_allclose(ramp.value_at(t), expected, rtol=0, atol=1e-15)
    assert fault_value(150.0, 1.0, 50.0, 200.0) == pytest.approx(0.5)

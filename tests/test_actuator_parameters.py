"""The actuator's parameter record: the nominal record reproduces the simulator bit for bit.

``tests/data/actuator_reference/actuator_reference.npz`` was written by the simulator before it
took a parameter record (module constants); every case is recomputed and must give the same
bytes (reference and fast integrator, both holds, all 19 faults abrupt and incipient, noise,
the real hour, fault injection, replicas).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

REFERENCE_DIR = Path(__file__).parent / "data" / "actuator_reference"


def _reference_module():
    spec = importlib.util.spec_from_file_location(
        "actuator_reference", REFERENCE_DIR / "make_reference.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def outputs():
    return _reference_module().reference_outputs()


def test_nominal_parameters_reproduce_the_stored_outputs_bit_for_bit(outputs):
    with np.load(REFERENCE_DIR / "actuator_reference.npz") as stored:
        assert sorted(stored.files) == sorted(outputs)
        for name in stored.files:
            expected = stored[name]
            got = outputs[name]
            assert got.dtype == expected.dtype and got.shape == expected.shape, name
            if not np.array_equal(got, expected, equal_nan=True):
                diff = np.nanmax(np.abs(got - expected))
                pytest.fail(f"{name}: differs from the stored output (max |diff| {diff:.3g})")

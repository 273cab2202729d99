"""Shared pytest configuration."""

from __future__ import annotations

import os

# scikit-learn's array-API check (part of `parametrize_with_checks`) only runs when SciPy's
# array-API mode is on, and it must be set before SciPy is first imported.
os.environ.setdefault("SCIPY_ARRAY_API", "1")

import numpy as np
import pytest
import torch

os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded numpy generator (every random test is seeded)."""
    return np.random.default_rng(20261121)


def pytest_collection_modifyitems(config, items):
    """Skip tests marked ``cuda`` when no CUDA device is present."""
    if torch.cuda.is_available():
        return
    skip = pytest.mark.skip(reason="no CUDA device available")
    for item in items:
        if "cuda" in item.keywords:
            item.add_marker(skip)

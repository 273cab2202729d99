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


def sine_inputs(n_runs: int, rng: np.random.Generator, T: int = 100) -> dict[str, np.ndarray]:
    """Inputs ``CV, P1, P2, T1`` (each ``(n_runs, T)``) of the synthetic sine-driven test runs.

    Sines of a random phase per run (drawn from ``rng``: one ``uniform(0, 2 pi, (n_runs, 1))``
    draw); the test files add their own outputs ``X``, ``F``.
    """
    t = np.arange(T)
    ph = rng.uniform(0, 2 * np.pi, (n_runs, 1))
    return {
        "CV": 0.5 + 0.3 * np.sin(2 * np.pi * t / 60 + ph),
        "P1": 0.8 + 0.05 * np.sin(2 * np.pi * t / 37 + 2 * ph),
        "P2": 0.3 + 0.05 * np.sin(2 * np.pi * t / 23 + 3 * ph),
        "T1": 0.3 + 0.02 * np.sin(2 * np.pi * t / 90 + ph),
    }


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

"""``benchmarks/shift_visibility.py``: the window figures against sums made by hand, and the
whole-part separation against `innovation_effect`'s deflection (a second implementation)."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from benchmark_scripts import load_benchmark

from bayes_fdi.benchmark.cases import innovation_effect

tool = load_benchmark("shift_visibility")


def _stream(r_x: np.ndarray, r_f: np.ndarray, dd: np.ndarray) -> xr.Dataset:
    t = np.arange(r_x.size, dtype=np.float64)
    return xr.Dataset(
        {"r_X": ("time", r_x), "r_F": ("time", r_f), "DD": ("time", dd.astype(np.float64))},
        coords={"time": t},
    )


def test_window_figures_by_hand():
    n = 40
    healthy = _stream(np.full(n, 1.0), np.zeros(n), np.zeros(n, bool))
    r_x = np.full(n, 1.0)
    r_x[20:25] = 4.0  # an effect of 3 on X for 5 s in the first window
    r_f = np.zeros(n)
    r_f[30:40] = 2.0  # of 2 on F for the whole second window
    dd = np.zeros(n, bool)
    dd[20:30] = True
    faulty = _stream(r_x, r_f, dd)
    noise = {"r_X": 1.5, "r_F": 2.0}
    rows = tool.window_figures(faulty, healthy, t_from=20.0, t_hor=40.0, window=10, noise=noise)
    assert [r["start"] for r in rows] == [0.0, 10.0]
    assert rows[0]["separation"] == pytest.approx(np.sqrt(5 * (3 / 1.5) ** 2))  # sqrt(20)
    assert rows[1]["separation"] == pytest.approx(np.sqrt(10 * (2 / 2.0) ** 2))
    assert rows[0]["rms_faulty"]["X"] == pytest.approx(np.sqrt((5 * 16 + 5) / 10))
    assert rows[0]["rms_healthy"] == {"X": 1.0, "F": 0.0}
    assert rows[1]["rms_faulty"]["F"] == pytest.approx(2.0)
    assert [r["dd"] for r in rows] == [1.0, 0.0]
    # a last window cut by t_hor
    rows = tool.window_figures(faulty, healthy, t_from=20.0, t_hor=35.0, window=10, noise=noise)
    assert rows[1]["separation"] == pytest.approx(np.sqrt(5.0))


def test_the_windows_add_up_to_the_matched_filters_deflection():
    rng = np.random.default_rng(7)
    n = 600
    healthy = _stream(rng.normal(size=n), rng.normal(size=n), np.zeros(n, bool))
    faulty = _stream(
        healthy["r_X"].values + rng.normal(0.3, 0.5, n),
        healthy["r_F"].values + np.where(np.arange(n) >= 300, 0.4, 0.0),
        np.ones(n, bool),
    )
    noise = {"r_X": 0.9, "r_F": 1.1}
    rows = tool.window_figures(faulty, healthy, t_from=300.0, t_hor=600.0, window=100, noise=noise)
    whole = innovation_effect(faulty, healthy, t_from=300.0, noise=noise)["deflection"]
    assert np.sqrt(sum(r["separation"] ** 2 for r in rows)) == pytest.approx(whole, rel=1e-12)

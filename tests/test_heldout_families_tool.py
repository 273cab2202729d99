"""``benchmarks/heldout_families.py``: the faults start after the diagnoser's fit proof, and the
fault figures count from that onset (against counts made by hand)."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest
import xarray as xr
from benchmark_scripts import load_benchmark

tool = load_benchmark("heldout_families")


def test_the_onset_follows_the_fit_proof():
    assert tool.fault_onset(SimpleNamespace(fit_proof_seconds=600)) == 900.0
    assert tool.fault_onset(SimpleNamespace(fit_proof_seconds=0)) == tool.FAULT_ONSET == 300.0
    assert tool.fault_onset(SimpleNamespace()) == 300.0  # a model without a proof


class _Stream:
    """Gives a hand-made decision stream for the runs it is asked about."""

    def __init__(self, dd: np.ndarray, state: np.ndarray, groups: dict) -> None:
        self.out = xr.Dataset(
            {"DD": (("run", "time"), dd), "state": (("run", "time"), state)},
            attrs={"groups": json.dumps(groups)},
        )

    def run(self, runs: xr.Dataset) -> xr.Dataset:
        return self.out


def test_fault_figures_count_from_the_onset():
    t = np.arange(10.0)
    runs = xr.Dataset(coords={"time": t})
    dd = np.zeros((3, 10), dtype=bool)
    dd[0, 2:] = True  # on before the onset (5 s) and after: detected at 5 s, kept on
    dd[1, 7:9] = True  # detected at 7 s, off again at 9 s
    state = np.full((3, 10), "fn", dtype=object)
    state[0, 2:] = "f1|f7"
    state[1, 7:9] = ["f2", "f1|f7"]
    groups = {"f1|f7": ["f1", "f7"], "f2": ["f2"]}
    figures = tool.fault_figures(_Stream(dd, state, groups), runs, ["f1", "f7", "f3"], onset=5.0)
    assert figures["detected_share"] == pytest.approx(2 / 3)
    assert figures["kept_on_share"] == pytest.approx(1 / 2)
    assert figures["median_t_dt"] == pytest.approx(1.0)  # delays 0 and 2 s
    # named seconds after the onset: run 0 f1|f7 for 5 s (right), run 1 f2 then f1|f7 (1 of 2)
    assert figures["group_r_ti"] == pytest.approx(6 / 7)

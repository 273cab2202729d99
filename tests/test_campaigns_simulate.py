"""Campaigns turned into datasets by the actuator model (small versions of the shipped files)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io
import xarray as xr

from bayes_fdi.actuator import Fault, benchmark_inputs, simulate
from bayes_fdi.campaigns.parsing import load_campaign
from bayes_fdi.campaigns.simulation import simulate_campaign
from bayes_fdi.cli import main
from bayes_fdi.datasets import load_dataset, save_dataset, validate_dataset

SIM = Path(__file__).parents[1] / "sim"
MAT = Path(__file__).parents[1] / "bayes_fdi" / "data" / "OneHourTestData_ExampleII.mat"
STATES = ["fn", *(f"f{i}" for i in range(1, 20))]


@pytest.fixture(scope="module")
def small_simulated():
    c = load_campaign(SIM / "paper-simulated.toml", runs_per_state=2, duration=40, batch_size=7)
    return c, simulate_campaign(c, progress=False)


def test_simulated_campaign_shapes_labels(small_simulated):
    c, ds = small_simulated
    validate_dataset(ds, require=("CV", "P1", "P2", "T1", "X", "F"))
    assert ds.sizes == {"run": 40, "time": 40}
    assert list(ds["state"].values) == [s for s in STATES for _ in range(2)]
    np.testing.assert_array_equal(ds["strength"].values, c.run_specs().strength)
    assert ds.attrs["campaign"] == "paper-simulated" and ds.attrs["seed"] == 2026
    assert ds.attrs["source"] == "benchmark-inputs"
    for name in ("CV", "P1", "P2", "T1", "X", "F"):
        assert float(ds[name].min()) >= 0.0 and float(ds[name].max()) <= 1.0


def test_result_does_not_depend_on_batch_size(small_simulated):
    c, ds = small_simulated
    other = simulate_campaign(c.replace(batch_size=40), progress=False)
    for name in ds.data_vars:
        np.testing.assert_array_equal(other[name].values, ds[name].values)
    reseeded = simulate_campaign(c, seed=11, progress=False)
    assert reseeded.attrs["seed"] == 11
    assert not np.array_equal(reseeded["strength"].values, ds["strength"].values)


def test_campaign_run_equals_a_direct_model_call(small_simulated):
    c, ds = small_simulated
    r = 5  # runs are fn, fn, f1, f1, f2, f2, ...: index 5 is the second f2 run
    assert str(ds["state"].values[r]) == "f2"
    inputs = benchmark_inputs(c.n_runs, c.duration, seed=ds.attrs["inputs_seed"], vary=True)
    fault = Fault("f2", float(ds["strength"].values[r]))
    direct = simulate(inputs.isel(run=[r]), [fault], seed=ds.attrs["noise_seed"])
    for name in ("CV", "P1", "P2", "T1", "X", "F"):
        np.testing.assert_array_equal(direct[name].values[0], ds[name].values[r])


def test_netcdf_round_trip_is_exact(small_simulated, tmp_path):
    _, ds = small_simulated
    save_dataset(ds, tmp_path / "c.nc")
    xr.testing.assert_identical(load_dataset(tmp_path / "c.nc"), ds)


def test_fault_signatures_follow_the_benchmark_table():
    """Same inputs for every run (vary = false): the benchmark's effect signs must show."""
    c = load_campaign(
        SIM / "paper-simulated.toml",
        runs_per_state=1,
        duration=200,
        states=["fn", "f1", "f7", "f10", "f18"],
        **{"inputs.vary": False, "faults.strength": [0.75, 0.75]},
    )
    ds = simulate_campaign(c, progress=False)
    x = ds["X"].mean("time").to_series().set_axis(ds["state"].values)
    f = ds["F"].mean("time").to_series().set_axis(ds["state"].values)
    # reference §3: dX'/dF' at strength 0.75 = f1 -0.26/+0.36, f7 -0.22/+0.36, f10 -0.09/+0.19,
    # f18 0/+0.36 (F' saturates at 1 where X is small, so only the signs are checked)
    for fault in ("f1", "f7", "f10"):
        assert x[fault] < x["fn"] - 0.05, fault
    for fault in ("f1", "f7", "f10", "f18"):
        assert f[fault] > f["fn"] + 0.05, fault
    assert abs(x["f18"] - x["fn"]) < 0.01


def test_lublin_campaign_uses_the_real_hour(tmp_path):
    c = load_campaign(SIM / "paper-lublin.toml", runs_per_state=2, duration=60,
                      states=["fn", "f1", "f18", "f17"])  # fmt: skip
    ds = simulate_campaign(c, progress=False)
    validate_dataset(ds)
    assert ds.sizes == {"run": 8, "time": 60}
    starts = ds["window_start"].values
    assert starts.min() >= 0 and starts.max() <= 3600 - 60
    raw = scipy.io.loadmat(MAT)["OneHourTestData_ExampleII"]
    divisors = {"P1": (1, 4000), "P2": (2, 4000), "T1": (3, 200), "F": (4, 40), "CV": (5, 100),
                "X": (6, 100)}  # fmt: skip
    for r in range(8):
        window = slice(starts[r], starts[r] + 60)
        state = str(ds["state"].values[r])
        for name, (row, div) in divisors.items():
            recorded = raw[row, window] / div
            if state == "fn" or (name in ("CV", "T1") and state != "f7"):
                np.testing.assert_array_equal(ds[name].values[r], recorded, err_msg=name)
            if state == "f17" and name == "P2":  # f17 > 0 lowers P2
                assert (ds[name].values[r] < recorded).all()
    f1 = ds["state"].values == "f1"
    recorded_x = np.array([raw[6, s : s + 60] / 100 for s in starts])
    assert (ds["X"].values[f1] < recorded_x[f1] - 0.05).mean() > 0.9  # clogging: X drops
    save_dataset(ds, tmp_path / "l.nc")
    xr.testing.assert_identical(load_dataset(tmp_path / "l.nc"), ds)


def test_lublin_even_windows():
    c = load_campaign(SIM / "paper-lublin.toml", runs_per_state=3, duration=350,
                      states=["fn", "f2"], **{"inputs.window": "even"})  # fmt: skip
    ds = simulate_campaign(c, progress=False)
    np.testing.assert_array_equal(ds["window_start"].values, [0, 1625, 3250] * 2)


def test_damadics_benchmark_scenarios():
    c = load_campaign(SIM / "damadics-benchmark.toml", duration=1000)
    ds = simulate_campaign(c, progress=False)
    assert ds.sizes == {"run": 45, "time": 1000}
    assert (ds["onset"].values[1:] == 900).all()
    before = slice(0, 900)
    x = ds["X"].values
    # identical inputs (vary = false): before the onset every run is the nominal run plus noise
    noise = 0.0014
    assert np.abs(x[:, before] - x[0, before]).max() < 12 * noise
    big_f1 = np.flatnonzero((ds["state"].values == "f1") & (ds["strength"].values == 0.75))[0]
    assert x[big_f1, 950:].mean() < x[0, 950:].mean() - 0.05


def test_cli_simulate(tmp_path, capsys):
    out = tmp_path / "s.nc"
    code = main([
        "simulate", str(SIM / "paper-simulated.toml"), "--out", str(out), "--seed", "5",
        "--set", "runs_per_state=1", "--set", "duration=20", "--set", "states=['fn','f3']",
        "--no-progress",
    ])  # fmt: skip
    assert code == 0
    ds = load_dataset(out)
    assert ds.sizes == {"run": 2, "time": 20} and ds.attrs["seed"] == 5
    assert "2 runs x 20 s" in capsys.readouterr().out
    code = main(["simulate", str(SIM / "paper-simulated.toml"), "--out", str(out),
                 "--set", "duration=-3"])  # fmt: skip
    assert code == 2
    assert "campaign.duration must be > 0" in capsys.readouterr().err

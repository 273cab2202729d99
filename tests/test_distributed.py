"""Tasks on a local 2-worker dask cluster give exactly the serial results."""

from __future__ import annotations

import builtins
import os
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from bayes_fdi.campaigns.parsing import load_campaign
from bayes_fdi.campaigns.simulation import simulate_campaign
from bayes_fdi.cli import main
from bayes_fdi.datasets import load_dataset
from bayes_fdi.distributed import cluster_client, run_tasks

pytest.importorskip("dask.distributed")
SIM = Path(__file__).parents[1] / "sim"


def _square_and_threads(x):
    import torch

    if x < 0:
        raise ValueError(f"negative task {x}")
    return x * x, torch.get_num_threads(), os.environ.get("OMP_NUM_THREADS")


def _dask_chunks_in_the_task_thread(x):
    import threading

    import dask.array as da

    me = threading.get_ident()
    here = da.zeros(4, chunks=1).map_blocks(lambda b: b + (threading.get_ident() == me))
    return bool(here.compute().all())


@pytest.fixture(scope="module")
def client():
    with cluster_client(workers=2) as c:
        yield c


def test_run_tasks_keeps_order_and_single_threads(client):
    address = client.scheduler.address
    out = run_tasks(_square_and_threads, range(7), scheduler=address, progress=False)
    assert [o[0] for o in out] == [x * x for x in range(7)]
    assert {o[1] for o in out} == {1}  # torch on one thread inside the workers
    assert {o[2] for o in out} == {"1"}  # OMP_NUM_THREADS of the local cluster's processes
    assert len(client.scheduler_info()["workers"]) == 2
    serial = run_tasks(_square_and_threads, range(7), progress=False)
    assert [o[0] for o in serial] == [o[0] for o in out]
    with pytest.raises(ValueError, match="negative task -3"):
        run_tasks(_square_and_threads, [1, -3], scheduler=address, progress=False)


def test_a_task_computes_its_dask_chunks_in_its_own_thread(client):
    """A recording read lazily is computed where the task writes its netCDF output: HDF5 is
    not thread-safe, so no other worker thread may read netCDF meanwhile."""
    address = client.scheduler.address
    out = run_tasks(_dask_chunks_in_the_task_thread, range(4), scheduler=address, progress=False)
    assert out == [True] * 4


def test_simulate_on_two_workers_equals_serial(client):
    campaign = load_campaign(SIM / "paper-simulated.toml", runs_per_state=1, duration=30,
                             batch_size=6)  # fmt: skip
    serial = simulate_campaign(campaign, progress=False)
    on_cluster = simulate_campaign(campaign, progress=False, scheduler=client.scheduler.address)
    xr.testing.assert_identical(on_cluster, serial)
    lublin = load_campaign(SIM / "paper-lublin.toml", runs_per_state=1, duration=30, batch_size=4)
    xr.testing.assert_identical(
        simulate_campaign(lublin, progress=False, scheduler=client.scheduler.address),
        simulate_campaign(lublin, progress=False),
    )


def test_simulate_command_with_workers(tmp_path):
    out = tmp_path / "c.nc"
    argv = ["simulate", str(SIM / "paper-simulated.toml"), "--out", str(out), "--workers", "2",
            "--set", "runs_per_state=1", "--set", "duration=20", "--quiet"]  # fmt: skip
    assert main(argv) == 0
    campaign = load_campaign(SIM / "paper-simulated.toml", runs_per_state=1, duration=20)
    expected = simulate_campaign(campaign, progress=False)
    for name in ("CV", "P1", "P2", "T1", "X", "F"):
        np.testing.assert_array_equal(load_dataset(out)[name].values, expected[name].values)


def test_bad_cluster_arguments_and_missing_dask(monkeypatch, capsys):
    with pytest.raises(ValueError, match="not both"):
        run_tasks(abs, [1], workers=2, scheduler="tcp://127.0.0.1:1")
    with pytest.raises(ValueError, match="positive integer"):
        run_tasks(abs, [1], workers=0)
    real_import = builtins.__import__

    def no_dask(name, *args, **kwargs):
        if name.startswith("dask"):
            raise ImportError("No module named 'dask'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_dask)
    with pytest.raises(ImportError, match=r"pip install 'bayes_fdi\[distributed\]'"):
        run_tasks(abs, [1], workers=2, progress=False)
    assert run_tasks(abs, [-1, 2], progress=False) == [1, 2]  # the serial path needs no dask
    toml = str(SIM / "paper-simulated.toml")
    status = main(["simulate", toml, "--out", "x.nc", "--workers", "2", "--scheduler", "tcp://a:1"])
    assert status == 2
    assert "not allowed with argument" in capsys.readouterr().err

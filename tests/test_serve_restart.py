"""``kill -9`` of ``bayes-fdi serve`` (a real subprocess, SIGKILL) and a restart: the log holds
every second once; the seconds it was down (and at most the last uncommitted second before the
kill) are BLIND; every record equals the batch ``run`` of the logged samples, i.e. the stream of
an uninterrupted run that missed those seconds; and the records before the kill equal those of
an uninterrupted ``serve`` of the same plant."""

from __future__ import annotations

import signal
import time

import numpy as np
import pytest
import xarray as xr
from serve_helpers import Process, fit_tiny_model, free_ports, plant_second, write_toml

from bayes_fdi.datasets import CHANNELS
from bayes_fdi.deployment.serve.durable_log import read_log
from bayes_fdi.diagnosis import OnlineDiagnoser

SPEED = 2.0
DURATION = 150


@pytest.mark.slow
def test_kill_9_and_restart_resume_the_stream(tmp_path):
    model = fit_tiny_model(tmp_path / "tiny.npz")
    plant_port, seva_a, seva_b = free_ports(3)
    valves = {"V1": 'fault = {name = "f18", strength = 0.8, onset = 110}', "V2": ""}
    sim = f"duration = {DURATION}"
    folders = {name: tmp_path / name for name in ("killed", "whole")}
    for f in folders.values():
        f.mkdir()
    tomls = {
        "killed": write_toml(
            folders["killed"] / "valve.toml",
            plant_port=plant_port,
            seva_port=seva_a,
            valves=valves,
            speed=SPEED,
            simulation=sim,
        ),
        "whole": write_toml(
            folders["whole"] / "valve.toml",
            plant_port=plant_port,
            seva_port=seva_b,
            valves=valves,
            speed=SPEED,
            simulation=sim,
        ),
    }
    args = {k: ["serve", "--config", str(t), "--model", str(model)] for k, t in tomls.items()}
    whole = Process(args["whole"], folders["whole"])
    killed = Process(args["killed"], folders["killed"])
    whole.wait_for("serve: 2 valve(s)", 120)
    killed.wait_for("serve: 2 valve(s)", 120)
    plant = Process(["simulate-plant", "--config", str(tomls["whole"])], tmp_path)
    start = float(plant.wait_for("simulated plant:", 120).split("from plant time ")[1])
    plant.wait_for("second 60 of", 120)
    killed_at = time.time()
    assert killed.stop(signal.SIGKILL) == -signal.SIGKILL
    time.sleep(4.0)  # 8 plant seconds down
    restarted = Process(args["killed"], folders["killed"])
    restarted.wait_for("serve: 2 valve(s)", 120)
    restarted_at = time.time()
    plant.wait_for("all seconds written", 180)
    time.sleep(1.0)
    assert restarted.stop() == 0 and whole.stop() == 0
    plant.stop()
    down = (restarted_at - killed_at) * SPEED  # plant seconds, an upper bound of the gap
    for valve in ("V1", "V2"):
        log = read_log(folders["killed"] / "log", valve)
        ref = read_log(folders["whole"] / "log", valve)
        k = plant_second(log["time"].values, start)
        assert np.all(np.diff(k) == 1) and k[0] == plant_second(ref["time"].values, start)[0]
        blind = k[log["status"].values == "BLIND"]
        blind = blind[blind < DURATION - 1]  # the plant's end
        assert blind.size > 0 and np.all(np.diff(blind) == 1)  # one interval: the kill
        assert blind.size <= down + 2 * SPEED + 1, (blind, down)
        assert 55 <= blind[0] <= 66
        assert "no data for" in log["note"].values[k == blind[0]][0]
        _equals_batch(log, model)
        # before the kill: the same records as the uninterrupted serve
        before = slice(0, int(np.flatnonzero(k == blind[0])[0]))
        for name in ("status", "state", "VMV_X", "VU_X", "VMV_F", "VU_F", "r_X", "r_F", "X"):
            np.testing.assert_array_equal(log[name].values[before], ref[name].values[before])
        if valve == "V1":
            assert "BLURRED" in log["status"].values[k > 115]


def _equals_batch(log, model):
    channels = xr.Dataset(
        {c: ("time", log[c].values) for c in CHANNELS},
        coords={"time": np.arange(log.sizes["time"], dtype=float)},
    )
    batch = OnlineDiagnoser.load(model).run(channels)
    for name in ("status", "state", "DD", "VMV_X", "VU_X", "VMV_F", "VU_F", "r_X", "r_F"):
        np.testing.assert_array_equal(log[name].values, batch[name].values, err_msg=name)

"""Outages of the plant's OPC UA server (the simulated plant stops its server for 5 s and for 60 s;
``serve`` and the plant are real subprocesses on 127.0.0.1, 2x real time): the log has every
second; the BLIND seconds are exactly those of the outages; on this (seeded) plant, whose
uninterrupted recording diagnosed in one batch ``run`` has no detection, none comes from the
outages either (a missing second counts as an in-control one, so the detector's statistic
decays through a gap as on fault-free data: ``docs/plant.md``); the records note
the lost and the regained connection; and every record equals the batch ``run`` of the logged
samples."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from serve_helpers import Process, fit_tiny_model, free_ports, plant_second, write_toml

from bayes_fdi.datasets import CHANNELS
from bayes_fdi.deployment.serve.config import load_config
from bayes_fdi.deployment.serve.durable_log import read_log
from bayes_fdi.deployment.serve.plant_simulator import plant_recording
from bayes_fdi.diagnosis import OnlineDiagnoser

SPEED = 2.0
DURATION = 170
OUTAGES = ((20, 5), (40, 60))  # (first plant second, seconds)


@pytest.mark.slow  # about 100 s: 170 plant seconds at 2x
def test_outages_of_5_and_60_s_are_blind_exactly_and_the_stream_goes_on(tmp_path):
    model = fit_tiny_model(tmp_path / "tiny.npz")
    plant_port, seva_port = free_ports(2)
    outages = ", ".join(f"{{start = {a}, seconds = {n}}}" for a, n in OUTAGES)
    toml = write_toml(
        tmp_path / "valve.toml",
        plant_port=plant_port,
        seva_port=seva_port,
        valves={"V1": "", "V2": ""},
        speed=SPEED,
        simulation=f"duration = {DURATION}\noutages = [{outages}]",
    )
    serve = Process(["serve", "--config", str(toml), "--model", str(model)], tmp_path)
    serve.wait_for("serve: 2 valve(s)", 120)
    plant = Process(["simulate-plant", "--config", str(toml), "--wait-subscribed"], tmp_path)
    start = float(plant.wait_for("simulated plant:", 120).split("from plant time ")[1])
    plant.wait_for("all seconds written", DURATION / SPEED + 60)
    plant.stop()
    assert serve.stop() == 0, serve.output
    config = load_config(str(toml), publishing=False)
    clean = OnlineDiagnoser.load(model).run(plant_recording(config, DURATION))
    down = {k for a, n in OUTAGES for k in range(a, a + n)}
    after = np.zeros(DURATION, dtype=bool)  # the outages and the 60 s after each
    for a, n in OUTAGES:
        after[a : a + n + 60] = True
    for i, valve in enumerate(("V1", "V2")):
        log = read_log(tmp_path / "log", valve)
        k = plant_second(log["time"].values, start)
        assert k[0] == 0 and np.all(np.diff(k) == 1), k
        status, note = log["status"].values, log["note"].values
        blind = {int(s) for s in k[status == "BLIND"] if s < DURATION - 1}  # not the end
        assert blind == down, sorted(blind ^ down)
        clean_dd = clean["DD"].isel(run=i).values
        dd = np.zeros(DURATION, dtype=bool)
        inside = k < DURATION
        dd[k[inside]] = log["DD"].values[inside]
        assert not clean_dd[after].any()  # the uninterrupted plant has no detection there
        assert not dd[after].any()  # and none came from the outages
        for a, n in OUTAGES:
            assert "lost" in note[k == a][0]
            assert any("reconnected" in x for x in note[(k >= a) & (k <= a + n)])
        _equals_batch(log, model)


def _equals_batch(log, model):
    channels = xr.Dataset(
        {c: ("time", log[c].values) for c in CHANNELS},
        coords={"time": np.arange(log.sizes["time"], dtype=float)},
    )
    batch = OnlineDiagnoser.load(model).run(channels)
    for name in ("status", "state", "DD", "VMV_X", "VU_X", "VMV_F", "VU_F", "r_X", "r_F"):
        np.testing.assert_array_equal(log[name].values, batch[name].values, err_msg=name)

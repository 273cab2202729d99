"""Seconds outside the model's input envelope in ``alarms.csv`` and ``summary.json``: counted
from the stream's ``novel_inputs``, per alarm and in all, chunk edges or not, and for a real
online diagnoser whose recording leaves the range it was fitted on."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import xarray as xr
from small_online import small_normal_models, small_normal_runs

from bayes_fdi.actuator import benchmark_inputs, simulate
from bayes_fdi.deployment.recording import diagnose_recording
from bayes_fdi.deployment.stream_files import AlarmCollector, outside_range
from bayes_fdi.diagnosis import OnlineDiagnoser


def test_alarm_collector_counts_the_seconds_outside_across_chunks():
    dd = np.array([0, 1, 1, 1, 0, 0, 1, 1, 1, 1], dtype=bool)
    novel = np.array([1, 1, 0, 1, 1, 0, 0, 1, 1, 1], dtype=bool)
    stream = xr.Dataset(
        {"DD": (("run", "time"), dd[None]), "state": (("run", "time"), np.full((1, 10), "f1")),
         "probability": (("run", "time"), np.full((1, 10), 0.5)),
         "novel_inputs": (("run", "time"), novel[None])},
        coords={"run": [0], "time": np.arange(10.0)},
    )  # fmt: skip
    for cuts in ([], [2], [3, 4, 7], list(range(1, 10))):
        collector = AlarmCollector()
        for seconds in np.split(np.arange(10), cuts):
            collector.append(stream.isel(time=seconds))
        # by hand: seconds 1-3 (novel at 1 and 3), seconds 6-9 (novel at 7, 8, 9)
        assert [x.seconds_outside_range for x in collector.finish()] == [2, 3]
    # a stream without the flag (a model that has no envelope) counts none
    assert not outside_range(stream.drop_vars("novel_inputs")).any()


@pytest.fixture(scope="module")
def fitted():
    return OnlineDiagnoser(small_normal_models()).fit(small_normal_runs())


def test_a_recording_outside_the_envelope_is_counted(fitted, tmp_path):
    rec = simulate(benchmark_inputs(1, 600, seed=7, vary=True), seed=7)
    rec = rec.drop_vars([c for c in rec.coords if c not in ("run", "time")])
    cv = rec["CV"].values.copy()
    high = float(fitted.envelope_.high_[0])
    cv[0, 300:420] = min(high + 0.05, 1.0)  # two minutes above the envelope's command range
    rec = rec.assign(CV=(("run", "time"), cv))
    res = diagnose_recording(fitted, rec, tmp_path, name="r", figure=False)
    stream = fitted.run(rec)
    novel = np.asarray(stream["novel_inputs"].values[0], dtype=bool)
    dd = np.asarray(stream["DD"].values[0], dtype=bool)
    # every second whose command lies above the envelope is counted (the rates may add more)
    assert novel[300:420].all() and res.seconds_outside_range == int(novel.sum()) >= 120
    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert summary["seconds_outside_range"] == res.seconds_outside_range
    alarms = pd.read_csv(tmp_path / "r" / "alarms.csv")
    assert len(alarms) >= 1  # the normal models extrapolate there: at least one alarm
    # independent: the flagged seconds inside each high period of DD
    edges = np.diff(np.concatenate(([0], dd.astype(int), [0])))
    periods = zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True)
    want = [int(novel[a:b].sum()) for a, b in periods]
    assert alarms["seconds_outside_range"].tolist() == want
    assert summary["alarm_seconds_outside_range"] == sum(want)


def test_the_cli_says_how_long_the_inputs_lay_outside(fitted, tmp_path, capsys):
    from bayes_fdi import model_files
    from bayes_fdi.cli import main

    rec = simulate(benchmark_inputs(1, 400, seed=8, vary=True), seed=8)
    rec = rec.drop_vars([c for c in rec.coords if c not in ("run", "time")])
    cv = rec["CV"].values.copy()
    cv[0, 200:260] = min(float(fitted.envelope_.high_[0]) + 0.05, 1.0)
    path = tmp_path / "rec.nc"
    rec.assign(CV=(("run", "time"), cv)).isel(run=0).to_netcdf(path)
    model_files.save(fitted, tmp_path / "model.npz")
    args = ["diagnose", str(path), "--model", str(tmp_path / "model.npz"), "--out",
            str(tmp_path / "out"), "--quiet", "--no-figure"]  # fmt: skip
    assert main(args) == 0
    summary = json.loads((tmp_path / "out" / "rec" / "summary.json").read_text())
    n = summary["seconds_outside_range"]
    assert n >= 60
    assert f"{n} s with inputs outside the range the model was fitted or commissioned on" in (
        capsys.readouterr().out
    )

"""``bayes-fdi fit`` and ``bayes-fdi diagnose``: the files a diagnosed recording gives, chunked or
whole, serial or on a cluster, with a stand-in online diagnoser (``stream_double``)."""

from __future__ import annotations

import json
import os
import time

import numpy as np
import pandas as pd
import pytest
import xarray as xr
from conftest import sine_inputs
from stream_double import StreamDouble

from bayes_fdi import model_files
from bayes_fdi.cli import main
from bayes_fdi.datasets import CHANNELS, make_dataset
from bayes_fdi.deployment import fitting as model_fitting
from bayes_fdi.deployment.recording import diagnose_recording, supports_chunks
from bayes_fdi.deployment.stream_files import CSV_COLUMNS, AlarmCollector


def recording(rng, T=1200, faults=((300, 420, "F", 0.05), (800, 860, "X", 0.06)), gap=None):
    """One synthetic run: sines in, a static actuator out, offsets on X or F in given windows."""
    ch = {k: v[0] for k, v in sine_inputs(1, rng, T).items()}
    X = 0.9 * ch["CV"] + 0.004 * rng.standard_normal(T)
    F = 0.7 * (1 - 0.8 * X) * np.sqrt(ch["P1"] - ch["P2"]) + 0.004 * rng.standard_normal(T)
    for a, b, name, offset in faults:
        (X if name == "X" else F)[a:b] += offset
    ds = make_dataset(dict(ch, X=X, F=F), allow_nan=True)
    ds = ds.drop_vars(["state", "strength", "onset", "profile", "ramp"])
    if gap is not None:
        ds["X"][0, gap[0] : gap[1]] = np.nan
    return ds


@pytest.fixture(scope="module")
def model():
    rng = np.random.default_rng(3)
    normal = xr.concat([recording(rng, 600, faults=()) for _ in range(3)], dim="run")
    return StreamDouble().fit(normal.assign_coords(run=[0, 1, 2]))


def _files(folder):
    return {p: (folder / p).read_bytes() for p in ("seva.csv", "alarms.csv")}


def test_files_follow_the_stream(model, tmp_path, rng):
    rec = recording(rng, gap=(100, 110))
    res = diagnose_recording(model, rec, tmp_path, name="r1")
    folder = tmp_path / "r1"
    assert set(res.files) == {"seva.csv", "seva.nc", "alarms.csv", "timeline.png", "summary.json"}
    stream = model.run(rec)
    csv = pd.read_csv(folder / "seva.csv")
    assert tuple(csv.columns) == CSV_COLUMNS and len(csv) == 1200
    np.testing.assert_array_equal(csv["time"], rec["time"].values)
    assert (csv["status"].to_numpy() == stream["status"].values[0]).all()
    assert (csv["state"].to_numpy() == stream["state"].values[0]).all()
    np.testing.assert_array_equal(csv["DD"].to_numpy(), stream["DD"].values[0].astype(int))
    # '%.9g': 9 significant digits, relative error below 5e-9
    np.testing.assert_allclose(csv["r_X"], stream["r_X"].values[0], rtol=5e-9)
    np.testing.assert_allclose(csv["X"], rec["X"].values[0], rtol=5e-9)
    assert (csv["status"][100:110] == "BLIND").all()  # the gap: BLIND, not dropped

    with xr.open_dataset(folder / "seva.nc") as nc:
        back = nc.load()
    xr.testing.assert_identical(back[list(stream.data_vars)].drop_attrs(), stream.drop_attrs())
    xr.testing.assert_identical(back[list(CHANNELS)].drop_attrs(), rec[list(CHANNELS)].drop_attrs())
    assert json.loads(back.attrs["groups"]) == json.loads(stream.attrs["groups"])

    summary = json.loads((folder / "summary.json").read_text())
    assert summary["seconds"] == 1200 and summary["status_counts"]["BLIND"] == 10
    alarms = pd.read_csv(folder / "alarms.csv")
    assert summary["alarms"] == len(alarms) == res.alarms >= 2
    # independent: the alarms are the high periods of DD
    dd = stream["DD"].values[0]
    starts = np.flatnonzero(np.diff(np.concatenate([[0], dd.astype(int)])) == 1)
    np.testing.assert_array_equal(alarms["start"], rec["time"].values[starts])
    assert (alarms["duration"] == alarms["end"] - alarms["start"] + 1).all()
    first = alarms.iloc[0]  # the F offset from 300 s: isolated to the F group
    assert 300 <= first["start"] < 330 and first["state"] == "f17|f18|f19"
    inside = (stream["time"] >= first["start"]) & (stream["time"] <= first["end"])
    held = stream["state"].values[0][inside.values] == first["state"]
    expected = np.nanmean(stream["probability"].values[0][inside.values][held])
    assert first["probability"] == pytest.approx(expected, rel=5e-9)  # written with %.9g


def test_chunked_equals_whole(model, tmp_path, rng):
    assert supports_chunks(model)
    rec = recording(rng, gap=(395, 405))
    diagnose_recording(model, rec, tmp_path / "whole", name="r", figure=False)
    for chunk in (97, 400):  # a chunk edge inside an alarm and inside the gap
        diagnose_recording(model, rec, tmp_path / f"c{chunk}", name="r", chunk_seconds=chunk,
                           figure=False)  # fmt: skip
        assert _files(tmp_path / f"c{chunk}" / "r") == _files(tmp_path / "whole" / "r")
        with (
            xr.open_dataset(tmp_path / f"c{chunk}" / "r" / "seva.nc") as a,
            xr.open_dataset(tmp_path / "whole" / "r" / "seva.nc") as b,
        ):
            xr.testing.assert_identical(a.load(), b.load())


def test_lazy_netcdf_recording_is_read_in_chunks(model, tmp_path, rng):
    rec = recording(rng)
    path = tmp_path / "rec.nc"
    rec.isel(run=0).to_netcdf(path)
    assert main(["diagnose", str(path), "--model", _saved(model, tmp_path), "--out",
                 str(tmp_path / "lazy"), "--chunk-seconds", "250", "--quiet"]) == 0  # fmt: skip
    diagnose_recording(model, rec, tmp_path / "eager", name="rec", figure=False)
    assert _files(tmp_path / "lazy" / "rec") == _files(tmp_path / "eager" / "rec")


def test_alarm_collector_across_chunks():
    """DD high over chunk edges and to the end; states and probabilities by hand."""
    dd = np.array([0, 1, 1, 1, 0, 0, 1, 1, 1, 1], dtype=bool)
    state = np.array(["fn", "unknown", "f1", "f1", "fn", "fn", "f2", "f2", "f3", "f3"])
    proba = np.array([np.nan, np.nan, 0.8, 0.6, np.nan, np.nan, 0.9, 0.7, 0.95, 0.85])
    t = np.arange(10.0) + 100
    stream = xr.Dataset(
        {"DD": (("run", "time"), dd[None]), "state": (("run", "time"), state[None]),
         "probability": (("run", "time"), proba[None])},
        coords={"run": [0], "time": t},
    )  # fmt: skip
    for edges in ([10], [2, 10], [3, 4, 7, 10], list(range(1, 11))):
        collector = AlarmCollector()
        a = 0
        for b in edges:
            collector.append(stream.isel(time=slice(a, b)))
            a = b
        alarms = collector.finish()
        assert [(x.start, x.end, x.state, x.ongoing) for x in alarms] == [
            (101.0, 103.0, "f1", False),
            (106.0, 109.0, "f3", True),  # f2 and f3 two seconds each: the later one wins
        ]
        assert alarms[0].probability == pytest.approx(0.7)
        assert alarms[1].probability == pytest.approx(0.9)
        assert alarms[0].first_isolated == 102.0


def _saved(model, tmp_path):
    path = tmp_path / "model.npz"
    if not path.exists():
        model_files.save(model, path)
    return str(path)


def test_fit_from_recordings_and_diagnose_cli(tmp_path, rng, monkeypatch, capsys):
    made = []  # the constructor arguments fit_from_recordings asks for

    def double(**params):
        made.append(params)
        return StreamDouble()

    monkeypatch.setattr(model_fitting, "new_online_diagnoser", double)
    paths = []
    for i in range(2):
        one = recording(rng, 600, faults=()).isel(run=0)
        frame = one.to_dataframe()[list(CHANNELS)].reset_index()
        for c, f in (("CV", 100), ("X", 100), ("P1", 4000), ("P2", 4000), ("T1", 200), ("F", 40)):
            frame[c] = frame[c] * f
        paths.append(tmp_path / f"normal{i}.csv")
        frame.to_csv(paths[-1], index=False, float_format="%.17g")
    fault = tmp_path / "leak.csv"
    pd.read_csv(paths[0]).to_csv(fault, index=False)
    model_file = tmp_path / "mine.npz"
    argv = ["fit", "--normal", *map(str, paths), "--fault", f"f18@100={fault}", "--units",
            "physical", "--normal-samples", "auto", "--out", str(model_file),
            "--quiet"]  # fmt: skip
    assert main(argv) == 0
    assert "StreamDouble fitted on 2 fault-free and 1 fault recording(s)" in capsys.readouterr().out
    fitted = model_files.load(model_file)
    assert fitted.n_fault_runs_ == 1
    # --normal-samples reaches the normal models (auto: a learning curve chooses the size)
    assert made[0]["normal_models"].max_train_samples == "auto"
    assert main(["fit", "--default", "--normal-samples", "3000", "--out", str(model_file)]) == 2
    assert "--normal-samples needs --normal" in capsys.readouterr().err
    assert main(["commission", str(paths[0]), "--normal-samples", "5", "--out", "x.npz"]) == 2
    assert "expected a whole number >= 10 or 'auto', got '5'" in capsys.readouterr().err
    out = tmp_path / "out"
    argv = ["diagnose", str(paths[1]), "--model", str(model_file), "--units", "physical",
            "--out", str(out), "--quiet"]  # fmt: skip
    assert main(argv) == 0
    assert "normal1: 600 s" in capsys.readouterr().out
    assert (out / "normal1" / "timeline.png").stat().st_size > 10_000
    # an offline FaultDiagnoser file is refused with a clear message
    assert main(["diagnose", str(paths[1]), "--model", _offline(tmp_path), "--out", str(out)]) == 1
    assert "diagnoses whole runs" in capsys.readouterr().err
    assert main(["diagnose", "--out", str(out)]) == 2
    assert "--example" in capsys.readouterr().err


def _offline(tmp_path):
    from bayes_fdi.diagnosis import FaultDiagnoser, KernelRidgeRegressor, svm_classifier
    from bayes_fdi.diagnosis.isolation.tree import HierarchicalClassifier

    rng = np.random.default_rng(0)
    runs = xr.concat([recording(rng, 60, faults=()) for _ in range(6)], dim="run")
    runs = runs.assign_coords(run=np.arange(6), state=("run", ["fn", "f1"] * 3))
    runs["X"] = runs["X"] + 0.05 * (runs["state"] == "f1")
    diag = FaultDiagnoser(KernelRidgeRegressor(width=0.3), HierarchicalClassifier(svm_classifier(
        cv=2)), interval_calibration=None).fit(runs.isel(run=[0, 2, 4]), runs)  # fmt: skip
    path = tmp_path / "offline.npz"
    diag.save(path)
    return str(path)


def test_default_model_is_fitted_once_and_cached(tmp_path, monkeypatch, capsys):
    calls = []

    def fake_fitter(seed, small, progress):
        calls.append((seed, small))
        rng = np.random.default_rng(seed)
        normal = xr.concat([recording(rng, 300, faults=()) for _ in range(2)], dim="run")
        return StreamDouble().fit(normal.assign_coords(run=[0, 1]))

    monkeypatch.setenv(model_fitting.CACHE_ENV, str(tmp_path / "cache"))
    monkeypatch.delenv(model_fitting.SMALL_ENV, raising=False)
    monkeypatch.setattr(model_fitting, "_default_fitter", lambda: fake_fitter)
    out = tmp_path / "out"
    from bayes_fdi.datasets import load_lublin_example

    load_lublin_example().to_netcdf(tmp_path / "lublin-example.nc")
    argv = ["diagnose", str(tmp_path / "lublin-example.nc"), "--out", str(out), "--quiet"]
    assert main([*argv, "--no-figure"]) == 0
    assert main([*argv, "--no-figure"]) == 0
    assert calls == [(0, False)]  # fitted on first use only
    cached = model_fitting.default_model_path()
    assert cached.parent == tmp_path / "cache" and cached.exists()
    assert [p.name for p in cached.parent.iterdir()] == [cached.name]  # no temporary file
    summary = json.loads((out / "lublin-example" / "summary.json").read_text())
    assert summary["seconds"] == 3600 and summary["model"]["default"] is True
    cached.write_bytes(b"garbage")  # a damaged cache is fitted again, with a warning
    with pytest.warns(UserWarning, match="cached default model unusable"):
        model_fitting.default_model(progress=False)
    assert len(calls) == 2


def test_fit_default_training_reaches_the_fitter_and_needs_default(tmp_path, monkeypatch, capsys):
    from bayes_fdi.default_diagnoser import DEFAULT_TRAINING, TRAININGS

    # the command line names the trainings without importing them: the same, the default first
    assert model_fitting.DEFAULT_TRAININGS[0] == DEFAULT_TRAINING
    assert set(model_fitting.DEFAULT_TRAININGS) == set(TRAININGS)
    assert DEFAULT_TRAINING in model_fitting.default_model_path(small=False).name
    calls = []

    def fake_fitter(seed, small, progress, **options):
        calls.append(options)
        rng = np.random.default_rng(seed)
        normal = xr.concat([recording(rng, 300, faults=()) for _ in range(2)], dim="run")
        return StreamDouble().fit(normal.assign_coords(run=[0, 1]))

    monkeypatch.setattr(model_fitting, "_default_fitter", lambda: fake_fitter)
    out = str(tmp_path / "m.npz")
    assert main(["fit", "--default", "--training", "dgen", "--out", out, "--quiet"]) == 0
    assert "fitted on the dgen training campaigns" in capsys.readouterr().out
    assert main(["fit", "--default", "--out", out, "--quiet"]) == 0
    assert "fitted on the excitation-mix training campaigns" in capsys.readouterr().out
    assert calls == [{"training": "dgen"}, {"training": DEFAULT_TRAINING}]
    assert (
        main(["fit", "--campaign", "damadics-benchmark", "--training", "dgen", "--out", out]) == 2
    )
    assert "--training needs --default" in capsys.readouterr().err
    assert main(["fit", "--default", "--training", "chirp", "--out", out]) == 2
    assert "invalid choice: 'chirp'" in capsys.readouterr().err


def _day_file(path, rng, start=57000, n=1400):
    """A synthetic Lublin day file (33 columns): actuator 3 with an F offset in the f19 event."""
    from bayes_fdi.datasets.lublin import ACTUATOR_COLUMNS, ACTUATOR_RANGES, DAY_COLUMNS

    rec = recording(rng, n, faults=((58150 - start, 58326 - start, "F", 0.06),)).isel(run=0)
    values = rng.uniform(1.0, 99.0, (n, 33))
    values[:, 0] = np.arange(start, start + n)
    for name, column in ACTUATOR_COLUMNS[3].items():
        values[:, DAY_COLUMNS.index(column)] = rec[name].values * ACTUATOR_RANGES[3][name][0]
    path.write_text("\n".join("\t".join(f"{v:.10g}" for v in row) for row in values) + "\n")
    return path


def test_real_fault_events_of_a_day_file_are_scored(model, tmp_path, rng):
    from bayes_fdi.scoring.picalc import picalc

    day = _day_file(tmp_path / "17112001.txt", rng)
    out = tmp_path / "out"
    assert main(["diagnose", str(day), "--model", _saved(model, tmp_path), "--out", str(out),
                 "--actuator", "3", "--quiet", "--no-figure"]) == 0  # fmt: skip
    events = pd.read_csv(out / "17112001" / "events.csv")
    assert list(events["fault"]) == ["f16", "f16", "f19"]  # 17 Nov, actuator 3
    assert events["covered"].all()
    f19 = events.iloc[2]
    assert f19["t_on"] == 57801  # the previous event ends at 57800
    stream = xr.open_dataset(out / "17112001" / "seva.nc").load().isel(run=0)
    t = stream["time"].values
    dd = stream["DD"].values.astype(bool)
    # independently: PICalc of DD alone (PID from the F group of the stand-in)
    pid = stream["indicated"].values[:, 1].astype(bool)
    cid = stream["indicated"].values[:, 0].astype(int)
    ref = picalc(t, dd, pid, cid, t_on=57801, t_from=58150, t_hor=58326)
    for key in ("t_dt", "r_fd", "r_td", "t_it", "r_ti", "r_mi"):
        assert f19[key] == pytest.approx(ref[key])
    assert 0 <= f19["t_dt"] < 60 and f19["isolated_as"] == "f17|f18|f19"
    summary = json.loads((out / "17112001" / "summary.json").read_text())
    assert summary["lublin_events"]["events"] == 3


def test_many_recordings_on_two_workers_equal_serial(model, tmp_path, rng):
    pytest.importorskip("dask.distributed")
    paths = []
    for i in range(3):
        rec = recording(rng, 700).isel(run=0)
        paths.append(tmp_path / f"rec{i}.nc")
        rec.to_netcdf(paths[-1])
    model_file = _saved(model, tmp_path)
    common = ["--model", model_file, "--quiet", "--no-figure", "--chunk-seconds", "300"]
    assert main(["diagnose", *map(str, paths), "--out", str(tmp_path / "serial"), *common]) == 0
    assert main(["diagnose", *map(str, paths), "--out", str(tmp_path / "cluster"),
                 "--workers", "2", *common]) == 0  # fmt: skip
    for i in range(3):
        assert _files(tmp_path / "cluster" / f"rec{i}") == _files(tmp_path / "serial" / f"rec{i}")
    names = sorted(os.listdir(tmp_path / "cluster"))
    assert names == ["rec0", "rec1", "rec2"]


def test_fit_from_a_shipped_campaign(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(model_fitting, "new_online_diagnoser", StreamDouble)
    out = tmp_path / "campaign-model.npz"
    sets = ["runs_per_state=1", "duration=60", 'states=["fn","f1","f18"]']
    argv = ["fit", "--campaign", "paper-simulated", "--out", str(out), "--quiet"]
    for text in sets:
        argv += ["--set", text]
    assert main(argv) == 0
    assert "fitted on campaign paper-simulated" in capsys.readouterr().out
    assert model_files.load(out).n_fault_runs_ == 2
    assert main(["fit", "--campaign", "no-such-campaign", "--out", str(out)]) == 2
    from bayes_fdi.campaigns.shipped import shipped_campaigns

    shipped = shipped_campaigns()
    assert {"damadics-benchmark", "online-normal", "paper-lublin", "paper-simulated",
            "shift-chirp", "shift-flow-loop", "shift-telegraph"} <= set(shipped)  # fmt: skip
    assert f"shipped: {', '.join(shipped)}" in capsys.readouterr().err


def test_installed_package_ships_the_campaign_files(tmp_path):
    """A built wheel holds sim/*.toml as package data (bayes_fdi/data/campaigns)."""
    import subprocess
    import sys
    import zipfile
    from pathlib import Path

    root = Path(__file__).parents[1]
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
         "-w", str(tmp_path), str(root)],
        check=True, capture_output=True,
    )  # fmt: skip
    (wheel,) = tmp_path.glob("*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    for toml in sorted((root / "sim").glob("*.toml")):
        assert f"bayes_fdi/data/campaigns/{toml.name}" in names


def test_progress_on_stderr_and_quiet(model, tmp_path, rng, capsys):
    from bayes_fdi.progress import busy

    with busy("a long step", interval=0.01):
        time.sleep(0.05)
    assert capsys.readouterr().err.splitlines()[-1].startswith("a long step: done in ")
    with busy("silent", enabled=False):
        pass
    assert capsys.readouterr().err == ""
    rec = recording(rng, 300, faults=()).isel(run=0)
    path = tmp_path / "r.nc"
    rec.to_netcdf(path)
    argv = ["diagnose", str(path), "--model", _saved(model, tmp_path), "--no-figure"]
    assert main([*argv, "--out", str(tmp_path / "a")]) == 0
    assert "diagnosing r" in capsys.readouterr().err  # the chunk progress bar
    assert main([*argv, "--out", str(tmp_path / "b"), "--quiet"]) == 0
    assert capsys.readouterr().err == ""


def test_interruption_leaves_no_files(model, tmp_path, rng):
    class Interrupted(StreamDouble):
        def run(self, recording, state=None, return_state=False):
            if state is not None:  # the second chunk
                raise KeyboardInterrupt
            return super().run(recording, state=state, return_state=return_state)

    broken = Interrupted().fit(recording(rng, 300, faults=()))
    with pytest.raises(KeyboardInterrupt):
        diagnose_recording(broken, recording(rng, 600), tmp_path, name="r", chunk_seconds=250)
    assert os.listdir(tmp_path) == []  # neither the files nor their partial copies


def test_an_interrupted_diagnosis_leaves_the_older_results_whole(model, tmp_path, rng):
    """Interrupted near its end, a diagnosis into a folder that holds an older result leaves
    the older files exactly as they were: the outputs are replaced as a whole or not at all."""

    class InterruptedAtTheEnd(StreamDouble):
        def run(self, recording, state=None, return_state=False):
            if state is not None and int(recording["time"].values[0]) >= 500:  # the last chunk
                raise KeyboardInterrupt
            return super().run(recording, state=state, return_state=return_state)

    runs = recording(rng, 600)
    diagnose_recording(model, runs, tmp_path, name="r", chunk_seconds=250, figure=True)
    before = {f: (tmp_path / "r" / f).read_bytes() for f in os.listdir(tmp_path / "r")}
    assert {"seva.csv", "alarms.csv", "summary.json", "timeline.png"} <= set(before)
    broken = InterruptedAtTheEnd().fit(recording(rng, 300, faults=()))
    with pytest.raises(KeyboardInterrupt):
        diagnose_recording(broken, runs, tmp_path, name="r", chunk_seconds=250, figure=True)
    assert os.listdir(tmp_path) == ["r"]  # no hidden partial folder or file left
    after = {f: (tmp_path / "r" / f).read_bytes() for f in os.listdir(tmp_path / "r")}
    assert after == before


def test_a_detection_only_model_says_so_and_names_the_residuals(tmp_path):
    """A model fitted on fault-free data only can detect but not name a fault: the alarm says
    so, names the residual that raised it and its sign, and so do ``seva.csv`` and
    ``summary.json``. The fault here adds flow (f18, bypass opened): F reads high."""
    from bayes_fdi.actuator import Fault, benchmark_inputs, simulate
    from bayes_fdi.diagnosis import DynamicNormalModels, OnlineDiagnoser

    normal = simulate(benchmark_inputs(4, 400, seed=1, vary=True), seed=1)
    models = DynamicNormalModels(
        x_widths=(8.0,),
        f_widths=(0.1,),
        evidence_max_samples=200,
        max_train_samples=300,
        calibration_folds=2,
        random_state=0,
    )
    diag = OnlineDiagnoser(models).fit(normal)
    faulty = simulate(
        benchmark_inputs(1, 400, seed=3, vary=True), [Fault("f18", 0.7, 150.0)], seed=3
    ).isel(run=0)
    diagnose_recording(diag, faulty, tmp_path, name="r", figure=False)
    alarms = pd.read_csv(tmp_path / "r" / "alarms.csv", keep_default_na=False)
    fault_alarm = alarms[alarms["start"] >= 150].iloc[0]
    assert fault_alarm["state"] == "unknown"
    assert "detection only" in fault_alarm["description"]
    assert "F high" in fault_alarm["evidence"]
    seva = pd.read_csv(tmp_path / "r" / "seva.csv", keep_default_na=False)
    dd = seva["DD"].to_numpy().astype(bool)
    assert (seva["description"][~dd] == "fn: no fault detected").all()
    assert seva["description"][dd].str.contains("detection only").all()
    assert (seva["evidence"][~dd] == "").all()
    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert summary["isolation"]["detection_only"] is True
    assert summary["isolation"]["note"].startswith("detection only")


def test_seva_nc_takes_a_mismatch_that_first_appears_in_a_later_chunk(model, tmp_path, rng):
    """The text width of seva.nc is fixed by the first chunk: it must hold every answer the
    diagnoser can give, "mismatch" (8 bytes) included, also with short group labels."""
    from bayes_fdi.deployment.stream_files import StreamNetCDFWriter

    rec = recording(rng, 600, faults=())
    stream = model.run(rec).assign_coords(group=["g1", "g2"])
    state = np.full(stream["state"].shape, "fn", dtype=object)
    state[:, 450:470] = "mismatch"  # a model mismatch in the second chunk only
    stream["state"] = (("run", "time"), state.astype(str))
    writer = StreamNetCDFWriter(tmp_path / "seva.nc")
    for a, b in ((0, 300), (300, 600)):
        part = {"time": slice(a, b)}
        writer.append(stream.isel(part), rec.isel(part))
    writer.close()
    back = xr.load_dataset(tmp_path / "seva.nc")
    np.testing.assert_array_equal(back["state"].values.astype(str), state.astype(str))


def test_the_cached_default_model_is_named_by_its_training_campaigns(tmp_path, monkeypatch):
    """A changed training campaign file changes the cache's name, so that the model cached from
    the old training is not loaded; the other campaign files do not."""
    import hashlib
    import shutil

    from bayes_fdi.campaigns import shipped

    folder = tmp_path / "campaigns"
    shutil.copytree(shipped.campaign_folder(), folder)
    monkeypatch.setattr(shipped, "campaign_folder", lambda: folder)
    monkeypatch.setenv("BAYES_FDI_CACHE", str(tmp_path / "cache"))
    before = model_fitting.default_model_path(small=False)
    # the digest is the SHA-256 of the online-*.toml files' names and contents, in name order
    digest = hashlib.sha256()
    for path in sorted(folder.glob("online-*.toml")):
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    assert before.name.endswith(f"-{digest.hexdigest()[:8]}.npz")
    (folder / "shift-chirp.toml").write_text("# not a training campaign\n")
    assert model_fitting.default_model_path(small=False) == before
    sine_sum = folder / "online-normal-sine-sum.toml"
    sine_sum.write_text(sine_sum.read_text() + "\n# changed\n")
    after = model_fitting.default_model_path(small=False)
    assert after != before and after.parent == before.parent
    assert model_fitting.default_model_path(small=True).name == after.name[:-4] + "-small.npz"

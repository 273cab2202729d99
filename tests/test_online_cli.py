"""The real online diagnoser end to end through the command line: ``bayes-fdi fit --default``,
``bayes-fdi diagnose`` (the default model fitted on first use and cached; the shipped Lublin
hour) and ``bayes-fdi benchmark --small`` (small training settings: seconds, not minutes)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from bayes_fdi.benchmark.scenarios import SCENARIOS
from bayes_fdi.cli import main
from bayes_fdi.datasets import load_lublin_example
from bayes_fdi.default_diagnoser import DEFAULT_FIT_PROOF_SECONDS
from bayes_fdi.deployment import fitting as model_fitting
from bayes_fdi.diagnosis import OnlineDiagnoser
from bayes_fdi.diagnosis.detection import CUSUM, TwoSpeedCUSUM
from bayes_fdi.diagnosis.isolation import ForestClassifier

#: Runs ``bayes-fdi diagnose`` in a fresh interpreter and prints the bayes_fdi modules it loaded.
_DIAGNOSE_AND_LIST_MODULES = """
import json, sys
from bayes_fdi.cli import main
status = main(sys.argv[1:])
print(json.dumps({"status": status, "modules": sorted(m for m in sys.modules
                                                       if m.startswith("bayes_fdi"))}))
"""


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """A fresh default-model cache with the small settings, filled by ``bayes-fdi diagnose`` of
    the shipped hour (written to a file) run in a fresh interpreter, which fits the default model
    on first use; also the modules that run loaded."""
    folder = tmp_path_factory.mktemp("cache")
    out = tmp_path_factory.mktemp("diagnosed")
    hour = out.parent / "lublin-hour.nc"
    load_lublin_example().to_netcdf(hour)
    env = dict(os.environ, **{model_fitting.CACHE_ENV: str(folder), model_fitting.SMALL_ENV: "1"})
    proc = subprocess.run(
        [
            sys.executable,
            "-c",
            _DIAGNOSE_AND_LIST_MODULES,
            "diagnose",
            str(hour),
            "--out",
            str(out),
            "--quiet",
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=1200,
        check=True,
    )
    loaded = json.loads(proc.stdout.strip().splitlines()[-1])
    assert loaded["status"] == 0
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(model_fitting.CACHE_ENV, str(folder))
        mp.setenv(model_fitting.SMALL_ENV, "1")
        path = model_fitting.default_model_path()
        yield path, out / "lublin-hour", mp, loaded["modules"], hour


def test_diagnose_loads_no_module_of_the_paper_or_the_benchmark(cache):
    """Deployment stands on the library alone, also when it fits the default model."""
    modules = cache[3]
    assert "bayes_fdi.default_diagnoser" in modules  # the default model was fitted here
    assert "bayes_fdi.deployment.recording" in modules
    assert [m for m in modules if m.startswith(("bayes_fdi.paper", "bayes_fdi.benchmark"))] == []


def test_diagnose_fits_the_default_model_once_and_caches_it(cache, tmp_path, capsys):
    path, *_, hour = cache
    assert path.exists() and path.name.endswith("-small.npz")
    stamp = path.stat().st_mtime_ns
    assert main(["diagnose", str(hour), "--out", str(tmp_path), "--quiet", "--no-figure"]) == 0
    assert path.stat().st_mtime_ns == stamp  # loaded, not fitted again
    assert "lublin-hour: 3600 s" in capsys.readouterr().out
    assert isinstance(OnlineDiagnoser.load(path), OnlineDiagnoser)


def test_diagnose_the_shipped_hour_writes_the_stream_of_the_model(cache):
    path, folder, *_ = cache
    model = OnlineDiagnoser.load(path)
    hour = load_lublin_example()
    stream = model.run(hour[["CV", "P1", "P2", "T1", "X", "F"]].isel(run=0))
    csv = pd.read_csv(folder / "seva.csv")
    assert len(csv) == 3600
    np.testing.assert_array_equal(csv["status"].to_numpy(), stream["status"].values.astype(str))
    np.testing.assert_array_equal(csv["state"].to_numpy(), stream["state"].values.astype(str))
    np.testing.assert_array_equal(csv["DD"].to_numpy().astype(bool), stream["DD"].values)
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["seconds"] == 3600 and summary["model"]["class"] == "OnlineDiagnoser"
    assert summary["model"]["default"] is True
    dd = stream["DD"].values
    alarms = pd.read_csv(folder / "alarms.csv")
    assert len(alarms) == int(dd[0] + np.sum(dd[1:] & ~dd[:-1]))
    assert (folder / "timeline.png").stat().st_size > 10_000


def test_diagnose_sets_the_fit_proof_of_the_model_it_loads(cache, tmp_path, capsys):
    path, folder, *_, hour = cache
    # the default model is trained on the simulator: it must see a valve fit before it names
    # a fault there
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["isolation"]["fit_proof_seconds"] == DEFAULT_FIT_PROOF_SECONDS
    argv = ["diagnose", str(hour), "--out", str(tmp_path), "--quiet", "--no-figure",
            "--fit-proof-seconds", "3600"]  # fmt: skip
    assert main(argv) == 0
    summary = json.loads((tmp_path / "lublin-hour" / "summary.json").read_text())
    assert summary["isolation"]["fit_proof_seconds"] == 3600
    assert (
        "once the stream has seen this valve fit the normal models for 3600 s"
        in (summary["isolation"]["note"])
    )
    csv = pd.read_csv(tmp_path / "lublin-hour" / "seva.csv", keep_default_na=False)
    model = OnlineDiagnoser.load(path).set_params(fit_proof_seconds=3600)
    stream = model.run(load_lublin_example()[["CV", "P1", "P2", "T1", "X", "F"]].isel(run=0))
    np.testing.assert_array_equal(csv["state"].to_numpy(), stream["state"].values.astype(str))
    detected = csv["DD"].to_numpy().astype(bool)
    assert set(csv["state"].to_numpy()[detected]) <= {"mismatch"}  # no fault within the hour
    capsys.readouterr()
    argv = ["diagnose", str(hour), "--out", str(tmp_path), "--commission-seconds", "1800",
            "--fit-proof-seconds", "60"]  # fmt: skip
    assert main(argv) == 2
    assert "--fit-proof-seconds sets a loaded model's proof" in capsys.readouterr().err


def test_fit_default_writes_a_model_that_diagnose_reads(cache, tmp_path, capsys):
    path, *_ = cache
    model_file = tmp_path / "model.npz"
    assert main(["fit", "--default", "--small", "--out", str(model_file), "--quiet"]) == 0
    assert "OnlineDiagnoser fitted on the excitation-mix training campaigns (small)" in (
        capsys.readouterr().out
    )
    # the default training: the excitation mix, the command's lag as a normal-model input and
    # the CUSUM (whose threshold holds better than the two-speed CUSUM's off the training
    # excitation)
    fitted = OnlineDiagnoser.load(model_file)
    assert isinstance(fitted.detector_, CUSUM) and not isinstance(fitted.detector_, TwoSpeedCUSUM)
    assert fitted.normal_models_.physics_inputs == ("command_lag",)
    assert fitted.normal_models_.std_coverage == 0.9
    # the k-means tree of RVCs names the faults, through the compiled per-second pass
    assert not isinstance(fitted.isolator_.classifier_, ForestClassifier)
    assert fitted.isolator_.lean_ is not None and fitted.isolator_.rows_independent
    # same seed, same settings: the same model as the cached default (same stream)
    hour = load_lublin_example().isel(run=0, time=slice(0, 600))
    a = fitted.run(hour)
    b = OnlineDiagnoser.load(path).run(hour)
    for name in ("DD", "stat_X", "stat_F", "X_hat", "F_hat_std", "group_proba"):
        np.testing.assert_array_equal(a[name].values, b[name].values)
    out = tmp_path / "out"
    argv = ["diagnose", "--example", "--model", str(model_file), "--out", str(out), "--quiet",
            "--no-figure", "--chunk-seconds", "1000"]  # fmt: skip
    assert main(argv) == 0
    whole = pd.read_csv(cache[1] / "seva.csv")
    chunked = pd.read_csv(out / "lublin-example" / "seva.csv")
    pd.testing.assert_frame_equal(whole, chunked)  # chunks of 1000 s: the same file


def test_benchmark_small_end_to_end(tmp_path):
    out = tmp_path / "bench"
    assert main(["benchmark", "--small", "--seeds", "1", "--out", str(out), "--quiet"]) == 0
    data = json.loads((out / "benchmark.json").read_text())
    assert len(data["scenarios"]) == len(SCENARIOS) == 44
    assert {r["seed"] for r in data["scenarios"]} == {10_000}  # evaluation seeds >= 10 000
    assert data["settings"]["small"] is True and data["settings"]["training_seed"] == 0
    real = data["real_hour"]
    assert real["seconds"] == 1800 and 0.0 <= real["clear_share"] <= 1.0
    assert data["fault_free"]["seconds"] == 3600
    groups = data["groups"]
    members = sorted((f for g in groups.values() for f in g), key=lambda f: int(f[1:]))
    # every fault is in one isolability group or declared undetectable (DGN0), never both
    assert sorted(members + data["undetectable"], key=lambda f: int(f[1:])) == [
        f"f{i}" for i in range(1, 20)
    ]
    by_name = {(r["fault"], r["mode"], r["size"]): r["indices"] for r in data["scenarios"]}
    # f1 big (a valve clogging that stops the stem) is far above the noise: detected
    assert by_name[("f1", "abrupt", "big")]["t_dt"] >= 0
    assert (out / "benchmark.md").stat().st_size > 1000
    assert len(list((out / "timelines").glob("*.png"))) == 44
    # the default model's fit proof, recorded and said
    assert data["settings"]["fit_proof_seconds"] == DEFAULT_FIT_PROOF_SECONDS
    assert f"only after {DEFAULT_FIT_PROOF_SECONDS} s without detection" in (
        (out / "benchmark.md").read_text()
    )

"""``bayes-fdi commission`` and ``bayes-fdi diagnose --example`` / ``--commission-seconds``: a
valve learnt from its healthy data, end to end through the command line."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from bayes_fdi.actuator import simulate
from bayes_fdi.actuator.excitation import level_loop_inputs
from bayes_fdi.cli import main
from bayes_fdi.diagnosis import OnlineDiagnoser


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    out = tmp_path_factory.mktemp("example")
    assert main(["diagnose", "--example", "--out", str(out), "--quiet"]) == 0
    return out


def test_the_first_example_commissions_on_the_first_half_and_diagnoses_the_second(example):
    clean = example / "lublin-example"
    summary = json.loads((clean / "summary.json").read_text())
    assert summary["alarms"] == 0
    assert summary["status_counts"] == {"CLEAR": 1800}
    assert summary["model"]["commissioned_on_seconds"] == 1800
    assert {"model.npz", "commissioning.md", "commissioning.json"} <= set(summary["files"])
    model = OnlineDiagnoser.load(clean / "model.npz")
    assert model.commissioning_["healthy"]["seconds"] == 1800
    # the valve's own lag, with its speed limits, is an input of its normal models: the real
    # valve follows a falling command at a limited speed, a rising one without one here
    nm = model.normal_models_
    assert nm.physics_inputs == ("command_lag",) and nm.lag_speed_limits and not nm.lag_as_mean
    tau_rise, tau_fall, v_rise, v_fall = nm.command_lag_
    assert 0 < tau_rise <= tau_fall and 0 < v_fall < 0.05 and v_rise == np.inf
    assert (clean / "commissioning.md").read_text().startswith("# Commissioning report")


def test_the_transplanted_bypass_opening_is_detected_and_read_as_extra_flow(example):
    alarms = pd.read_csv(example / "lublin-example-f18" / "alarms.csv", keep_default_na=False)
    assert len(alarms) == 1
    alarm = alarms.iloc[0]
    onset = 1800 + 300
    assert onset <= alarm["start"] <= onset + 10
    assert "F high" in alarm["evidence"]
    assert "f18" in alarm["state"] and "bypass" in alarm["description"]


@pytest.mark.slow
def test_commission_writes_a_model_and_its_report_and_diagnose_uses_it(tmp_path):
    # one valve at one operating point: commissioned on its first 2400 s, diagnosed after
    run = simulate(level_loop_inputs(1, 3300, seed=13), seed=13)
    healthy, later = run.isel(time=slice(0, 2400)), run.isel(time=slice(2400, None))
    healthy.to_netcdf(tmp_path / "healthy.nc")
    out = tmp_path / "plant.npz"
    assert main(["commission", str(tmp_path / "healthy.nc"), "--out", str(out), "--quiet"]) == 0
    assert out.exists() and (tmp_path / "plant.md").exists() and (tmp_path / "plant.json").exists()
    report = json.loads((tmp_path / "plant.json").read_text())
    assert report["healthy"]["seconds"] == 2400
    later.to_netcdf(tmp_path / "later.nc")
    assert (
        main(
            [
                "diagnose",
                str(tmp_path / "later.nc"),
                "--model",
                str(out),
                "--out",
                str(tmp_path / "d"),
                "--quiet",
                "--no-figure",
            ]
        )
        == 0
    )
    seva = pd.read_csv(tmp_path / "d" / "later" / "seva.csv")
    assert (seva["status"] == "CLEAR").mean() >= 0.95


@pytest.mark.slow
def test_diagnose_commissions_on_the_first_seconds_of_each_recording(tmp_path):
    run = simulate(level_loop_inputs(1, 2400, seed=13), seed=13)
    run.to_netcdf(tmp_path / "valve.nc")
    assert (
        main(
            [
                "diagnose",
                str(tmp_path / "valve.nc"),
                "--commission-seconds",
                "1800",
                "--isolation",
                "forest",
                "--out",
                str(tmp_path / "d"),
                "--quiet",
                "--no-figure",
            ]
        )
        == 0
    )
    folder = tmp_path / "d" / "valve"
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["seconds"] == 600 and summary["model"]["commissioned_on_seconds"] == 1800
    assert (folder / "model.npz").exists()
    assert np.isclose(summary["start"], 1800.0)
    report = json.loads((folder / "commissioning.json").read_text())
    assert report["isolation_classifier"] == "forest"  # the option reaches the commissioning
    assert "random forest" in (folder / "commissioning.md").read_text()


def test_commission_seconds_that_leave_nothing_is_a_usage_error(tmp_path, capsys):
    run = simulate(level_loop_inputs(1, 1000, seed=13), seed=13)
    run.to_netcdf(tmp_path / "valve.nc")
    status = main(
        [
            "diagnose",
            str(tmp_path / "valve.nc"),
            "--commission-seconds",
            "1000",
            "--out",
            str(tmp_path / "d"),
            "--quiet",
        ]
    )
    assert status == 2
    assert "leaves nothing to diagnose" in capsys.readouterr().err


def test_the_isolation_classifier_is_chosen_by_name(tmp_path, capsys):
    from bayes_fdi.cli import build_parser
    from bayes_fdi.commissioning.commission import ISOLATION_CLASSIFIERS

    healthy = tmp_path / "valve.nc"
    simulate(level_loop_inputs(1, 700, seed=13), seed=13).to_netcdf(healthy)
    out = str(tmp_path / "m.npz")
    args = build_parser("commission").parse_args(["commission", str(healthy), "--out", out])
    assert args.isolation == "tree"
    for name in ISOLATION_CLASSIFIERS:  # every classifier commissioning offers, by its name
        args = build_parser("commission").parse_args(
            ["commission", str(healthy), "--out", out, "--isolation", name]
        )
        assert args.isolation == name
    assert main(["commission", str(healthy), "--out", out, "--isolation", "svm"]) == 2
    assert "invalid choice: 'svm'" in capsys.readouterr().err


def test_diagnose_chooses_the_commissioned_isolation_and_refuses_it_without_commissioning(
    tmp_path, capsys
):
    from bayes_fdi.cli import build_parser
    from bayes_fdi.cli_arguments import ISOLATION_CHOICES
    from bayes_fdi.commissioning.commission import ISOLATION_CLASSIFIERS

    assert ISOLATION_CHOICES == ISOLATION_CLASSIFIERS  # the options' choices, the library's names

    recording = tmp_path / "valve.nc"
    simulate(level_loop_inputs(1, 700, seed=13), seed=13).to_netcdf(recording)
    out = ["--out", str(tmp_path / "d")]
    parse = build_parser("diagnose").parse_args
    args = parse(["diagnose", str(recording), "--commission-seconds", "650", *out])
    assert args.isolation is None  # the commissioning's default, the tree
    for name in ISOLATION_CLASSIFIERS:  # every classifier commissioning offers, by its name
        args = parse(["diagnose", "--example", "--isolation", name, *out])
        assert args.isolation == name
    assert main(["diagnose", "--example", "--isolation", "svm", *out]) == 2
    assert "invalid choice: 'svm'" in capsys.readouterr().err
    # a model that is not commissioned here has no classifier to choose (refused before the
    # model file is read)
    (tmp_path / "m.npz").write_bytes(b"")
    for extra in ([str(recording)], ["--example", "--model", str(tmp_path / "m.npz")]):
        status = main(["diagnose", *extra, "--isolation", "forest", *out])
        assert status == 2
        assert "--isolation chooses the classifier of a model commissioned here" in (
            capsys.readouterr().err
        )

"""A recording against the model's training ranges: wrongly declared units are refused with the
unit that fits, a recording far outside in every unit is named, one inside passes."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import xarray as xr

from bayes_fdi.cli import main
from bayes_fdi.datasets import load_lublin_example
from bayes_fdi.datasets.known_ranges import channel_ranges, check_known_ranges, units_of
from bayes_fdi.diagnosis import OnlineDiagnoser

#: normalised training ranges, [1st percentile, median, 99th percentile]
RANGES = {"F": [0.25, 0.43, 0.61], "X": [0.53, 0.62, 0.73]}


def _recording(**medians: float) -> xr.Dataset:
    return xr.Dataset({c: (("run", "time"), np.full((1, 5), v)) for c, v in medians.items()})


def test_channel_ranges_are_percentiles_of_the_finite_samples():
    values = np.r_[np.arange(101.0), np.nan]  # 0..100: percentiles 1, 50, 99 are 1, 50, 99
    ds = xr.Dataset({"X": (("run", "time"), values[None])})
    assert channel_ranges(ds) == {"X": [1.0, 50.0, 99.0]}


def test_flow_in_kg_per_s_declared_as_t_per_h_is_refused_naming_kg_per_s():
    # 17 t/h written as 4.72 kg/s and declared t/h: 4.72 / 40 = 0.118 of full scale, below
    # 0.25 - max(0.25 * 0.36, 0.05) = 0.16; in kg/s: 4.72 * 3.6 / 40 = 0.425, inside.
    ds = _recording(F=4.722 / 40, X=0.62)
    with pytest.raises(ValueError, match=r"F: median 4.722 't/h'.*in 'kg/s' it would lie inside"):
        check_known_ranges(ds, RANGES, "physical", source="rec")


def test_far_outside_in_every_unit_is_a_note_and_inside_is_silent():
    ds = _recording(F=0.43, X=0.92)  # X at 92 %: no unit of a fraction brings it to 53-73 %
    (note,) = check_known_ranges(ds, RANGES, "physical", source="rec")
    assert note.startswith("rec: X: median 92 '%'") and "in no known unit" in note
    assert check_known_ranges(_recording(F=0.20, X=0.70), RANGES, "physical") == []  # within


def test_units_of_a_read_recording_and_none_where_unknown():
    units = '{"CV": "%", "P1": "kPa", "P2": "kPa", "T1": "degC", "X": "%", "F": "t/h"}'
    assert units_of(xr.Dataset(attrs={"units": units})) == json.loads(units)
    assert units_of(xr.Dataset(attrs={"units": "CV = raw / 100 %"})) is None  # free text
    assert units_of(xr.Dataset()) is None


def test_diagnose_refuses_a_recording_declared_in_the_wrong_units(tmp_path, capsys):
    hour = load_lublin_example()
    model = OnlineDiagnoser(random_state=0).fit(hour.isel(time=slice(0, 900)))
    assert set(model.training_ranges_) == {"CV", "P1", "P2", "T1", "X", "F"}
    model.training_units_ = {c: "1" for c in ("CV", "P1", "P2", "T1", "X", "F")}
    model.save(tmp_path / "m.npz")
    assert OnlineDiagnoser.load(tmp_path / "m.npz").training_ranges_ == model.training_ranges_
    run = hour.isel(run=0, time=slice(900, 1500))
    frame = pd.DataFrame({"time": run["time"].values, "CV": run["CV"].values * 100,
                          "P1": run["P1"].values * 4000, "P2": run["P2"].values * 4000,
                          "T1": run["T1"].values * 200, "X": run["X"].values * 100,
                          "F": run["F"].values * 40 / 3.6})  # fmt: skip
    frame.to_csv(tmp_path / "kgs.csv", index=False)
    files = [str(tmp_path / "kgs.csv"), "--model", str(tmp_path / "m.npz")]
    argv = ["diagnose", *files, "--units", "physical", "--out", str(tmp_path / "out"), "--quiet"]
    argv.append("--no-figure")
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "far outside what the model was fitted on" in err and "in 'kg/s'" in err
    assert "the model was fitted on recordings declared as CV=1,P1=1" in err
    assert not (tmp_path / "out" / "kgs").exists()  # nothing written
    assert main([*argv, "--no-unit-check"]) == 0  # the user's word: diagnosed as they are
    assert (tmp_path / "out" / "kgs" / "seva.csv").exists()


def test_fit_reports_the_range_it_covers_and_that_it_detects_only(tmp_path, capsys):
    run = load_lublin_example().isel(run=0, time=slice(0, 1200))
    frame = pd.DataFrame({"time": run["time"].values, **{c: run[c].values for c in
                          ("CV", "P1", "P2", "T1", "X", "F")}})  # fmt: skip
    frame.to_csv(tmp_path / "healthy.csv", index=False)
    argv = ["fit", "--normal", str(tmp_path / "healthy.csv"), "--out", str(tmp_path / "m.npz")]
    assert main([*argv, "--quiet"]) == 0
    out = capsys.readouterr().out
    low, high = np.percentile(run["CV"].values * 100, [1, 99])  # the same percentiles, in %
    assert f"CV {low:.4g} to {high:.4g} %" in out
    assert "detection only" in out and "bayes-fdi commission" in out

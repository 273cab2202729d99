"""Real Lublin data: the packaged hour and the day-file loader (tested on files written here)."""

from __future__ import annotations

import hashlib
import json
import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from bayes_fdi.datasets import load_dataset, save_dataset, validate_dataset
from bayes_fdi.datasets.lublin import (
    DAY_COLUMNS,
    LUBLIN_FAULT_EVENTS,
    LublinGapWarning,
    find_gaps,
    load_lublin_day,
    load_lublin_example,
    lublin_fault_labels,
)

SHARED_MAT = Path("/work/shared/data/lublin/OneHourTestData_ExampleII.mat")
PACKAGED_MAT = Path(__file__).parents[1] / "bayes_fdi" / "data" / "OneHourTestData_ExampleII.mat"

# Column (1-based, from the benchmark data description) and divisor of each channel, per actuator,
# written out independently of the module's tables.
EXPECTED = {
    1: {"P1": (2, 1000), "P2": (3, 1000), "T1": (4, 200), "F": (5, 500), "CV": (6, 100),
        "X": (7, 100)},
    2: {"P1": (18, 1000), "P2": (19, 1000), "T1": (20, 200), "F": (21, 100), "CV": (22, 100),
        "X": (23, 100)},
    3: {"P1": (24, 4000), "P2": (25, 4000), "T1": (26, 200), "F": (27, 40), "CV": (28, 100),
        "X": (29, 100)},
}  # fmt: skip


def test_packaged_hour_is_the_dablib_file():
    assert PACKAGED_MAT.stat().st_size == 317_016
    digest = hashlib.sha256(PACKAGED_MAT.read_bytes()).hexdigest()
    assert digest.startswith("b26450f9") and digest.endswith("752d")  # README of the shared copy
    if SHARED_MAT.exists():
        assert PACKAGED_MAT.read_bytes() == SHARED_MAT.read_bytes()


def test_example_hour_units_and_labels():
    ds = load_lublin_example()
    validate_dataset(ds)
    assert ds.sizes == {"run": 1, "time": 3600}
    np.testing.assert_array_equal(ds["time"].values, np.arange(3600.0))
    assert str(ds["state"].values[0]) == "fn" and ds.attrs["campaign"] == "lublin-example"
    assert ds.attrs["actuator"] == 3 and ds.attrs["date"] == "2001-10-11"
    raw = scipy.io.loadmat(PACKAGED_MAT)["OneHourTestData_ExampleII"]
    for name, (row, div) in {"P1": (1, 4000), "P2": (2, 4000), "T1": (3, 200), "F": (4, 40),
                             "CV": (5, 100), "X": (6, 100)}.items():  # fmt: skip
        np.testing.assert_array_equal(ds[name].values[0], raw[row] / div)
    # physical ranges quoted in the data README (kPa, degC, t/h, %)
    assert ds["P1"].min() * 4000 == pytest.approx(3439.3)
    assert ds["P2"].max() * 4000 == pytest.approx(2673.5)
    assert ds["F"].max() * 40 == pytest.approx(28.3)
    assert ds["X"].min() * 100 == pytest.approx(48.7)
    assert ds["T1"].max() * 200 == pytest.approx(101.2)
    assert json.loads(ds.attrs["gaps"])["X"]["n_missing"] == 0


def _day_matrix(rng, n_rows=300, start=0):
    values = rng.uniform(1.0, 99.0, (n_rows, 33)).round(2)
    values[:, 0] = np.arange(start, start + n_rows)
    return values


def _write(path, values, fmt="%.2f"):
    lines = []
    for row in values:
        lines.append("\t".join("NaN" if np.isnan(v) else fmt % v for v in row))
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("actuator", [1, 2, 3])
def test_day_file_columns_and_units(tmp_path, rng, actuator):
    values = _day_matrix(rng, start=37000)
    path = _write(tmp_path / "17112001.txt", values)
    ds = load_lublin_day(path, actuator=actuator)
    assert ds.sizes == {"run": 1, "time": 300}
    np.testing.assert_array_equal(ds["time"].values, np.arange(37000.0, 37300.0))
    for name, (col, div) in EXPECTED[actuator].items():
        np.testing.assert_allclose(ds[name].values[0], values[:, col - 1] / div, rtol=1e-15)
    assert ds.attrs["actuator"] == actuator and ds.attrs["day"] == "17112001"
    assert ds.attrs["date"] == "2001-11-17"
    events = json.loads(ds.attrs["fault_events"])
    assert events and all(e["actuator"] == actuator and e["date"] == "17112001" for e in events)


def test_day_file_values_outside_range_are_kept(tmp_path, rng):
    values = _day_matrix(rng)
    values[5, 28] = 103.5  # Act3 X above 100 % closing
    values[6, 23] = -12.0  # Act3 P1 negative (sensor offset)
    ds = load_lublin_day(_write(tmp_path / "day.txt", values), actuator=3)
    assert ds["X"].values[0, 5] == pytest.approx(1.035)
    assert ds["P1"].values[0, 6] == pytest.approx(-12.0 / 4000)
    assert ds.attrs["date"] == "" and ds.attrs["day"] == "" and ds.attrs["fault_events"] == "[]"


def test_day_file_gaps_are_kept_and_reported(tmp_path, rng):
    values = _day_matrix(rng, n_rows=200)
    values[10:15, 28] = np.nan  # Act3 X: 5 samples
    values[100, 28] = np.nan  # Act3 X: 1 sample
    values[50:80, 26] = np.nan  # Act3 F: 30 samples
    values[0:3, 1] = np.nan  # Act1 P1 gap, not Act3's business
    path = _write(tmp_path / "day.txt", values)
    with pytest.warns(LublinGapWarning) as record:
        ds = load_lublin_day(path, actuator=3)
    message = str(record[0].message)
    assert "X (6 samples in 2 gap(s))" in message and "F (30 samples in 1 gap(s))" in message
    assert "P1" not in message
    assert np.isnan(ds["X"].values[0]).sum() == 6 and np.isnan(ds["F"].values[0]).sum() == 30
    gaps = find_gaps(ds)
    assert [(g.channel, g.start, g.stop, g.length) for g in gaps] == [
        ("X", 10.0, 14.0, 5),
        ("X", 100.0, 100.0, 1),
        ("F", 50.0, 79.0, 30),
    ]
    summary = json.loads(ds.attrs["gaps"])
    assert summary["X"] == {"n_missing": 6, "n_gaps": 2, "spans": [[10.0, 14.0], [100.0, 100.0]]}
    assert summary["CV"]["n_missing"] == 0
    with pytest.raises(ValueError, match="NaN"):
        validate_dataset(ds)
    validate_dataset(ds, allow_nan=True)
    # non-gap values untouched
    np.testing.assert_allclose(ds["X"].values[0, 20:100], values[20:100, 28] / 100)
    # netCDF keeps the gaps
    save_dataset(ds, tmp_path / "day.nc")
    back = load_dataset(tmp_path / "day.nc")
    np.testing.assert_array_equal(np.isnan(back["X"].values), np.isnan(ds["X"].values))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_lublin_day(path, actuator=2)  # actuator 2 columns have no gaps: no warning


def test_day_file_time_gap_is_inferred(tmp_path, rng):
    values = _day_matrix(rng, n_rows=50, start=100)
    values[20, 0] = np.nan
    ds = load_lublin_day(_write(tmp_path / "day.txt", values), actuator=3, warn=False)
    np.testing.assert_array_equal(ds["time"].values, np.arange(100.0, 150.0))


def test_full_size_day_file(tmp_path, rng):
    values = rng.uniform(0.0, 100.0, (86_400, 33))
    values[:, 0] = np.arange(86_400)
    values[40_000:40_010, 27] = np.nan
    path = tmp_path / "20112001.txt"
    np.savetxt(path, values, fmt="%.1f", delimiter="\t")
    with pytest.warns(LublinGapWarning, match=r"CV \(10 samples"):
        ds = load_lublin_day(path, actuator=3)
    assert ds.sizes == {"run": 1, "time": 86_400}
    np.testing.assert_allclose(ds["F"].values[0], np.round(values[:, 26], 1) / 40)
    assert ds.attrs["day"] == "20112001"


@pytest.mark.parametrize(
    ("edit", "pattern"),
    [
        (lambda rows: rows.__setitem__(7, rows[7] + "\t1.0"), "line 8 has 34 tab-separated"),
        (lambda rows: rows.__setitem__(3, rows[3].rsplit("\t", 1)[0]), "line 4 has 32"),
        (
            lambda rows: rows.__setitem__(5, _cell(rows[5], 4, "abc")),
            r"line 6, column 5 \(F51_01\)",
        ),
        (lambda rows: rows.__setitem__(9, _cell(rows[9], 28, "inf")), r"line 10, column 29"),
        (lambda rows: rows.__setitem__(2, _cell(rows[2], 10, "")), r"line 3, column 11"),
        (lambda rows: rows.__setitem__(6, _cell(rows[6], 0, "99")), r"line 7, column 1 \(time\)"),
    ],
)
def test_bad_day_files_name_line_and_column(tmp_path, rng, edit, pattern):
    rows = _write(tmp_path / "ok.txt", _day_matrix(rng, n_rows=20)).read_text().splitlines()
    edit(rows)
    path = tmp_path / "bad.txt"
    path.write_text("\n".join(rows) + "\n")
    with pytest.raises(ValueError, match=pattern):
        load_lublin_day(path, actuator=3)


def _cell(line, column, token):
    fields = line.split("\t")
    fields[column] = token
    return "\t".join(fields)


def test_bad_arguments(tmp_path, rng):
    path = _write(tmp_path / "day.txt", _day_matrix(rng, n_rows=5))
    with pytest.raises(ValueError, match="actuator must be 1, 2 or 3"):
        load_lublin_day(path, actuator=4)
    (tmp_path / "empty.txt").write_text("\n\n")
    with pytest.raises(ValueError, match="empty"):
        load_lublin_day(tmp_path / "empty.txt")
    values = _day_matrix(rng, n_rows=5, start=86_398)
    with pytest.raises(ValueError, match="outside one day"):
        load_lublin_day(_write(tmp_path / "late.txt", values))


def test_fault_events_and_labels():
    assert len(LUBLIN_FAULT_EVENTS) == 19
    assert {e.fault for e in LUBLIN_FAULT_EVENTS} == {"f16", "f17", "f18", "f19"}
    assert len(DAY_COLUMNS) == 33
    labels = lublin_fault_labels("17112001", 3)
    assert labels.shape == (86_400,)
    assert labels[58_200] == "f19" and labels[57_500] == "f16" and labels[57_600] == "fn"
    expected_faulty = (57530 - 57475 + 1) + (57800 - 57675 + 1) + (58325 - 58150 + 1)
    assert (labels != "fn").sum() == expected_faulty
    assert (lublin_fault_labels("20112001", 2) == "f17").sum() == 86_400 - 44_400
    assert (lublin_fault_labels("11102001", 3) == "fn").all()
    with pytest.raises(ValueError, match="DDMM2001"):
        lublin_fault_labels("2001-11-17", 3)


def test_padded_fields_and_windows_line_endings(tmp_path, rng):
    values = _day_matrix(rng, n_rows=30)
    text = "\r\n".join("\t".join(f" {v:.2f} " for v in row) for row in values) + "\r\n"
    (tmp_path / "pad.txt").write_text(text)
    ds = load_lublin_day(tmp_path / "pad.txt", actuator=1)
    np.testing.assert_allclose(ds["F"].values[0], values[:, 4] / 500, rtol=1e-15)

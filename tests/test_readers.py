"""Readers of recordings: units, sampling, gaps and formats (CSV, MATLAB v5 and v7.3, netCDF)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import xarray as xr

from bayes_fdi.datasets import CHANNELS, load_lublin_example
from bayes_fdi.datasets.readers import (
    PHYSICAL_UNITS,
    RecordingGapWarning,
    normalise,
    parse_units,
    read_csv,
    read_day_file,
    read_mat,
    read_netcdf,
    read_recording,
    to_physical,
)

# DABLib's ranges (docs/damadics.md, "Signals and their normalisation"): P' = P / 4 MPa,
# T1' = T1 / 200 degC, F' = F / 40 t/h, X' and CV' = % / 100.
RANGES = {"CV": 100.0, "P1": 4000.0, "P2": 4000.0, "T1": 200.0, "X": 100.0, "F": 40.0}


@pytest.fixture
def hour():
    """The shipped real hour: normalised channels and their physical values."""
    ds = load_lublin_example().isel(time=slice(0, 120))
    norm = {c: ds[c].values[0] for c in CHANNELS}
    phys = {c: norm[c] * RANGES[c] for c in CHANNELS}
    return ds["time"].values, norm, phys


def _frame(time, channels, order=("time", "F", "CV", "P2", "P1", "T1", "X")):
    data = {"time": time, **channels}
    return pd.DataFrame({k: data[k] for k in order})


def test_csv_physical_units_match_dablib_normalisation(hour, tmp_path):
    time, norm, phys = hour
    path = tmp_path / "rec.csv"
    _frame(time, phys).assign(comment="x").to_csv(path, index=False, float_format="%.17g")
    ds = read_csv(path, units="physical")
    assert ds.sizes == {"run": 1, "time": 120} and "state" not in ds.coords
    np.testing.assert_array_equal(ds["time"].values, time)
    for c in CHANNELS:  # x * r / r: two roundings of a float64 (relative 2.3e-16 each)
        np.testing.assert_allclose(ds[c].values[0], norm[c], rtol=5e-16)
    assert json.loads(ds.attrs["units"]) == PHYSICAL_UNITS
    assert json.loads(ds.attrs["ignored_columns"]) == ["comment"]
    assert ds.attrs["resampled"] == "no"


def test_per_column_units_and_column_mapping(hour, tmp_path):
    time, norm, phys = hour
    frame = pd.DataFrame(
        {
            "t_s": time,
            "valve_cmd": phys["CV"],
            "p_in_MPa": phys["P1"] / 1000,
            "p_out_bar": phys["P2"] / 100,
            "temp_K": phys["T1"] + 273.15,
            "stem": norm["X"],
            "flow_kgs": phys["F"] / 3.6,
        }
    )
    path = tmp_path / "rec.csv"
    frame.to_csv(path, index=False, float_format="%.17g")
    columns = {"t_s": "time", "valve_cmd": "CV", "p_in_MPa": "P1", "p_out_bar": "P2",
               "temp_K": "T1", "stem": "X", "flow_kgs": "F"}  # fmt: skip
    units = {"CV": "%", "P1": "MPa", "P2": "bar", "T1": "K", "X": "1", "F": "kg/s"}
    ds = read_csv(path, columns=columns, units=units)
    for c in CHANNELS:  # unit conversions: a few float64 roundings
        np.testing.assert_allclose(ds[c].values[0], norm[c], rtol=1e-12)
    # the command line's form of the same units
    assert parse_units("CV=%,P1=MPa,P2=bar,T1=K,X=1,F=kg/s") == units


def test_to_physical_inverts_normalise():
    values = np.array([0.0, 0.25, 1.0])
    for c in CHANNELS:
        for unit in ("1", PHYSICAL_UNITS[c]):
            np.testing.assert_allclose(to_physical(normalise(values, c, unit), c, unit), values)
    assert normalise(np.array([373.15]), "T1", "K")[0] == pytest.approx(0.5)


def test_bad_units_are_named():
    with pytest.raises(ValueError, match="unit 'psi' of P1 is not known"):
        parse_units(dict(PHYSICAL_UNITS, P1="psi"))
    with pytest.raises(ValueError, match=r"no unit given for channel\(s\) \['X', 'F'\]"):
        parse_units({"CV": "%", "P1": "kPa", "P2": "kPa", "T1": "degC"})
    with pytest.raises(ValueError, match="unknown channel"):
        parse_units(dict(PHYSICAL_UNITS, Q="1"))
    with pytest.raises(ValueError, match="'normalised', 'physical'"):
        parse_units("SI")


def test_gaps_stay_gaps_and_missing_seconds_become_nan(hour, tmp_path):
    time, norm, _ = hour
    frame = _frame(time, norm)
    frame.loc[10:14, "X"] = np.nan
    frame = frame.drop(index=range(50, 53))  # three seconds without any sample
    path = tmp_path / "gaps.csv"
    frame.to_csv(path, index=False, float_format="%.17g", na_rep="")
    with pytest.warns(RecordingGapWarning, match="3 s without any sample"):
        ds = read_csv(path)
    assert ds.sizes["time"] == 120  # the missing seconds are rows of NaN, not dropped
    x = ds["X"].values[0]
    assert np.isnan(x[10:15]).all() and np.isnan(x[50:53]).all()
    assert np.isfinite(np.delete(x, [*range(10, 15), 50, 51, 52])).all()
    gaps = json.loads(ds.attrs["gaps"])
    assert gaps["X"]["spans"] == [[time[10], time[14]], [time[50], time[52]]]
    assert gaps["CV"]["n_missing"] == 3
    np.testing.assert_array_equal(ds["X"].values[0, :10], norm["X"][:10])


def test_other_rates_need_an_explicit_resample(tmp_path):
    t = np.arange(200) / 10.0
    channels = {c: np.full(t.size, 0.5) for c in CHANNELS}
    channels["X"] = t / 100.0
    channels["F"][33] = np.nan  # one NaN sample: its second is NaN, not averaged over
    path = tmp_path / "fast.csv"
    _frame(t, channels).to_csv(path, index=False, float_format="%.17g", na_rep="NaN")
    with pytest.raises(ValueError, match=r"every 0.1 s \(10 Hz\).*resample='mean'"):
        read_csv(path)
    with pytest.warns(RecordingGapWarning, match="F"):
        ds = read_csv(path, resample="mean")
    np.testing.assert_array_equal(ds["time"].values, np.arange(0.0, 21.0))  # 0 and 20: partial
    # second k averages the samples with k - 0.5 <= t < k + 0.5 (pandas' groupby, independently)
    expected = pd.Series(channels["X"]).groupby(np.floor(t + 0.5)).mean()
    np.testing.assert_allclose(ds["X"].values[0], expected.to_numpy(), rtol=1e-14)
    assert np.isnan(ds["F"].values[0, 3]) and ds.attrs["resampled"] == "mean"
    assert np.isfinite(np.delete(ds["F"].values[0], 3)).all()

    slow_t = np.arange(0, 40, 2.0)
    slow = {c: 0.1 + slow_t / 100.0 for c in CHANNELS}
    slow["CV"][5] = np.nan
    path = tmp_path / "slow.csv"
    _frame(slow_t, slow).to_csv(path, index=False, float_format="%.17g")
    with pytest.raises(ValueError, match="every 2 s"):
        read_csv(path)
    with pytest.warns(RecordingGapWarning, match="CV"):
        ds = read_csv(path, resample="linear")
    grid = np.arange(0.0, 39.0)
    np.testing.assert_array_equal(ds["time"].values, grid)
    np.testing.assert_allclose(ds["X"].values[0], 0.1 + grid / 100.0, rtol=1e-14)
    cv = ds["CV"].values[0]  # NaN at t = 10 s spoils (8, 12): interpolation never bridges it
    assert np.isnan(cv[9:12]).all() and np.isfinite(np.delete(cv, [9, 10, 11])).all()


def test_bad_csv_contents_name_the_cell(hour, tmp_path):
    time, norm, _ = hour
    frame = _frame(time, norm).astype(object)
    frame.loc[7, "P2"] = "1,5"
    path = tmp_path / "bad.csv"
    frame.to_csv(path, index=False, sep=";")
    with pytest.raises(ValueError, match=r"line 9, column 'P2': '1,5' is not a number"):
        read_csv(path, delimiter=";")
    frame = _frame(time, norm)
    frame.loc[4, "time"] = frame.loc[3, "time"]
    frame.to_csv(path, index=False)
    with pytest.raises(ValueError, match="time must increase; sample 5"):
        read_csv(path)
    frame = _frame(time, norm).drop(columns="F")
    frame.to_csv(path, index=False)
    with pytest.raises(ValueError, match=r"no column for \['F'\]"):
        read_csv(path)
    frame = _frame(time, norm).drop(columns="time")
    frame.to_csv(path, index=False)
    with pytest.raises(ValueError, match="give rate="):
        read_csv(path)
    ds = read_csv(path, rate=1.0)
    np.testing.assert_array_equal(ds["time"].values, np.arange(120.0))


def test_date_time_stamps(hour, tmp_path):
    time, norm, _ = hour
    stamps = pd.Timestamp("2001-11-17 15:00:00") + pd.to_timedelta(time - time[0], unit="s")
    frame = _frame(time, norm)
    frame["time"] = stamps.strftime("%Y-%m-%dT%H:%M:%S")
    path = tmp_path / "stamped.csv"
    frame.to_csv(path, index=False, float_format="%.17g")
    ds = read_csv(path)
    np.testing.assert_array_equal(ds["time"].values, time - time[0])
    assert ds.attrs["time_origin"].startswith("2001-11-17T15:00:00")


def _write_mat73(path, variables):
    """A MATLAB v7.3 file: HDF5 with MATLAB's 512-byte header; vectors stored as (1, n)."""
    import h5py

    with h5py.File(path, "w", userblock_size=512) as f:
        for name, values in variables.items():
            f.create_dataset(name, data=np.asarray(values)[None, :])
            f[name].attrs["MATLAB_class"] = np.bytes_("double")
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Nov 19 00:00:00 2001 HDF5"
    with open(path, "r+b") as f:
        f.write(header.ljust(116) + b"\x00" * 8 + b"\x00\x02IM")


@pytest.mark.parametrize("version", ["v5", "v7.3"])
def test_mat_files(hour, tmp_path, version):
    from scipy.io import savemat

    time, norm, phys = hour
    variables = {"t": time, **{f"sig_{c}": phys[c] for c in CHANNELS}, "other": time * 0}
    path = tmp_path / f"rec_{version}.mat"
    if version == "v5":
        savemat(path, variables)
    else:
        _write_mat73(path, variables)
    columns = {"t": "time", **{f"sig_{c}": c for c in CHANNELS}}
    ds = read_recording(path, columns=columns, units="physical")
    assert ds.attrs["format"] == ("mat" if version == "v5" else "mat-v7.3")
    for c in CHANNELS:
        np.testing.assert_allclose(ds[c].values[0], norm[c], rtol=5e-16)
    assert json.loads(ds.attrs["ignored_columns"]) == ["other"]
    with pytest.raises(ValueError, match=r"no column for \['time', 'CV'"):
        read_mat(path)


def test_netcdf_variables_units_and_lazy_chunks(hour, tmp_path):
    time, norm, phys = hour
    ds = xr.Dataset(
        {c: ("time", phys[c], {"units": PHYSICAL_UNITS[c]}) for c in CHANNELS},
        coords={"time": time},
    )
    path = tmp_path / "rec.nc"
    ds.to_netcdf(path)
    with pytest.raises(ValueError, match=r"declares units '%' but CV was given as '1'"):
        read_netcdf(path)
    eager = read_netcdf(path, units="physical")
    lazy = read_netcdf(path, units="physical", chunks={"time": 50})
    assert lazy["X"].chunks is not None and lazy["X"].chunks[1] == (50, 50, 20)
    xr.testing.assert_identical(lazy.load().drop_attrs(), eager.drop_attrs())
    for c in CHANNELS:
        np.testing.assert_allclose(eager[c].values[0], norm[c], rtol=5e-16)


def test_project_format_netcdf_and_day_files(tmp_path, rng):
    from bayes_fdi.datasets import save_dataset

    hour = load_lublin_example()
    path = tmp_path / "hour.nc"
    save_dataset(hour, path)
    back = read_recording(path)
    xr.testing.assert_equal(back[list(CHANNELS)], hour[list(CHANNELS)])
    with pytest.raises(ValueError, match="normalised already"):
        read_recording(path, units="physical")

    values = rng.uniform(1.0, 99.0, (300, 33)).round(2)
    values[:, 0] = np.arange(57000, 57300)
    values[10:20, 28] = np.nan  # Act3 X: a gap
    day = tmp_path / "17112001.txt"
    day.write_text(
        "\n".join("\t".join("NaN" if np.isnan(v) else f"{v:.2f}" for v in row) for row in values)
    )
    with pytest.warns(RecordingGapWarning, match="X"):
        ds = read_recording(day, actuator=3)
    assert "state" not in ds.coords and ds.attrs["day"] == "17112001"
    assert json.loads(ds.attrs["fault_events"])  # 17 Nov: real faults on actuator 3
    np.testing.assert_allclose(ds["X"].values[0, :10], values[:10, 28] / 100.0, rtol=1e-15)
    assert read_day_file(day, actuator=1).attrs["actuator"] == 1
    with pytest.raises(ValueError, match="fixed columns and units"):
        read_recording(day, units="physical")
    with pytest.raises(ValueError, match="cannot tell the format"):
        read_recording(tmp_path / "rec.xlsx")


# ----------------------------------------------------------------------------------------------
# files that used to be read wrongly: each read against hand-written values
# ----------------------------------------------------------------------------------------------
HEADER = "time,CV,P1,P2,T1,X,F"


def _write(path, lines):
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("header", [HEADER, HEADER + ","])
def test_a_delimiter_at_the_end_of_every_line_ends_the_row(tmp_path, header):
    rows = [f"{t},0.5,0.8,0.6,0.2,{x},0.3," for t, x in [(0, 0.41), (1, 0.42), (2, 0.43)]]
    ds = read_csv(_write(tmp_path / "trailing.csv", [header, *rows]))
    np.testing.assert_array_equal(ds["time"].values, [0.0, 1.0, 2.0])
    np.testing.assert_array_equal(ds["X"].values[0], [0.41, 0.42, 0.43])
    np.testing.assert_array_equal(ds["CV"].values[0], [0.5, 0.5, 0.5])
    np.testing.assert_array_equal(ds["F"].values[0], [0.3, 0.3, 0.3])
    assert json.loads(ds.attrs["ignored_columns"]) == []


def test_unused_duplicate_columns_are_listed_not_refused(tmp_path):
    lines = [
        HEADER + ",note,note ",
        "0,0.5,0.8,0.6,0.2,0.4,0.3,a,b",
        "1,0.5,0.8,0.6,0.2,0.4,0.3,c,d",
    ]
    ds = read_csv(_write(tmp_path / "notes.csv", lines))
    assert json.loads(ds.attrs["ignored_columns"]) == ["note", "note"]


@pytest.mark.parametrize(
    "stamps, offsets",
    [  # spring forward (one hour of wall clock skipped), fall back (one hour repeated), UTC
        (["2024-03-31T01:59:58+01:00", "2024-03-31T01:59:59+01:00",
          "2024-03-31T03:00:00+02:00", "2024-03-31T03:00:01+02:00"], ["+01:00", "+02:00"]),
        (["2024-10-27T02:59:58+02:00", "2024-10-27T02:59:59+02:00",
          "2024-10-27T02:00:00+01:00", "2024-10-27T02:00:01+01:00"], ["+02:00", "+01:00"]),
        (["2024-01-10T11:00:00Z", "2024-01-10T11:00:01Z", "2024-01-10T11:00:02Z",
          "2024-01-10T11:00:03Z"], ["+00:00"]),
    ],
)  # fmt: skip
def test_date_times_with_utc_offsets_are_instants(tmp_path, stamps, offsets):
    lines = [HEADER, *(f"{s},0.5,0.8,0.6,0.2,0.{i + 1},0.3" for i, s in enumerate(stamps))]
    ds = read_csv(_write(tmp_path / "dst.csv", lines))
    np.testing.assert_array_equal(ds["time"].values, [0.0, 1.0, 2.0, 3.0])  # 1 s apart each
    np.testing.assert_array_equal(ds["X"].values[0], [0.1, 0.2, 0.3, 0.4])
    first = stamps[0].replace("Z", "+00:00")
    assert ds.attrs["time_origin"] == first  # the first instant, with the offset it was written in
    assert json.loads(ds.attrs["time_offsets"]) == offsets


def test_one_utc_offset_keeps_its_instants_and_the_offset(tmp_path):
    stamps = [f"2024-01-10T12:00:0{i}+01:00" for i in (0, 1, 2, 4)]
    lines = [HEADER, *(f"{s},0.5,0.8,0.6,0.2,0.4,0.3" for s in stamps)]
    with pytest.warns(RecordingGapWarning, match="1 s without any sample"):
        ds = read_csv(_write(tmp_path / "cet.csv", lines))
    np.testing.assert_array_equal(ds["time"].values, [0.0, 1.0, 2.0, 3.0, 4.0])
    assert np.isnan(ds["X"].values[0, 3])  # 12:00:03 is missing: a gap, nothing shifted
    assert ds.attrs["time_origin"] == "2024-01-10T12:00:00+01:00"  # not 11:00 without an offset
    assert json.loads(ds.attrs["time_offsets"]) == ["+01:00"]
    naive = read_csv(_write(tmp_path / "local.csv", [HEADER, "2024-01-10T12:00:00,1,1,1,1,1,1"]))
    assert naive.attrs["time_origin"] == "2024-01-10T12:00:00" and "time_offsets" not in naive.attrs


def test_chunks_keep_values_and_name_the_right_line(tmp_path, monkeypatch):
    from bayes_fdi.datasets import csv_columns

    monkeypatch.setattr(csv_columns, "CHUNK_ROWS", 3)  # 12 lines: four chunks
    x = [round(0.05 * (i + 1), 2) for i in range(10)]
    rows = [f"{i},0.5,0.8,0.6,0.2,{v},0.3" for i, v in enumerate(x)]
    lines = [HEADER, *rows[:4], "", *rows[4:7], "", *rows[7:]]  # empty lines 6 and 10
    ds = read_csv(_write(tmp_path / "chunked.csv", lines))
    np.testing.assert_array_equal(ds["X"].values[0], x)
    np.testing.assert_array_equal(ds["time"].values, np.arange(10.0))
    lines[12] = "9,0.5,0.8,0.6,0.2,oops,0.3"  # rows[9], line 13
    with pytest.raises(ValueError, match=r"line 13, column 'X': 'oops' is not a number"):
        read_csv(_write(tmp_path / "chunked.csv", lines))
    # chunk 1 (lines 2-4) with UTC offsets, chunk 2 (lines 5-7) without
    stamps = [f"2024-01-10T12:00:0{i}" + ("+01:00" if i < 3 else "") for i in range(6)]
    lines = [HEADER, *(f"{s},0.5,0.8,0.6,0.2,0.4,0.3" for s in stamps)]
    with pytest.raises(ValueError, match=r"line 2 \('2024-01-10T12:00:00\+01:00'\) has a UTC "
                       r"offset but line 5 \('2024-01-10T12:00:03'\) has none"):  # fmt: skip
        read_csv(_write(tmp_path / "mixed.csv", lines))


def test_a_long_real_gap_is_kept(tmp_path):
    """Spans up to a day are never refused; longer ones only where one jump makes them."""
    row = "0.5,0.8,0.6,0.2,0.4,0.3"
    lines = [HEADER, *(f"{t},{row}" for t in [0, 1, 2, 80_000, 80_001])]
    with pytest.warns(RecordingGapWarning, match="79997 s without any sample"):
        ds = read_csv(_write(tmp_path / "night.csv", lines))
    assert ds.sizes["time"] == 80_002
    # two stretches of 20000 s, 180000 s apart: a span of 5.5x the samples, kept
    lines = [HEADER, *(f"{t},{row}" for t in [*range(20_000), *range(200_000, 220_000)])]
    with pytest.warns(RecordingGapWarning, match="180000 s without any sample"):
        assert read_csv(_write(tmp_path / "two.csv", lines)).sizes["time"] == 220_000
    # two stretches of 10000 s, 190000 s apart: 21x the samples, refused
    lines = [HEADER, *(f"{t},{row}" for t in [*range(10_000), *range(200_000, 210_000)])]
    with pytest.raises(
        ValueError, match=r"sample 10001 \(line 10002, time 200000\) is 190001 s \(2\.2 days\) "
        r"away from sample 10000 \(line 10001, time 9999\): the 20000 samples would span "
        r"209999 s on the 1-s grid, over 10 times the 20000 s they cover"
    ):  # fmt: skip
        read_csv(_write(tmp_path / "far.csv", lines))


def test_units_check_names_likely_units_and_can_be_turned_off(tmp_path):
    from bayes_fdi.datasets.units import check_plausible_units, likely_units

    lines = [HEADER, *(f"{i},50,3500,2600,43,61,17" for i in range(5))]
    path = _write(tmp_path / "physical.csv", lines)
    as_is = read_csv(path, check_units=False)  # the values as they are: X = 61 x full stroke
    np.testing.assert_array_equal(as_is["X"].values[0], [61.0] * 5)
    assert likely_units(as_is, "normalised") == {
        "CV": ["%"], "P1": ["kPa"], "P2": ["kPa", "Pa"], "T1": ["degC"], "X": ["%"],
        "F": ["t/h", "kg/s"],
    }  # fmt: skip
    ds = read_csv(path, units="physical")
    np.testing.assert_allclose(ds["X"].values[0], [0.61] * 5, rtol=1e-15)
    np.testing.assert_allclose(ds["P1"].values[0], [0.875] * 5, rtol=1e-15)
    assert check_plausible_units(ds, "physical") == PHYSICAL_UNITS
    real = load_lublin_example()  # a real hour passes as it is
    assert check_plausible_units(real, "normalised") == dict.fromkeys(CHANNELS, "1")

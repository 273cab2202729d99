"""Catalogue of bad recordings: each gets a clear error naming the problem, nothing read wrongly.

As in ``test_bad_inputs.py``, every entry states the call, the error class and a pattern its
message must match: the file's line and value, the column, or the likely units. Real files are
written and read (no mocks). A full disk is a real tmpfs of 1 MB, mounted where the test may.
"""

from __future__ import annotations

import errno
import os
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pytest
import xarray as xr

from bayes_fdi.datasets import CHANNELS, make_dataset, save_dataset
from bayes_fdi.datasets.readers import read_recording
from bayes_fdi.memory import InsufficientMemoryError

HEADER = "time,CV,P1,P2,T1,X,F"
ROW = "0.5,0.8,0.6,0.2,0.5,0.4"  # CV .. F, normalised


class Case(NamedTuple):
    call: Callable[[Path], Any]
    error: type[BaseException]
    match: str


def _csv(tmp: Path, lines: list[str], name: str = "rec.csv") -> Path:
    path = tmp / name
    path.write_text("\n".join(lines) + "\n")
    return path


def _read(lines: list[str], **kwargs: Any) -> Callable[[Path], Any]:
    return lambda t: read_recording(_csv(t, lines), **kwargs)


def _seconds(times: list[float]) -> list[str]:
    return [HEADER, *(f"{t!r},{ROW}" for t in times)]


def _sparse_terabyte(tmp: Path) -> Any:
    """A valid start, then zeros up to 1 TiB: its size alone exceeds any memory.

    101 lines in 2711 bytes: 2^40 / 2711 x 101 = 4.1e10 rows of 7 numbers, x 8 B x 3 copies.
    """
    path = _csv(tmp, _seconds(list(range(100))), "huge.csv")
    os.truncate(path, 1 << 40)  # sparse: no disk space used
    return read_recording(path)


def _many_far_stretches() -> list[str]:
    """100 stretches of 3 s, 10^9 s apart: no single jump, but a grid of 9.9e10 s x 8 x 8 B."""
    return _seconds([k * 1e9 + i for k in range(100) for i in range(3)])


def _lazy_netcdf(tmp: Path) -> Any:
    physical = {"CV": 50.0, "P1": 3500.0, "P2": 2600.0, "T1": 43.0, "X": 61.0, "F": 17.0}
    ds = xr.Dataset(
        {c: ("time", np.full(10, physical[c])) for c in CHANNELS},
        coords={"time": np.arange(10.0)},
    )
    ds.to_netcdf(tmp / "rec.nc")
    return read_recording(tmp / "rec.nc", chunks={"time": 5})


PHYSICAL_ROWS = [HEADER, *(f"{i},50,3500,2600,43,61,17" for i in range(5))]
BAR_ROWS = [HEADER, *(f"{i},50,35,26,43,61,17" for i in range(5))]
KG_PER_HOUR_ROWS = [HEADER, *(f"{i},50,3500,2600,43,61,17000" for i in range(5))]

READER_CASES: dict[str, Case] = {
    "csv: the last of 600 timestamps mistyped 1e8": Case(
        _read(_seconds([*range(599), 1e8])),
        ValueError,
        r"sample 600 \(line 601, time 100000000\) is 9\.99994e\+07 s \(1\.16e\+03 days\) away "
        r"from sample 599 \(line 600, time 598\): the 600 samples would span 1e\+08 s .*"
        r"A mistyped timestamp\?",
    ),
    "csv: the first timestamp mistyped 0 among epoch seconds": Case(
        _read(_seconds([0, *(1.7e9 + i for i in range(599))])),
        ValueError,
        r"sample 1 \(line 2, time 0\) is 1\.7e\+09 s .* away from sample 2 \(line 3, "
        r"time 1700000000\)",
    ),
    "csv: a grid of 1e11 s from far stretches": Case(
        _read(_many_far_stretches()),
        InsufficientMemoryError,
        r"rec\.csv: 9\.9e\+10 s on the 1-s grid x 6 channels needs about 6\.34 TB of memory, "
        r"more than the .* available: split the recording",
    ),
    "csv: a file larger than the memory": Case(
        _sparse_terabyte,
        InsufficientMemoryError,
        r"reading .*huge\.csv \(about 4\.1e\+10 rows\) needs about 7\.86 TB of memory, more "
        r"than the .* available: split the recording",
    ),
    "csv: two X columns": Case(
        _read([HEADER + ",X", *(f"{i},{ROW},0.9" for i in range(3))]),
        ValueError,
        r"column 'X' appears 2 times \(columns 6 and 8\): which one holds X is ambiguous",
    ),
    "csv: X and 'X '": Case(
        _read([HEADER + ",X ", *(f"{i},{ROW},0.9" for i in range(3))]),
        ValueError,
        r"columns 'X' and 'X ' \(columns 6 and 8\) differ only by spaces around the name",
    ),
    "csv: a value beyond the named columns": Case(
        _read([HEADER, *(f"{i},{ROW},9" for i in range(3))]),
        ValueError,
        r"line 2 has 8 fields but the header names 7 columns; the last field '9' has no column "
        r"name \(every column would shift by one\)",
    ),
    "csv: a trailing delimiter, and a value there on line 4": Case(
        _read([HEADER, f"0,{ROW},", f"1,{ROW},", f"2,{ROW},9"]),
        ValueError,
        r"line 4 holds '9' in column 8, which has no name in the header",
    ),
    "csv: fewer fields than the header on the first line": Case(
        _read([HEADER, "0,0.5,0.8", f"1,{ROW}"]),
        ValueError,
        r"line 2 has 3 fields but the header names 7 columns",
    ),
    "csv: date-times with and without UTC offsets": Case(
        _read([HEADER, f"2024-01-10T12:00:00,{ROW}", f"2024-01-10T12:00:01+01:00,{ROW}"]),
        ValueError,
        r"line 3 \('2024-01-10T12:00:01\+01:00'\) has a UTC offset but line 2 "
        r"\('2024-01-10T12:00:00'\) has none",
    ),
    "csv: a time that is no date-time": Case(
        _read([HEADER, f"2024-01-10T12:00:00,{ROW}", f"yesterday,{ROW}"]),
        ValueError,
        r"line 3: 'yesterday' is neither seconds nor an ISO date-time",
    ),
    "csv: physical values without units": Case(
        _read(PHYSICAL_ROWS),
        ValueError,
        r"X from 61 to 61 \(1st to 99th percentile\) in '1' is 61 to 61 x DABLib's range: "
        r"likely '%'.*Declare the units, e\.g\. units='physical' \(command line: --units "
        r"physical\), or pass check_units=False",
    ),
    "csv: pressures in bar declared as kPa": Case(
        _read(BAR_ROWS, units="physical"),
        ValueError,
        r"P1 from 35 to 35 \(1st to 99th percentile\) in 'kPa' is 0\.00875 to 0\.00875 x "
        r"DABLib's range: likely 'bar'; P2 from 26 to 26 .* likely 'bar'\. Declare the units, "
        r"e\.g\. units='CV=%,P1=bar,P2=bar,T1=degC,X=%,F=t/h'",
    ),
    "csv: a flow in kg/h": Case(
        _read(KG_PER_HOUR_ROWS, units="physical"),
        ValueError,
        r"F from 1\.7e\+04 to 1\.7e\+04 .* no known unit fits \(known: '1', 't/h', 'kg/s'\)\. "
        r"Convert F to a known unit",
    ),
    "netcdf (lazy): physical values without units": Case(
        _lazy_netcdf, ValueError, r"rec\.nc: values implausible .* X from 61 to 61 .* likely '%'"
    ),
}


def test_the_catalogue_covers_the_readers():
    assert len(READER_CASES) >= 15


@pytest.mark.parametrize("name", list(READER_CASES))
def test_bad_recording(name, tmp_path):
    case = READER_CASES[name]
    with pytest.raises(case.error, match=case.match):
        case.call(tmp_path)


@pytest.fixture
def tiny_disk(tmp_path):
    """A real file system of 1 MB (tmpfs), mounted for the test and unmounted after it."""
    mount = tmp_path / "tiny"
    mount.mkdir()
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mount)],
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        pytest.skip(f"cannot mount a 1 MB tmpfs here (needs root): {done.stderr.strip()}")
    try:
        yield mount
    finally:
        # lazily: HDF5 keeps the failed file's descriptor (emptied, deleted) until the process ends
        subprocess.run(["umount", "--lazy", str(mount)], check=True)


def test_a_full_disk_is_named_and_leaves_nothing(tiny_disk):
    rng = np.random.default_rng(20261124)
    ds = make_dataset({c: rng.uniform(0, 1, (4, 100_000)) for c in CHANNELS})  # 19 MB, random
    before = os.statvfs(tiny_disk)
    with pytest.raises(OSError, match=r"No space left on device: .* free after writing part") as e:
        save_dataset(ds, tiny_disk / "out.nc")
    assert e.value.errno == errno.ENOSPC and e.value.filename == str(tiny_disk / "out.nc")
    assert os.listdir(tiny_disk) == []  # no partial file, no temporary file
    after = os.statvfs(tiny_disk)
    assert after.f_bfree == before.f_bfree  # the failed file's blocks came back
    small = make_dataset({c: np.full((1, 10), 0.5) for c in CHANNELS})
    save_dataset(small, tiny_disk / "small.nc")  # the disk is usable again
    assert os.listdir(tiny_disk) == ["small.nc"]

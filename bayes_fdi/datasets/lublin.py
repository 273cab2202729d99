"""Real actuator data from the Lublin Sugar Factory (DAMADICS benchmark).

Two sources are supported:

- :func:`load_lublin_example` — the one real, fault-free hour of Actuator 3 (boiler feed-water level
  loop LC74_20, 11 Oct 2001) that ships with DABLib; it is packaged with ``bayes_fdi``.
- :func:`load_lublin_day` — one day file ``DDMM2001.txt`` of the full 25-day benchmark set
  (86 400 rows × 33 tab-separated columns, ``NaN`` for gaps), for any of the three actuators.
  The day files are not distributed with ``bayes_fdi``.

Both return a one-run dataset in the project's format (see :mod:`bayes_fdi.datasets`), with the
signals divided by the ranges listed in :data:`ACTUATOR_RANGES`. Real values are never clipped or
altered: a value outside the nominal range gives a normalised value outside ``[0, 1]``, and a gap
stays ``NaN``. Gaps are reported (:func:`find_gaps`, the ``gaps`` attribute and a
:class:`LublinGapWarning`), never filled.

The 19 faults injected on purpose into the real plant are listed in :data:`LUBLIN_FAULT_EVENTS`;
:func:`lublin_fault_labels` turns them into a per-second label vector for one day and actuator.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
import re
import warnings
from collections.abc import Mapping, Sequence
from importlib import resources
from typing import NamedTuple

import numpy as np
import xarray as xr

from bayes_fdi.datasets.format import CHANNELS, make_dataset

__all__ = [
    "ACTUATOR_COLUMNS",
    "ACTUATOR_RANGES",
    "DAY_COLUMNS",
    "EXAMPLE_SHA256",
    "LUBLIN_FAULT_EVENTS",
    "Gap",
    "LublinFaultEvent",
    "LublinGapWarning",
    "find_gaps",
    "load_lublin_day",
    "load_lublin_example",
    "lublin_fault_labels",
]

#: File name of the packaged real hour (in ``bayes_fdi/data``).
EXAMPLE_FILE = "OneHourTestData_ExampleII.mat"
#: sha256 of the packaged real hour, checked on every load.
EXAMPLE_SHA256 = "b26450f9772731fa68b3a6ad75c9a63b5bb2b820b5d0b7b4954aa8660595752d"
#: Rows of the example matrix holding each channel (row 0 is time in s).
_EXAMPLE_ROWS = {"P1": 1, "P2": 2, "T1": 3, "F": 4, "CV": 5, "X": 6}

#: The 33 columns of a day file ``DDMM2001.txt`` (1-based column ``i`` is ``DAY_COLUMNS[i - 1]``),
#: from the data description of the benchmark (v02Mar2002).
DAY_COLUMNS: tuple[str, ...] = (
    "time",
    # Actuator 1 (thin juice, level loop LC51_03) and its process
    "P51_05", "P51_06", "T51_01", "F51_01", "LC51_03CV", "LC51_03X", "LC51_03PV",
    "TC51_05", "T51_08", "D51_01", "D51_02", "F51_02", "PC51_01", "T51_06", "P51_03", "T51_07",
    # Actuator 2 (thick juice, flow loop FC57_03)
    "P57_03", "P57_04", "T57_03", "FC57_03PV", "FC57_03CV", "FC57_03X",
    # Actuator 3 (boiler feed water, level loop LC74_20) and the boiler steam
    "P74_00", "P74_01", "T74_00", "F74_00", "LC74_20CV", "LC74_20X", "LC74_20PV",
    "F74_30", "P74_30", "T74_30",
)  # fmt: skip

#: Day-file tag of each project channel, per actuator.
ACTUATOR_COLUMNS: dict[int, dict[str, str]] = {
    1: {"CV": "LC51_03CV", "P1": "P51_05", "P2": "P51_06", "T1": "T51_01", "X": "LC51_03X",
        "F": "F51_01"},
    2: {"CV": "FC57_03CV", "P1": "P57_03", "P2": "P57_04", "T1": "T57_03", "X": "FC57_03X",
        "F": "FC57_03PV"},
    3: {"CV": "LC74_20CV", "P1": "P74_00", "P2": "P74_01", "T1": "T74_00", "X": "LC74_20X",
        "F": "F74_00"},
}  # fmt: skip

#: Normalisation of each channel, per actuator: ``(divisor, unit)``; normalised = raw / divisor.
#: Pressures and flows use each actuator's own measuring range from the data description
#: (Act1 and Act2: 0–1000 kPa, Act1 flow 0–500 m³/h, Act2 flow 0–100 m³/h; Act3: 0–4000 kPa and
#: 0–40 t/h, which is also DABLib's P/4 MPa and F/40 t/h). Temperatures use DABLib's T/200 °C for
#: every actuator (all three instruments span at most 0–150 °C). CV and X are % of closing.
ACTUATOR_RANGES: dict[int, dict[str, tuple[float, str]]] = {
    1: {"CV": (100.0, "%"), "P1": (1000.0, "kPa"), "P2": (1000.0, "kPa"), "T1": (200.0, "degC"),
        "X": (100.0, "%"), "F": (500.0, "m3/h")},
    2: {"CV": (100.0, "%"), "P1": (1000.0, "kPa"), "P2": (1000.0, "kPa"), "T1": (200.0, "degC"),
        "X": (100.0, "%"), "F": (100.0, "m3/h")},
    3: {"CV": (100.0, "%"), "P1": (4000.0, "kPa"), "P2": (4000.0, "kPa"), "T1": (200.0, "degC"),
        "X": (100.0, "%"), "F": (40.0, "t/h")},
}  # fmt: skip

_DAY_NAME = re.compile(r"^(\d{2})(\d{2})(\d{4})$")
_SECONDS_PER_DAY = 86_400


class LublinFaultEvent(NamedTuple):
    """One fault injected on purpose into the real plant (benchmark data description).

    ``start`` and ``end`` are seconds from midnight, both inclusive; ``end`` is 86 399 for a fault
    that lasted to the end of the day.
    """

    date: str  #: ``"DDMM2001"``, the stem of the day file
    actuator: int
    fault: str
    start: int
    end: int
    note: str = ""


#: The 19 real fault events of the Lublin data (date, actuator, fault, start, end, note).
#: Only f16–f19 occur in the real data.
LUBLIN_FAULT_EVENTS: tuple[LublinFaultEvent, ...] = (
    LublinFaultEvent("30102001", 1, "f18", 58800, 59800),
    LublinFaultEvent("09112001", 1, "f16", 57275, 57550),
    LublinFaultEvent("09112001", 1, "f18", 58830, 58930),
    LublinFaultEvent("09112001", 1, "f18", 58520, 58625),
    LublinFaultEvent("17112001", 1, "f18", 54600, 54700),
    LublinFaultEvent("17112001", 1, "f16", 56670, 56770),
    LublinFaultEvent("20112001", 1, "f17", 37780, 38400),
    LublinFaultEvent("17112001", 2, "f17", 53780, 53794),
    LublinFaultEvent("17112001", 2, "f17", 54193, 54215),
    LublinFaultEvent("17112001", 2, "f19", 55482, 55517, "recorded flow is fault-free"),
    LublinFaultEvent("17112001", 2, "f19", 55977, 56015, "recorded flow is fault-free"),
    LublinFaultEvent("17112001", 2, "f19", 57030, 57072, "recorded flow is fault-free"),
    LublinFaultEvent("20112001", 2, "f17", 44400, _SECONDS_PER_DAY - 1, "until end of day"),
    LublinFaultEvent("30102001", 3, "f18", 57340, 57890),
    LublinFaultEvent("09112001", 3, "f16", 60650, 60700),
    LublinFaultEvent("09112001", 3, "f16", 60870, 60960),
    LublinFaultEvent("17112001", 3, "f16", 57475, 57530),
    LublinFaultEvent("17112001", 3, "f16", 57675, 57800),
    LublinFaultEvent("17112001", 3, "f19", 58150, 58325),
)


class LublinGapWarning(UserWarning):
    """Warned when a loaded real record has gaps (``NaN``); the gaps are kept, not filled."""


class Gap(NamedTuple):
    """A run of consecutive missing samples in one channel of one run."""

    channel: str
    run: int
    start: float  #: time coordinate of the first missing sample
    stop: float  #: time coordinate of the last missing sample (inclusive)
    length: int  #: number of missing samples


def find_gaps(ds: xr.Dataset, channels: Sequence[str] | None = None) -> list[Gap]:
    """List every run of consecutive ``NaN`` samples in a dataset.

    Parameters
    ----------
    ds
        A dataset in the project's format.
    channels
        Channels to inspect; default every channel present.

    Returns
    -------
    list of Gap
        Ordered by channel, run and time.
    """
    names = [c for c in CHANNELS if c in ds.data_vars] if channels is None else list(channels)
    missing = [c for c in names if c not in ds.data_vars]
    if missing:
        raise ValueError(f"dataset lacks channel(s) {missing}")
    times = ds["time"].values
    gaps: list[Gap] = []
    for name in names:
        values = np.asarray(ds[name].transpose("run", "time").values)
        for run in range(values.shape[0]):
            isnan = np.isnan(values[run]).astype(np.int8)
            edges = np.diff(np.concatenate(([0], isnan, [0])))
            starts = np.flatnonzero(edges == 1)
            stops = np.flatnonzero(edges == -1)  # exclusive
            for a, b in zip(starts, stops, strict=True):
                gaps.append(Gap(name, run, float(times[a]), float(times[b - 1]), int(b - a)))
    return gaps


def _gap_attrs(ds: xr.Dataset) -> dict[str, str]:
    gaps = find_gaps(ds)
    summary: dict[str, dict] = {}
    for name in ds.data_vars:
        spans = [[g.start, g.stop] for g in gaps if g.channel == name]
        summary[str(name)] = {
            "n_missing": int(np.isnan(ds[name].values).sum()),
            "n_gaps": len(spans),
            "spans": spans,
        }
    return {"gaps": json.dumps(summary)}


def _warn_gaps(ds: xr.Dataset, source: str) -> None:
    summary = json.loads(ds.attrs["gaps"])
    with_gaps = {k: v for k, v in summary.items() if v["n_missing"]}
    if with_gaps:
        detail = ", ".join(
            f"{k} ({v['n_missing']} samples in {v['n_gaps']} gap(s))" for k, v in with_gaps.items()
        )
        warnings.warn(
            f"{source}: gaps (NaN) kept, not filled, in channel(s) {detail}; "
            "see find_gaps(ds) or ds.attrs['gaps']",
            LublinGapWarning,
            stacklevel=3,
        )


def _example_bytes() -> bytes:
    data = resources.files("bayes_fdi").joinpath("data", EXAMPLE_FILE).read_bytes()
    digest = hashlib.sha256(data).hexdigest()
    if digest != EXAMPLE_SHA256:
        raise ValueError(
            f"packaged {EXAMPLE_FILE} is corrupt: sha256 {digest}, expected {EXAMPLE_SHA256}"
        )
    return data


def load_lublin_example() -> xr.Dataset:
    """Load the packaged real hour of Lublin Actuator 3 as a one-run dataset.

    The hour is fault-free (state ``"fn"``), sampled at 1 Hz (``time`` = 0 … 3599 s). Signals are
    normalised as DABLib does: P1, P2 kPa / 4000; T1 °C / 200; F t/h / 40; CV and X % / 100. No
    value is clipped or otherwise altered (all lie inside ``[0, 1]`` in this file).

    Returns
    -------
    xarray.Dataset
        One run, channels ``CV, P1, P2, T1, X, F``; attrs ``campaign="lublin-example"``,
        ``source``, ``actuator``, ``date``, ``units`` and ``sha256``.

    Examples
    --------
    >>> from bayes_fdi.datasets.lublin import load_lublin_example
    >>> ds = load_lublin_example()
    >>> ds.sizes["time"], str(ds.state.values[0])
    (3600, 'fn')
    """
    from scipy.io import loadmat

    mat = loadmat(io.BytesIO(_example_bytes()))
    matrix = np.asarray(mat["OneHourTestData_ExampleII"], dtype=np.float64)
    if matrix.shape != (11, 3600):
        raise ValueError(f"{EXAMPLE_FILE}: expected an 11 x 3600 matrix, got {matrix.shape}")
    ranges = ACTUATOR_RANGES[3]
    channels = {name: matrix[_EXAMPLE_ROWS[name]] / ranges[name][0] for name in CHANNELS}
    ds = make_dataset(
        channels,
        state="fn",
        campaign="lublin-example",
        attrs={
            "source": (
                "Lublin Sugar Factory, real process data shipped with DABLib v1.22 "
                f"({EXAMPLE_FILE}, Bartys & Syfert, WUT 2002)"
            ),
            "actuator": 3,
            "loop": "LC74_20 boiler feed-water level",
            "date": "2001-10-11",
            "units": _units_attr(3),
            "sha256": EXAMPLE_SHA256,
        },
    )
    ds = ds.assign_coords(time=matrix[0])
    ds.attrs.update(_gap_attrs(ds))
    return ds


def _units_attr(actuator: int, ranges: Mapping[str, tuple[float, str]] | None = None) -> str:
    ranges = ACTUATOR_RANGES[actuator] if ranges is None else ranges
    return "; ".join(f"{k} = raw / {v[0]:g} {v[1]}" for k, v in ranges.items())


def _parse_day_text(text: str, source: str) -> np.ndarray:
    """Parse a day file's text into a float array (n_rows, 33); errors name line and column."""
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines:
        raise ValueError(f"{source}: the file is empty")
    n_cols = len(DAY_COLUMNS)
    rows = [line.rstrip(" \t\r") for line in lines]
    for i, line in enumerate(rows):
        n = line.count("\t") + 1
        if n != n_cols:
            raise ValueError(
                f"{source}: line {i + 1} has {n} tab-separated column(s), expected {n_cols}"
            )
    try:
        import pandas as pd

        frame = pd.read_csv(
            io.StringIO("\n".join(rows)),
            sep="\t",
            header=None,
            dtype=np.float64,
            na_values=["NaN", "nan"],
            keep_default_na=False,
            skip_blank_lines=False,
            engine="c",
        )
        values = frame.to_numpy(dtype=np.float64)
        if values.shape != (len(rows), n_cols):
            raise ValueError("shape")  # fall through to the exact scan below
    except (ValueError, TypeError):
        values = None
    bad = None if values is None else np.argwhere(np.isinf(values))
    if values is not None and not len(bad):
        return values
    # Slow exact parse: locate the first offending cell (or parse what pandas refused).
    out = np.empty((len(rows), n_cols))
    for i, line in enumerate(rows):
        for j, field in enumerate(line.split("\t")):
            token = field.strip()
            try:
                value = float(token)
            except ValueError:
                value = None
            if value is None or math.isinf(value):
                raise ValueError(
                    f"{source}: line {i + 1}, column {j + 1} ({DAY_COLUMNS[j]}): "
                    f"{token!r} is not a number (gaps must be written NaN)"
                )
            out[i, j] = value
    return out


def load_lublin_day(
    path: str | os.PathLike,
    actuator: int = 3,
    *,
    ranges: Mapping[str, tuple[float, str]] | None = None,
    warn: bool = True,
) -> xr.Dataset:
    """Load one day file ``DDMM2001.txt`` of the Lublin benchmark for one actuator.

    Parameters
    ----------
    path
        A tab-separated text file with 33 columns per line (column 1 = seconds from midnight, then
        the signals of :data:`DAY_COLUMNS`) and ``NaN`` for missing samples. A full day has 86 400
        lines; shorter files (any contiguous stretch of seconds) load the same way.
    actuator
        1, 2 or 3; picks the columns of :data:`ACTUATOR_COLUMNS`.
    ranges
        Override of the normalisation ``{channel: (divisor, unit)}``; default
        :data:`ACTUATOR_RANGES` ``[actuator]``.
    warn
        Emit a :class:`LublinGapWarning` naming the channels with gaps.

    Returns
    -------
    xarray.Dataset
        One run (state ``"fn"``; see :data:`LUBLIN_FAULT_EVENTS` and :func:`lublin_fault_labels`
        for the real faults of that day) with channels ``CV, P1, P2, T1, X, F`` divided by the
        ranges; ``time`` holds the seconds from midnight of column 1. Gaps stay ``NaN``. Attrs:
        ``campaign="lublin-day"``, ``source``, ``actuator``, ``day`` (``"DDMM2001"`` when the file
        name has that form, else ``""``), ``date`` (the same day as ``"2001-MM-DD"``),
        ``units``, ``gaps`` (JSON: per channel ``n_missing``, ``n_gaps`` and inclusive ``spans``
        in seconds) and ``fault_events`` (JSON list of that day's real fault events of this
        actuator).

    Raises
    ------
    ValueError
        For an unknown actuator, a line without 33 columns, a non-numeric or infinite value (the
        message names line and column), or a time column that does not advance by 1 s.
    """
    if actuator not in ACTUATOR_COLUMNS:
        raise ValueError(f"actuator must be 1, 2 or 3, got {actuator!r}")
    source = os.fspath(path)
    with open(source, encoding="latin-1") as handle:
        text = handle.read()
    values = _parse_day_text(text, source)
    time = values[:, 0]
    known = np.flatnonzero(~np.isnan(time))
    if not len(known):
        raise ValueError(f"{source}: column 1 (time) has no value")
    first = time[known[0]] - known[0]
    expected = first + np.arange(len(time))
    wrong = known[time[known] != expected[known]]
    if len(wrong):
        i = int(wrong[0])
        raise ValueError(
            f"{source}: line {i + 1}, column 1 (time): {time[i]:g} s, expected {expected[i]:g} s "
            "(rows must be consecutive seconds)"
        )
    if first < 0 or expected[-1] >= _SECONDS_PER_DAY:
        raise ValueError(
            f"{source}: column 1 (time) spans {first:g}..{expected[-1]:g} s, outside one day "
            f"(0..{_SECONDS_PER_DAY - 1})"
        )
    ranges = dict(ACTUATOR_RANGES[actuator] if ranges is None else ranges)
    missing = [c for c in CHANNELS if c not in ranges]
    if missing:
        raise ValueError(f"ranges lacks channel(s) {missing}")
    columns = ACTUATOR_COLUMNS[actuator]
    channels = {}
    for name in CHANNELS:
        divisor = float(ranges[name][0])
        if not np.isfinite(divisor) or divisor <= 0:
            raise ValueError(f"ranges[{name!r}] divisor must be > 0, got {divisor}")
        channels[name] = values[:, DAY_COLUMNS.index(columns[name])] / divisor
    stem = os.path.splitext(os.path.basename(source))[0]
    day = stem if _DAY_NAME.match(stem) else ""
    events = [e._asdict() for e in LUBLIN_FAULT_EVENTS if e.date == day and e.actuator == actuator]
    ds = _make_real(channels, source, actuator, day, ranges, events)
    ds = ds.assign_coords(time=expected.astype(np.float64))
    ds.attrs.update(_gap_attrs(ds))
    if warn:
        _warn_gaps(ds, source)
    return ds


def _make_real(channels, source, actuator, day, ranges, events) -> xr.Dataset:
    return make_dataset(
        channels,
        state="fn",
        campaign="lublin-day",
        attrs={
            "source": f"Lublin Sugar Factory benchmark day file {os.path.basename(source)}",
            "actuator": int(actuator),
            "date": f"{day[4:]}-{day[2:4]}-{day[:2]}" if day else "",
            "day": day,
            "units": _units_attr(actuator, ranges),
            "fault_events": json.dumps(events),
        },
        allow_nan=True,
    )


def lublin_fault_labels(date: str, actuator: int, times: np.ndarray | None = None) -> np.ndarray:
    """Per-second state labels of one real day and actuator from :data:`LUBLIN_FAULT_EVENTS`.

    Parameters
    ----------
    date
        ``"DDMM2001"`` (the day file's stem).
    actuator
        1, 2 or 3.
    times
        Seconds from midnight to label (default the whole day, 0 … 86 399).

    Returns
    -------
    numpy.ndarray of str
        ``"fn"`` outside the injected faults, the fault name (``"f16"`` … ``"f19"``) inside.
    """
    if actuator not in ACTUATOR_COLUMNS:
        raise ValueError(f"actuator must be 1, 2 or 3, got {actuator!r}")
    if not _DAY_NAME.match(date):
        raise ValueError(f"date must be 'DDMM2001' (8 digits), got {date!r}")
    t = np.arange(_SECONDS_PER_DAY) if times is None else np.asarray(times)
    labels = np.full(t.shape, "fn", dtype="<U3")
    for e in LUBLIN_FAULT_EVENTS:
        if e.date == date and e.actuator == actuator:
            labels[(t >= e.start) & (t <= e.end)] = e.fault
    return labels

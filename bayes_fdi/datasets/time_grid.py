"""The model's 1-s time grid: a recording's time column in seconds, resampling, and its gaps.

The rules (which seconds a resampled value averages or interpolates, what becomes a gap) are those
of the readers, in the "Sampling" paragraph of `bayes_fdi.datasets.readers`, which use this
module: `to_seconds` converts a time column or coordinate (seconds, date-times or durations),
`parse_date_times` reads ISO date-times (with or without UTC offsets), `to_second_grid` puts the
samples on whole seconds, `gap_summary` lists each channel's NaN spans and `warn_gaps` reports them
with a `RecordingGapWarning`.

Before the grid is allocated, `to_second_grid` refuses a time span that one jump makes far longer
than the samples suggest (a mistyped timestamp: :data:`MAX_SPAN_RATIO`) and checks the grid's
memory against the memory available (`check_recording_memory`).

Date-times with UTC offsets are instants: they are converted to UTC, so that seconds between them
are exact across a daylight-saving switch (``+01:00`` then ``+02:00``); the first timestamp (with
its offset) is the origin, and the offsets met are kept for the record. Date-times without offsets
are taken as they are written (local time: a daylight-saving switch shows as a gap or as time
going back, which is refused); a column mixing both is refused.
"""

from __future__ import annotations

import datetime
import math
import re
import warnings
from collections.abc import Callable, Mapping
from typing import Any, NamedTuple

import numpy as np

from bayes_fdi.datasets.format import CHANNELS
from bayes_fdi.memory import InsufficientMemoryError, available_memory, format_bytes

__all__ = [
    "MAX_SPAN_RATIO",
    "MIN_REFUSED_SPAN",
    "RESAMPLE_METHODS",
    "TIME_TOLERANCE",
    "DateTimes",
    "RecordingGapWarning",
    "check_recording_memory",
    "date_time_origin",
    "gap_summary",
    "parse_date_times",
    "to_second_grid",
    "to_seconds",
    "warn_gaps",
]

RESAMPLE_METHODS: tuple[str, ...] = ("mean", "linear")
#: Timestamps closer than this to the 1-s grid (s) are taken as on it.
TIME_TOLERANCE = 1e-6
#: A recording whose time span exceeds this many times what its samples cover (samples x the
#: median step, at least 1 s) is refused where a single jump makes most of the span: one
#: mistyped timestamp (``1e8`` at the end of a 600-row file) would otherwise make a grid of
#: 10^8 seconds (gigabytes, then hours of BLIND diagnosis).
MAX_SPAN_RATIO = 10.0
#: Spans up to this (s, one day) are never refused: short files keep their gaps as they are.
MIN_REFUSED_SPAN = 86400.0
#: The UTC offset at the end of an ISO date-time (after the time of day).
_OFFSET = re.compile(r"\d:\d{2}(?::\d{2}(?:[.,]\d*)?)?\s*(Z|[+-]\d{2}(?::?\d{2})?)$")


class RecordingGapWarning(UserWarning):
    """A recording has gaps (NaN or missing seconds); they are kept, and come out BLIND."""


class DateTimes(NamedTuple):
    """ISO date-times read from text: instants and the UTC offsets they were written with."""

    #: ``datetime64[ns]``: UTC where the text has offsets, as written where it has none.
    instants: np.ndarray
    #: The distinct UTC offsets (``"+01:00"``) in order of appearance; empty without offsets.
    offsets: tuple[str, ...]


def _offset_text(found: str) -> str:
    """``Z``, ``+01``, ``+0100`` or ``+01:00`` as ``+HH:MM``."""
    if found == "Z":
        return "+00:00"
    digits = found[1:].replace(":", "")
    return f"{found[0]}{digits[:2]}:{digits[2:4] or '00'}"


def parse_date_times(
    text: Any, source: str, label: Callable[[int], str] | None = None
) -> DateTimes:
    """ISO date-times (text) as instants; refuses text that is no date-time and mixed offsets.

    Parameters
    ----------
    text
        The time column's cells.
    source
        The file, for messages.
    label
        Sample index -> its name in messages (default ``"sample N"``).
    """
    import pandas as pd

    name = label or (lambda i: f"sample {i + 1}")
    cells = pd.Series(np.asarray(text, dtype=object)).astype(str).str.strip()
    found = cells.str.extract(_OFFSET, expand=False)
    with_offset = found.notna().to_numpy()
    if with_offset.any() and not with_offset.all():
        a, b = int(np.flatnonzero(with_offset)[0]), int(np.flatnonzero(~with_offset)[0])
        raise ValueError(
            f"{source}: {name(a)} ({cells.iloc[a]!r}) has a UTC offset but {name(b)} "
            f"({cells.iloc[b]!r}) has none; write every timestamp with its offset, or none"
        )
    aware = bool(with_offset.any())
    stamps = pd.to_datetime(cells, format="ISO8601", utc=aware, errors="coerce")
    if stamps.isna().any():
        row = int(np.flatnonzero(stamps.isna().to_numpy())[0])
        raise ValueError(
            f"{source}: {name(row)}: {cells.iloc[row]!r} is neither seconds nor an ISO "
            "date-time (e.g. 2024-03-31T02:59:59+01:00)"
        )
    if aware:
        stamps = stamps.dt.tz_localize(None)  # UTC, as naive instants
        offsets = tuple(dict.fromkeys(_offset_text(f) for f in found.drop_duplicates()))
    else:
        offsets = ()
    return DateTimes(stamps.to_numpy().astype("datetime64[ns]"), offsets)


def date_time_origin(first: np.datetime64, offset: str = "") -> str:
    """ISO text of the first instant: as written, with ``offset`` (``"+01:00"``) where given."""
    import pandas as pd

    stamp = pd.Timestamp(first)
    if not offset:
        return stamp.isoformat()
    sign = -1 if offset[0] == "-" else 1
    delta = datetime.timedelta(hours=int(offset[1:3]), minutes=int(offset[4:6]))
    return stamp.tz_localize("UTC").tz_convert(datetime.timezone(sign * delta)).isoformat()


def to_seconds(time: Any, source: str) -> tuple[np.ndarray, str]:
    """Seconds (float) of a time column or coordinate, and the ISO origin for date-times.

    Text is read by :func:`parse_date_times`: with UTC offsets, the origin keeps the first
    timestamp's offset.
    """
    t = np.asarray(time)
    if np.issubdtype(t.dtype, np.datetime64):
        origin = t[0]
        seconds = (t - origin) / np.timedelta64(1, "ns") * 1e-9
        return seconds.astype(np.float64), date_time_origin(origin)
    if np.issubdtype(t.dtype, np.timedelta64):
        return (t / np.timedelta64(1, "ns") * 1e-9).astype(np.float64), ""
    if t.dtype.kind in "OUS":
        parsed = parse_date_times(t, source)
        seconds, _ = to_seconds(parsed.instants, source)
        offset = parsed.offsets[0] if parsed.offsets else ""
        return seconds, date_time_origin(parsed.instants[0], offset)
    try:
        return t.astype(np.float64), ""
    except (TypeError, ValueError):
        raise ValueError(f"{source}: the time column is not numeric") from None


def _check_span(time: np.ndarray, typical: float, source: str, name: Callable[[int], str]) -> None:
    """Refuse a span that one jump makes :data:`MAX_SPAN_RATIO` times what the samples cover."""
    n = time.size
    span = float(time[-1] - time[0])
    covered = n * max(typical, 1.0)
    if n < 2 or span <= MIN_REFUSED_SPAN or span <= MAX_SPAN_RATIO * covered:
        return
    step = np.diff(time)
    jump = int(np.argmax(step))
    if step[jump] < 0.5 * span:
        return  # many gaps, none dominant: the memory check decides
    suspect, other = (0, 1) if jump == 0 else (jump + 1, jump)
    raise ValueError(
        f"{source}: {name(suspect)} is {step[jump]:.6g} s ({step[jump] / 86400:.3g} days) "
        f"away from {name(other)}: the {n} samples would span {span:.6g} s on the 1-s grid, "
        f"over {MAX_SPAN_RATIO:g} times the {covered:.6g} s they cover. A mistyped "
        "timestamp? (For a recording with so long a gap, write one file per stretch.)"
    )


def check_recording_memory(n_bytes: float, what: str) -> None:
    """Raise `InsufficientMemoryError` if reading a recording needs more than is available.

    As `bayes_fdi.memory.check_memory`, with advice for recordings: shorter files, or netCDF
    read lazily.
    """
    available = available_memory()
    if available is not None and n_bytes > available:
        raise InsufficientMemoryError(
            f"{what} needs about {format_bytes(n_bytes)} of memory, more than the "
            f"{format_bytes(available)} available: split the recording into shorter files, or "
            "write it as netCDF on the 1-s grid and read it lazily (chunks=)"
        )


def _check_grid_memory(n_seconds: float, n_channels: int, source: str) -> None:
    """The grid's channels, its time and the temporaries of the gap summary must fit."""
    check_recording_memory(
        n_seconds * 8.0 * (n_channels + 2),
        f"{source}: {n_seconds:.6g} s on the 1-s grid x {n_channels} channels",
    )


def to_second_grid(
    time: np.ndarray,
    channels: dict[str, np.ndarray],
    resample: str | None,
    source: str,
    label: Callable[[int], str] | None = None,
    copy: bool = True,
) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, Any]]:
    """Put the samples on the 1-s grid; returns time, channels, info.

    The rules are the "Sampling" paragraph of `bayes_fdi.datasets.readers`. ``label`` names
    sample ``i`` in messages (default ``"sample N (T s)"``; a CSV reader adds the line).
    ``copy=False`` returns the channels themselves where they are on the grid already, without
    a missing second (a reader that owns them saves a copy); else every channel is new.

    Raises
    ------
    ValueError
        If time is not finite or does not increase, or one jump makes the span over
        :data:`MAX_SPAN_RATIO` times what the samples cover (naming the sample and its time).
    bayes_fdi.memory.InsufficientMemoryError
        If the grid would not fit in the memory available (checked before allocating it).
    """
    if resample is not None and resample not in RESAMPLE_METHODS:
        raise ValueError(f"resample must be None or one of {RESAMPLE_METHODS}, got {resample!r}")
    name = label or (lambda i: f"sample {i + 1} ({time[i]:g} s)")
    n = time.size
    if n == 0:
        raise ValueError(f"{source}: the recording has no samples")
    if not np.all(np.isfinite(time)):
        row = int(np.flatnonzero(~np.isfinite(time))[0])
        raise ValueError(f"{source}: time of {name(row)} is missing or not finite")
    if n > 1:
        step = np.diff(time)
        if np.any(step <= 0):
            row = int(np.flatnonzero(step <= 0)[0])
            raise ValueError(
                f"{source}: time must increase; {name(row + 1)} does not come after {name(row)}"
            )
        typical = float(np.median(step))
    else:
        typical = 1.0
    _check_span(time, typical, source, name)
    _check_grid_memory(float(time[-1] - time[0]) + 1.0, len(channels), source)
    on_grid = n == 1 or (
        abs(typical - 1.0) <= TIME_TOLERANCE
        and np.all(np.abs(np.diff(time) - np.round(np.diff(time))) <= TIME_TOLERANCE)
    )
    info: dict[str, Any] = {"sampling_step": typical, "resampled": "no"}
    if on_grid:
        offsets = np.round(time - time[0]).astype(np.int64)
        grid = time[0] + np.arange(offsets[-1] + 1, dtype=np.float64)
        out = {}
        for name, values in channels.items():
            if grid.size == n and not copy:
                out[name] = values
                continue
            full = np.full(grid.size, np.nan)
            full[offsets] = values
            out[name] = full
        info["missing_seconds"] = int(grid.size - n)
        return grid, out, info
    if resample is None:
        raise ValueError(
            f"{source}: sampled every {typical:g} s ({1 / typical:g} Hz); the model runs at 1 Hz. "
            "Ask for resampling explicitly: resample='mean' (average each second, for faster "
            "recordings) or 'linear' (interpolate, for slower ones); on the command line "
            "--resample mean|linear"
        )
    if resample == "mean":  # every sample falls in a second: the edge seconds may be partial
        start, stop = math.floor(time[0] + 0.5), math.floor(time[-1] + 0.5)
    else:  # interpolation only between samples: never beyond the first and the last
        start = math.ceil(time[0] - TIME_TOLERANCE)
        stop = math.floor(time[-1] + TIME_TOLERANCE)
    grid = np.arange(start, stop + 1, dtype=np.float64)
    out = {}
    if resample == "mean":
        # second k holds the samples with k - 0.5 <= t < k + 0.5
        which = np.floor(time - start + 0.5).astype(np.int64)
        keep = (which >= 0) & (which < grid.size)
        counts = np.bincount(which[keep], minlength=grid.size)
        for name, values in channels.items():
            v = values[keep]
            nan = np.bincount(which[keep], weights=np.isnan(v), minlength=grid.size)
            total = np.bincount(which[keep], weights=np.nan_to_num(v), minlength=grid.size)
            with np.errstate(invalid="ignore", divide="ignore"):
                mean = total / counts
            out[name] = np.where((counts > 0) & (nan == 0), mean, np.nan)
    else:
        right = np.searchsorted(time, grid, side="left").clip(1, n - 1)
        left = right - 1
        exact = np.isclose(time[right], grid, rtol=0, atol=TIME_TOLERANCE)
        left = np.where(exact, right, left)
        close = (time[right] - time[left]) <= 2 * typical + TIME_TOLERANCE
        span = np.where(right > left, time[right] - time[left], 1.0)
        w = np.where(right > left, (grid - time[left]) / span, 0.0)
        for name, values in channels.items():
            value = (1 - w) * values[left] + w * values[right]
            out[name] = np.where(close, value, np.nan)
    info["resampled"] = resample
    return grid, out, info


def gap_summary(time: np.ndarray, channels: Mapping[str, np.ndarray]) -> dict[str, dict]:
    """Per channel: its NaN seconds, its number of gaps and their ``[first, last]`` times."""
    summary = {}
    for name in CHANNELS:
        isnan = np.isnan(channels[name]).astype(np.int8)
        edges = np.diff(np.concatenate(([0], isnan, [0])))
        starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        spans = [[float(time[a]), float(time[b - 1])] for a, b in zip(starts, stops, strict=True)]
        summary[name] = {"n_missing": int(isnan.sum()), "n_gaps": len(spans), "spans": spans}
    return summary


def warn_gaps(gaps: Mapping[str, dict], missing_seconds: int, source: str) -> None:
    """A `RecordingGapWarning` naming the channels with gaps (none when there are none)."""
    with_gaps = {k: v for k, v in gaps.items() if v["n_missing"]}
    if with_gaps:
        detail = ", ".join(
            f"{k} ({v['n_missing']} s in {v['n_gaps']} gap(s))" for k, v in with_gaps.items()
        )
        extra = f"; {missing_seconds} s without any sample" if missing_seconds else ""
        warnings.warn(
            f"{source}: gaps kept as NaN (diagnosed BLIND) in {detail}{extra}",
            RecordingGapWarning,
            stacklevel=3,
        )

"""The model's 1-s time grid: a recording's time column in seconds, resampling, and its gaps.

The rules (which seconds a resampled value averages or interpolates, what becomes a gap) are those
of the readers, in the "Sampling" paragraph of `bayes_fdi.datasets.readers`, which use this
module: `to_seconds` converts a time column or coordinate (seconds, date-times or durations),
`to_second_grid` puts the samples on whole seconds, `gap_summary` lists each channel's NaN spans
and `warn_gaps` reports them with a `RecordingGapWarning`.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np

from bayes_fdi.datasets.format import CHANNELS

__all__ = [
    "RESAMPLE_METHODS",
    "TIME_TOLERANCE",
    "RecordingGapWarning",
    "gap_summary",
    "to_second_grid",
    "to_seconds",
    "warn_gaps",
]

RESAMPLE_METHODS: tuple[str, ...] = ("mean", "linear")
#: Timestamps closer than this to the 1-s grid (s) are taken as on it.
TIME_TOLERANCE = 1e-6


class RecordingGapWarning(UserWarning):
    """A recording has gaps (NaN or missing seconds); they are kept, and come out BLIND."""


def to_seconds(time: Any, source: str) -> tuple[np.ndarray, str]:
    """Seconds (float) of a time column or coordinate, and the ISO origin for date-times."""
    t = np.asarray(time)
    if np.issubdtype(t.dtype, np.datetime64):
        origin = t[0]
        seconds = (t - origin) / np.timedelta64(1, "ns") * 1e-9
        import pandas as pd

        return seconds.astype(np.float64), pd.Timestamp(origin).isoformat()
    if np.issubdtype(t.dtype, np.timedelta64):
        return (t / np.timedelta64(1, "ns") * 1e-9).astype(np.float64), ""
    if t.dtype.kind in "OUS":
        import pandas as pd

        try:
            stamps = pd.to_datetime(pd.Series(t), format="ISO8601").to_numpy()
        except (ValueError, TypeError) as exc:
            raise ValueError(
                f"{source}: the time column is neither seconds nor date-times ({exc})"
            ) from None
        return to_seconds(stamps.astype("datetime64[ns]"), source)
    try:
        return t.astype(np.float64), ""
    except (TypeError, ValueError):
        raise ValueError(f"{source}: the time column is not numeric") from None


def to_second_grid(
    time: np.ndarray, channels: dict[str, np.ndarray], resample: str | None, source: str
) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, Any]]:
    """Put the samples on the 1-s grid; returns time, channels, info.

    The rules are the "Sampling" paragraph of `bayes_fdi.datasets.readers`.
    """
    if resample is not None and resample not in RESAMPLE_METHODS:
        raise ValueError(f"resample must be None or one of {RESAMPLE_METHODS}, got {resample!r}")
    n = time.size
    if n == 0:
        raise ValueError(f"{source}: the recording has no samples")
    if not np.all(np.isfinite(time)):
        row = int(np.flatnonzero(~np.isfinite(time))[0])
        raise ValueError(f"{source}: time of sample {row + 1} is missing or not finite")
    if n > 1:
        step = np.diff(time)
        if np.any(step <= 0):
            row = int(np.flatnonzero(step <= 0)[0])
            raise ValueError(
                f"{source}: time must increase; sample {row + 2} ({time[row + 1]:g} s) does not "
                f"come after sample {row + 1} ({time[row]:g} s)"
            )
        typical = float(np.median(step))
    else:
        typical = 1.0
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

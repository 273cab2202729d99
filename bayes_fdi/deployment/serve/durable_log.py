"""The durable log of ``serve``: every second of every valve, and the stream state to resume from.

Layout under the log folder::

    journal/000000000042.parquet        one part per commit (every second by default): the
                                        rows of every valve since the last commit, and each
                                        valve's checkpoint (its stream state after its last row)
    VALVE/2024-05-01/1714521600-1714522199.nc
                                        the valve's segments of the current day (netCDF)
    VALVE/VALVE_2024-04-30.nc           one file per valve and closed day (netCDF)

Every file is written whole or not at all (`bayes_fdi.atomic.atomic_path`: a temporary file,
``fsync``, rename). A commit is one journal part, so a ``kill -9`` loses at most the rows not
yet committed. Every ``segment_seconds`` the journal is split into per-valve segments (then its
parts are removed); when a valve's records reach a new UTC day, the previous day's segments are
merged into its daily file (then removed). A crash between two of these steps leaves rows in
two places; `recover` finishes the step at start and the readers drop repeated seconds.

The netCDF files are in the project's recording format along ``time`` (date-times, one row a
second): channels ``CV .. F`` (normalised), so ``bayes-fdi diagnose`` reads a day file as a
recording, and the record's columns (`bayes_fdi.deployment.serve.records.ROW_COLUMNS`). `read_log`
reads a valve's whole log back (daily files, segments and journal) as one dataset; `read_recent`
its last seconds (the live page's history after a restart).

Written by hand: the journal/segment/day layering is this project's; Parquet (pyarrow) and
netCDF (xarray) do the file formats.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import glob
import json
import os
import shutil
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
import xarray as xr

from bayes_fdi.atomic import atomic_path
from bayes_fdi.datasets import CHANNELS
from bayes_fdi.deployment.serve.records import FLOAT_COLUMNS, ROW_COLUMNS

__all__ = ["Checkpoint", "DurableLog", "read_log", "read_recent", "rows_to_dataset"]

_META_KEY = b"bayes_fdi.checkpoints"
_TEXT = ("status", "state", "reason", "note")
_FLAGS = ("DD", "FFID")


class Checkpoint(NamedTuple):
    """Where a valve's stream stands after its last logged second."""

    last_second: int
    state: str  #: `bayes_fdi.deployment.serve.records.encode_state` text
    model: str  #: fingerprint of the model file the state belongs to


def _day(second: int) -> str:
    return dt.datetime.fromtimestamp(second, dt.UTC).strftime("%Y-%m-%d")


def rows_to_dataset(
    rows: Sequence[Mapping[str, Any]], groups: Sequence[str], attrs: Mapping[str, Any] = ()
) -> xr.Dataset:
    """Rows (`bayes_fdi.deployment.serve.records`) as a dataset along ``time`` (date-times)."""
    n = len(rows)
    seconds = np.array([r["time"] for r in rows], dtype=np.int64)
    data: dict[str, Any] = {}
    for name in (*CHANNELS, *FLOAT_COLUMNS, "received", "published"):
        data[name] = ("time", np.array([r[name] for r in rows], dtype=np.float64))
    for name in _TEXT:
        data[name] = ("time", np.array([str(r[name]) for r in rows], dtype=object))
    for name in _FLAGS:
        data[name] = ("time", np.array([bool(r[name]) for r in rows], dtype=bool))
    proba = np.full((n, len(groups)), np.nan)
    for i, r in enumerate(rows):
        p = np.asarray(r["group_proba"], dtype=np.float64)
        if p.size == len(groups):
            proba[i] = p
    data["group_proba"] = (("time", "group"), proba)
    ds = xr.Dataset(
        data,
        coords={
            "time": seconds.astype("datetime64[s]").astype("datetime64[ns]"),
            "group": np.asarray(list(groups), dtype=object),
        },
        attrs=dict(attrs),
    )
    for c in CHANNELS:
        ds[c].attrs["units"] = "1"  # normalised (the diagnoser's units)
    ds["received"].attrs["units"] = ds["published"].attrs["units"] = "Unix s (wall clock)"
    return ds


def _write_netcdf(ds: xr.Dataset, path: str) -> None:
    os.makedirs(os.path.dirname(path), exist_ok=True)
    encoding = {"time": {"units": "seconds since 1970-01-01", "dtype": "int64"}}
    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp, engine="netcdf4", encoding=encoding)


def _open(path: str) -> xr.Dataset:
    with xr.open_dataset(path, engine="netcdf4") as ds:
        return ds.load()


def _checkpoint_attrs(cp: Checkpoint | None) -> dict[str, Any]:
    if cp is None:
        return {}
    return {"checkpoint": json.dumps(cp._asdict())}


def _checkpoint_of(attrs: Mapping[str, Any]) -> Checkpoint | None:
    text = attrs.get("checkpoint")
    return None if text is None else Checkpoint(**json.loads(text))


class DurableLog:
    """The log folder of one ``serve`` process (see the module docstring).

    Parameters
    ----------
    folder
        The log folder (created).
    groups
        Valve -> labels of its model's isolability groups (the ``group_proba`` columns).
    segment_seconds
        Journal commits between two splits of the journal into segments.
    """

    def __init__(self, folder: str, groups: Mapping[str, Sequence[str]], segment_seconds: int):
        self.folder = os.path.abspath(folder)
        self.groups = {v: tuple(g) for v, g in groups.items()}
        self.segment_seconds = int(segment_seconds)
        self.journal = os.path.join(self.folder, "journal")
        os.makedirs(self.journal, exist_ok=True)
        self._parts = sorted(glob.glob(os.path.join(self.journal, "*.parquet")))
        last = os.path.basename(self._parts[-1]) if self._parts else "-1.parquet"
        self._next_part = int(last.split(".")[0]) + 1
        self._commits = 0

    # ------------------------------------------------------------------ writing
    def commit(
        self, rows: Mapping[str, Sequence[Mapping[str, Any]]], checkpoints: Mapping[str, Checkpoint]
    ) -> str | None:
        """Write one journal part (rows of every valve, their checkpoints); returns its path."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        flat = [(valve, r) for valve, rs in rows.items() for r in rs]
        if not flat:
            return None
        columns: dict[str, Any] = {"valve": pa.array([v for v, _ in flat], pa.string())}
        for name in ROW_COLUMNS:
            values = [r[name] for _, r in flat]
            if name == "group_proba":
                columns[name] = pa.array(
                    [np.asarray(v).tolist() for v in values], pa.list_(pa.float64())
                )
            elif name in _TEXT:
                columns[name] = pa.array(values, pa.string())
            elif name in _FLAGS:
                columns[name] = pa.array(values, pa.bool_())
            elif name == "time":
                columns[name] = pa.array(values, pa.int64())
            else:
                columns[name] = pa.array(values, pa.float64())
        meta = {v: cp._asdict() for v, cp in checkpoints.items()}
        table = pa.table(columns).replace_schema_metadata({_META_KEY: json.dumps(meta)})
        path = os.path.join(self.journal, f"{self._next_part:012d}.parquet")
        with atomic_path(path) as tmp:
            pq.write_table(table, tmp, compression="zstd")
        self._next_part += 1
        self._parts.append(path)
        self._commits += 1
        if self._commits >= self.segment_seconds:
            self.flush()
        return path

    def flush(self) -> None:
        """Split the journal into per-valve segments, remove its parts, close finished days."""
        parts = list(self._parts)
        if not parts:
            return
        per_valve: dict[str, list[dict[str, Any]]] = {}
        last_cp: dict[str, tuple[int, Checkpoint]] = {}
        for path in parts:
            for valve, rows, cp in _read_part(path):
                per_valve.setdefault(valve, []).extend(rows)
                if cp is not None:
                    last_cp[valve] = (rows[-1]["time"] if rows else cp.last_second, cp)
        for valve, rows in per_valve.items():
            self._write_segments(valve, rows, last_cp.get(valve))
        for path in parts:
            with contextlib.suppress(FileNotFoundError):
                os.remove(path)
        self._parts = [p for p in self._parts if p not in parts]
        self._commits = 0
        for valve in per_valve:
            self.close_days(valve)

    def _write_segments(
        self, valve: str, rows: list[dict[str, Any]], cp: tuple[int, Checkpoint] | None
    ) -> None:
        by_day: dict[str, list[dict[str, Any]]] = {}
        for r in sorted(rows, key=lambda r: r["time"]):
            by_day.setdefault(_day(r["time"]), []).append(r)
        groups = self.groups.get(valve, ())
        for day, day_rows in by_day.items():
            first, last = day_rows[0]["time"], day_rows[-1]["time"]
            checkpoint = cp[1] if cp is not None and cp[0] == last else None
            attrs = {"valve": valve, **_checkpoint_attrs(checkpoint)}
            ds = rows_to_dataset(day_rows, groups, attrs)
            _write_netcdf(ds, os.path.join(self.folder, valve, day, f"{first}-{last}.nc"))

    def close_days(self, valve: str) -> None:
        """Merge the segments of every day before the valve's newest into its daily file."""
        base = os.path.join(self.folder, valve)
        days = sorted(d for d in os.listdir(base) if os.path.isdir(os.path.join(base, d)))
        for day in days[:-1]:
            folder = os.path.join(base, day)
            daily = os.path.join(base, f"{valve}_{day}.nc")
            if not os.path.exists(daily):
                segments = _sorted_segments(folder)
                if segments:
                    merged = _concat([_open(p) for p in segments])
                    _write_netcdf(merged, daily)
            shutil.rmtree(folder, ignore_errors=True)

    # ------------------------------------------------------------------ reading back
    def recover(self) -> dict[str, Checkpoint]:
        """Finish what a crash interrupted; return each valve's last checkpoint."""
        for valve in self._valve_folders():
            base = os.path.join(self.folder, valve)
            for day in os.listdir(base):
                if os.path.isdir(os.path.join(base, day)) and os.path.exists(
                    os.path.join(base, f"{valve}_{day}.nc")
                ):
                    shutil.rmtree(os.path.join(base, day), ignore_errors=True)
        self.flush()
        out = {}
        for valve in self._valve_folders():
            cp = self._last_checkpoint(valve)
            if cp is not None:
                out[valve] = cp
        return out

    def _valve_folders(self) -> list[str]:
        return sorted(
            v
            for v in os.listdir(self.folder)
            if v != "journal" and os.path.isdir(os.path.join(self.folder, v))
        )

    def _last_checkpoint(self, valve: str) -> Checkpoint | None:
        base = os.path.join(self.folder, valve)
        days = sorted(d for d in os.listdir(base) if os.path.isdir(os.path.join(base, d)))
        files = _sorted_segments(os.path.join(base, days[-1])) if days else []
        files += sorted(glob.glob(os.path.join(base, f"{glob.escape(valve)}_*.nc")))
        best: Checkpoint | None = None
        for path in files:
            with xr.open_dataset(path, engine="netcdf4") as ds:
                cp = _checkpoint_of(ds.attrs)
            if cp is not None and (best is None or cp.last_second > best.last_second):
                best = cp
        return best


def _sorted_segments(folder: str) -> list[str]:
    def first(path: str) -> int:
        return int(os.path.basename(path).split("-")[0])

    return sorted(glob.glob(os.path.join(folder, "*.nc")), key=first)


def _read_part(path: str) -> list[tuple[str, list[dict[str, Any]], Checkpoint | None]]:
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    meta = json.loads(table.schema.metadata[_META_KEY])
    columns = table.to_pydict()
    valves = columns.pop("valve")
    rows_by: dict[str, list[dict[str, Any]]] = {}
    for i, valve in enumerate(valves):
        row = {name: columns[name][i] for name in ROW_COLUMNS}
        row = {k: (np.nan if v is None and k not in _TEXT else v) for k, v in row.items()}
        rows_by.setdefault(valve, []).append(row)
    out = []
    for valve in sorted(set(rows_by) | set(meta)):
        cp = Checkpoint(**meta[valve]) if valve in meta else None
        out.append((valve, rows_by.get(valve, []), cp))
    return out


def _concat(parts: Sequence[xr.Dataset]) -> xr.Dataset:
    """Datasets along time, sorted, each second once (the first copy), attrs of the last."""
    if len(parts) == 1:
        return parts[0]
    merged = xr.concat(
        list(parts),
        dim="time",
        data_vars="all",
        coords="minimal",
        compat="override",
        join="outer",
        combine_attrs="drop",
    )
    _, index = np.unique(merged["time"].values, return_index=True)
    merged = merged.isel(time=np.sort(index)).sortby("time")
    attrs = {}
    for p in parts:
        if "checkpoint" in p.attrs or not attrs:
            attrs = dict(p.attrs)
    merged.attrs = attrs
    return merged


def read_log(folder: str | os.PathLike[str], valve: str) -> xr.Dataset:
    """A valve's whole log (daily files, segments, journal) as one dataset along ``time``."""
    folder = os.path.abspath(os.fspath(folder))
    base = os.path.join(folder, valve)
    parts: list[xr.Dataset] = []
    groups: tuple[str, ...] | None = None
    if os.path.isdir(base):
        for path in sorted(glob.glob(os.path.join(base, f"{glob.escape(valve)}_*.nc"))):
            parts.append(_open(path))
        for day in sorted(d for d in os.listdir(base) if os.path.isdir(os.path.join(base, d))):
            parts += [_open(p) for p in _sorted_segments(os.path.join(base, day))]
    if parts:
        groups = tuple(str(g) for g in parts[-1]["group"].values)
    rows: list[dict[str, Any]] = []
    for path in sorted(glob.glob(os.path.join(folder, "journal", "*.parquet"))):
        with contextlib.suppress(FileNotFoundError):  # flushed meanwhile: in the segments
            for v, rs, _ in _read_part(path):
                if v == valve:
                    rows += rs
    if rows:
        if groups is None:
            groups = tuple(f"g{i}" for i in range(len(rows[0]["group_proba"])))
        parts.append(rows_to_dataset(rows, groups, {"valve": valve}))
    if not parts:
        raise FileNotFoundError(f"no log of valve {valve!r} in {folder}")
    return _concat(parts)


def read_recent(folder: str | os.PathLike[str], valve: str, seconds: int) -> xr.Dataset | None:
    """The last ``seconds`` seconds of a valve's segments and daily files, newest file first
    until they are covered (None: the valve has none). The journal is not read: call it when
    the journal is flushed (after `DurableLog.recover`, or in the log's writer thread)."""
    base = os.path.join(os.path.abspath(os.fspath(folder)), valve)
    if not os.path.isdir(base):
        return None
    days = sorted(d for d in os.listdir(base) if os.path.isdir(os.path.join(base, d)))
    files = [p for day in days for p in _sorted_segments(os.path.join(base, day))]
    files = sorted(glob.glob(os.path.join(base, f"{glob.escape(valve)}_*.nc"))) + files
    parts: list[xr.Dataset] = []
    newest: np.datetime64 | None = None
    for path in reversed(files):
        part = _open(path)
        if part.sizes["time"] == 0:
            continue
        parts.insert(0, part)
        newest = part["time"].values[-1] if newest is None else max(newest, part["time"].values[-1])
        if part["time"].values[0] <= newest - np.timedelta64(int(seconds) - 1, "s"):
            break
    if not parts:
        return None
    merged = _concat(parts)
    first = merged["time"].values[-1] - np.timedelta64(int(seconds) - 1, "s")
    return merged.sel(time=slice(first, None))

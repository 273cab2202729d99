"""Files of a diagnosed recording, written chunk by chunk: the 1 Hz stream, its alarms, its figure.

A decision stream (:meth:`bayes_fdi.diagnosis.OnlineDiagnoser.run`) may be longer than memory, so
every writer here takes it in time chunks, in order, and keeps only what the next chunk needs:

- :class:`StreamCSVWriter`: ``seva.csv``, one row per second (per run), columns
  :data:`CSV_COLUMNS` (values normalised as the recording, see the docs);
- :class:`StreamNetCDFWriter`: ``seva.nc``, the whole stream (every variable of the contract, the
  recording's six channels, the stream's attributes), appended along an unlimited ``time``;
- :class:`AlarmCollector`: the alarms (the high periods of ``DD``) with the state they were
  isolated as and its probability, across chunk boundaries;
- :class:`FigureCollector`: the stream and recording kept whole for short recordings, or reduced
  to per-bin means (DD and ``indicated``: any; status: the most severe) for long ones, so that
  `bayes_fdi.diagnosis.online.timeline.plot_timeline` draws a day or a year alike.

All files are written atomically: the long writes go to a hidden ``.NAME.XXXX.partial`` file
next to the destination, moved over it by `bayes_fdi.atomic.atomic_path` when ``close`` succeeds
(and removed by ``abort``), so a file appears complete or not at all, and an interruption (Ctrl-C)
stops the diagnosis at once rather than being deferred to the end of the recording.

Written by hand: netCDF4 appends along an unlimited dimension directly (xarray cannot append to
a netCDF file); the alarm bookkeeping is the project's.
"""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
import xarray as xr

from bayes_fdi.atomic import atomic_path

__all__ = [
    "CSV_COLUMNS",
    "FULL_FIGURE_SECONDS",
    "STATUS_SEVERITY",
    "Alarm",
    "AlarmCollector",
    "FigureCollector",
    "StreamCSVWriter",
    "StreamNetCDFWriter",
    "check_stream",
    "outside_range",
    "write_alarms",
]

#: Columns of ``seva.csv`` (a leading ``run`` column when the recording holds several runs).
CSV_COLUMNS: tuple[str, ...] = (
    "time", "status", "state", "description", "probability", "evidence", "DD", "FFID",
    "X", "X_hat", "X_hat_std", "r_X", "stat_X", "VMV_X", "VU_X",
    "F", "F_hat", "F_hat_std", "r_F", "stat_F", "VMV_F", "VU_F",
)  # fmt: skip
#: Stream variables every diagnoser must give: those of the stream of
#: :meth:`bayes_fdi.diagnosis.OnlineDiagnoser.run` (listed in ``docs/online.md``).
STREAM_VARIABLES: tuple[str, ...] = (
    "DD", "FFID", "indicated", "group_proba", "fault_proba", "state", "probability", "status",
    "X_hat", "X_hat_std", "F_hat", "F_hat_std", "r_X", "r_F", "stat_X", "stat_F",
    "VMV_X", "VU_X", "VMV_F", "VU_F",
)  # fmt: skip
#: Statuses from the most to the least severe (a reduced figure bin shows the most severe).
STATUS_SEVERITY: tuple[str, ...] = ("BLURRED", "DAZZLED", "BLIND", "CLEAR")
#: Recordings up to this many seconds are drawn and scored from the whole stream; longer ones
#: from per-bin summaries.
FULL_FIGURE_SECONDS = 2 * 86_400
#: About this many bins are drawn for a longer recording.
FIGURE_BINS = 6000
_CHANNELS = ("CV", "P1", "P2", "T1", "X", "F")
#: Values per netCDF chunk (about 8 MB of float64).
_CHUNK_VALUES = 1_000_000


def check_stream(stream: xr.Dataset, chunk: xr.Dataset) -> xr.Dataset:
    """Check that ``stream`` follows the contract for ``chunk``; returns it with dims ordered."""
    missing = [v for v in STREAM_VARIABLES if v not in stream]
    if missing:
        raise ValueError(
            f"the diagnoser's stream lacks variable(s) {missing}: a diagnoser must give every "
            "variable of OnlineDiagnoser.run's stream"
        )
    for name in ("group", "fault"):
        if name not in stream.coords:
            raise ValueError(f"the diagnoser's stream has no {name!r} coordinate")
    if "run" not in stream.dims:
        stream = stream.expand_dims(run=chunk["run"].values)
    if stream.sizes["time"] != chunk.sizes["time"] or stream.sizes["run"] != chunk.sizes["run"]:
        raise ValueError(
            f"the diagnoser returned a stream of {dict(stream.sizes)} for a chunk of "
            f"{dict(chunk.sizes)}"
        )
    order = ("run", "time", "group", "fault")
    return stream.transpose(*[d for d in order if d in stream.dims], ...)


# ----------------------------------------------------------------------------------------------
# seva.csv
# ----------------------------------------------------------------------------------------------
class _PartialFile:
    """A hidden file next to ``path`` written over a long time, then committed atomically.

    The file is filled while the recording is diagnosed (an interruption can stop that at any
    time); :meth:`commit` then moves it over ``path`` with `bayes_fdi.atomic.atomic_path`
    (flushed to disk, renamed), :meth:`discard` removes it.
    """

    def __init__(self, path: Any) -> None:
        import tempfile

        self.path = os.path.abspath(os.fspath(path))
        folder, name = os.path.split(self.path)
        fd, self.partial = tempfile.mkstemp(prefix=f".{name}.", suffix=".partial", dir=folder)
        os.close(fd)

    def commit(self) -> None:
        with atomic_path(self.path) as tmp:
            os.replace(self.partial, tmp)

    def discard(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            os.remove(self.partial)


def _describe(states: np.ndarray, detection_only: bool) -> np.ndarray:
    """`describe_state` of every entry of ``states`` (each distinct state described once)."""
    from bayes_fdi.diagnosis.seva import describe_state

    names, where = np.unique(np.asarray(states).astype(str), return_inverse=True)
    words = np.array(
        [describe_state(s, detection_only=detection_only) for s in names], dtype=object
    )
    return words[where.reshape(-1)] if names.size else np.array([], dtype=object)


class StreamCSVWriter:
    """``seva.csv``: one row per second (and run), columns :data:`CSV_COLUMNS`."""

    def __init__(self, path: Any, *, several_runs: bool, detection_only: bool = False) -> None:
        self.path = path
        self.several_runs = several_runs
        self.detection_only = detection_only
        self._file = _PartialFile(path)
        self._handle = open(self._file.partial, "w", newline="", encoding="utf-8")
        columns = ("run", *CSV_COLUMNS) if several_runs else CSV_COLUMNS
        self._handle.write(",".join(columns) + "\n")

    def append(self, stream: xr.Dataset, chunk: xr.Dataset) -> None:
        """Write the rows of one chunk (``stream`` checked by :func:`check_stream`)."""
        import pandas as pd

        n_runs, n_t = stream.sizes["run"], stream.sizes["time"]
        data: dict[str, np.ndarray] = {}
        if self.several_runs:
            data["run"] = np.repeat(stream["run"].values, n_t)
        data["time"] = np.tile(stream["time"].values, n_runs)
        for name in CSV_COLUMNS[1:]:
            if name == "description":
                data[name] = _describe(data["state"], self.detection_only)
                continue
            if name not in stream and name == "evidence":  # a diagnoser that gives none
                data[name] = np.full(n_runs * n_t, "")
                continue
            source = chunk if name in ("X", "F") else stream
            values = np.asarray(source[name].transpose("run", "time").values).reshape(-1)
            if values.dtype == bool:
                values = values.astype(np.int8)
            data[name] = values
        pd.DataFrame(data).to_csv(
            self._handle, header=False, index=False, float_format="%.9g", lineterminator="\n"
        )

    def close(self) -> None:
        """Finish the file (it appears at ``path`` only now)."""
        self._handle.close()
        self._file.commit()

    def abort(self) -> None:
        """Drop the file (nothing appears at ``path``)."""
        self._handle.close()
        self._file.discard()


# ----------------------------------------------------------------------------------------------
# seva.nc
# ----------------------------------------------------------------------------------------------
class StreamNetCDFWriter:
    """``seva.nc``: the stream and the recording's channels, appended chunk by chunk.

    Booleans are stored as ``int8`` with the attribute ``dtype = "bool"`` and text as fixed-width
    UTF-8 characters (``_Encoding``), as xarray writes them, so ``xarray.open_dataset`` reads the
    file back as the stream the diagnoser returned. Chunks hold up to an hour, and each variable's
    chunk cache a few chunks, so memory stays bounded however long the recording.
    """

    def __init__(self, path: Any, attrs: dict[str, Any] | None = None) -> None:
        self.path = path
        self.attrs = dict(attrs or {})
        self._file = _PartialFile(path)
        self._nc: Any = None
        self._written = 0

    def _create(self, stream: xr.Dataset, chunk: xr.Dataset) -> None:
        import netCDF4

        nc = netCDF4.Dataset(self._file.partial, "w", format="NETCDF4")
        nc.createDimension("run", stream.sizes["run"])
        nc.createDimension("time", None)
        for dim in ("group", "fault"):
            nc.createDimension(dim, stream.sizes[dim])
        for name in ("run", "group", "fault"):
            values = np.asarray(stream[name].values)
            var = nc.createVariable(name, str if values.dtype.kind in "OU" else values.dtype, name)
            var[:] = values.astype(object) if values.dtype.kind in "OU" else values
        time = nc.createVariable("time", "f8", ("time",))
        time.units = "s"
        # chunks of up to an hour (the default along an unlimited dimension is one value: slow
        # and large), and a chunk cache of a few chunks per variable (netCDF's default of 64 MB
        # per variable grows with every day appended)
        n_runs = stream.sizes["run"]
        t_chunk = max(1, min(stream.sizes["time"], _CHUNK_VALUES // n_runs, 3600))
        self._width = _text_width(stream)
        nc.createDimension("text", self._width)
        for name in (*STREAM_VARIABLES, *_CHANNELS):
            source = chunk if name in _CHANNELS else stream
            da = source[name].transpose("run", "time", ...)
            dims = da.dims
            extra = tuple(da.sizes[d] for d in dims[2:])
            sizes = (min(n_runs, _CHUNK_VALUES), t_chunk, *extra)
            kind = da.dtype.kind
            if kind == "b":
                var = nc.createVariable(name, "i1", dims, zlib=True, complevel=1,
                                        chunksizes=sizes)  # fmt: skip
                var.setncattr("dtype", "bool")
            elif kind in "OU":  # fixed-width UTF-8 text, as xarray writes it: bounded memory
                var = nc.createVariable(name, "S1", (*dims, "text"), zlib=True, complevel=1,
                                        chunksizes=(*sizes, self._width))  # fmt: skip
                var.setncattr("_Encoding", "utf-8")
            else:
                var = nc.createVariable(name, da.dtype, dims, zlib=True, complevel=1,
                                        fill_value=np.nan, chunksizes=sizes)  # fmt: skip
            item = 1 if kind in "bOU" else da.dtype.itemsize
            width = self._width if kind in "OU" else 1
            var.set_var_chunk_cache(size=4 * item * width * math.prod(sizes), nelems=61,
                                    preemption=0.75)  # fmt: skip
            for key, value in da.attrs.items():
                var.setncattr(key, value)
        for key, value in {**stream.attrs, **self.attrs}.items():
            nc.setncattr(key, value if not isinstance(value, bool) else int(value))
        self._nc = nc

    def append(self, stream: xr.Dataset, chunk: xr.Dataset) -> None:
        """Append one chunk along ``time``."""
        if self._nc is None:
            self._create(stream, chunk)
        nc = self._nc
        a, b = self._written, self._written + stream.sizes["time"]
        nc["time"][a:b] = np.asarray(stream["time"].values, dtype=np.float64)
        for name in (*STREAM_VARIABLES, *_CHANNELS):
            source = chunk if name in _CHANNELS else stream
            values = np.asarray(source[name].transpose("run", "time", ...).values)
            if values.dtype == bool:
                values = values.astype(np.int8)
            elif values.dtype.kind in "OU":
                values = self._chars(name, values)
            nc[name][:, a:b, ...] = values
        self._written = b

    def _chars(self, name: str, values: np.ndarray) -> np.ndarray:
        import netCDF4

        encoded = np.char.encode(values.astype(str), "utf-8")
        if encoded.dtype.itemsize > self._width:
            raise ValueError(
                f"the stream's {name} holds a label longer than its groups and faults "
                f"({encoded.dtype.itemsize} > {self._width} bytes)"
            )
        return netCDF4.stringtochar(encoded.astype(f"S{self._width}"))

    def close(self) -> None:
        """Finish the file (it appears at ``path`` only now)."""
        if self._nc is not None:
            self._nc.close()
        self._file.commit()

    def abort(self) -> None:
        """Drop the file."""
        if self._nc is not None:
            with contextlib.suppress(RuntimeError, OSError):
                self._nc.close()
        self._file.discard()


def _text_width(stream: xr.Dataset) -> int:
    """Bytes of the longest label a stream can hold (statuses, groups, faults, and the plain
    answers ``mismatch``, ``unknown`` and ``fn``), whichever chunk first holds it."""
    from bayes_fdi.diagnosis.online.stream import MISMATCH

    labels = [*STATUS_SEVERITY, MISMATCH, "unknown", "fn"]
    labels += [str(g) for g in stream["group"].values] + [str(f) for f in stream["fault"].values]
    current = [str(v) for name in ("state", "status") for v in np.unique(stream[name].values)]
    return max(len(text.encode("utf-8")) for text in labels + current)


# ----------------------------------------------------------------------------------------------
# alarms
# ----------------------------------------------------------------------------------------------
class Alarm(NamedTuple):
    """One alarm: a high period of DD (``end`` inclusive)."""

    run: int
    start: float  #: first second with DD high
    end: float  #: last second with DD high
    duration: float  #: seconds with DD high (end - start + 1)
    state: str  #: the state named for the most seconds of the alarm (a fault, group or "unknown")
    description: str  #: what ``state`` means (`bayes_fdi.diagnosis.seva.describe_state`)
    probability: float  #: mean probability of ``state`` over those seconds (NaN if none given)
    evidence: str  #: the residuals that raised the alarm and their sign, named most often
    seconds_in_state: int
    first_isolated: float  #: first second naming a fault or group (NaN if never)
    ongoing: bool  #: DD still high at the end of the recording
    #: seconds of it with the inputs outside the model's envelope (the ranges it was fitted or
    #: commissioned on), where its normal models extrapolate
    seconds_outside_range: int = 0


def outside_range(stream: xr.Dataset) -> np.ndarray:
    """``(run, time)`` whether each second's inputs lay outside the model's input envelope
    (the stream's ``novel_inputs``; all False for a stream without it)."""
    if "novel_inputs" not in stream:
        return np.zeros((stream.sizes["run"], stream.sizes["time"]), dtype=bool)
    return np.asarray(stream["novel_inputs"].transpose("run", "time").values, dtype=bool)


class AlarmCollector:
    """Collect the alarms of a stream given chunk by chunk (per run), in bounded memory
    (``detection_only``: the model cannot name faults, which the descriptions say)."""

    def __init__(self, *, detection_only: bool = False) -> None:
        self.detection_only = detection_only
        self._open: dict[int, dict[str, Any]] = {}
        self.alarms: list[Alarm] = []

    def append(self, stream: xr.Dataset) -> None:
        """Add one chunk (dims ``run``, ``time``)."""
        from bayes_fdi.diagnosis.online.stream import UNNAMED_STATES  # lazy: pulls torch, numba

        times = np.asarray(stream["time"].values, dtype=np.float64)
        dd_all = np.asarray(stream["DD"].transpose("run", "time").values, dtype=bool)
        state_all = np.asarray(stream["state"].transpose("run", "time").values).astype(str)
        proba_all = np.asarray(stream["probability"].transpose("run", "time").values, dtype=float)
        if "evidence" in stream:
            evidence_all = np.asarray(stream["evidence"].transpose("run", "time").values)
        else:
            evidence_all = np.full(dd_all.shape, "", dtype=object)
        outside_all = outside_range(stream)
        for i, run in enumerate(int(r) for r in stream["run"].values):
            dd = dd_all[i]
            current = self._open.pop(run, None)
            if current is not None and not (dd.size and dd[0]):
                self._close(run, current, ongoing=False)  # it ended with the previous chunk
                current = None
            edges = np.diff(np.concatenate(([0], dd.astype(np.int8), [0])))
            starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
            for a, b in zip(starts, stops, strict=True):
                if current is None:
                    current = {"start": times[a], "states": {}, "first": math.nan, "evidence": {},
                               "outside": 0}  # fmt: skip
                current["outside"] += int(np.count_nonzero(outside_all[i, a:b]))
                said, n_said = np.unique(evidence_all[i, a:b].astype(str), return_counts=True)
                for words, k in zip(said, n_said, strict=True):
                    if words:
                        current["evidence"][words] = current["evidence"].get(words, 0) + int(k)
                names, where = np.unique(state_all[i, a:b], return_inverse=True)
                probs = proba_all[i, a:b]
                for k, name in enumerate(names):
                    mine = probs[where == k]
                    ok = mine[np.isfinite(mine)]
                    count, n_ok, total, last = current["states"].get(name, (0, 0, 0.0, -math.inf))
                    last = max(last, float(times[a + np.flatnonzero(where == k)[-1]]))
                    current["states"][name] = (count + mine.size, n_ok + ok.size,
                                               total + float(ok.sum()), last)  # fmt: skip
                named = np.flatnonzero(~np.isin(state_all[i, a:b], UNNAMED_STATES))
                if math.isnan(current["first"]) and named.size:
                    current["first"] = times[a + named[0]]
                current["end"] = times[b - 1]
                if b == dd.size:  # it may go on in the next chunk
                    self._open[run] = current
                else:
                    self._close(run, current, ongoing=False)
                current = None

    def _close(self, run: int, current: dict[str, Any], *, ongoing: bool) -> None:
        states = current["states"]
        # the state named for the most seconds; ties go to the one named last
        best = max(states, key=lambda s: (states[s][0], states[s][3]))
        count, n_ok, total, _ = states[best]
        said = current["evidence"]
        from bayes_fdi.diagnosis.seva import describe_state

        self.alarms.append(
            Alarm(
                run=run,
                start=float(current["start"]),
                end=float(current["end"]),
                duration=float(current["end"] - current["start"] + 1.0),
                state=str(best),
                description=describe_state(str(best), detection_only=self.detection_only),
                probability=total / n_ok if n_ok else math.nan,
                evidence=max(said, key=lambda w: (said[w], w)) if said else "",
                seconds_in_state=int(count),
                first_isolated=float(current["first"]),
                ongoing=ongoing,
                seconds_outside_range=int(current["outside"]),
            )
        )

    def finish(self) -> list[Alarm]:
        """Close the alarms still open (``ongoing``) and return all, by run and start."""
        for run, current in list(self._open.items()):
            self._close(run, current, ongoing=True)
        self._open.clear()
        return sorted(self.alarms, key=lambda a: (a.run, a.start))


def write_alarms(alarms: Sequence[Alarm], path: Any) -> None:
    """``alarms.csv``: one row per alarm (the fields of :class:`Alarm`)."""
    import pandas as pd

    frame = pd.DataFrame(list(alarms), columns=list(Alarm._fields))
    with atomic_path(path) as tmp:
        frame.to_csv(tmp, index=False, float_format="%.9g", lineterminator="\n")


# ----------------------------------------------------------------------------------------------
# the figure's data
# ----------------------------------------------------------------------------------------------
_FIGURE_STREAM = ("X_hat", "X_hat_std", "F_hat", "F_hat_std", "r_X", "r_F", "DD", "status",
                  "indicated", "group_proba", "state")  # fmt: skip


class FigureCollector:
    """What the timeline figure of one run needs, whole or reduced to about 6000 bins.

    Parameters
    ----------
    n_seconds
        Length of the recording (decides whole or reduced, and the bin width).
    run
        Position of the run drawn (a recording of several runs: the first by default).
    """

    def __init__(self, n_seconds: int, run: int = 0) -> None:
        self.run = run
        self.bin = 1 if n_seconds <= FULL_FIGURE_SECONDS else math.ceil(n_seconds / FIGURE_BINS)
        self._streams: list[xr.Dataset] = []
        self._recordings: list[xr.Dataset] = []
        self.attrs: dict[str, Any] = {}

    @property
    def whole(self) -> bool:
        """True when the figure is drawn from every second."""
        return self.bin == 1

    def chunk_multiple(self, chunk_seconds: int) -> int:
        """The chunk length rounded up to whole bins (bins must not straddle chunks)."""
        return math.ceil(chunk_seconds / self.bin) * self.bin

    def append(self, stream: xr.Dataset, chunk: xr.Dataset) -> None:
        """Add one chunk (the stream checked by :func:`check_stream`)."""
        self.attrs = dict(stream.attrs)
        one = stream[[v for v in _FIGURE_STREAM if v in stream]].isel(run=self.run)
        rec = chunk[list(_CHANNELS)].isel(run=self.run)
        if self.whole:
            self._streams.append(one)
            self._recordings.append(rec)
            return
        self._streams.append(self._reduce_stream(one))
        self._recordings.append(self._reduce_numeric(rec))

    def _bins(self, ds: xr.Dataset) -> np.ndarray:
        return np.arange(ds.sizes["time"]) // self.bin

    def _reduce_numeric(self, ds: xr.Dataset) -> xr.Dataset:
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # an all-NaN bin stays NaN
            out = ds.groupby(xr.DataArray(self._bins(ds), dims="time", name="bin")).mean()
        times = ds["time"].values[:: self.bin]
        return out.rename({"bin": "time"}).assign_coords(time=times)

    def _reduce_stream(self, ds: xr.Dataset) -> xr.Dataset:
        numeric = [v for v in ds.data_vars if ds[v].dtype.kind == "f"]
        out = self._reduce_numeric(ds[numeric])
        bins = xr.DataArray(self._bins(ds), dims="time", name="bin")
        times = ds["time"].values[:: self.bin]
        for name in ("DD", "indicated"):
            if name in ds:
                red = ds[name].groupby(bins).any().rename({"bin": "time"})
                out[name] = red.assign_coords(time=times)
        if "status" in ds:
            status = np.asarray(ds["status"].values).astype(str)
            rank = np.full(status.size, len(STATUS_SEVERITY), dtype=np.int64)
            for i, name in enumerate(STATUS_SEVERITY):
                rank[status == name] = i
            worst = np.full(times.size, len(STATUS_SEVERITY))
            np.minimum.at(worst, self._bins(ds), rank)
            labels = np.array([*STATUS_SEVERITY, "UNKNOWN"], dtype=object)
            out["status"] = ("time", labels[worst])
        return out

    def datasets(self) -> tuple[xr.Dataset, xr.Dataset]:
        """The stream and the recording of the drawn run (whole or per-bin)."""
        stream = xr.concat(self._streams, dim="time", data_vars="all", coords="minimal")
        recording = xr.concat(self._recordings, dim="time", data_vars="all", coords="minimal")
        stream.attrs = self.attrs
        return stream, recording

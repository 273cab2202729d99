"""Diagnosing recordings with a fitted online diagnoser: ``bayes-fdi diagnose``.

:func:`diagnose_recording` runs an online diagnoser (``run`` of ``ONLINE_CONTRACT.md``) over a
recording in time chunks and writes, in ``OUT/<name>/``:

- ``seva.csv``: one row per second (per run): time, status, state, probability, DD, FFID, the
  measured X and F, their normal-model predictions, residuals, detector statistics and SEVA
  validated values (columns `bayes_fdi.deployment.stream_files.CSV_COLUMNS`; values normalised as
  the recording);
- ``seva.nc``: the whole decision stream and the recording's channels (netCDF);
- ``alarms.csv``: one row per alarm (start, end, duration, isolated fault or group, probability);
- ``timeline.png``: the timeline figure (`bayes_fdi.diagnosis.online.timeline.plot_timeline`);
- ``events.csv``: for a Lublin day file with real faults (:data:`LUBLIN_FAULT_EVENTS`), the
  benchmark's indices (PICalc) of each real fault event;
- ``summary.json``: what was diagnosed, with what, and the counts.

Chunks: a recording longer than ``chunk_seconds`` is diagnosed chunk by chunk, the stream state
carried from one chunk to the next (``run(chunk, state=state, return_state=True) -> (stream,
state)``), so a lazily read recording longer than memory is diagnosed in bounded memory and the
files equal those of one call on the whole recording.

Many recordings: ``workers``/``scheduler`` diagnose one recording per task on a dask cluster
(`bayes_fdi.distributed`); the files are the same. The workers read the recordings
and write the results themselves, so with ``--scheduler`` both must be on a file system the
workers share.
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import time
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import xarray as xr

from bayes_fdi.cli_arguments import UsageError, input_file
from bayes_fdi.datasets import CHANNELS, validate_dataset
from bayes_fdi.deployment.stream_files import (
    AlarmCollector,
    FigureCollector,
    StreamCSVWriter,
    StreamNetCDFWriter,
    check_stream,
    write_alarms,
)

__all__ = [
    "DEFAULT_CHUNK_SECONDS",
    "EXAMPLE_NAME",
    "RecordingResult",
    "configure_parser",
    "diagnose_files",
    "diagnose_recording",
    "run_from_cli",
    "score_lublin_events",
    "supports_chunks",
]

#: Seconds per chunk (one day at 1 Hz).
DEFAULT_CHUNK_SECONDS = 86_400
#: Output name of the shipped Lublin hour (``--example``).
EXAMPLE_NAME = "lublin-example"
#: Fault-free seconds before a real fault event scored (the Step I benchmark uses 600 s).
EVENT_LEAD_SECONDS = 600
_LABELS = ("state", "strength", "onset", "profile", "ramp")


class RecordingResult(NamedTuple):
    """What :func:`diagnose_recording` wrote for one recording."""

    name: str
    folder: str
    seconds: int  #: length of the recording (s)
    runs: int
    alarms: int
    status_counts: dict
    files: tuple


def supports_chunks(diagnoser: Any) -> bool:
    """Whether ``diagnoser.run`` takes ``state`` and ``return_state`` (chunked diagnosis)."""
    try:
        params = inspect.signature(diagnoser.run).parameters
    except (TypeError, ValueError):
        return False
    return "state" in params and "return_state" in params


def _as_runs(recording: xr.Dataset) -> xr.Dataset:
    if not isinstance(recording, xr.Dataset):
        raise ValueError(f"a recording is an xarray.Dataset, got {type(recording).__name__}")
    if "time" not in recording.dims:
        raise ValueError(f"the recording has no 'time' dimension (dims {tuple(recording.dims)})")
    if "run" not in recording.dims:
        recording = recording.expand_dims(run=[0])
    missing = [c for c in CHANNELS if c not in recording.data_vars]
    if missing:
        raise ValueError(f"the recording lacks channel(s) {missing}")
    extra = [v for v in recording.data_vars if v not in CHANNELS]
    labels = [c for c in _LABELS if c in recording.coords]
    # the diagnoser sees the six channels only, never labels
    return recording.drop_vars(extra + labels).transpose("run", "time")


def diagnose_recording(
    diagnoser: Any,
    recording: xr.Dataset,
    out: str | os.PathLike,
    *,
    name: str = "recording",
    chunk_seconds: int = DEFAULT_CHUNK_SECONDS,
    figure: bool = True,
    progress: bool = False,
    model_info: Mapping[str, Any] | None = None,
) -> RecordingResult:
    """Diagnose one recording and write its files in ``out/name`` (see the module docstring).

    Parameters
    ----------
    diagnoser
        A fitted online diagnoser (``run(recording)``; chunked also ``state``/``return_state``).
    recording
        Dims ``time`` (and ``run``), channels ``CV, P1, P2, T1, X, F`` normalised (e.g. from
        `bayes_fdi.datasets.read_recording`); may be lazy (dask), read chunk by chunk.
    out
        Output folder; the files go to ``out/name`` (created).
    name
        Sub-folder name (the recording's file stem).
    chunk_seconds
        Seconds diagnosed per call (memory bound).
    figure
        Draw ``timeline.png``.
    progress
        A progress bar over the recording's seconds.
    model_info
        Recorded in ``summary.json`` (e.g. the model file).

    Returns
    -------
    RecordingResult
    """
    if isinstance(chunk_seconds, bool) or not isinstance(chunk_seconds, int) or chunk_seconds < 1:
        raise ValueError(f"chunk_seconds must be a positive integer, got {chunk_seconds!r}")
    attrs = dict(recording.attrs)
    recording = _as_runs(recording)
    n_runs, n_t = recording.sizes["run"], recording.sizes["time"]
    if n_t == 0:
        raise ValueError(f"{name}: the recording has no samples")
    collector = FigureCollector(n_t)
    chunk = collector.chunk_multiple(chunk_seconds)
    chunked = n_t > chunk
    if chunked and not supports_chunks(diagnoser):
        raise ValueError(
            f"{name}: {n_t} s is longer than one chunk ({chunk} s) and {type(diagnoser).__name__}"
            ".run cannot carry its state across chunks; give a larger chunk_seconds"
        )
    folder = Path(out) / name
    folder.mkdir(parents=True, exist_ok=True)
    csv = StreamCSVWriter(folder / "seva.csv", several_runs=n_runs > 1)
    nc = StreamNetCDFWriter(folder / "seva.nc", attrs={"recording": name})
    alarms = AlarmCollector()
    counts: dict[str, int] = {}
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=n_t, desc=f"diagnosing {name}", unit="s", leave=False)
    state = None
    try:
        for a in range(0, n_t, chunk):
            part = recording.isel(time=slice(a, a + chunk)).load()
            validate_dataset(part, require=CHANNELS, allow_nan=True)
            if chunked:
                stream, state = diagnoser.run(part, state=state, return_state=True)
            else:
                stream = diagnoser.run(part)
            stream = check_stream(stream, part)
            csv.append(stream, part)
            nc.append(stream, part)
            alarms.append(stream)
            collector.append(stream, part)
            status, n = np.unique(
                np.asarray(stream["status"].values).astype(str), return_counts=True
            )
            for s, k in zip(status, n, strict=True):
                counts[str(s)] = counts.get(str(s), 0) + int(k)
            if bar is not None:
                bar.update(part.sizes["time"])
    except BaseException:
        csv.abort()
        nc.abort()
        raise
    finally:
        if bar is not None:
            bar.close()
    csv.close()
    nc.close()
    found = alarms.finish()
    write_alarms(found, folder / "alarms.csv")
    files = ["seva.csv", "seva.nc", "alarms.csv"]
    stream_one, recording_one = collector.datasets()
    if figure:
        _figure(stream_one, recording_one, folder / "timeline.png", name, collector)
        files.append("timeline.png")
    summary: dict[str, Any] = {
        "recording": name,
        "source": attrs.get("source", ""),
        "seconds": int(n_t),
        "runs": int(n_runs),
        "start": float(recording["time"].values[0]),
        "end": float(recording["time"].values[-1]),
        "status_counts": counts,
        "alarms": len(found),
        "alarm_seconds": float(sum(al.duration for al in found)),
        "model": dict(model_info or {}),
        "recording_attrs": {k: _json_value(v) for k, v in attrs.items()},
    }
    events = _events(attrs)
    if events and collector.whole and n_runs == 1:
        scored = score_lublin_events(stream_one, events)
        _write_events(scored, folder / "events.csv")
        files.append("events.csv")
        summary["lublin_events"] = _event_summary(stream_one, events, scored)
    files.append("summary.json")
    summary["files"] = files
    _write_json(summary, folder / "summary.json")
    return RecordingResult(name, os.fspath(folder), int(n_t), int(n_runs), len(found), counts,
                           tuple(files))  # fmt: skip


def _json_value(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value


def _write_json(data: Mapping[str, Any], path: Path) -> None:
    from bayes_fdi.atomic import atomic_path

    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as handle:
        json.dump(data, handle, indent=2, allow_nan=True)
        handle.write("\n")


def _figure(stream: xr.Dataset, recording: xr.Dataset, path: Path, name: str, collector) -> None:
    from bayes_fdi.diagnosis.online.timeline import plot_timeline

    title = name if collector.whole else f"{name} (means over {collector.bin} s)"
    plot_timeline(stream, recording, path=path, title=title)


# ----------------------------------------------------------------------------------------------
# the real Lublin fault events
# ----------------------------------------------------------------------------------------------
def _events(attrs: Mapping[str, Any]) -> list[dict[str, Any]]:
    text = attrs.get("fault_events")
    if not text:
        return []
    try:
        events = json.loads(text)
    except (TypeError, ValueError):
        return []
    return [e for e in events if isinstance(e, dict) and {"fault", "start", "end"} <= set(e)]


def score_lublin_events(
    stream: xr.Dataset, events: Sequence[Mapping[str, Any]]
) -> list[dict[str, Any]]:
    """The benchmark's indices of each real fault event in a day's stream (one run).

    Each event is scored by :func:`~bayes_fdi.scoring.picalc.picalc` over the
    zone ``[t_on, t_hor)``: ``t_from`` = the event's start, ``t_hor`` = one second after its end
    (Step III's zones are user-entered; the fault ends there), ``t_on`` = ``EVENT_LEAD_SECONDS``
    before the start, later if the recording or the previous event (of any fault) ends later.
    An event the stream does not cover is listed with ``covered = False`` and no indices.
    """
    from bayes_fdi.benchmark.harness import decision_signals
    from bayes_fdi.scoring.picalc import PICALC_KEYS, picalc

    t = np.asarray(stream["time"].values, dtype=np.float64)
    ordered = sorted(events, key=lambda e: (float(e["start"]), float(e["end"])))
    out = []
    for k, event in enumerate(ordered):
        start, end = float(event["start"]), float(event["end"])
        previous_end = max((float(e["end"]) for e in ordered[:k]), default=-np.inf)
        t_on = max(start - EVENT_LEAD_SECONDS, t[0], previous_end + 1)
        t_hor = end + 1
        row: dict[str, Any] = {
            "fault": event["fault"], "start": start, "end": end, "actuator": event.get("actuator"),
            "date": event.get("date"), "note": event.get("note", ""), "t_on": t_on,
            "covered": bool(t[0] <= t_on < start < t_hor <= t[-1] + 1),
        }  # fmt: skip
        if row["covered"]:
            signals = decision_signals(stream, str(event["fault"]))
            indices = picalc(t, signals.dd, signals.pid, signals.cid, t_on=t_on, t_from=start,
                             t_hor=t_hor, indicated=signals.indicated,
                             group_sizes=signals.group_sizes)  # fmt: skip
            row.update(indices)
            inside = (t >= start) & (t < t_hor)
            named = np.asarray(stream["state"].values).astype(str)[inside & signals.dd]
            values, n = np.unique(named, return_counts=True)
            row["isolated_as"] = str(values[np.argmax(n)]) if n.size else ""
        else:
            row.update(dict.fromkeys(PICALC_KEYS, np.nan))
            row["isolated_as"] = ""
        out.append(row)
    return out


def _write_events(rows: Sequence[Mapping[str, Any]], path: Path) -> None:
    import pandas as pd

    from bayes_fdi.atomic import atomic_path

    with atomic_path(path) as tmp:
        pd.DataFrame(list(rows)).to_csv(tmp, index=False, float_format="%.6g", lineterminator="\n")


def _event_summary(stream: xr.Dataset, events, scored) -> dict[str, Any]:
    """False-alarm share outside the events and how many events were detected."""
    t = np.asarray(stream["time"].values, dtype=np.float64)
    dd = np.asarray(stream["DD"].values, dtype=bool)
    faulty = np.zeros(t.size, dtype=bool)
    for e in events:
        faulty |= (t >= float(e["start"])) & (t <= float(e["end"]))
    covered = [r for r in scored if r["covered"]]
    return {
        "events": len(scored),
        "covered": len(covered),
        "detected": sum(1 for r in covered if r["t_dt"] >= 0),
        "isolated": sum(1 for r in covered if r["t_it"] >= 0),
        "dd_share_outside_events": float(dd[~faulty].mean()) if (~faulty).any() else np.nan,
    }


# ----------------------------------------------------------------------------------------------
# many recordings
# ----------------------------------------------------------------------------------------------
class _Job(NamedTuple):
    """One recording to diagnose (a task; everything a worker needs)."""

    diagnoser: Any
    path: str | None  #: None: the shipped Lublin hour
    name: str
    out: str
    reading: dict
    chunk_seconds: int
    figure: bool
    progress: bool
    model_info: dict


def _read(path: str | None, reading: Mapping[str, Any], chunk_seconds: int) -> xr.Dataset:
    from bayes_fdi.datasets import load_lublin_example
    from bayes_fdi.datasets.readers import FORMATS, read_recording

    if path is None:
        return load_lublin_example()
    options = {k: v for k, v in reading.items() if v is not None}
    fmt = FORMATS.get(os.path.splitext(path)[1].lower())
    if fmt == "netcdf" and _has_dask() and options.get("resample") is None:
        options["chunks"] = {"time": chunk_seconds}  # lazy: read chunk by chunk
    if fmt != "day":
        options.pop("actuator", None)
    if fmt == "netcdf":
        options.pop("rate", None)
    return read_recording(path, **options)


def _has_dask() -> bool:
    try:
        import dask  # noqa: F401
    except ImportError:
        return False
    return True


def _diagnose_job(job: _Job) -> RecordingResult:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # gaps are reported in the files, not as warnings
        recording = _read(job.path, job.reading, job.chunk_seconds)
    return diagnose_recording(job.diagnoser, recording, job.out, name=job.name,
                              chunk_seconds=job.chunk_seconds, figure=job.figure,
                              progress=job.progress, model_info=job.model_info)  # fmt: skip


def diagnose_files(
    diagnoser: Any,
    paths: Sequence[str | None],
    out: str | os.PathLike,
    *,
    reading: Mapping[str, Any] | None = None,
    chunk_seconds: int = DEFAULT_CHUNK_SECONDS,
    figure: bool = True,
    progress: bool = True,
    workers: int | None = None,
    scheduler: str | None = None,
    model_info: Mapping[str, Any] | None = None,
) -> list[RecordingResult]:
    """Diagnose recording files (``None``: the shipped Lublin hour), one task per recording.

    ``reading`` holds the reader's options (`bayes_fdi.datasets.readers.read_recording`);
    netCDF recordings are read lazily in chunks when dask is installed.
    """
    from bayes_fdi.distributed import run_tasks

    names = [EXAMPLE_NAME if p is None else Path(p).stem for p in paths]
    seen: dict[str, str] = {}
    for name, path in zip(names, paths, strict=True):
        if name in seen:
            raise UsageError(
                f"two recordings would write to the same folder {name!r}: {seen[name]} and {path}"
            )
        seen[name] = str(path)
    serial = workers is None and scheduler is None
    reading = dict(reading or {})
    info = dict(model_info or {})
    jobs = []
    for p, name in zip(paths, names, strict=True):
        path = None if p is None else os.fspath(p)
        jobs.append(_Job(diagnoser, path, name, os.fspath(out), reading, chunk_seconds, figure,
                         progress and serial, info))  # fmt: skip
    return run_tasks(_diagnose_job, jobs, workers=workers, scheduler=scheduler,
                     progress=progress and len(jobs) > 1, desc="recordings",
                     unit="recording")  # fmt: skip


# ----------------------------------------------------------------------------------------------
# command line
# ----------------------------------------------------------------------------------------------
def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``bayes-fdi diagnose``."""
    from bayes_fdi.cli_arguments import output_folder, positive_int
    from bayes_fdi.deployment.fitting import add_reading_arguments
    from bayes_fdi.distributed import add_cluster_arguments

    parser.add_argument(
        "recordings",
        nargs="*",
        type=input_file,
        metavar="RECORDING",
        help="recordings to diagnose: .csv/.tsv, .mat, .nc, or Lublin day files DDMM2001.txt",
    )
    parser.add_argument(
        "--example",
        action="store_true",
        help=f"also diagnose the real Lublin hour shipped with bayes_fdi (as '{EXAMPLE_NAME}')",
    )
    parser.add_argument(
        "--out", required=True, type=output_folder, help="output folder (one sub-folder each)"
    )
    parser.add_argument(
        "--model",
        type=input_file,
        default=None,
        help="model file written by bayes-fdi fit (default: the default model, fitted on "
        "first use and cached)",
    )
    parser.add_argument(
        "--chunk-seconds",
        type=positive_int,
        default=DEFAULT_CHUNK_SECONDS,
        help=f"seconds diagnosed at a time (memory bound; default {DEFAULT_CHUNK_SECONDS})",
    )
    parser.add_argument("--no-figure", action="store_true", help="do not draw timeline.png")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    add_reading_arguments(parser)
    add_cluster_arguments(parser)


def run_from_cli(args: argparse.Namespace) -> int:
    """Run ``bayes-fdi diagnose``."""
    from bayes_fdi.deployment.fitting import (
        default_model,
        default_model_path,
        load_online_model,
        reading_options,
    )

    paths: list[str | None] = list(args.recordings)
    if args.example:
        paths.append(None)
    if not paths:
        raise UsageError("give one or more recordings, or --example for the shipped Lublin hour")
    reading = reading_options(args)
    t0 = time.perf_counter()
    if args.model:
        diagnoser = load_online_model(args.model)
        info = {"file": os.path.abspath(args.model)}
    else:
        diagnoser = default_model(progress=not args.quiet)
        info = {"file": os.fspath(default_model_path()), "default": True}
    info["class"] = type(diagnoser).__name__
    os.makedirs(args.out, exist_ok=True)
    results = diagnose_files(diagnoser, paths, args.out, reading=reading,
                             chunk_seconds=args.chunk_seconds, figure=not args.no_figure,
                             progress=not args.quiet, workers=args.workers,
                             scheduler=args.scheduler, model_info=info)  # fmt: skip
    for r in results:
        counts = ", ".join(f"{k} {v} s" for k, v in sorted(r.status_counts.items()))
        print(f"{r.name}: {r.seconds} s, {r.alarms} alarm(s); {counts} -> {r.folder}")
    print(f"diagnosed {len(results)} recording(s) in {time.perf_counter() - t0:.1f} s")
    return 0

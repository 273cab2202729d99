"""One recording diagnosed by a fitted online diagnoser, in time chunks, into its files.

:func:`diagnose_recording` runs an online diagnoser (its ``run``, see
`bayes_fdi.diagnosis.OnlineDiagnoser.run`) over a recording in time chunks and writes, in
``OUT/<name>/``:

- ``seva.csv``: one row per second (per run): time, status, state, probability, DD, FFID, the
  measured X and F, their normal-model predictions, residuals, detector statistics and SEVA
  validated values (columns `bayes_fdi.deployment.stream_files.CSV_COLUMNS`; values normalised as
  the recording);
- ``seva.nc``: the whole decision stream and the recording's channels (netCDF);
- ``alarms.csv``: one row per alarm (start, end, duration, isolated fault or group, probability);
- ``timeline.png``: the timeline figure (`bayes_fdi.diagnosis.online.timeline.plot_timeline`);
- ``events.csv``: for a Lublin day file with real faults, the benchmark's indices (PICalc) of
  each real fault event (`bayes_fdi.deployment.lublin_events`);
- ``summary.json``: what was diagnosed, with what, and the counts.

Chunks: a recording longer than ``chunk_seconds`` is diagnosed chunk by chunk, the stream state
carried from one chunk to the next (``run(chunk, state=state, return_state=True) -> (stream,
state)``), so a lazily read recording longer than memory is diagnosed in bounded memory and the
files equal those of one call on the whole recording.
"""

from __future__ import annotations

import inspect
import json
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import xarray as xr

from bayes_fdi.atomic import atomic_folder
from bayes_fdi.datasets import CHANNELS, validate_dataset
from bayes_fdi.deployment.lublin_events import (
    event_summary,
    fault_events,
    score_lublin_events,
    write_events,
)
from bayes_fdi.deployment.stream_files import (
    AlarmCollector,
    FigureCollector,
    StreamCSVWriter,
    StreamNetCDFWriter,
    check_stream,
    outside_range,
    write_alarms,
)

__all__ = [
    "DEFAULT_CHUNK_SECONDS",
    "RecordingResult",
    "diagnose_recording",
    "isolation_summary",
    "supports_chunks",
]

#: Seconds per chunk (one day at 1 Hz).
DEFAULT_CHUNK_SECONDS = 86_400
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
    #: seconds whose inputs lay outside the model's input envelope (its normal models extrapolate)
    seconds_outside_range: int = 0


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
    attachments: Mapping[str, Callable[[Path], Any]] | None = None,
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
    attachments
        Other files of the recording's folder: name -> a function writing it to the given
        path (e.g. the model commissioned on the recording's first seconds).

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
    destination = Path(out) / name
    with atomic_folder(destination) as folder:
        for file_name, write in (attachments or {}).items():
            write(folder / file_name)
        counts, found, files, outside = _write_outputs(
            diagnoser,
            recording,
            folder,
            name,
            attrs,
            chunk,
            chunked,
            collector,
            figure,
            progress,
            model_info,
            tuple(attachments or {}),
        )
    return RecordingResult(
        name, os.fspath(destination), int(n_t), int(n_runs), len(found), counts, tuple(files),
        outside,
    )  # fmt: skip


def isolation_summary(diagnoser: Any) -> dict[str, Any]:
    """What the model can name: ``detection_only`` (no fault library), its isolability
    groups, the faults it treats as undetectable, and ``fit_proof_seconds`` (the seconds it
    must see the valve fit before it reads a detection as a fault)."""
    detection_only = getattr(diagnoser, "isolator_", True) is None
    groups = [list(g) for g in getattr(diagnoser, "groups_", ())]
    proof = int(getattr(diagnoser, "fit_proof_seconds", 0))
    named = f"faults named up to {len(groups)} isolability groups"
    if proof:
        named += (
            f", once the stream has seen this valve fit the normal models for {proof} s without "
            "an alarm (an earlier alarm is a model mismatch)"
        )
    return {
        "detection_only": bool(detection_only),
        "note": (
            "detection only: this model has no fault library, so every alarm is an unknown "
            "fault; commission the valve with faults (bayes-fdi commission) to name them"
            if detection_only
            else named
        ),
        "groups": groups,
        "undetectable": list(getattr(diagnoser, "undetectable_", ())),
        "fit_proof_seconds": proof,
    }


def _write_outputs(
    diagnoser: Any,
    recording: xr.Dataset,
    folder: Path,
    name: str,
    attrs: Mapping[str, Any],
    chunk: int,
    chunked: bool,
    collector: FigureCollector,
    figure: bool,
    progress: bool,
    model_info: Mapping[str, Any] | None,
    attached: tuple[str, ...],
) -> tuple[dict[str, int], list, list[str], int]:
    """Diagnose ``recording`` chunk by chunk into the files of ``folder``; the seconds per
    status, the alarms, the files written and the seconds outside the input envelope."""
    n_runs, n_t = recording.sizes["run"], recording.sizes["time"]
    isolation = isolation_summary(diagnoser)
    detection_only = isolation["detection_only"]
    csv = StreamCSVWriter(
        folder / "seva.csv", several_runs=n_runs > 1, detection_only=detection_only
    )
    nc = StreamNetCDFWriter(folder / "seva.nc", attrs={"recording": name})
    alarms = AlarmCollector(detection_only=detection_only)
    counts: dict[str, int] = {}
    outside = 0
    bar = None
    if progress:
        from bayes_fdi.progress import progress_bar

        bar = progress_bar(n_t, f"diagnosing {name}", unit="s", leave=False)
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
            outside += int(np.count_nonzero(outside_range(stream)))
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
        "seconds_outside_range": outside,
        "alarm_seconds_outside_range": int(sum(al.seconds_outside_range for al in found)),
        "model": dict(model_info or {}),
        "isolation": isolation,
        "recording_attrs": {k: _json_value(v) for k, v in attrs.items()},
    }
    events = fault_events(attrs)
    if events and collector.whole and n_runs == 1:
        scored = score_lublin_events(stream_one, events)
        write_events(scored, folder / "events.csv")
        files.append("events.csv")
        summary["lublin_events"] = event_summary(stream_one, events, scored)
    files += [*attached, "summary.json"]
    summary["files"] = files
    _write_json(summary, folder / "summary.json")
    return counts, found, files, outside


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

"""``bayes-fdi diagnose``: recordings diagnosed second by second with a fitted online diagnoser.

Each recording is read (`bayes_fdi.datasets.read_recording`, in declared units) and diagnosed by
`bayes_fdi.deployment.recording.diagnose_recording` into its own folder. Many recordings:
``workers``/``scheduler`` diagnose one recording per task on a dask cluster
(`bayes_fdi.distributed`); the files are the same. The workers read the recordings and write
the results themselves, so with ``--scheduler`` both must be on a file system the workers
share. Without ``--model`` the default model is used (`bayes_fdi.deployment.fitting`).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import xarray as xr

from bayes_fdi.cli_arguments import ISOLATION_CHOICES, UsageError, input_file
from bayes_fdi.deployment.recording import (
    DEFAULT_CHUNK_SECONDS,
    RecordingResult,
    diagnose_recording,
)

__all__ = ["EXAMPLE_NAME", "configure_parser", "diagnose_files", "run_from_cli"]

#: Output name of the shipped Lublin hour (``--example``).
EXAMPLE_NAME = "lublin-example"


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
    commission_seconds: int | None  #: commission on the first seconds, diagnose the rest
    isolation: str  #: the commissioned model's isolation classifier


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
    diagnoser, info, attachments = job.diagnoser, job.model_info, None
    if job.commission_seconds is not None:
        healthy, recording = split_healthy(recording, job.commission_seconds, job.name)
        done, info, attachments = commission_in_place(
            healthy, progress=job.progress, isolation=job.isolation
        )
        diagnoser = done.diagnoser
    elif job.reading.get("check_units", True):
        _check_ranges(diagnoser, recording, job.reading.get("units") or "normalised", job.name)
    return diagnose_recording(
        diagnoser,
        recording,
        job.out,
        name=job.name,
        chunk_seconds=job.chunk_seconds,
        figure=job.figure,
        progress=job.progress,
        model_info=info,
        attachments=attachments,
    )


def _check_ranges(diagnoser: Any, recording: xr.Dataset, units: Any, name: str) -> None:
    """Refuse a recording that looks declared in the wrong units for this model; say where it
    lies far outside the model's training data in every unit (`check_known_ranges`)."""
    from bayes_fdi.datasets.known_ranges import check_known_ranges

    ranges = getattr(diagnoser, "training_ranges_", None)
    if not ranges:
        return  # a model file written before the ranges were recorded
    try:
        notes = check_known_ranges(recording, ranges, units, source=name)
    except ValueError as exc:
        known = getattr(diagnoser, "training_units_", None)
        if not known:
            raise
        pairs = ",".join(f"{c}={u}" for c, u in known.items())
        hint = f"the model was fitted on recordings declared as {pairs}"
        raise ValueError(f"{exc} ({hint})") from None
    for note in notes:
        print(f"note: {note}: expect 'mismatch' (commission this valve)", file=sys.stderr)


def diagnose_example(
    out: str | os.PathLike, *, isolation: str = "tree", **options: Any
) -> list[RecordingResult]:
    """The first example: commission on the first half of the shipped Lublin hour (with the
    isolation classifier ``isolation``), diagnose the second half (``EXAMPLE_NAME``) and the
    same half with the bypass valve half opened (f18, strength 0.5) from 300 s into it,
    transplanted with the commissioned twin's parameters (``EXAMPLE_NAME-f18``). ``options``:
    those of `diagnose_recording`."""
    from bayes_fdi.actuator import Fault
    from bayes_fdi.datasets import load_lublin_example
    from bayes_fdi.twin import transplant

    hour = load_lublin_example()
    first, second = split_healthy(hour, 1800, EXAMPLE_NAME)
    done, info, attachments = commission_in_place(
        first, progress=options.get("progress", True), isolation=isolation
    )
    faulty = transplant(second, [Fault("f18", 0.5, onset=300.0)], done.twin.parameters_)
    info = {**info, "file": f"../{EXAMPLE_NAME}/model.npz"}
    return [
        diagnose_recording(
            done.diagnoser,
            second,
            out,
            name=EXAMPLE_NAME,
            model_info={**info, "file": "model.npz"},
            attachments=attachments,
            **options,
        ),
        diagnose_recording(
            done.diagnoser,
            faulty,
            out,
            name=f"{EXAMPLE_NAME}-f18",
            model_info={**info, "transplanted": "f18 0.5 from 300 s into the half"},
            **options,
        ),
    ]


def split_healthy(recording: xr.Dataset, seconds: int, name: str) -> tuple[xr.Dataset, xr.Dataset]:
    """The first ``seconds`` of a recording (declared healthy) and the rest."""
    recording = recording.load()
    t = recording["time"].values
    cut = int(np.searchsorted(t, t[0] + seconds))
    if cut >= t.size:
        raise UsageError(
            f"{name}: --commission-seconds {seconds} leaves nothing to diagnose (the recording "
            f"holds {t.size} s)"
        )
    return recording.isel(time=slice(0, cut)), recording.isel(time=slice(cut, None))


def commission_in_place(
    healthy: xr.Dataset, *, progress: bool, seed: int = 0, isolation: str = "tree"
) -> tuple:
    """Commission on ``healthy`` (with the isolation classifier ``isolation``, one of
    `~bayes_fdi.commissioning.commission.ISOLATION_CLASSIFIERS`): the diagnoser, its
    ``summary.json`` entry, and the files it adds to the recording's folder (``model.npz``,
    ``commissioning.md``, ``commissioning.json``)."""
    from bayes_fdi.commissioning import commission

    done = commission(healthy, seed=seed, progress=progress, isolation=isolation)
    return (done, *_commission_files(done))


def _commission_files(done: Any) -> tuple[dict, dict]:
    """``summary.json``'s entry of a commissioned model and the files it adds to a folder."""
    from bayes_fdi import model_files
    from bayes_fdi.atomic import write_text
    from bayes_fdi.commissioning.report import render_report
    from bayes_fdi.reporting import write_json

    info = {
        "commissioned_on_seconds": int(done.report["healthy"]["seconds"]),
        "file": "model.npz",
        "class": type(done.diagnoser).__name__,
    }
    attachments = {
        "model.npz": lambda path: model_files.save(done.diagnoser, path),
        "commissioning.md": lambda path: write_text(path, render_report(done.report)),
        "commissioning.json": lambda path: write_json(done.report, path),
    }
    return info, attachments


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
    commission_seconds: int | None = None,
    isolation: str = "tree",
) -> list[RecordingResult]:
    """Diagnose recording files (``None``: the shipped Lublin hour), one task per recording.

    ``commission_seconds``: each recording's first seconds are declared healthy, a model is
    commissioned on them (`commission_in_place`; ``diagnoser`` is then unused) and the rest is
    diagnosed with it (its isolation classifier: ``isolation``); the model and its report go
    into the recording's folder.

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
        jobs.append(
            _Job(
                diagnoser,
                path,
                name,
                os.fspath(out),
                reading,
                chunk_seconds,
                figure,
                progress and serial,
                info,
                commission_seconds,
                isolation,
            )
        )
    return run_tasks(
        _diagnose_job,
        jobs,
        workers=workers,
        scheduler=scheduler,
        progress=progress and len(jobs) > 1,
        desc="recordings",
        unit="recording",
    )


# ----------------------------------------------------------------------------------------------
# command line
# ----------------------------------------------------------------------------------------------
def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``bayes-fdi diagnose``."""
    from bayes_fdi.cli_arguments import non_negative_int, output_folder, positive_int
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
        help="the first example: commission a model on the first half of the real Lublin hour "
        f"shipped with bayes_fdi, then diagnose its second half as '{EXAMPLE_NAME}' and the same "
        f"half with a bypass opening transplanted 300 s in as '{EXAMPLE_NAME}-f18' (with "
        "--model: diagnose the whole hour with that model instead)",
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
    parser.add_argument(
        "--commission-seconds",
        type=positive_int,
        default=None,
        metavar="N",
        help="commission a model on each recording's first N seconds, which you declare "
        "healthy, and diagnose the rest with it (the model and its report are written beside "
        "the results)",
    )
    parser.add_argument(
        "--isolation",
        choices=ISOLATION_CHOICES,
        default=None,
        help="with --commission-seconds or --example: the commissioned model's isolation "
        "classifier, the k-means tree of RVCs (default) or a random forest (as bayes-fdi "
        "commission --isolation)",
    )
    parser.add_argument(
        "--fit-proof-seconds",
        type=non_negative_int,
        default=None,
        metavar="N",
        help="with the default model or --model: seconds the stream must see the model fit the "
        "valve, without detection, before it reads a detection as a fault; an earlier one is "
        "'model mismatch: commission this valve' (default: the model's own, 600 for the "
        "default model, which was trained on the simulator, 0 for a model fitted on the "
        "valve's data)",
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
    if not paths and not args.example:
        raise UsageError("give one or more recordings, or --example for the shipped Lublin hour")
    commissions = args.commission_seconds is not None or (args.example and not args.model)
    if args.isolation is not None and not commissions:
        raise UsageError(
            "--isolation chooses the classifier of a model commissioned here: it belongs to "
            "--commission-seconds or --example (without --model)"
        )
    if args.fit_proof_seconds is not None and commissions:
        raise UsageError(
            "--fit-proof-seconds sets a loaded model's proof; a model commissioned here was "
            "fitted on the valve's own data and reads every detection as a fault"
        )
    isolation = args.isolation or "tree"
    reading = reading_options(args)
    t0 = time.perf_counter()
    os.makedirs(args.out, exist_ok=True)
    common = {
        "chunk_seconds": args.chunk_seconds,
        "figure": not args.no_figure,
        "progress": not args.quiet,
    }
    results: list[RecordingResult] = []
    if args.example and not args.model:
        results += diagnose_example(args.out, isolation=isolation, **common)
    elif args.example:
        paths.append(None)
    diagnoser, info = None, {}
    if paths and args.commission_seconds is None:
        if args.model:
            diagnoser = load_online_model(args.model)
            info = {"file": os.path.abspath(args.model)}
        else:
            diagnoser = default_model(progress=not args.quiet)
            info = {"file": os.fspath(default_model_path()), "default": True}
        if args.fit_proof_seconds is not None:
            diagnoser.set_params(fit_proof_seconds=args.fit_proof_seconds)
        info["class"] = type(diagnoser).__name__
    if paths:
        results += diagnose_files(
            diagnoser,
            paths,
            args.out,
            reading=reading,
            workers=args.workers,
            scheduler=args.scheduler,
            model_info=info,
            commission_seconds=args.commission_seconds,
            isolation=isolation,
            **common,
        )
    for r in results:
        counts = ", ".join(f"{k} {v} s" for k, v in sorted(r.status_counts.items()))
        print(f"{r.name}: {r.seconds} s, {r.alarms} alarm(s); {counts} -> {r.folder}")
        if r.seconds_outside_range:
            print(
                f"  {r.seconds_outside_range} s with inputs outside the range the model was "
                "fitted or commissioned on (DAZZLED when quiet; alarms.csv counts them per "
                "alarm): there its normal models extrapolate; commission on data that cover "
                "this operating range"
            )
    print(f"diagnosed {len(results)} recording(s) in {time.perf_counter() - t0:.1f} s")
    return 0

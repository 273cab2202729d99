"""Fitting the online diagnoser for deployment: ``bayes-fdi fit`` and the cached default model.

A model file (`bayes_fdi.model_files.format`) is what ``bayes-fdi diagnose --model`` reads.
``bayes-fdi fit`` writes one from

- the default training campaigns (``--default``;
  `bayes_fdi.default_diagnoser.fit_online_diagnoser`),
- a campaign TOML file (``--campaign``): its fault-free runs fit the normal models and its faulty
  runs the isolation, or
- the user's own recordings (``--normal`` fault-free recordings, optionally ``--fault
  STATE@ONSET=FILE`` recordings of known faults), read by `bayes_fdi.datasets.readers`.

`default_model` is the model ``bayes-fdi diagnose`` uses without ``--model``: fitted from the
default campaigns on first use and cached (`bayes_fdi.deployment.model_cache` says where, and
under which name), written atomically; later calls load it. Delete the cache folder (or pass
``refit=True``, ``bayes-fdi fit --default --out PATH``) to fit again.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi import model_files
from bayes_fdi.cli_arguments import UsageError, input_file, output_file
from bayes_fdi.datasets import CHANNELS, STATES, make_dataset
from bayes_fdi.deployment.model_cache import (
    CACHE_ENV,
    DEFAULT_TRAININGS,
    SMALL_ENV,
    cache_dir,
    default_model_path,
    small_settings,
    training_fingerprint,
)

__all__ = [
    "CACHE_ENV",
    "DEFAULT_TRAININGS",
    "SMALL_ENV",
    "cache_dir",
    "configure_parser",
    "default_model",
    "default_model_path",
    "fit_from_campaign",
    "fit_from_recordings",
    "load_online_model",
    "new_online_diagnoser",
    "recordings_as_runs",
    "run_from_cli",
    "training_fingerprint",
]


def _default_fitter() -> Callable[..., Any]:
    try:
        from bayes_fdi.default_diagnoser import fit_online_diagnoser
    except ImportError as exc:
        raise RuntimeError(
            "this bayes_fdi has no online diagnoser to fit a default model "
            f"(bayes_fdi.default_diagnoser: {exc}); give --model"
        ) from None
    return fit_online_diagnoser


def new_online_diagnoser(**params: Any) -> Any:
    """An unfitted `bayes_fdi.diagnosis.OnlineDiagnoser` (``params`` as its constructor's)."""
    try:
        from bayes_fdi.diagnosis import OnlineDiagnoser
    except ImportError:
        raise RuntimeError("this bayes_fdi has no online diagnoser (OnlineDiagnoser)") from None
    return OnlineDiagnoser(**params)


def load_online_model(path: str | os.PathLike, **kwargs: Any) -> Any:
    """Read a model file and check it holds an online diagnoser (one with ``run``)."""
    model = model_files.load(path, **kwargs)
    if not callable(getattr(model, "run", None)):
        raise ValueError(
            f"{os.fspath(path)} holds a {type(model).__name__}, which diagnoses whole runs; "
            "diagnose needs an online diagnoser (write one with bayes-fdi fit)"
        )
    return model


def default_model(
    *, progress: bool = True, refit: bool = False, small: bool | None = None, seed: int = 0
) -> Any:
    """The default online diagnoser: loaded from the cache, or fitted and cached on first use.

    Parameters
    ----------
    progress
        Show the fitting's progress (the first use takes minutes).
    refit
        Fit again even if a cached model exists (and replace it).
    small
        The quick settings (default: from ``$BAYES_FDI_SMALL``), cached under another name.
    seed
        Seed of the default campaigns (a model of another seed is not cached).
    """
    small = small_settings() if small is None else small
    path = default_model_path(small=small)
    if seed == 0 and path.exists() and not refit:
        try:
            return load_online_model(path)
        except ValueError as exc:
            warnings.warn(f"cached default model unusable ({exc}); fitting it again", stacklevel=2)
    fit = _default_fitter()
    if progress:
        print(f"fitting the default model (once; cached in {path.parent})", file=sys.stderr)
    model = fit(seed=seed, small=small, progress=progress)
    if seed == 0:
        path.parent.mkdir(parents=True, exist_ok=True)
        model_files.save(model, path)
    return model


# ----------------------------------------------------------------------------------------------
# fitting from campaigns and recordings
# ----------------------------------------------------------------------------------------------
def _split_by_state(runs: xr.Dataset) -> tuple[xr.Dataset, xr.Dataset | None]:
    states = np.asarray(runs["state"].values).astype(str)
    normal = np.flatnonzero(states == "fn")
    faulty = np.flatnonzero(states != "fn")
    if normal.size == 0:
        raise ValueError("the training data hold no fault-free ('fn') run for the normal models")
    return runs.isel(run=normal), (runs.isel(run=faulty) if faulty.size else None)


def fit_from_campaign(
    campaign: Any,
    *,
    seed: int | None = None,
    progress: bool = True,
    workers: int | None = None,
    scheduler: str | None = None,
    estimator: Any = None,
) -> Any:
    """Simulate a campaign and fit an online diagnoser on it (fault-free and faulty runs).

    ``estimator`` is the unfitted diagnoser (default `new_online_diagnoser`), cloned.
    """
    from sklearn.base import clone

    from bayes_fdi.campaigns.simulation import simulate_campaign

    runs = simulate_campaign(
        campaign, seed=seed, progress=progress, workers=workers, scheduler=scheduler
    )
    normal, faulty = _split_by_state(runs)
    model = new_online_diagnoser() if estimator is None else clone(estimator)
    return model.fit(normal, faulty)


def recordings_as_runs(
    recordings: Sequence[xr.Dataset], states: Sequence[str], onsets: Sequence[float]
) -> xr.Dataset:
    """One dataset of labelled runs from one-run recordings of possibly different lengths.

    Each recording becomes a run whose ``time`` starts at 0 (its own first second); shorter runs
    end in NaN (no measurement: never used for fitting). ``onsets`` are in the recordings' own
    time; they become seconds from each run's start. The strength of a user's fault is unknown,
    so the runs have no ``strength`` coordinate.
    """
    if not recordings:
        raise ValueError("no recordings to fit on")
    for ds, state in zip(recordings, states, strict=True):
        if ds.sizes.get("run", 1) != 1:
            raise ValueError("each training recording must hold one run")
        if state not in STATES:
            raise ValueError(f"unknown state {state!r}; states are fn, f1..f19")
    n = max(ds.sizes["time"] for ds in recordings)
    arrays = {c: np.full((len(recordings), n), np.nan) for c in CHANNELS}
    starts = []
    for i, ds in enumerate(recordings):
        one = ds.isel(run=0) if "run" in ds.dims else ds
        for c in CHANNELS:
            arrays[c][i, : one.sizes["time"]] = np.asarray(one[c].values, dtype=np.float64)
        starts.append(float(one["time"].values[0]))
    onset = [max(0.0, float(o) - s) for o, s in zip(onsets, starts, strict=True)]
    runs = make_dataset(
        arrays, state=list(states), onset=onset, campaign="user-recordings", allow_nan=True
    )
    return runs.drop_vars("strength")  # unknown for a user's recording: no made-up value


def fit_from_recordings(
    normal: Sequence[xr.Dataset],
    faults: Sequence[tuple[str, float, xr.Dataset]] = (),
    *,
    estimator: Any = None,
    normal_samples: int | str = 2000,
    progress: bool = False,
) -> Any:
    """Fit an online diagnoser on the user's recordings.

    Parameters
    ----------
    normal
        Fault-free recordings (normal models), checked by
        `bayes_fdi.commissioning.check_healthy`: data that cannot identify the normal models
        (too short, a channel that does not move) are refused.
    faults
        ``(state, onset, recording)`` for recordings of known faults (onset in the recording's
        own time; 0 or earlier: faulty throughout).
    estimator
        The unfitted diagnoser, cloned (default: `new_online_diagnoser` with
        ``DynamicNormalModels(max_train_samples=normal_samples)``).
    normal_samples
        Samples the default normal models are fitted on (a seeded subset), or ``"auto"``:
        chosen by a learning curve on held-out minutes (see
        `~bayes_fdi.diagnosis.normal_models.training_size`).
    progress
        Say on stderr that the fit is running (after the checks).
    """
    from sklearn.base import clone

    from bayes_fdi.commissioning import check_healthy
    from bayes_fdi.progress import busy

    normal_runs = check_healthy(
        recordings_as_runs(normal, ["fn"] * len(normal), [0.0] * len(normal))
    )
    fault_runs = None
    if faults:
        states, onsets, recs = zip(*faults, strict=True)
        fault_runs = recordings_as_runs(list(recs), list(states), list(onsets))
    if estimator is None:
        from bayes_fdi.diagnosis.normal_models import DynamicNormalModels

        models = DynamicNormalModels(max_train_samples=normal_samples)
        estimator = new_online_diagnoser(normal_models=models)
    model = clone(estimator)
    with busy("fitting the normal models, detector and isolation", enabled=progress):
        return model.fit(normal_runs, fault_runs)


# ----------------------------------------------------------------------------------------------
# command line
# ----------------------------------------------------------------------------------------------
def _fault_argument(text: str) -> tuple[str, float, str]:
    """``STATE@ONSET=FILE`` or ``STATE=FILE`` (faulty throughout)."""
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"expected STATE@ONSET=FILE, got {text!r}")
    label, path = text.split("=", 1)
    state, _, onset = label.partition("@")
    state = state.strip()
    if state not in STATES[1:]:
        raise argparse.ArgumentTypeError(f"unknown fault {state!r} in {text!r}; faults are f1..f19")
    try:
        when = float(onset) if onset.strip() else 0.0
    except ValueError:
        raise argparse.ArgumentTypeError(f"onset {onset!r} in {text!r} is not a number") from None
    return state, when, input_file(path)


def _campaign_argument(text: str) -> str:
    """A campaign TOML file, or the name of a shipped campaign."""
    from bayes_fdi.campaigns.shipped import campaign_path

    if text.endswith(".toml") or os.path.sep in text:
        return input_file(text)
    try:
        return os.fspath(campaign_path(text))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def normal_samples(text: str) -> int | str:
    """``--normal-samples``: a count of at least 10, or ``auto``."""
    if text == "auto":
        return text
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 10:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 10 or 'auto', got {text!r}")
    return value


def add_normal_samples_argument(parser: argparse.ArgumentParser) -> None:
    """``--normal-samples N|auto`` (shared by ``fit --normal`` and ``commission``)."""
    parser.add_argument(
        "--normal-samples",
        type=normal_samples,
        default=None,
        metavar="N|auto",
        help="samples of the healthy data the normal models are fitted on (a seeded subset; "
        "default 2000), or 'auto': as many as a learning curve on held-out minutes shows to "
        "help, up to 4000 (slower: a fit of 4000 samples can cost ten times one of 2000)",
    )


def add_reading_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments that say how to read recordings (shared by ``fit`` and ``diagnose``)."""
    group = parser.add_argument_group("reading recordings (bayes_fdi.datasets.readers)")
    group.add_argument(
        "--units",
        default="normalised",
        help="units of the recordings: 'normalised' (default), 'physical' (CV and X in %%, P1 "
        "and P2 in kPa, T1 in degC, F in t/h) or CHANNEL=UNIT pairs, e.g. "
        "CV=%%,X=%%,P1=MPa,P2=MPa,T1=degC,F=t/h",
    )
    group.add_argument(
        "--columns",
        default=None,
        metavar="NAME=CHANNEL,...",
        help="the file's column (or variable) names of the channels, e.g. "
        "t=time,valve=CV,pin=P1,pout=P2,temp=T1,stem=X,flow=F",
    )
    group.add_argument(
        "--resample",
        choices=("mean", "linear"),
        default=None,
        help="bring a recording sampled at another rate than 1 Hz to 1 Hz (without it, "
        "such a recording is an error)",
    )
    group.add_argument(
        "--rate", type=float, default=None, help="samples per second, for files without a time"
    )
    group.add_argument(
        "--actuator",
        type=int,
        choices=(1, 2, 3),
        default=3,
        help="actuator of a Lublin day file DDMM2001.txt (default 3)",
    )
    group.add_argument(
        "--no-unit-check",
        dest="check_units",
        action="store_false",
        help="read values as they are, even where they look declared in the wrong units "
        "(implausible by orders of magnitude, or far outside the model's training data)",
    )


def reading_options(args: argparse.Namespace) -> dict[str, Any]:
    """The reader's keyword arguments from :func:`add_reading_arguments`' options."""
    from bayes_fdi.datasets.readers import parse_units

    try:
        parse_units(args.units)
        columns = None
        if args.columns:
            pairs = [p.split("=", 1) for p in args.columns.split(",") if p.strip()]
            if any(len(p) != 2 for p in pairs):
                raise ValueError(f"--columns expects NAME=CHANNEL pairs, got {args.columns!r}")
            columns = {k.strip(): v.strip() for k, v in pairs}
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    options = {"units": args.units, "columns": columns, "resample": args.resample,
               "rate": args.rate, "actuator": args.actuator}  # fmt: skip
    if not args.check_units:
        options["check_units"] = False
    return options


def read_for_fitting(path: str, options: Mapping[str, Any]) -> xr.Dataset:
    """Read one recording (eagerly) with the reading options."""
    from bayes_fdi.datasets.readers import read_recording

    return read_recording(path, **{k: v for k, v in options.items() if v is not None})


def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``bayes-fdi fit``."""
    from bayes_fdi.campaigns.simulation import add_override_argument
    from bayes_fdi.distributed import add_cluster_arguments

    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument(
        "--default",
        action="store_true",
        help="fit the default model (the default training campaigns), as diagnose does on first "
        "use",
    )
    source.add_argument(
        "--campaign",
        type=_campaign_argument,
        metavar="TOML_OR_NAME",
        help="simulate this campaign TOML file, or a shipped campaign by name (e.g. "
        "damadics-benchmark), and fit on it",
    )
    source.add_argument(
        "--normal",
        nargs="+",
        type=input_file,
        metavar="RECORDING",
        help="fault-free recordings of the actuator (fit the normal models on them)",
    )
    add_normal_samples_argument(parser)
    parser.add_argument(
        "--fault",
        action="append",
        default=[],
        type=_fault_argument,
        metavar="STATE@ONSET=FILE",
        help="with --normal: a recording of a known fault, e.g. f18@900=valve_leak.csv (onset "
        "in the recording's own time; omit @ONSET for faulty throughout); repeatable",
    )
    parser.add_argument(
        "--out",
        required=True,
        type=output_file(".npz"),
        help="model file to write (.npz), written atomically",
    )
    add_override_argument(
        parser, "with --campaign: override a campaign key, as bayes-fdi simulate --set"
    )
    parser.add_argument("--seed", type=int, default=None, help="seed of the simulation")
    parser.add_argument(
        "--small", action="store_true", help="with --default: the quick settings (a few minutes)"
    )
    parser.add_argument(
        "--training", choices=DEFAULT_TRAININGS, default=None,
        help="with --default: the training campaigns (default excitation-mix: four excitation "
        "families; dgen: the DAMADICS test generator's sines alone)",
    )  # fmt: skip
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    add_reading_arguments(parser)
    add_cluster_arguments(parser)


def run_from_cli(args: argparse.Namespace) -> int:
    """Run ``bayes-fdi fit``."""
    t0 = time.perf_counter()
    progress = not args.quiet
    if args.fault and not args.normal:
        raise UsageError("--fault needs --normal (the fault-free recordings)")
    if args.overrides and not args.campaign:
        raise UsageError("--set needs --campaign")
    if args.normal_samples is not None and not args.normal:
        raise UsageError("--normal-samples needs --normal (the fault-free recordings)")
    if args.training and not args.default:
        raise UsageError("--training needs --default")
    if args.default:
        training = args.training or DEFAULT_TRAININGS[0]
        seed = 0 if args.seed is None else args.seed
        model = _default_fitter()(seed=seed, small=args.small, progress=progress, training=training)
        what = f"the {training} training campaigns" + (" (small)" if args.small else "")
    elif args.campaign:
        from bayes_fdi.campaigns.simulation import load_with_overrides

        campaign = load_with_overrides(args.campaign, args.overrides)
        model = fit_from_campaign(campaign, seed=args.seed, progress=progress,
                                  workers=args.workers, scheduler=args.scheduler)  # fmt: skip
        what = f"campaign {campaign.name}"
    else:
        options = reading_options(args)
        normal = [read_for_fitting(p, options) for p in args.normal]
        faults = [(s, onset, read_for_fitting(p, options)) for s, onset, p in args.fault]
        model = fit_from_recordings(
            normal, faults, normal_samples=args.normal_samples or 2000, progress=progress
        )
        what = f"{len(normal)} fault-free and {len(faults)} fault recording(s)"
    model_files.save(model, args.out)
    size = os.path.getsize(args.out)
    print(
        f"wrote {args.out}: {type(model).__name__} fitted on {what} "
        f"({size / 1e6:.1f} MB) in {time.perf_counter() - t0:.1f} s"
    )
    ranges = getattr(model, "training_ranges_", None)
    if ranges:
        print("  fitted on (1st to 99th percentile): " + covered_ranges(ranges))
    size = getattr(getattr(model, "normal_models_", None), "training_size_", None)
    if size is not None:
        print("  normal models " + size.describe())
    if getattr(model, "isolator_", True) is None:
        print(
            "  detection only: no fault recordings, so every alarm is an 'unknown' fault; "
            "`bayes-fdi commission` builds a fault library from the healthy recordings"
        )
    return 0


def covered_ranges(ranges: Mapping[str, Sequence[float]]) -> str:
    """A model's training ranges (`training_ranges_`) in physical units, in one line."""
    from bayes_fdi.datasets.units import PHYSICAL_UNITS, to_physical

    parts = []
    for channel, (low, _, high) in ranges.items():
        a, b = (float(to_physical(v, channel)) for v in (low, high))
        parts.append(f"{channel} {a:.4g} to {b:.4g} {PHYSICAL_UNITS[channel]}")
    return ", ".join(parts)

"""Simulation campaigns: declarative TOML files turned into labelled datasets.

:func:`simulate_campaign` runs the DAMADICS model (:mod:`bayes_fdi.actuator`) on every run of a
validated campaign and returns a dataset in the project's format (:mod:`bayes_fdi.datasets`);
``bayes-fdi simulate CAMPAIGN.toml --out FILE.nc`` does both and writes the file atomically (the
output path is checked before simulating, the memory the campaign needs too).

The schema and its validation (:func:`load_campaign`, :func:`parse_campaign`) live in
`bayes_fdi.campaigns.parsing`, the :class:`Campaign` record in `bayes_fdi.campaigns.spec`;
their public names are importable from this module too.
"""

from __future__ import annotations

import os
import tomllib
from collections.abc import Sequence
from typing import Any

import numpy as np

from bayes_fdi.campaigns.parsing import check_seed, load_campaign, thaw
from bayes_fdi.campaigns.spec import (
    LUBLIN_HOUR,
    Campaign,
    CampaignError,
    RunSpec,
)
from bayes_fdi.cli_arguments import UsageError, input_file, output_file
from bayes_fdi.datasets.format import NETCDF_SUFFIXES
from bayes_fdi.memory import check_memory

__all__ = [
    "check_campaign_memory",
    "configure_parser",
    "run_from_cli",
    "simulate_campaign",
    "window_starts",
]


# ----------------------------------------------------------------------------------------------
# simulation
# ----------------------------------------------------------------------------------------------
def _derived_seeds(seed: int) -> tuple[int, int, int]:
    """Independent seeds for the inputs, the measurement noise and the Lublin windows."""
    streams = np.random.SeedSequence(seed).spawn(4)[1:]
    return tuple(int(s.generate_state(1, dtype=np.uint32)[0]) for s in streams)  # type: ignore


def window_starts(campaign: Campaign, specs: RunSpec, seed: int) -> np.ndarray:
    """Start (s) of each run's window in the real hour (``source = "lublin-example"``).

    ``window = "random"``: uniform integers in ``[0, 3600 - duration]``, independently per run.
    ``window = "even"``: the runs of each state are spaced evenly over the hour (the first at 0,
    the last at ``3600 - duration``), so every state sees the same windows.
    """
    last = LUBLIN_HOUR - campaign.duration
    n = len(specs.state)
    if campaign.inputs["window"] == "random":
        return np.random.default_rng(seed).integers(0, last + 1, n)
    starts = np.empty(n, dtype=np.int64)
    for state in dict.fromkeys(specs.state.tolist()):
        idx = np.flatnonzero(specs.state == state)
        starts[idx] = np.rint(np.linspace(0, last, len(idx))).astype(np.int64)
    return starts


def _faults(specs: RunSpec, rows: np.ndarray) -> list:
    from bayes_fdi.actuator import Fault

    out = []
    for r in rows:
        if specs.state[r] == "fn":
            out.append(None)
        else:
            out.append(Fault(str(specs.state[r]), float(specs.strength[r]), float(specs.onset[r]),
                             str(specs.profile[r]), float(specs.ramp[r])))  # fmt: skip
    return out


#: float64 values held per (run, second) of a campaign's dataset at the peak of its simulation:
#: six channels in the simulated batches, in their concatenation and in the validated result
_VALUES_PER_SAMPLE = 18
#: ... and per (run, second) of the batch being simulated (see `bayes_fdi.actuator.simulate`)
_BATCH_VALUES_PER_SAMPLE = 30


def check_campaign_memory(campaign: Campaign) -> None:
    """Raise `bayes_fdi.memory.InsufficientMemoryError` if the campaign cannot fit in memory.

    The estimate counts the dataset's six float64 channels three times (simulated batches, their
    concatenation, the result) plus the simulator's working arrays of one batch.
    """
    n, duration = campaign.n_runs, campaign.duration
    batch = min(n, campaign.batch_size)
    n_bytes = 8.0 * duration * (_VALUES_PER_SAMPLE * n + _BATCH_VALUES_PER_SAMPLE * batch)
    check_memory(n_bytes, f"campaign {campaign.name}: {n} run(s) x {duration} s")


def _simulate_batch(task: tuple) -> Any:
    """Simulate one batch ``(source, drive, faults, noise_seed)`` (a task of `run_tasks`)."""
    from bayes_fdi.actuator import inject_faults, simulate

    source, batch, faults, noise_seed = task
    if source in ("benchmark-inputs", "excitation"):
        return simulate(batch, faults, seed=noise_seed)
    return inject_faults(batch, faults, seed=noise_seed)


def simulate_campaign(
    campaign: Campaign | str | os.PathLike,
    seed: int | None = None,
    progress: bool = True,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
):
    """Simulate every run of a campaign into a dataset.

    Parameters
    ----------
    campaign
        A :class:`Campaign` or the path of a campaign TOML file.
    seed
        Overrides the campaign's seed. Fault strengths, input variation (or the excitation's
        draws), measurement noise and Lublin windows are drawn from independent streams of this
        seed, per run, so the result does not depend on ``batch_size``.
    progress
        Show a progress bar (on stderr).
    workers, scheduler
        Simulate the batches on a local dask cluster of ``workers`` processes or on the cluster
        at ``scheduler`` (`bayes_fdi.distributed`); the result is the same.

    Returns
    -------
    xarray.Dataset
        ``campaign.n_runs`` runs of ``campaign.duration`` s in the project's format, labelled
        with ``state``, ``strength``, ``onset``, ``profile``, ``ramp``; for the Lublin source also
        the per-run coordinate ``window_start`` (s into the real hour). Attributes: ``campaign``
        (name), ``seed``, ``source``, ``description``, ``campaign_config`` (the validated table
        as JSON) and ``inputs_seed``/``noise_seed``/``window_seed``.
    """
    import json

    import xarray as xr

    from bayes_fdi.actuator import benchmark_inputs

    if not isinstance(campaign, Campaign):
        campaign = load_campaign(campaign)
    seed = campaign.seed if seed is None else check_seed(seed, "seed")
    check_campaign_memory(campaign)
    specs = campaign.run_specs(seed)
    inputs_seed, noise_seed, window_seed = _derived_seeds(seed)
    n, duration = campaign.n_runs, campaign.duration
    labels = {"state": specs.state, "strength": specs.strength, "onset": specs.onset,
              "profile": specs.profile, "ramp": specs.ramp}  # fmt: skip
    extra_coords: dict[str, Any] = {}
    if campaign.source == "benchmark-inputs":
        drive = benchmark_inputs(n, duration, seed=inputs_seed, vary=bool(campaign.inputs["vary"]))
    elif campaign.source == "excitation":
        from bayes_fdi.campaigns.excitation import excitation_inputs

        drive = excitation_inputs(campaign.excitation, n, duration, seed=inputs_seed)
        # a loop's own signals (the tank level of level-loop) are not channels of the actuator
        drive = drive.drop_vars([c for c in drive.coords if drive[c].dims == ("run", "time")])
    else:
        from bayes_fdi.datasets.lublin import load_lublin_example

        hour = load_lublin_example()
        starts = window_starts(campaign, specs, window_seed)
        offsets = starts[:, None] + np.arange(duration)[None, :]
        drive = xr.Dataset(
            {c: (("run", "time"), hour[c].values[0][offsets]) for c in hour.data_vars},
            coords={"run": np.arange(n), "time": np.arange(duration, dtype=np.float64)},
            attrs=dict(hour.attrs),
        )
        extra_coords = {"window_start": ("run", starts.astype(np.int64))}
    drive = drive.assign_coords({k: ("run", v) for k, v in labels.items()})

    from bayes_fdi.distributed import run_tasks

    size = campaign.batch_size
    batches = [np.arange(a, min(n, a + size)) for a in range(0, n, size)]
    tasks = [(campaign.source, drive.isel(run=r), _faults(specs, r), noise_seed) for r in batches]
    parts = run_tasks(_simulate_batch, tasks, workers=workers, scheduler=scheduler,
                      progress=progress, desc=f"simulating {campaign.name}", unit="run",
                      sizes=[len(r) for r in batches])  # fmt: skip
    ds = xr.concat(parts, dim="run", combine_attrs="override") if len(parts) > 1 else parts[0]
    ds = ds[["CV", "P1", "P2", "T1", "X", "F"]].assign_coords(extra_coords)
    attrs = {k: v for k, v in ds.attrs.items() if k in ("bayes_fdi_version", "integrator")}
    attrs.update(
        campaign=campaign.name,
        seed=int(seed),
        source=campaign.source,
        description=campaign.description,
        campaign_config=json.dumps(thaw(campaign.raw), sort_keys=True),
        inputs_seed=inputs_seed,
        noise_seed=noise_seed,
        window_seed=window_seed,
    )
    if campaign.source == "lublin-example":
        attrs["real_data"] = hour.attrs["source"]
    ds.attrs = attrs
    from bayes_fdi.datasets import validate_dataset

    return validate_dataset(ds)


# ----------------------------------------------------------------------------------------------
# command line
# ----------------------------------------------------------------------------------------------
def parse_override(text: str) -> tuple[str, Any]:
    """``"KEY=VALUE"`` (``--set``) as ``(key, value)``: the value read as TOML, else as text."""
    if "=" not in text:
        raise CampaignError(f"--set expects KEY=VALUE, got {text!r}")
    key, value = (part.strip() for part in text.split("=", 1))
    try:
        parsed = tomllib.loads(f"v = {value}")["v"]
    except tomllib.TOMLDecodeError:
        parsed = value  # a bare word, e.g. --set source=lublin-example
    return key, parsed


def load_with_overrides(path: Any, overrides: Sequence[str]) -> Campaign:
    """`load_campaign` of ``path`` with ``--set KEY=VALUE`` overrides; a bad file or override
    raises a `UsageError` naming it."""
    try:
        return load_campaign(path, **dict(parse_override(text) for text in overrides))
    except CampaignError as exc:
        raise UsageError(str(exc)) from exc


def add_override_argument(parser: Any, help_text: str) -> None:
    """The ``--set KEY=VALUE`` option (repeatable) of the commands that read a campaign."""
    parser.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
        help=help_text,
    )  # fmt: skip


def _seed_argument(text: str) -> int:
    import argparse

    try:
        return check_seed(int(text), "--seed")
    except (ValueError, CampaignError) as exc:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {text!r}") from exc


def configure_parser(parser) -> None:
    """Add the arguments of ``bayes-fdi simulate``."""
    parser.add_argument(
        "campaign", type=input_file, help="campaign TOML file (see sim/ and docs/data.md)"
    )
    parser.add_argument(
        "--out",
        required=True,
        type=output_file(*NETCDF_SUFFIXES),
        help="dataset file to write (netCDF: .nc), written atomically",
    )
    parser.add_argument(
        "--seed", type=_seed_argument, default=None, help="override the campaign's seed"
    )
    add_override_argument(
        parser,
        "override a campaign key before validation, e.g. --set runs_per_state=5 "
        "--set faults.strength=[0.6,0.9] (bare keys are [campaign] keys; repeatable)",
    )
    parser.add_argument(
        "--quiet", "--no-progress", dest="quiet", action="store_true", help="hide the progress bar"
    )
    from bayes_fdi.distributed import add_cluster_arguments

    add_cluster_arguments(parser)


def run_from_cli(args) -> int:
    """Run ``bayes-fdi simulate``: every check (arguments, campaign, memory) before simulating."""
    import time

    from bayes_fdi.datasets import save_dataset

    campaign = load_with_overrides(args.campaign, args.overrides)
    check_campaign_memory(campaign)
    t0 = time.perf_counter()
    ds = simulate_campaign(
        campaign,
        seed=args.seed,
        progress=not args.quiet,
        workers=args.workers,
        scheduler=args.scheduler,
    )
    save_dataset(ds, args.out)
    elapsed = time.perf_counter() - t0
    counts = ", ".join(
        f"{s}: {int((ds['state'].values == s).sum())}" for s in dict.fromkeys(ds["state"].values)
    )
    print(
        f"wrote {args.out}: {ds.sizes['run']} runs x {ds.sizes['time']} s "
        f"(campaign {campaign.name}, seed {ds.attrs['seed']}) in {elapsed:.1f} s\n"
        f"  runs per state: {counts}"
    )
    return 0

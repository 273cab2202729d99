"""The shift benchmark: the 44 Step-I scenarios under excitation families the training never saw.

``bayes-fdi benchmark --shift --out DIR`` runs the benchmark of `bayes_fdi.benchmark.harness`
(the same scenarios, PICalc indices, fault-free hours, calibration and report) once per shift
family, with the inputs (CV, P1, P2, T1) that family draws instead of DGen's sines, and writes
a summary over the families (`bayes_fdi.benchmark.shift_report`).

The families are the shipped campaign files ``sim/shift-*.toml`` (:func:`shift_families`):
each declares an ``[excitation]`` table (`bayes_fdi.campaigns.excitation`) that no training
campaign uses; they were fixed before any result of the shift benchmark was seen.

Seeds
-----
All in the benchmark's evaluation range, apart from the training campaigns' seeds (< 1000):

- the excitation of benchmark seed ``10_000 + k`` is run ``k`` of the family's generator with
  seed :data:`SHIFT_INPUT_SEED`, drawn once over the longest horizon; every scenario reads its
  first ``t_hor`` seconds, so the scenarios of a seed share their inputs as DGen's do;
- the measurement noise of the scenario at position ``p`` of
  `~bayes_fdi.benchmark.scenarios.SCENARIOS` with seed ``s`` is the stream
  ``numpy.random.default_rng([SHIFT_NOISE_SEED + p, s])``;
- the fault-free hours: run 0 of the generator with seed
  `~bayes_fdi.benchmark.scenarios.FAULT_FREE_SEED`, noise stream ``[FAULT_FREE_SEED, 0]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import xarray as xr

from bayes_fdi.actuator import simulate
from bayes_fdi.benchmark.harness import MAX_BATCH_SAMPLES, run_benchmark
from bayes_fdi.benchmark.scenarios import (
    BENCHMARK_SEED,
    FAULT_FREE_SEED,
    SCENARIOS,
    T_ON,
    BenchmarkScenario,
    benchmark_seeds,
)
from bayes_fdi.campaigns import load_campaign
from bayes_fdi.campaigns.excitation import excitation_inputs
from bayes_fdi.campaigns.shipped import campaign_path, shipped_campaigns

__all__ = [
    "SHIFT_INPUT_SEED",
    "SHIFT_NOISE_SEED",
    "SHIFT_PREFIX",
    "ShiftFamily",
    "ShiftInputs",
    "family_fault_free",
    "run_from_cli",
    "run_shift_benchmark",
    "shift_families",
]

#: The shift families are the shipped campaigns whose name starts with this.
SHIFT_PREFIX = "shift-"
#: Seed of the shift families' excitation draws (run k for benchmark seed 10 000 + k).
SHIFT_INPUT_SEED = 30_000
#: First seed of the shift runs' measurement noise (one per scenario position).
SHIFT_NOISE_SEED = 40_000
_POSITION = {s.name: i for i, s in enumerate(SCENARIOS)}
_INPUTS = ["CV", "P1", "P2", "T1"]


class ShiftFamily(NamedTuple):
    """One shift family: a shipped ``sim/shift-*.toml`` campaign's excitation."""

    name: str  #: the campaign's name without the prefix, e.g. ``"chirp"``
    family: str  #: the generator family of its ``[excitation]`` table
    description: str
    excitation: Mapping[str, Any]  #: the parsed ``[excitation]`` table
    path: str


def shift_families() -> tuple[ShiftFamily, ...]:
    """The shift families: every shipped ``shift-*.toml`` campaign, by name.

    Raises
    ------
    ValueError
        If one of them does not draw its inputs from an excitation family.
    """
    out = []
    for name in shipped_campaigns():
        if not name.startswith(SHIFT_PREFIX):
            continue
        path = campaign_path(name)
        campaign = load_campaign(path)
        if campaign.source != "excitation":
            raise ValueError(f"{path}: a shift family needs campaign.source = 'excitation'")
        out.append(
            ShiftFamily(
                name[len(SHIFT_PREFIX) :],
                str(campaign.excitation["family"]),
                campaign.description,
                campaign.excitation,
                str(path),
            )
        )
    return tuple(out)


class ShiftInputs:
    """A family's excitation for the benchmark seeds, and the benchmark's runs under it.

    Parameters
    ----------
    family
        The shift family.
    seeds
        The benchmark seeds (``>= first_seed``).
    duration
        Seconds drawn: the longest horizon the runs need.
    first_seed, input_seed, noise_seed
        Seed ``first_seed + k`` reads run ``k`` of the family's draw with ``input_seed``, and
        a scenario's noise seed is ``noise_seed`` plus its position in the table. The defaults
        are the shift benchmark's (`BENCHMARK_SEED`, `SHIFT_INPUT_SEED`, `SHIFT_NOISE_SEED`);
        a study that must stay apart from its evaluation draws with seeds of its own.
    """

    def __init__(
        self,
        family: ShiftFamily,
        seeds: Sequence[int],
        duration: int,
        *,
        first_seed: int = BENCHMARK_SEED,
        input_seed: int = SHIFT_INPUT_SEED,
        noise_seed: int = SHIFT_NOISE_SEED,
    ) -> None:
        seeds = [int(s) for s in seeds]
        if not seeds or min(seeds) < first_seed:
            raise ValueError(f"ShiftInputs: seeds must be >= {first_seed}, got {seeds}")
        self.family = family
        self.noise_seed = int(noise_seed)
        runs = max(seeds) - first_seed + 1
        drawn = excitation_inputs(family.excitation, runs, int(duration), seed=input_seed)
        drawn = drawn[_INPUTS].isel(run=[s - first_seed for s in seeds])
        self.inputs = drawn.assign_coords(run=np.asarray(seeds, dtype=np.int64))

    def simulate(self, scenario: BenchmarkScenario, seeds: Sequence[int]) -> xr.Dataset:
        """The scenario simulated up to its ``t_hor`` with each seed (``run`` = the seed), as
        `~bayes_fdi.benchmark.scenarios.simulate_scenario` does under DGen's inputs."""
        if scenario.name not in _POSITION:
            raise ValueError(f"ShiftInputs.simulate: {scenario.name!r} is not a Step-I scenario")
        position = _POSITION[scenario.name]
        duration = round(scenario.t_hor)
        if duration > self.inputs.sizes["time"]:
            raise ValueError(
                f"ShiftInputs.simulate: {scenario.name} needs {duration} s, "
                f"{self.inputs.sizes['time']} s were drawn"
            )
        drive = self.inputs.sel(run=[int(s) for s in seeds]).isel(time=slice(0, duration))
        faults = [scenario.fault_spec()] * drive.sizes["run"]
        ds = simulate(drive, faults, seed=self.noise_seed + position)
        ds.attrs.update(scenario.run_attrs(position, seeds), excitation=self.family.name)
        return ds

    def effects_inputs(self, duration: int) -> xr.Dataset:
        """The first seed's excitation over ``duration`` s (the fault effects' inputs)."""
        return self.inputs.isel(run=[0], time=slice(0, int(duration)))

    def fault_free(
        self, hours: float, *, warmup: float = T_ON, seed: int = FAULT_FREE_SEED
    ) -> xr.Dataset:
        """The family's `family_fault_free` hours (inputs and noise drawn with ``seed``)."""
        return family_fault_free(self.family, hours, warmup=warmup, seed=seed)


def family_fault_free(
    family: ShiftFamily, hours: float, *, warmup: float = T_ON, seed: int = FAULT_FREE_SEED
) -> xr.Dataset:
    """One fault-free run of ``warmup + hours`` under ``family``, inputs and noise drawn with
    ``seed`` (as `~bayes_fdi.benchmark.scenarios.fault_free_hours` under DGen's inputs)."""
    if not hours > 0:
        raise ValueError(f"fault_free: hours must be > 0, got {hours!r}")
    duration = round(warmup + 3600.0 * hours)
    drive = excitation_inputs(family.excitation, 1, duration, seed=seed)
    ds = simulate(drive[_INPUTS], None, seed=seed)
    ds = ds.assign_coords(run=[seed])
    ds.attrs.update(warmup=float(warmup), hours=float(hours), excitation=family.name)
    return ds


def run_shift_benchmark(
    diagnoser: Any,
    out: str | Path,
    *,
    families: Sequence[ShiftFamily] | None = None,
    n_seeds: int = 10,
    scenarios: Sequence[BenchmarkScenario] | None = None,
    hours: float = 8.0,
    figures: bool = True,
    n_bootstrap: int = 200,
    max_batch_samples: int = MAX_BATCH_SAMPLES,
    progress: bool = True,
    settings: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Run the benchmark under every shift family; write ``out/NAME/`` per family (the
    nominal benchmark's report and JSON, `~bayes_fdi.benchmark.harness.run_benchmark`) and the
    summary ``out/benchmark.md``, ``out/benchmark.json``.

    Parameters are those of `~bayes_fdi.benchmark.harness.run_benchmark` (the real Lublin hour
    is not part of it: it does not depend on the excitation), plus ``families`` (default
    :func:`shift_families`).

    Returns
    -------
    dict
        What ``out/benchmark.json`` holds (`bayes_fdi.benchmark.shift_report`).
    """
    from bayes_fdi.benchmark.shift_report import write_shift_report

    wall0 = time.perf_counter()
    families = list(shift_families() if families is None else families)
    if not families:
        raise ValueError("run_shift_benchmark: no shift family")
    scenarios = list(SCENARIOS if scenarios is None else scenarios)
    seeds = benchmark_seeds(n_seeds)
    longest = round(max(s.t_hor for s in scenarios))
    per_family: dict[str, dict[str, Any]] = {}
    # the training time belongs to the whole run (the summary), not to one family's report
    run_settings = {k: v for k, v in dict(settings or {}).items() if k != "fit_wall_s"}
    for family in families:
        if progress:
            sys.stderr.write(f"shift family {family.name} ({family.family})\n")
        inputs = ShiftInputs(family, seeds, longest)
        per_family[family.name] = run_benchmark(
            diagnoser,
            Path(out) / family.name,
            n_seeds=n_seeds,
            scenarios=scenarios,
            hours=hours,
            real_hour=False,
            figures=figures,
            n_bootstrap=n_bootstrap,
            max_batch_samples=max_batch_samples,
            progress=progress,
            settings={**run_settings, "excitation": _family_entry(family)},
            simulator=inputs.simulate,
            fault_free=inputs.fault_free,
            effects_inputs=inputs.effects_inputs,
        )
        del inputs
    wall = time.perf_counter() - wall0
    return write_shift_report(families, per_family, out, wall_s=wall, settings=settings)


def _family_entry(family: ShiftFamily) -> dict[str, Any]:
    """A family as the reports record it."""
    return {
        "name": family.name,
        "family": family.family,
        "description": family.description,
        "file": Path(family.path).name,
    }


def run_from_cli(args: argparse.Namespace) -> int:
    """Run ``bayes-fdi benchmark --shift``: fit the default diagnoser, run every shift family."""
    from bayes_fdi.default_diagnoser import fit_online_diagnoser

    n_seeds = args.seeds if args.seeds is not None else (2 if args.small else 10)
    t0 = time.perf_counter()
    diagnoser = fit_online_diagnoser(seed=0, small=args.small, progress=not args.quiet)
    fit_s = time.perf_counter() - t0
    results = run_shift_benchmark(
        diagnoser,
        args.out,
        n_seeds=n_seeds,
        scenarios=[s.truncated(2400) for s in SCENARIOS] if args.small else None,
        hours=1.0 if args.small else 8.0,
        progress=not args.quiet,
        settings={"small": bool(args.small), "fit_wall_s": fit_s, "training_seed": 0},
    )
    total = time.perf_counter() - t0
    sys.stderr.write(
        f"shift benchmark: {len(results['families'])} families in {total:.0f} s "
        f"(fit {fit_s:.0f} s); report {Path(args.out) / 'benchmark.md'}\n"
    )
    return 0

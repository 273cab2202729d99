"""The commissioning benchmark: ``bayes-fdi benchmark --commissioning --out DIR``.

A sibling of the DAMADICS benchmark (`bayes_fdi.benchmark.harness`) for diagnosers commissioned
on a valve's own healthy data (`bayes_fdi.commissioning.commission`). Two parts:

1. **The real hour** (`bayes_fdi.benchmark.real_hour`): commissioned on the first half of the
   real Lublin hour; its second half clean, and with each fault of the library transplanted at
   the benchmark's small / medium / big strengths (abrupt, 300 s into the half), scored with
   PICalc; the group-level confusion.
2. **Perturbed plants** (`bayes_fdi.benchmark.plants`, `bayes_fdi.benchmark.plant_runs`):
   simulated valves whose parameters lie 20-30 % from nominal, each in a level loop at its own
   operating point, commissioned on one healthy hour; then the 44 Step-I scenarios run on each
   plant under its own closed-loop inputs, scored with PICalc as the DAMADICS harness does.

The default diagnoser (`bayes_fdi.default_diagnoser.fit_online_diagnoser`, trained on the
nominal simulator) runs on the same data beside the commissioned one. Every seed lies apart
from those of training and commissioning (see the two modules). `run_commissioning_benchmark`
writes ``DIR/benchmark.json`` and ``DIR/benchmark.md``
(`bayes_fdi.benchmark.commissioning_report`).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from bayes_fdi.benchmark.commissioning_summary import targets
from bayes_fdi.benchmark.plant_runs import COMMISSIONING_SECONDS, plant_benchmark
from bayes_fdi.benchmark.plants import MAX_PLANT_SEEDS, MAX_PLANTS, draw_plant
from bayes_fdi.benchmark.real_hour import real_hour_benchmark
from bayes_fdi.benchmark.scenarios import SCENARIOS, BenchmarkScenario

__all__ = [
    "FULL",
    "SMALL",
    "run_commissioning_benchmark",
    "run_from_cli",
    "small_commission_options",
]

#: The full benchmark: plants, seeds per plant and scenario, twin draws per transplanted case,
#: horizon cut (None: every scenario to its own t_hor).
FULL: dict[str, Any] = {"plants": 5, "seeds": 2, "draws": 3, "horizon": None}
#: The quick version (``--small``): not the benchmark's numbers.
SMALL: dict[str, Any] = {"plants": 1, "seeds": 1, "draws": 1, "horizon": 2400.0}


def small_commission_options(seed: int = 0) -> dict[str, Any]:
    """Lighter commissioning for the quick version: fewer transplanted runs, lighter normal
    models (as the default diagnoser's quick version has them)."""
    from bayes_fdi.commissioning.commission import NORMAL_MODEL_OPTIONS
    from bayes_fdi.diagnosis.normal_models.dynamic import DynamicNormalModels

    return {
        "runs_per_fault": 3,
        "evaluation_runs": 1,
        "normal_models": DynamicNormalModels(
            max_train_samples=800, calibration_folds=3, random_state=seed, **NORMAL_MODEL_OPTIONS
        ),
    }


def _load() -> float | None:
    try:
        return float(os.getloadavg()[0])
    except OSError:  # pragma: no cover - platforms without a load average
        return None


def run_commissioning_benchmark(
    default: Any,
    out: str | os.PathLike,
    *,
    n_plants: int = FULL["plants"],
    n_seeds: int = FULL["seeds"],
    draws: int = FULL["draws"],
    scenarios: Sequence[BenchmarkScenario] | None = None,
    real_hour: bool = True,
    commission_options: Mapping[str, Any] | None = None,
    commission_seconds: int = COMMISSIONING_SECONDS,
    progress: bool = True,
    settings: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Run the commissioning benchmark and write ``benchmark.json`` and ``benchmark.md``.

    Parameters
    ----------
    default
        The default online diagnoser (fitted), run beside the commissioned ones.
    out
        Output folder (created).
    n_plants, n_seeds
        Perturbed plants (0 for none), and seeds per plant and scenario.
    draws
        Twin parameter draws per transplanted case of the real hour.
    scenarios
        The scenarios run on each plant (default: the 44 of
        `bayes_fdi.benchmark.scenarios.SCENARIOS`; a subset or truncated ones for quick runs).
    real_hour
        Whether to run the real-hour part.
    commission_options
        Extra arguments of `bayes_fdi.commissioning.commission` (both parts).
    commission_seconds
        Healthy seconds each plant is commissioned on (default one hour).
    progress
        Progress on stderr.
    settings
        Extra provenance stored under ``"settings"``.

    Returns
    -------
    dict
        What ``benchmark.json`` holds: ``"real_hour"`` (`real_hour_benchmark`), ``"plants"``
        (one `plant_benchmark` per plant), ``"targets"``, ``"timing"``, ``"load"``,
        ``"settings"``.
    """
    from bayes_fdi.benchmark.commissioning_report import write_commissioning_report

    scenarios = list(SCENARIOS if scenarios is None else scenarios)
    for name, value, limit in (
        ("n_plants", n_plants, MAX_PLANTS),
        ("n_seeds", n_seeds, MAX_PLANT_SEEDS),
    ):
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= limit:
            raise ValueError(f"{name} must be an integer in [0, {limit}], got {value!r}")
    if n_plants and (not scenarios or n_seeds < 1):
        raise ValueError("the perturbed plants need scenarios and at least one seed")
    wall0, cpu0, load0 = time.perf_counter(), time.process_time(), _load()
    options = dict(commission_options or {})
    results: dict[str, Any] = {"real_hour": None, "plants": []}
    if real_hour:
        t0 = time.perf_counter()
        results["real_hour"] = real_hour_benchmark(
            default, draws=draws, commission_options=options, progress=progress
        )
        results["real_hour"]["wall_s"] = time.perf_counter() - t0
    bar = None
    if progress and n_plants:
        from tqdm.auto import tqdm

        bar = tqdm(total=n_plants * n_seeds * len(scenarios), desc="plants", unit="run")
    try:
        for i in range(n_plants):
            plant = draw_plant(i)
            results["plants"].append(
                plant_benchmark(
                    plant,
                    default,
                    scenarios=scenarios,
                    n_seeds=n_seeds,
                    commission_options=options,
                    commission_seconds=commission_seconds,
                    bar=bar,
                )
            )
    finally:
        if bar is not None:
            bar.close()
    results["load"] = {"start": load0, "end": _load(), "cpus": os.cpu_count()}
    results["timing"] = {
        "wall_s": time.perf_counter() - wall0,
        "cpu_s": time.process_time() - cpu0,
    }
    results["settings"] = {
        "n_plants": int(n_plants),
        "n_seeds": int(n_seeds),
        "draws": int(draws),
        "n_scenarios": len(scenarios),
        "horizons": sorted({s.t_hor for s in scenarios}),
        "full_scenarios": scenarios == list(SCENARIOS),
        "commission_options": sorted(options),
        "commission_seconds": int(commission_seconds),
        **dict(settings or {}),
    }
    results["targets"] = targets(results)
    write_commissioning_report(results, out)
    return results


def run_from_cli(args: argparse.Namespace) -> int:
    """Fit the default diagnoser, run the commissioning benchmark, write the report."""
    from bayes_fdi.cli_arguments import UsageError
    from bayes_fdi.default_diagnoser import fit_online_diagnoser

    size = SMALL if args.small else FULL
    isolation = getattr(args, "isolation", None) or "tree"
    n_plants = size["plants"] if args.plants is None else args.plants
    n_seeds = size["seeds"] if args.seeds is None else args.seeds
    if not 0 <= n_plants <= MAX_PLANTS:
        raise UsageError(f"--plants must lie in [0, {MAX_PLANTS}], got {n_plants}")
    if not 1 <= n_seeds <= MAX_PLANT_SEEDS:
        raise UsageError(f"--seeds must lie in [1, {MAX_PLANT_SEEDS}], got {n_seeds}")
    t0 = time.perf_counter()
    default = fit_online_diagnoser(seed=0, small=args.small, progress=not args.quiet)
    fit_s = time.perf_counter() - t0
    horizon = size["horizon"]
    scenarios = [s.truncated(horizon) for s in SCENARIOS] if horizon else None
    results = run_commissioning_benchmark(
        default,
        args.out,
        n_plants=n_plants,
        n_seeds=n_seeds,
        draws=size["draws"],
        scenarios=scenarios,
        commission_options={
            **(small_commission_options() if args.small else {}),
            "isolation": isolation,
        },
        progress=not args.quiet,
        settings={
            "small": bool(args.small),
            "default_fit_wall_s": fit_s,
            "horizon": horizon,
            "isolation": isolation,
        },
    )
    total = time.perf_counter() - t0
    sys.stderr.write(
        f"commissioning benchmark: {len(results['plants'])} plant(s) in {total:.0f} s "
        f"(default model fit {fit_s:.0f} s); report {Path(args.out) / 'benchmark.md'}\n"
    )
    return 0

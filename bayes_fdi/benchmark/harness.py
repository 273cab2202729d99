"""The DAMADICS benchmark (Step I) for the online diagnoser: ``bayes-fdi benchmark --out DIR``.

:func:`run_benchmark` takes a fitted online diagnoser (the contract of
:class:`bayes_fdi.diagnosis.OnlineDiagnoser`: ``run(recording)`` returns the 1 Hz decision
stream; ``sklearn.base.clone`` + ``fit(normal_runs)`` gives a fresh detector) and

1. simulates the 44 Step-I scenarios (:mod:`bayes_fdi.benchmark.scenarios`) with N noise
   seeds, each up to its own ``t_hor``, in batches of equal horizon (bounded memory; the model
   runs once per scenario, each seed only draws its noise);
2. runs the diagnoser on every batch (it sees the six channels only, no labels), derives the
   benchmark's decision signals DD, PID, CID from the stream and the truth
   (`bayes_fdi.scoring.decision_signals`) and computes PICalc's indices
   (:func:`bayes_fdi.scoring.picalc`), run by run (`bayes_fdi.benchmark.collection`);
3. measures what the faults do to the measured signals against the noise
   (`bayes_fdi.benchmark.effects`), the group-level calibration of the per-second isolation
   probabilities, the false alarms of simulated fault-free hours and of the second half of the
   real Lublin hour (detector refitted on its first half);
4. writes ``DIR/benchmark.json``, ``DIR/benchmark.md`` (`bayes_fdi.benchmark.report`), one timeline
   figure per scenario (first seed) and a reliability diagram.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import xarray as xr

from bayes_fdi.actuator import FAULT_TABLE
from bayes_fdi.benchmark.collection import RunCollector, group_calibration
from bayes_fdi.benchmark.effects import fault_effects
from bayes_fdi.benchmark.scenarios import (
    SCENARIOS,
    BenchmarkScenario,
    benchmark_seeds,
    fault_free_hours,
    simulate_scenario,
    strip_truth,
)
from bayes_fdi.diagnosis.online.timeline import plot_timeline
from bayes_fdi.scoring.decision_signals import decision_high, rising_edges

__all__ = [
    "run_benchmark",
    "run_from_cli",
]

#: Samples per call of ``diagnoser.run`` (runs of equal horizon are batched up to this).
MAX_BATCH_SAMPLES = 300_000


# ----------------------------------------------------------------------------------------------
# the runner
# ----------------------------------------------------------------------------------------------
def _batches(scenarios, seeds, max_samples):
    """Lists of (scenario, seeds) whose runs share a horizon, at most ``max_samples`` each."""
    by_horizon: dict[float, list[tuple[BenchmarkScenario, int]]] = {}
    for s in scenarios:
        by_horizon.setdefault(s.t_hor, []).extend((s, seed) for seed in seeds)
    for t_hor, pairs in by_horizon.items():
        per_batch = max(1, int(max_samples // t_hor))
        for i in range(0, len(pairs), per_batch):
            chunk = pairs[i : i + per_batch]
            grouped: dict[str, tuple[BenchmarkScenario, list[int]]] = {}
            for s, seed in chunk:
                grouped.setdefault(s.name, (s, []))[1].append(seed)
            yield list(grouped.values())


#: Simulates one scenario with the given noise seeds (one run per seed, ``run`` = the seed).
ScenarioSimulator = Callable[[BenchmarkScenario, Sequence[int]], xr.Dataset]


class _Simulations:
    """Each scenario simulated once with all its seeds, kept until its last run is taken."""

    def __init__(
        self,
        scenarios: Sequence[BenchmarkScenario],
        seeds: Sequence[int],
        simulator: ScenarioSimulator = simulate_scenario,
    ) -> None:
        self.simulator = simulator
        self.seeds = list(seeds)
        self.left = {s.name: len(self.seeds) for s in scenarios}
        self.cache: dict[str, xr.Dataset] = {}

    def take(self, scenario: BenchmarkScenario, seeds: Sequence[int]) -> xr.Dataset:
        if scenario.name not in self.cache:
            self.cache[scenario.name] = self.simulator(scenario, self.seeds)
        runs = self.cache[scenario.name].sel(run=list(seeds))
        self.left[scenario.name] -= len(seeds)
        if self.left[scenario.name] == 0:
            del self.cache[scenario.name]
        return runs


def _fault_free(diagnoser: Any, hours: float, simulate_hours: Callable) -> dict[str, Any]:
    ds = simulate_hours(hours)
    stream = diagnoser.run(strip_truth(ds)).isel(run=0)
    counted = stream["time"].values >= ds.attrs["warmup"]
    dd = decision_high(stream["DD"].values)[counted]
    status = np.asarray(stream["status"].values).astype(str)[counted]
    alarms = rising_edges(dd)
    return {
        "hours": float(hours),
        "seconds": int(counted.sum()),
        "seed": int(ds.run.values[0]),
        "alarms": alarms,
        "alarms_per_8h": alarms * 8.0 / hours,
        "r_fd": float(dd.mean()),
        "clear_share": float(np.mean(status == "CLEAR")),
    }


def _real_hour(diagnoser: Any) -> dict[str, Any]:
    """Refit on the first half of the shipped Lublin hour (normal runs only); run the second."""
    from sklearn.base import clone

    from bayes_fdi.datasets import load_lublin_example

    hour = load_lublin_example()
    half = hour.sizes["time"] // 2
    fresh = clone(diagnoser).fit(hour.isel(time=slice(0, half)))
    stream = fresh.run(strip_truth(hour.isel(time=slice(half, None)))).isel(run=0)
    dd = decision_high(stream["DD"].values)
    status = np.asarray(stream["status"].values).astype(str)
    return {
        "seconds": int(dd.size),
        "alarms": rising_edges(dd),
        "clear_share": float(np.mean(status == "CLEAR")),
        "r_fd": float(dd.mean()),
        "status_counts": {str(s): int(np.sum(status == s)) for s in sorted(set(status))},
    }


def run_benchmark(
    diagnoser: Any,
    out: str | os.PathLike,
    *,
    n_seeds: int = 10,
    scenarios: Sequence[BenchmarkScenario] | None = None,
    hours: float = 8.0,
    real_hour: bool = True,
    figures: bool = True,
    n_bootstrap: int = 200,
    max_batch_samples: int = MAX_BATCH_SAMPLES,
    progress: bool = True,
    settings: Mapping[str, Any] | None = None,
    simulator: ScenarioSimulator = simulate_scenario,
    fault_free: Callable[[float], xr.Dataset] = fault_free_hours,
    effects_inputs: Callable[[int], xr.Dataset] | None = None,
) -> dict[str, Any]:
    """Run the benchmark with a fitted online diagnoser and write the results into ``out``.

    Parameters
    ----------
    diagnoser
        A fitted online diagnoser (``run(recording)`` returns the decision stream of
        `bayes_fdi.diagnosis.OnlineDiagnoser.run`; for the real hour it is cloned and refitted with
        ``fit(normal_runs)``).
    out
        Output folder (created): ``benchmark.json``, ``benchmark.md``, ``timelines/*.png``,
        ``reliability.png``.
    n_seeds
        Noise seeds per scenario (:func:`~bayes_fdi.benchmark.scenarios.benchmark_seeds`).
    scenarios
        Default: all 44 (:data:`~bayes_fdi.benchmark.scenarios.SCENARIOS`); a subset or
        :meth:`~bayes_fdi.benchmark.scenarios.BenchmarkScenario.truncated` ones for quick runs.
    hours
        Simulated fault-free hours for the false-alarm budget (after a 300-s warm-up).
    real_hour, figures
        Whether to evaluate the real Lublin hour and draw the figures.
    n_bootstrap
        Run-level bootstrap resamples of the calibration interval.
    max_batch_samples
        Samples per call of ``diagnoser.run``.
    progress
        Progress bar on stderr.
    settings
        Extra provenance stored under ``"settings"`` (e.g. how the diagnoser was trained).
    simulator, fault_free, effects_inputs
        Where the runs come from: ``simulator(scenario, seeds)`` simulates a scenario (default
        :func:`~bayes_fdi.benchmark.scenarios.simulate_scenario`, DGen's inputs),
        ``fault_free(hours)`` the fault-free run with its ``warmup`` and ``hours`` attributes
        (default :func:`~bayes_fdi.benchmark.scenarios.fault_free_hours`) and
        ``effects_inputs(duration)`` one run of the inputs the fault effects are measured under
        (default DGen's); the shift benchmark (`bayes_fdi.benchmark.shift`) passes its
        excitation families'.

    Returns
    -------
    dict
        What ``benchmark.json`` holds: ``"scenarios"`` (one row per scenario and seed:
        ``fault``, ``mode``, ``size``, ``seed``, ``indices``), ``"real_hour"`` (``seconds``,
        ``alarms``, ``clear_share``), ``"fault_free"``, ``"calibration"``, ``"effects"``,
        ``"confident_wrong"``, ``"model_std"``, ``"innovation_rms"`` (median over the runs of
        the whitened innovations' RMS before the fault), ``"timing"``, ``"settings"``.
    """
    from bayes_fdi.benchmark.report import write_report

    wall0 = time.perf_counter()
    scenarios = list(SCENARIOS if scenarios is None else scenarios)
    if not scenarios:
        raise ValueError("run_benchmark: no scenarios")
    seeds = benchmark_seeds(n_seeds)
    out = Path(out)
    (out / "timelines").mkdir(parents=True, exist_ok=True)
    col = RunCollector(seed=0)
    simulations = _Simulations(scenarios, seeds, simulator)
    runs = _run_scenarios(
        diagnoser, simulations, scenarios, seeds, col, out, figures, max_batch_samples, progress
    )
    c0 = time.process_time()
    results: dict[str, Any] = {
        "scenarios": col.rows,
        "real_hour": _real_hour(diagnoser) if real_hour else None,
        "fault_free": _fault_free(diagnoser, hours, fault_free),
    }
    extra_cpu = time.process_time() - c0
    results["calibration"] = group_calibration(
        col, n_bootstrap, seed=0, figure=out / "reliability.png" if figures else None
    )
    results["confident_wrong"] = {
        "seconds": col.confident_wrong,
        "faulty_seconds": col.faulty_seconds,
        "share": col.confident_wrong / max(col.faulty_seconds, 1),
        "probabilities_seconds": col.confident_wrong_probabilities,
        "probabilities_share": col.confident_wrong_probabilities / max(col.faulty_seconds, 1),
    }
    results["model_std"] = {c: float(np.median(v)) if v else None for c, v in col.model_std.items()}
    results["innovation_rms"] = {
        c: float(np.median(v)) if v else None for c, v in col.innovation_rms.items()
    }
    results["effects"] = fault_effects(scenarios, inputs=effects_inputs)
    results["scenario_table"] = [_scenario_row(s) for s in scenarios]
    results["figures"] = runs.figures
    results["groups"] = json.loads(col.attrs.get("groups") or "{}")
    results["undetectable"] = json.loads(col.attrs.get("undetectable") or "[]")
    results["timing"] = runs.timing(extra_cpu, wall_s=time.perf_counter() - wall0)
    results["settings"] = {
        "n_seeds": int(n_seeds),
        "seeds": list(seeds),
        "hours": hours,
        "n_scenarios": len(scenarios),
        "full_benchmark": _is_full(scenarios),
        "fit_proof_seconds": int(col.attrs.get("fit_proof_seconds") or 0),
        **dict(settings or {}),
    }
    write_report(results, out)
    return results


class _ScenarioRuns(NamedTuple):
    """What running the diagnoser on every scenario and seed produced besides the indices."""

    figures: dict[str, str]  #: scenario name -> its timeline figure (relative to ``out``)
    simulation_cpu_s: float
    run_cpu_s: float
    samples: int  #: samples the diagnoser ran on

    def timing(self, extra_cpu_s: float, wall_s: float) -> dict[str, Any]:
        """The ``timing`` entry of ``benchmark.json``."""
        return {
            "simulation_cpu_s": self.simulation_cpu_s,
            "run_cpu_s": self.run_cpu_s,
            "run_samples": self.samples,
            "run_samples_per_cpu_s": self.samples / self.run_cpu_s if self.run_cpu_s > 0 else None,
            "fault_free_and_real_hour_cpu_s": extra_cpu_s,
            "wall_s": wall_s,
        }


def _run_scenarios(
    diagnoser: Any,
    simulations: _Simulations,
    scenarios: Sequence[BenchmarkScenario],
    seeds: Sequence[int],
    col: RunCollector,
    out: Path,
    figures: bool,
    max_batch_samples: int,
    progress: bool,
) -> _ScenarioRuns:
    """Simulate every scenario with every seed, batch by batch, run the diagnoser on each batch
    and add every run to ``col``; draw each scenario's first seed's timeline."""
    sim_cpu = run_cpu = 0.0
    samples = 0
    batches = list(_batches(scenarios, seeds, max_batch_samples))
    bar = None
    if progress:
        from bayes_fdi.progress import progress_bar

        bar = progress_bar(len(scenarios) * len(seeds), "benchmark", unit="run")
    figures_written: dict[str, str] = {}
    try:
        for batch in batches:
            c0 = time.process_time()
            parts = [simulations.take(s, run_seeds) for s, run_seeds in batch]
            recording = xr.concat(parts, dim="run", combine_attrs="drop_conflicts")
            n_runs = recording.sizes["run"]
            recording = recording.assign_coords(run=np.arange(n_runs))
            c1 = time.process_time()
            stream = diagnoser.run(strip_truth(recording))
            c2 = time.process_time()
            sim_cpu += c1 - c0
            run_cpu += c2 - c1
            samples += n_runs * recording.sizes["time"]
            r = 0
            for s, run_seeds in batch:
                for seed in run_seeds:
                    one = stream.isel(run=r)
                    col.add(s, seed, one)
                    if figures and seed == seeds[0]:
                        figures_written[s.name] = _timeline(s, one, recording.isel(run=r), out)
                    r += 1
                    if bar is not None:
                        bar.update(1)
            del stream, recording, parts
    finally:
        if bar is not None:
            bar.close()
    return _ScenarioRuns(figures_written, sim_cpu, run_cpu, samples)


def _timeline(scenario: BenchmarkScenario, one: xr.Dataset, run: xr.Dataset, out: Path) -> str:
    """Draw the decision stream ``one`` of ``run`` with the scenario's truth; its path."""
    truth = {
        "fault": scenario.fault,
        "onset": scenario.t_from,
        "label": f"{scenario.name}: {FAULT_TABLE[scenario.fault].description}",
        "strength": scenario.strength_at(one["time"].values),
    }
    path = out / "timelines" / f"{scenario.slug}.png"
    plot_timeline(one, run, truth=truth, path=path)
    return f"timelines/{scenario.slug}.png"


def _scenario_row(s: BenchmarkScenario) -> dict[str, Any]:
    """A scenario's definition, as ``benchmark.json`` lists it."""
    return {
        "name": s.name,
        "fault": s.fault,
        "mode": s.mode,
        "size": s.size,
        "strength": s.strength,
        "direction": s.direction,
        "t_on": s.t_on,
        "t_from": s.t_from,
        "t_fd": s.t_fd,
        "t_hor": s.t_hor,
    }


def _is_full(scenarios: Sequence[BenchmarkScenario]) -> bool:
    return list(scenarios) == list(SCENARIOS)


# ----------------------------------------------------------------------------------------------
# command line
# ----------------------------------------------------------------------------------------------
def run_from_cli(args: argparse.Namespace) -> int:
    """Run ``bayes-fdi benchmark`` (its options: `bayes_fdi.commands.benchmark`).

    Fit the online diagnoser on its training campaigns, run the benchmark, write the report
    (with ``--commissioning``: the commissioning benchmark,
    `bayes_fdi.benchmark.commissioning.run_from_cli`; with ``--shift``: the shift benchmark,
    `bayes_fdi.benchmark.shift.run_from_cli`)."""
    from bayes_fdi.cli_arguments import UsageError
    from bayes_fdi.default_diagnoser import fit_online_diagnoser

    if args.commissioning and getattr(args, "shift", False):
        raise UsageError("--shift and --commissioning are two benchmarks: run one at a time")
    if args.commissioning:
        from bayes_fdi.benchmark import commissioning

        return commissioning.run_from_cli(args)
    if args.plants is not None:
        raise UsageError("--plants belongs to --commissioning")
    if getattr(args, "isolation", None) is not None:
        raise UsageError("--isolation belongs to --commissioning")
    if getattr(args, "shift", False):
        from bayes_fdi.benchmark import shift

        return shift.run_from_cli(args)

    n_seeds = args.seeds if args.seeds is not None else (2 if args.small else 10)
    t0 = time.perf_counter()
    diagnoser = fit_online_diagnoser(seed=0, small=args.small, progress=not args.quiet)
    fit_s = time.perf_counter() - t0
    scenarios = [s.truncated(2400) for s in SCENARIOS] if args.small else None
    results = run_benchmark(
        diagnoser,
        args.out,
        n_seeds=n_seeds,
        scenarios=scenarios,
        hours=1.0 if args.small else 8.0,
        progress=not args.quiet,
        settings={"small": bool(args.small), "fit_wall_s": fit_s, "training_seed": 0},
    )
    total = time.perf_counter() - t0
    sys.stderr.write(
        f"benchmark: {len(results['scenarios'])} runs in {total:.0f} s "
        f"(fit {fit_s:.0f} s); report {Path(args.out) / 'benchmark.md'}\n"
    )
    return 0

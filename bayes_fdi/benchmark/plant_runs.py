"""One perturbed plant in the commissioning benchmark: commissioned on its healthy hour, then
the Step-I scenarios run on it.

`plant_benchmark` takes a plant of `bayes_fdi.benchmark.plants`, commissions a diagnoser on its
healthy hour (`bayes_fdi.commissioning.commission`), checks the twin and both diagnosers on a
held-out healthy half hour, and runs every scenario of `bayes_fdi.benchmark.scenarios` on the
plant with each of its seeds (a level-loop input of its own per scenario and seed), scored with
PICalc in the scenario's zones exactly as the DAMADICS harness scores them
(`bayes_fdi.benchmark.cases.score_case`). The default diagnoser runs on the same runs, beside
the commissioned one. For each abrupt scenario the same run without the fault (same inputs, same
noise) gives the fault's effect on the commissioned diagnoser's innovations
(`bayes_fdi.benchmark.cases.innovation_effect`).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from bayes_fdi.benchmark.cases import (
    clean_summary,
    groups_of,
    innovation_effect,
    innovation_noise,
    score_case,
    zeroed,
)
from bayes_fdi.benchmark.plants import PerturbedPlant, healthy_run, scenario_run, scenario_seed
from bayes_fdi.benchmark.real_hour import commissioning_summary
from bayes_fdi.benchmark.scenarios import SCENARIOS, BenchmarkScenario
from bayes_fdi.datasets import CHANNELS

__all__ = ["COMMISSIONING_SECONDS", "HELDOUT_SECONDS", "plant_benchmark", "plant_case_row"]

#: Healthy seconds a plant is commissioned on, and held out for the checks.
COMMISSIONING_SECONDS, HELDOUT_SECONDS = 3600, 1800
#: The position of each scenario in the table (its seeds follow it, also when truncated).
POSITION = {s.name: i for i, s in enumerate(SCENARIOS)}


def _commission(
    plant: PerturbedPlant, options: Mapping[str, Any], seconds: int
) -> tuple[Any, dict]:
    """The commissioning result (None if `check_healthy` refused the data) and its summary."""
    from bayes_fdi.commissioning import check_healthy, commission

    healthy = healthy_run(plant, seconds)
    try:
        check_healthy(healthy)
    except ValueError as exc:
        return None, {"refused": str(exc)}
    t0, c0 = time.perf_counter(), time.process_time()
    result = commission(healthy, seed=0, progress=False, **dict(options))
    summary = commissioning_summary(result)
    summary["wall_s"] = time.perf_counter() - t0
    summary["cpu_s"] = time.process_time() - c0
    return result, summary


def _scenario_cases(
    models: Mapping[str, Any],
    plant: PerturbedPlant,
    scenario: BenchmarkScenario,
    k: int,
    noise: Mapping[str, float] | None,
) -> list[dict[str, Any]]:
    position = POSITION[scenario.name]
    run = scenario_run(plant, scenario, k, position)[list(CHANNELS)]
    healthy = None
    if scenario.mode == "abrupt" and "commissioned" in models:
        healthy = scenario_run(plant, scenario, k, position, faulty=False)[list(CHANNELS)]
    rows = []
    for model, diagnoser in models.items():
        one = zeroed(diagnoser.run(run).isel(run=0))
        row = {**plant_case_row(plant, scenario, k, one), "model": model}
        if healthy is not None and model == "commissioned" and noise is not None:
            clean = zeroed(diagnoser.run(healthy).isel(run=0))
            row["effect"] = innovation_effect(
                one,
                clean,
                t_from=scenario.t_from,
                noise=noise,
                faulty_data=run,
                healthy_data=healthy,
            )
        rows.append(row)
    return rows


def plant_case_row(
    plant: PerturbedPlant, scenario: BenchmarkScenario, k: int, one: Any
) -> dict[str, Any]:
    """The scored row of one diagnosed scenario run on ``plant`` with its ``k``-th seed
    (``one``: the decision stream, its time counted in the case's frame): the case's
    identification and `score_case`'s indices."""
    t = np.asarray(one["time"].values)
    return {
        "plant": plant.index,
        "scenario": scenario.name,
        "fault": scenario.fault,
        "mode": scenario.mode,
        "size": scenario.size,
        "seed": k,
        "run_seed": scenario_seed(plant.index, k, POSITION[scenario.name]),
        **score_case(
            one,
            scenario.fault,
            t_on=scenario.t_on,
            t_from=scenario.t_from,
            t_hor=scenario.t_hor,
            strength=scenario.strength_at(t),
        ),
    }


def plant_benchmark(
    plant: PerturbedPlant,
    default: Any,
    *,
    scenarios: Sequence[BenchmarkScenario],
    n_seeds: int,
    commission_options: Mapping[str, Any] | None = None,
    commission_seconds: int = COMMISSIONING_SECONDS,
    bar: Any = None,
) -> dict[str, Any]:
    """Commission ``plant`` and run ``scenarios`` on it with ``n_seeds`` seeds.

    Parameters
    ----------
    plant
        From `bayes_fdi.benchmark.plants.draw_plant`.
    default
        The default online diagnoser, run beside the commissioned one.
    scenarios
        Scenarios of `bayes_fdi.benchmark.scenarios.SCENARIOS` (possibly truncated).
    n_seeds
        Seeds per scenario (`bayes_fdi.benchmark.plants.scenario_seed`).
    commission_options
        Extra arguments of `bayes_fdi.commissioning.commission`.
    commission_seconds
        Length of the healthy recording commissioning learns from (s).
    bar
        A progress bar advanced once per scenario and seed (or None).

    Returns
    -------
    dict
        ``plant`` (its description), ``commissioning`` (or ``{"refused": message}``),
        ``twin_check`` and ``clean`` (per model) on the held-out healthy half hour, ``noise``,
        ``cases`` (one row per scenario, seed and model) and ``timing``.
    """
    result, summary = _commission(plant, commission_options or {}, int(commission_seconds))
    summary["healthy_seconds"] = int(commission_seconds)
    models = {"default": default}
    if result is not None:
        models = {"commissioned": result.diagnoser, **models}
    heldout = healthy_run(plant, HELDOUT_SECONDS, heldout=True)
    clean_streams = {
        m: zeroed(d.run(heldout[list(CHANNELS)]).isel(run=0)) for m, d in models.items()
    }
    noise = innovation_noise(clean_streams["commissioned"]) if result is not None else None
    t0, c0 = time.perf_counter(), time.process_time()
    cases = []
    for k in range(int(n_seeds)):
        for scenario in scenarios:
            cases += _scenario_cases(models, plant, scenario, k, noise)
            if bar is not None:
                bar.update(1)
    return {
        "plant": plant.describe(),
        "commissioning": summary,
        "twin_check": result.twin.check(heldout)._asdict() if result is not None else None,
        "clean": {m: clean_summary(s) for m, s in clean_streams.items()},
        "noise": noise,
        "groups": {m: groups_of(d) for m, d in models.items()},
        "cases": cases,
        "timing": {
            "scenarios_wall_s": time.perf_counter() - t0,
            "scenarios_cpu_s": time.process_time() - c0,
        },
    }

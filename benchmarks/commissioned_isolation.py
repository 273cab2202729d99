"""What limits a commissioned diagnoser's isolation on the perturbed plants.

The commissioning benchmark names the group of only a few big abrupt faults at r_ti >= 0.9 on
each perturbed plant. This script asks which of three things sets that figure, by changing one
at a time and re-running the plant part of the benchmark (the 14 big abrupt Step-I scenarios on
each plant, ``--seeds`` benchmark seeds, the plant's own level-loop inputs, scored by the same
PICalc code and summary as ``bayes-fdi benchmark --commissioning``):

- ``--library true``: the fault libraries are transplanted with the plant's *true* physical
  parameters instead of draws from the twin's posterior (`transplant_library` is given the
  plant's `ActuatorParameters` for this run). If the twin's parameter errors set the figure,
  this raises it.
- ``--runs-per-fault N``: more transplanted runs per fault in each library (12 by default),
  on the same healthy hour: more signatures of the same background.
- ``--temperature-bounds LOW,HIGH``: the bounds of the group probabilities' calibration
  temperature (``commission``'s ``temperature_bounds``; 1,50 by default, which never
  sharpens them; 0.02,50 lets the calibration sharpen them as it did before).
- ``--detect-rate R``: a fault detected in fewer than this share of its training
  transplants is declared undetectable (``commission``'s ``detect_rate``, 0.5 by default as
  in the simulator-trained diagnoser; 0.25 classifies the faults that only their large sizes
  make detectable).
- ``--strength-draw stratified``: each fault's library strengths drawn one in each slice of the
  range per profile and sign instead of independently (`transplant_library`'s
  ``strength_draw``).
- ``--hours H``: commissioning on H hours of the plant's healthy data instead of one: the
  libraries are transplanted into windows spread over more varied healthy data (set-points and
  demand drift move the valve over a wider range).

Each line printed is one plant: big abrupt scenarios detected in at least half the seeds (as
the benchmark counts them) and, among them, those whose median group-level r_ti reaches 0.9;
then the median r_ti of the detected faults the diagnoser can isolate (not declared
undetectable). ``--json PATH`` writes every scenario's indices.

Run: ``OMP_NUM_THREADS=1 PYTHONPATH=. python benchmarks/commissioned_isolation.py
[--plants 0,1,2,3,4] [--seeds 2] [--library twin|true] [--hours 1] [--runs-per-fault 12]
[--commission-seed 0] [--isolation tree|forest] [--strength-draw uniform|stratified]
[--temperature-bounds 1,50] [--detect-rate 0.5] [--json PATH]``
(about 2.5 CPU min per plant and hour).
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

import bayes_fdi.twin as twin_module
from bayes_fdi.cli_arguments import ISOLATION_CHOICES


def _plant_rows(plant, diagnoser, scenarios, n_seeds):
    from bayes_fdi.benchmark.cases import zeroed
    from bayes_fdi.benchmark.plant_runs import POSITION, plant_case_row
    from bayes_fdi.benchmark.plants import scenario_run
    from bayes_fdi.datasets import CHANNELS

    rows = []
    for k in range(n_seeds):
        for scenario in scenarios:
            run = scenario_run(plant, scenario, k, POSITION[scenario.name])[list(CHANNELS)]
            one = zeroed(diagnoser.run(run).isel(run=0))
            rows.append(plant_case_row(plant, scenario, k, one))
    return rows


def _named_share(diagnoser, healthy, twin, seed: int) -> float:
    """Mean over the faults the diagnoser classifies of the share of their faulty seconds named
    by their group, in abrupt transplants of size 0.75 into ``healthy`` (two runs per fault,
    draws apart from the libraries': `expected_performance` with seed ``10 seed + 5``)."""
    from bayes_fdi.commissioning import LIBRARY_FAULTS
    from bayes_fdi.commissioning.expectations import expected_performance

    faults = [f for f in LIBRARY_FAULTS if f not in set(diagnoser.undetectable_)]
    rows = expected_performance(
        diagnoser, healthy, twin, faults=faults, sizes=(0.75,), seed=10 * seed + 5
    )
    return float(np.mean([r["named_share"] for r in rows]))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plants", default="0,1,2,3,4", help="plant indices, comma-separated")
    parser.add_argument("--seeds", type=int, default=2, help="benchmark seeds per scenario")
    parser.add_argument("--library", choices=("twin", "true"), default="twin")
    parser.add_argument("--strength-draw", choices=twin_module.STRENGTH_DRAWS, default="uniform")
    parser.add_argument("--hours", type=float, default=1.0, help="healthy hours commissioned on")
    parser.add_argument("--runs-per-fault", type=int, default=12)
    parser.add_argument("--commission-seed", type=int, default=0)
    parser.add_argument("--isolation", choices=ISOLATION_CHOICES, default="tree")
    parser.add_argument(
        "--temperature-bounds",
        default="1,50",
        help="bounds of the calibration temperature, LOW,HIGH (commission's temperature_bounds)",
    )
    parser.add_argument(
        "--detect-rate",
        type=float,
        default=None,
        help="share of its training transplants below which a fault is declared undetectable "
        "(commission's detect_rate; default its DETECT_RATE)",
    )
    parser.add_argument("--json", default=None, help="write every scenario's indices here")
    args = parser.parse_args(argv)
    bounds = tuple(float(b) for b in args.temperature_bounds.split(","))

    from bayes_fdi.benchmark.commissioning_summary import (
        big_abrupt_by_plant,
        confident_wrong_share,
    )
    from bayes_fdi.benchmark.plant_runs import HELDOUT_SECONDS
    from bayes_fdi.benchmark.plants import draw_plant, healthy_run
    from bayes_fdi.benchmark.scenarios import SCENARIOS
    from bayes_fdi.commissioning import DETECT_RATE, commission

    detect_rate = DETECT_RATE if args.detect_rate is None else args.detect_rate
    scenarios = [s for s in SCENARIOS if s.mode == "abrupt" and s.size == "big"]
    print(
        f"isolation: {args.isolation}; library: {args.library}, strengths "
        f"{args.strength_draw}; {args.hours:g} h healthy; "
        f"{args.runs_per_fault} runs per fault; temperature bounds {bounds}; "
        f"detect rate {detect_rate:g}; "
        f"commissioning seed {args.commission_seed}; "
        f"{args.seeds} seeds; "
        f"load average {os.getloadavg()[0]:.1f}",
        flush=True,
    )
    transplant = twin_module.transplant_library
    all_rows = []
    for index in (int(p) for p in args.plants.split(",")):
        plant = draw_plant(index)
        true = plant.parameters if args.library == "true" else None

        def library(healthy, twin, _true=true, _draw=args.strength_draw, **kwargs):
            return transplant(healthy, twin if _true is None else _true, strength_draw=_draw,
                              **kwargs)  # fmt: skip

        twin_module.transplant_library = library
        c0 = time.process_time()
        healthy = healthy_run(plant, round(3600 * args.hours))
        try:
            result = commission(
                healthy,
                runs_per_fault=args.runs_per_fault,
                isolation=args.isolation,
                temperature_bounds=bounds,
                detect_rate=detect_rate,
                seed=args.commission_seed,
                progress=False,
            )
            commissioning_cpu = time.process_time() - c0
            diagnoser = result.diagnoser
            backgrounds = {
                "the commissioning data": healthy,
                "a new healthy half hour": healthy_run(plant, HELDOUT_SECONDS, heldout=True),
            }
            named = {
                name: _named_share(diagnoser, data, result.twin, args.commission_seed)
                for name, data in backgrounds.items()
            }
        finally:
            twin_module.transplant_library = transplant
        rows = _plant_rows(plant, diagnoser, scenarios, args.seeds)
        all_rows += rows
        entry = big_abrupt_by_plant(rows)[index]
        undetectable = set(diagnoser.undetectable_)
        r_ti = {}
        for r in rows:
            if r["fault"] not in undetectable and r["indices"]["t_dt"] >= 0:  # -1: undetermined
                r_ti.setdefault(r["fault"], []).append(max(r["indices"]["r_ti"], 0.0))
        medians = [float(np.median(v)) for v in r_ti.values()]
        wrong = confident_wrong_share(rows)["share"]
        fitted = result.report["calibration"]["temperature"]
        temperature = "none" if fitted is None else f"{fitted:.3g}"
        print(
            f"plant {index}: detected {len(entry['detected'])} of {entry['scenarios']}, "
            f"r_ti >= 0.9 on {len(entry['isolated'])} "
            f"({', '.join(s.split()[0] for s in entry['isolated']) or '-'}); median r_ti of "
            f"the {len(medians)} isolable detected faults "
            f"{np.median(medians) if medians else float('nan'):.2f}; {len(diagnoser.groups_)} "
            f"groups; calibration temperature {temperature}; confident wrong group in "
            f"{100 * wrong:.2f} % of the faulty seconds; "
            f"commissioning {commissioning_cpu:.0f} CPU s",
            flush=True,
        )
        print(
            "    held-out transplants (0.75, abrupt) named by their group, mean over the "
            "classified faults: "
            + "; ".join(f"into {name} {share:.2f}" for name, share in named.items()),
            flush=True,
        )
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump({"settings": vars(args), "rows": all_rows}, f, indent=1, default=str)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The default model's isolation refitted with other classifiers, scored on held-out seeds.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/isolation_classifiers.py MODEL --out DIR \
        [--variants tree@0,tree@1,forest@0] [--seeds 4] [--shift | --plants 5,6]

The online diagnoser of ``MODEL`` (e.g. the default model, fitted with seed 0) keeps its normal
models, whitening and detector; its isolation is refitted on the signatures its own stream gives
on the default training campaigns (`bayes_fdi.default_diagnoser.simulate_online_campaigns`,
seed 0), as `fit_online_diagnoser` fits it, with each variant ``CLASSIFIER@SEED``: ``tree`` (the
k-means tree of RVCs), ``forest`` (`~bayes_fdi.diagnosis.isolation.ForestClassifier`) or
``forest-t1`` (the forest, its temperature held at 1 or above so that it never sharpens), the seed
drawing the training signatures kept per fault, the tree's design or the forest's bootstrap. The
groups come from the validation runs, the temperature from the calibration runs, as in the fit.

Each variant is then scored with the benchmark's harness on seeds the benchmark never uses:

- nominal: the 44 Step-I scenarios with the noise seeds ``31000 + k`` (the evaluation seeds are
  ``10000 + k``), half a simulated fault-free hour, no real hour;
- ``--shift``: the shift families (``sim/shift-*.toml``) with input seed 35 000 and noise seeds
  from 45 000 (the shift benchmark's are 30 000 and 40 000);
- ``--plants 5,6``: the 44 scenarios with 2 seeds on perturbed plants that the commissioning
  benchmark never scores (it scores plants 0-4; `bayes_fdi.benchmark.plants.draw_plant`), whose
  valves the default model was not trained on: the share of the faulty seconds named as a wrong
  group at p > 0.9, and the big abrupt faults at r_ti >= 0.9.

Writes ``DIR/VARIANT/`` (the benchmark's report and JSON; the ECE's interval from 100 bootstrap
resamples of the runs) and prints one line per variant (and family): the group-level ECE with its
interval, accuracy and mean confidence, the big abrupt faults with group r_ti >= 0.9, the
confident wrong share and the CPU seconds.
"""

from __future__ import annotations

import argparse
import copy
import json
import time
from pathlib import Path

import numpy as np

#: Noise seeds of the nominal selection runs are this plus the benchmark seed's index.
NOMINAL_NOISE_OFFSET = 21_000
#: Input and first noise seeds of the shift selection runs.
SHIFT_INPUT_SEED, SHIFT_NOISE_SEED = 35_000, 45_000


def refit_isolation(base, runs, variant: str):
    """A copy of ``base`` whose isolation is refitted on ``runs`` (training, validation and
    calibration fault runs) with ``variant`` (``tree@S``, ``forest@S``, ``forest-t1@S``), as
    `fit_online_diagnoser` fits it (`~bayes_fdi.diagnosis.online.training.fit_isolation`)."""
    from bayes_fdi.calibration import TemperatureScaler
    from bayes_fdi.diagnosis.isolation import ForestClassifier
    from bayes_fdi.diagnosis.online.training import detection_components, fit_isolation

    kind, _, seed_text = variant.partition("@")
    seed = int(seed_text or 0)
    if kind not in ("tree", "forest", "forest-t1"):
        raise SystemExit(f"unknown classifier {kind!r} in {variant!r}: tree, forest, forest-t1")
    fitted = fit_isolation(
        detection_components(base),
        *runs,
        classifier=None if kind == "tree" else ForestClassifier(random_state=seed),
        calibrator=TemperatureScaler(bounds=(1.0, 50.0) if kind == "forest-t1" else (0.02, 50.0)),
        group_threshold=base.group_threshold,
        detect_rate=base.detect_rate,
        max_signatures_per_fault=base.max_signatures_per_fault,
        random_state=seed,
        seconds={},
        group_rule=base.isolator_.group_rule,
    )
    model = copy.deepcopy(base)
    model.isolator_, model.undetectable_ = fitted.isolator, fitted.undetectable
    model.detection_rates_ = fitted.detection_rates
    return model


def summary(result: dict) -> str:
    """One line of a benchmark result: calibration, the report's r_ti target, confident wrong."""
    from bayes_fdi.benchmark.report import target_rows

    cal = result["calibration"]
    r_ti = next(m for t, m, _ in target_rows(result) if t.startswith("r_ti >= 0.9"))
    return (
        f"ECE {cal['ece']:.3f} [{cal['ci_low']:.3f}, {cal['ci_high']:.3f}], accuracy "
        f"{cal['accuracy']:.3f} at confidence {cal['mean_confidence']:.3f}; r_ti >= 0.9: {r_ti}; "
        f"confident wrong {100 * result['confident_wrong']['share']:.2f} %"
    )


def plant_summary(model, index: int) -> str:
    """The model on perturbed plant ``index``: the 44 scenarios with its seeds 0 and 1, scored
    as the commissioning benchmark scores its plants."""
    from bayes_fdi.benchmark.cases import zeroed
    from bayes_fdi.benchmark.commissioning_summary import confident_wrong_share
    from bayes_fdi.benchmark.plant_runs import POSITION, plant_case_row
    from bayes_fdi.benchmark.plants import draw_plant, scenario_run
    from bayes_fdi.benchmark.scenarios import SCENARIOS
    from bayes_fdi.datasets import CHANNELS

    plant = draw_plant(index)
    rows = []
    for k in (0, 1):
        for scenario in SCENARIOS:
            run = scenario_run(plant, scenario, k, POSITION[scenario.name])[list(CHANNELS)]
            rows.append(plant_case_row(plant, scenario, k, zeroed(model.run(run).isel(run=0))))
    wrong = confident_wrong_share(rows)
    r_ti: dict[str, list[float]] = {}
    for row in rows:
        if row["mode"] == "abrupt" and row["size"] == "big" and row["indices"]["t_dt"] >= 0:
            r_ti.setdefault(row["scenario"], []).append(row["indices"]["r_ti"])
    high = sum(float(np.median(v)) >= 0.9 for v in r_ti.values())
    return (
        f"confident wrong {100 * wrong['share']:.2f} % of {wrong['faulty_seconds']} faulty s; "
        f"r_ti >= 0.9 for {high} of the {len(r_ti)} big abrupt faults detected in a seed"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="a model file of a fitted OnlineDiagnoser with isolation")
    parser.add_argument("--out", required=True, help="output folder (created)")
    parser.add_argument("--variants", default="tree@0,tree@1,tree@2,forest@0,forest@1,forest@2")
    parser.add_argument("--seeds", type=int, default=4, help="noise seeds per scenario")
    parser.add_argument("--shift", action="store_true", help="under the shift families")
    parser.add_argument("--plants", default=None, help="perturbed plants, e.g. 5,6")
    args = parser.parse_args()
    import bayes_fdi.benchmark.shift as shift
    from bayes_fdi.benchmark.harness import run_benchmark
    from bayes_fdi.benchmark.scenarios import simulate_scenario
    from bayes_fdi.default_diagnoser import simulate_online_campaigns
    from bayes_fdi.deployment.fitting import load_online_model

    base = load_online_model(args.model)
    if base.isolator_ is None:
        raise SystemExit(f"{args.model}: a detection-only model has no isolation to refit")
    data = simulate_online_campaigns(seed=0, progress=False)
    runs = (data["train"], data["validation"], data["calibration"])
    # the selection seeds: the shift families' module seeds, the nominal scenarios' noise
    shift.SHIFT_INPUT_SEED, shift.SHIFT_NOISE_SEED = SHIFT_INPUT_SEED, SHIFT_NOISE_SEED
    cache: dict[str, object] = {}

    def simulator(scenario, seeds):
        if scenario.name not in cache:
            runs = simulate_scenario(scenario, [NOMINAL_NOISE_OFFSET + s for s in seeds])
            cache[scenario.name] = runs.assign_coords(run=list(seeds))
        return cache[scenario.name].sel(run=list(seeds))

    for variant in args.variants.split(","):
        t0 = time.process_time()
        model = refit_isolation(base, runs, variant)
        out = Path(args.out) / variant
        options = dict(
            n_seeds=args.seeds, hours=0.5, figures=False, progress=False, n_bootstrap=100
        )
        if args.plants:
            for plant in args.plants.split(","):
                print(f"{variant} plant {plant}: {plant_summary(model, int(plant))}", flush=True)
        elif args.shift:
            result = shift.run_shift_benchmark(model, out, **options)
            for family in result["families"]:
                name = family["name"]
                one = json.loads((out / name / "benchmark.json").read_text())
                print(f"{variant} {name}: {summary(one)}", flush=True)
        else:
            result = run_benchmark(model, out, real_hour=False, simulator=simulator, **options)
            print(f"{variant}: {summary(result)}", flush=True)
        print(f"{variant}: {time.process_time() - t0:.0f} CPU s", flush=True)


if __name__ == "__main__":
    main()

"""Would a temperature that reads the excitation calibrate the benchmarks' seconds? Measured.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/excitation_temperature.py [--model FILE] \
        [--seeds 5000,5001] [--window 120] [--covariates inputs|strength]

The group probabilities of the default model (``--model``, or the cached default model) are
recalibrated on the calibration runs of its training (the seven fault campaign files, seed 0's
calibration set) in four more ways, all from the classifier's own probabilities (the model's
calibrator set aside):

- *one temperature* (`~bayes_fdi.calibration.TemperatureScaler`);
- *a temperature that reads the excitation*: ``log T`` linear in the logarithms of covariates
  (the maximum-likelihood fit of ``benchmarks/calibration_families.py``): with
  ``--covariates inputs`` (default) the standard deviations over the trailing ``--window`` s
  of CV, of its one-second increments and of the pressure drop P1 - P2 (what an online
  diagnoser can know at each second); with ``--covariates strength`` the signature's strength,
  the absolute means since the detection of X's and F's residuals in units of their
  predictive standard deviations;
- *Dirichlet calibration* and *vector scaling* (`~bayes_fdi.calibration.DirichletScaler`,
  ``parametrization="full"`` and ``"diagonal"``; they may change the named group, so their
  accuracy is printed too).

Each is scored, beside the model's own calibration and the classifier's probabilities as they
are, on the sample the benchmark's ECE is computed on (every detected faulty second of an
isolable fault, at most 600 evenly spaced a run: the rule of
`bayes_fdi.benchmark.collection.RunCollector`) of the 44 Step-I scenarios under DGen's inputs
and under each shift family of ``sim/shift-*.toml``, with noise seeds (and, for the shift
families, input draws) that neither the training (below 1000) nor the benchmarks' evaluation
(10 000 and up) uses: default 5000 and 5001. Top-label ECE (15 bins), accuracy and mean
confidence per excitation; results to stdout and ``benchmarks/out/excitation_temperature.json``
(``excitation_temperature-strength.json`` with ``--covariates strength``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import calibration_families as families  # sibling scripts
from calibration_by_fault_kind import SELECTION_SEEDS, selection_inputs

ROOT = Path(__file__).resolve().parents[1]
#: Floor of a probability before its logarithm.
PROBABILITY_FLOOR = 1e-12
#: Floor of each input covariate before its logarithm (a constant input).
INPUT_FLOOR = families.COVARIATE_FLOOR["inputs"]


def design(cov: np.ndarray, floor: float = INPUT_FLOOR) -> np.ndarray:
    """The rows ``[1, log c_1, ..., log c_k]`` of ``log T``'s linear model (by default the
    input covariates: ``[1, log std CV, log std dCV, log std dP]``), each covariate floored at
    ``floor``."""
    return np.column_stack([np.ones(len(cov)), np.log(np.maximum(cov, floor))])


def benchmark_sample(
    calibrated, raw, runs, scenario, window: int, covariates: str = "inputs"
) -> list[tuple]:
    """Per run of ``runs`` (one scenario; ``run`` = the seed), the benchmark's calibration
    seconds as `~bayes_fdi.benchmark.collection.RunCollector` keeps them: the model's
    probabilities (stream ``calibrated``), the classifier's own (stream ``raw``), the
    covariates of mode ``covariates`` (``calibration_families.covariates_of``) and the true
    group index, as ``(proba, raw_proba, cov, true)``."""
    from bayes_fdi.benchmark.collection import RunCollector

    collector = RunCollector(seed=0)
    cov_all = families.covariates_of(runs, raw, window, covariates)
    out = []
    for i, seed in enumerate(runs["run"].values):
        kept = len(collector.index)
        collector.add(scenario, int(seed), calibrated.isel(run=i))
        if len(collector.index) == kept:  # no calibration second in this run
            continue
        keep = collector.index[-1]
        own = raw.isel(run=i)["group_proba"].transpose("time", "group").values[keep]
        out.append((collector.proba[-1], own, cov_all[i][keep], collector.true[-1]))
    return out


def score_sample(rows, classes, single, weights, floor=INPUT_FLOOR, scalers=None) -> dict:
    """ECE, accuracy and confidence of the sample ``rows``: under the model's calibration, the
    classifier's own probabilities, ``single`` (a fitted temperature scaler), the covariates'
    temperature with ``weights`` (covariates floored at ``floor``) and each fitted recalibrator
    of ``scalers`` (name -> scaler with ``transform``)."""
    proba, own, cov, true = (np.concatenate([r[k] for r in rows]) for k in range(4))
    log_own = np.log(np.maximum(own, PROBABILITY_FLOOR))
    return {
        "seconds": int(true.size),
        "model": families.scores(proba, true, classes),
        "raw": families.scores(own, true, classes),
        "one_temperature": families.scores(single.transform(own), true, classes),
        "excitation_temperature": families.scores(
            families.scaled(log_own, design(cov, floor) @ weights), true, classes
        ),
        **{
            name: families.scores(scaler.transform(own), true, classes)
            for name, scaler in (scalers or {}).items()
        },
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default=None, help="a model file (default: the default model)")
    parser.add_argument("--seeds", default=",".join(str(s) for s in SELECTION_SEEDS))
    parser.add_argument("--window", type=int, default=120)
    parser.add_argument(
        "--covariates", choices=("inputs", "strength"), default="inputs",
        help="what the temperature reads: the inputs' trailing spreads (default) or the "
        "signature's strength (calibration_families.py's modes)",
    )  # fmt: skip
    args = parser.parse_args()
    from bayes_fdi.benchmark.scenarios import SCENARIOS, simulate_scenario, strip_truth
    from bayes_fdi.benchmark.shift import shift_families
    from bayes_fdi.calibration import DirichletScaler, TemperatureScaler
    from bayes_fdi.default_diagnoser import simulate_online_campaigns
    from bayes_fdi.deployment.fitting import default_model, load_online_model
    from bayes_fdi.reporting import write_json

    seeds = [int(s) for s in args.seeds.split(",")]
    if min(seeds) < 1000 or max(seeds) >= 10_000:
        raise SystemExit("--seeds: use seeds in [1000, 10000), apart from training and evaluation")
    t0 = time.process_time()

    def load():
        return load_online_model(args.model) if args.model else default_model(progress=False)

    model, raw = load(), load()
    raw.isolator_.calibrator_ = None  # the classifier's own group probabilities
    classes = list(range(len(model.isolator_.group_labels_)))
    calibration = simulate_online_campaigns(seed=0, progress=False)["calibration"]
    mode = args.covariates
    floor = families.COVARIATE_FLOOR[mode]
    fit = [families.family_seconds(raw, ds, args.window, mode) for ds in calibration]
    own, true, cov = (np.concatenate([s[k] for s in fit]) for k in ("proba", "true", "cov"))
    single = TemperatureScaler(classes=classes).fit(own, true)
    log_own = np.log(np.maximum(own, PROBABILITY_FLOOR))
    weights = families.fit_input_temperature(log_own, true, design(cov, floor))
    scalers = {
        name: DirichletScaler(classes=classes, parametrization=kind, random_state=0).fit(own, true)
        for name, kind in (("dirichlet", "full"), ("vector_scaling", "diagonal"))
    }
    result = {
        "seeds": seeds,
        "window": args.window,
        "covariates": mode,
        "calibration_seconds": int(true.size),
        "one_temperature": float(single.temperature_),
        "excitation_weights": weights.tolist(),
        "excitations": {},
    }
    inputs = {"DGen (nominal)": None, **{f.name: f for f in shift_families()}}
    longest = max(round(s.t_hor) for s in SCENARIOS)
    for name, family in inputs.items():
        shifted = None if family is None else selection_inputs(family, seeds, longest)
        rows = []
        for scenario in SCENARIOS:
            if shifted is None:
                runs = simulate_scenario(scenario, seeds)
            else:
                runs = shifted.simulate(scenario, seeds)
            x = strip_truth(runs)
            raw_stream = raw.run(x)
            rows += benchmark_sample(model.run(x), raw_stream, runs, scenario, args.window, mode)
        result["excitations"][name] = score_sample(rows, classes, single, weights, floor, scalers)
    result["cpu_seconds"] = time.process_time() - t0
    names = ", ".join(f"log {c}" for c in families.COVARIATES[mode])
    print(
        f"fitted on {result['calibration_seconds']} calibration seconds: one temperature "
        f"{single.temperature_:.3f}; log T = "
        + " ".join(f"{w:+.3f}" for w in weights)
        + f" . [1, {names}]"
    )
    print(
        "| excitation | seconds | accuracy | ECE: the model's | as classified | one T | "
        f"T from the {mode} | Dirichlet: ECE, accuracy | vector scaling: ECE, accuracy |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, r in result["excitations"].items():
        print(
            f"| {name} | {r['seconds']} | {r['model']['accuracy']:.3f} | "
            + " | ".join(
                f"{r[k]['ece']:.3f} ({r[k]['confidence']:.3f})"
                for k in ("model", "raw", "one_temperature", "excitation_temperature")
            )
            + " | "
            + " | ".join(
                f"{r[k]['ece']:.3f}, {r[k]['accuracy']:.3f}"
                for k in ("dirichlet", "vector_scaling")
            )
            + " |"
        )
    print(f"(mean confidence in brackets) {result['cpu_seconds']:.0f} CPU s")
    suffix = "" if mode == "inputs" else f"-{mode}"
    out = ROOT / "benchmarks" / "out" / f"excitation_temperature{suffix}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    write_json(result, out)


if __name__ == "__main__":
    main()

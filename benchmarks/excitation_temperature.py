"""Would a temperature that reads the excitation calibrate the benchmarks' seconds? Measured.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/excitation_temperature.py [--model FILE] \
        [--seeds 5000,5001] [--window 120]

The group probabilities of the default model (``--model``, or the cached default model) are
recalibrated on the calibration runs of its training (the seven fault campaign files, seed 0's
calibration set) in two more ways, both from the classifier's own probabilities (the model's
calibrator set aside):

- *one temperature* (`~bayes_fdi.calibration.TemperatureScaler`);
- *a temperature that reads the excitation*: ``log T`` linear in the logarithms of the
  standard deviations over the trailing ``--window`` s of CV, of its one-second increments and
  of the pressure drop P1 - P2 (what an online diagnoser can know at each second; the
  maximum-likelihood fit of ``benchmarks/calibration_families.py``).

Each is scored, beside the model's own calibration and the classifier's probabilities as they
are, on the sample the benchmark's ECE is computed on (every detected faulty second of an
isolable fault, at most 600 evenly spaced a run: the rule of
`bayes_fdi.benchmark.collection.RunCollector`) of the 44 Step-I scenarios under DGen's inputs
and under each shift family of ``sim/shift-*.toml``, with noise seeds (and, for the shift
families, input draws) that neither the training (below 1000) nor the benchmarks' evaluation
(10 000 and up) uses: default 5000 and 5001. Top-label ECE (15 bins), accuracy and mean
confidence per excitation; results to stdout and ``benchmarks/out/excitation_temperature.json``.
"""

from __future__ import annotations

import argparse
import importlib.util
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: Noise seeds (and shift input draws) of the selection runs.
SELECTION_SEEDS = (5000, 5001)
#: Floor of each standard deviation before its logarithm (a constant input).
COVARIATE_FLOOR = 1e-5
#: Floor of a probability before its logarithm.
PROBABILITY_FLOOR = 1e-12


def _families_module():
    spec = importlib.util.spec_from_file_location(
        "calibration_families", ROOT / "benchmarks" / "calibration_families.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


families = _families_module()


def design(cov: np.ndarray) -> np.ndarray:
    """The rows ``[1, log std CV, log std dCV, log std dP]`` of ``log T``'s linear model."""
    return np.column_stack([np.ones(len(cov)), np.log(np.maximum(cov, COVARIATE_FLOOR))])


def input_covariates(runs, i: int, window: int) -> np.ndarray:
    """``(time, 3)``: the trailing standard deviations of CV, its increments and P1 - P2 of run
    ``i`` of ``runs``."""
    cv = runs["CV"].isel(run=i).values
    dp = (runs["P1"] - runs["P2"]).isel(run=i).values
    dcv = np.diff(cv, prepend=cv[:1])
    return np.stack([families.trailing_std(v[None], window)[0] for v in (cv, dcv, dp)], -1)


def benchmark_sample(calibrated, raw, runs, scenario, window: int) -> list[tuple]:
    """Per run of ``runs`` (one scenario), the benchmark's calibration seconds: the model's
    probabilities (stream ``calibrated``), the classifier's own (stream ``raw``), the input
    covariates and the true group index, as ``(proba, raw_proba, cov, true)``."""
    from bayes_fdi.benchmark.collection import CALIBRATION_SECONDS_PER_RUN
    from bayes_fdi.scoring.decision_signals import decision_signals

    out = []
    t = np.asarray(calibrated["time"].values, dtype=np.float64)
    for i in range(calibrated.sizes["run"]):
        one = calibrated.isel(run=i)
        sig = decision_signals(one, scenario.fault)
        if sig.true_group is None:
            continue
        proba = one["group_proba"].transpose("time", "group").values
        own = raw.isel(run=i)["group_proba"].transpose("time", "group").values
        faulty = (t >= scenario.t_from) & (t < scenario.t_hor)
        keep = np.flatnonzero(faulty & sig.dd & np.isfinite(proba).all(axis=1))
        if keep.size > CALIBRATION_SECONDS_PER_RUN:
            pos = np.linspace(0, keep.size - 1, CALIBRATION_SECONDS_PER_RUN)
            keep = keep[np.round(pos).astype(np.int64)]
        cov = input_covariates(runs, i, window)
        out.append((proba[keep], own[keep], cov[keep], np.full(keep.size, sig.true_group)))
    return out


def score_sample(rows, classes, single, weights) -> dict:
    """ECE, accuracy and confidence of the sample ``rows`` four ways: the model's calibration,
    the classifier's own probabilities, ``single`` (a fitted temperature scaler) and the
    excitation's temperature with ``weights``."""
    proba, own, cov, true = (np.concatenate([r[k] for r in rows]) for k in range(4))
    log_own = np.log(np.maximum(own, PROBABILITY_FLOOR))
    return {
        "seconds": int(true.size),
        "model": families.scores(proba, true, classes),
        "raw": families.scores(own, true, classes),
        "one_temperature": families.scores(single.transform(own), true, classes),
        "excitation_temperature": families.scores(
            families.scaled(log_own, design(cov) @ weights), true, classes
        ),
    }


def shift_runs(family, scenario, seeds, drawn):
    """``scenario`` simulated under the shift ``family``'s inputs ``drawn`` (one run per seed),
    with noise seed ``seed + the scenario's position``, as the shift benchmark does with its
    own seeds."""
    from bayes_fdi.actuator import simulate
    from bayes_fdi.benchmark.scenarios import SCENARIOS

    position = [s.name for s in SCENARIOS].index(scenario.name)
    drive = drawn.isel(time=slice(0, round(scenario.t_hor)))
    return simulate(drive, [scenario.fault_spec()] * len(seeds), seed=seeds[0] + position)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default=None, help="a model file (default: the default model)")
    parser.add_argument("--seeds", default=",".join(str(s) for s in SELECTION_SEEDS))
    parser.add_argument("--window", type=int, default=120)
    args = parser.parse_args()
    from bayes_fdi.benchmark.scenarios import SCENARIOS, simulate_scenario, strip_truth
    from bayes_fdi.benchmark.shift import shift_families
    from bayes_fdi.calibration import TemperatureScaler
    from bayes_fdi.campaigns.excitation import excitation_inputs
    from bayes_fdi.datasets import CHANNELS
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
    fit = [families.family_seconds(raw, ds, args.window, "inputs") for ds in calibration]
    own, true, cov = (np.concatenate([s[k] for s in fit]) for k in ("proba", "true", "cov"))
    single = TemperatureScaler(classes=classes).fit(own, true)
    log_own = np.log(np.maximum(own, PROBABILITY_FLOOR))
    weights = families.fit_input_temperature(log_own, true, design(cov))
    result = {
        "seeds": seeds,
        "window": args.window,
        "calibration_seconds": int(true.size),
        "one_temperature": float(single.temperature_),
        "excitation_weights": weights.tolist(),
        "excitations": {},
    }
    inputs = {"DGen (nominal)": None, **{f.name: f for f in shift_families()}}
    longest = max(round(s.t_hor) for s in SCENARIOS)
    for name, family in inputs.items():
        drawn = None
        if family is not None:
            drawn = excitation_inputs(family.excitation, len(seeds), longest, seed=seeds[0])
            drawn = drawn[["CV", "P1", "P2", "T1"]]
        rows = []
        for scenario in SCENARIOS:
            if family is None:
                runs = simulate_scenario(scenario, seeds)
                x = strip_truth(runs)
            else:
                runs = shift_runs(family, scenario, seeds, drawn)
                x = runs[list(CHANNELS)]
            rows += benchmark_sample(model.run(x), raw.run(x), runs, scenario, args.window)
        result["excitations"][name] = score_sample(rows, classes, single, weights)
    result["cpu_seconds"] = time.process_time() - t0
    print(
        f"fitted on {result['calibration_seconds']} calibration seconds: one temperature "
        f"{single.temperature_:.3f}; log T = "
        + " ".join(f"{w:+.3f}" for w in weights)
        + " . [1, log std CV, log std dCV, log std dP]"
    )
    print(
        "| excitation | seconds | accuracy | ECE: the model's | as classified | one T | "
        "T from the excitation |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name, r in result["excitations"].items():
        print(
            f"| {name} | {r['seconds']} | {r['model']['accuracy']:.3f} | "
            + " | ".join(
                f"{r[k]['ece']:.3f} ({r[k]['confidence']:.3f})"
                for k in ("model", "raw", "one_temperature", "excitation_temperature")
            )
            + " |"
        )
    print(f"(mean confidence in brackets) {result['cpu_seconds']:.0f} CPU s")
    out = ROOT / "benchmarks" / "out" / "excitation_temperature.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    write_json(result, out)


if __name__ == "__main__":
    main()

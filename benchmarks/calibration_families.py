"""The default diagnoser's group probabilities family by family: what one temperature can calibrate.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/calibration_families.py [--model FILE] \
        [--seed 0] [--covariates inputs|window|strength] [--window 120] [--heldout-seed 601]

A model recalibrated by one temperature (``--model``, or `fit_online_diagnoser` with
``--seed`` and ``calibration="temperature"``: the default model at seed 0 but for its
recalibration by age bins) runs over its own calibration runs: the seven fault campaign files of its
training mix (the DGen sines, sums of sines, steps and ramps, a PI level loop; abrupt and
incipient), simulated with the calibration set's seeds, the runs its temperature was fitted
on. Every detected second after a fault's onset with a group probability counts, as in the
benchmark's calibration sample. Per family: the share of those seconds whose most probable
group holds the true fault (accuracy), the mean of that probability (confidence) and the
top-label ECE (15 bins) under the model's own temperature.

Then each family in turn plays an excitation the calibration never saw (leave one family out):

- *one temperature* (`~bayes_fdi.calibration.TemperatureScaler`, fitted without bounds on the
  other six families' seconds), scored on the left-out family;
- *a temperature that reads the excitation*: ``log T`` linear in the logarithms of
  covariates (three measures of how much the excitation moves, or the signature's strength),
  fitted by maximum likelihood on the other six
  families (hand-written here: an experiment, not a calibrator of the library), scored the
  same way. ``--covariates inputs`` (default): the standard deviations over the trailing
  ``--window`` s of CV, of its one-second increments and of the pressure drop P1 - P2;
  ``--covariates window``: the variances, over the isolation window since the detection, of
  the predicted position X_hat, of the signed root of the pressure drop and of the predicted
  flow F_hat (the regressors of the signature's slopes, which its running sums hold);
  ``--covariates strength``: how far the fault has moved the residuals, the absolute means
  since the detection of X's and F's residuals in units of their predictive standard
  deviations (a signature's strength against the noise, whatever the excitation).

Both keep the named group, so they change the confidence, never the accuracy. Last, both
temperatures fitted on all seven files score held-out runs of the DGen file (the nominal
benchmark's excitation) simulated with ``--heldout-seed`` (default 601: neither a training
nor an evaluation seed). Results go to
stdout and ``benchmarks/out/calibration_families-COVARIATES.json``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: Input excitation covariates of the input-aware temperature (and the floor of each standard
#: deviation before its logarithm, below any family's median: a constant input).
COVARIATES = {
    "inputs": ("std CV", "std dCV", "std dP"),
    "window": ("var X_hat", "var s", "var F_hat"),
    "strength": ("|mean z_X|", "|mean z_F|"),
}
COVARIATE_FLOOR = {"inputs": 1e-5, "window": 1e-8, "strength": 1e-3}
#: The campaign file of the DGen sines (the nominal benchmark's excitation) in ``sim/``.
DGEN_FILE = "online-faults-abrupt"


def trailing_std(values: np.ndarray, window: int) -> np.ndarray:
    """Standard deviation over the trailing ``window`` seconds (fewer at a run's start) of
    each row of ``values`` ``(runs, time)``: what an online diagnoser can know at each second."""
    import pandas as pd

    frame = pd.DataFrame(np.asarray(values, dtype=np.float64).T)
    return frame.rolling(window, min_periods=1).std(ddof=0).to_numpy().T


def _moments_since_detection(values: np.ndarray, detected: np.ndarray):
    """Mean and variance of each row of ``values`` ``(runs, time)`` over the seconds since the
    last rising edge of ``detected`` (NaN while it is off; NaN values skipped), as the signature
    window counts them."""
    mean, var = np.full(values.shape, np.nan), np.full(values.shape, np.nan)
    for r in range(values.shape[0]):
        n = s1 = s2 = 0.0
        for t in range(values.shape[1]):
            if not detected[r, t]:
                continue
            if t == 0 or not detected[r, t - 1]:
                n = s1 = s2 = 0.0
            if np.isfinite(values[r, t]):
                n, s1, s2 = n + 1.0, s1 + values[r, t], s2 + values[r, t] ** 2
            if n > 0:
                mean[r, t] = s1 / n
                var[r, t] = max(s2 / n - (s1 / n) ** 2, 0.0)
    return mean, var


def variance_since_detection(values: np.ndarray, detected: np.ndarray) -> np.ndarray:
    """Variance of each row of ``values`` over the seconds since DD last rose
    (`_moments_since_detection`)."""
    return _moments_since_detection(values, detected)[1]


def mean_since_detection(values: np.ndarray, detected: np.ndarray) -> np.ndarray:
    """Mean of each row of ``values`` over the seconds since DD last rose
    (`_moments_since_detection`)."""
    return _moments_since_detection(values, detected)[0]


def covariates_of(runs, stream, window: int, covariates: str) -> np.ndarray:
    """``(runs, time, k)`` covariates of every second of ``runs`` (diagnosed as ``stream``),
    by the mode ``covariates`` (a key of `COVARIATES`; module docstring). The input covariates
    read ``runs`` alone (``stream`` may be None)."""
    if covariates != "inputs":
        dd = stream["DD"].transpose("run", "time").values.astype(bool)
    if covariates == "strength":  # the normal models' standardised residuals
        z = [
            ((runs[c] - stream[f"{c}_hat"]) / stream[f"{c}_hat_std"])
            .transpose("run", "time")
            .values
            for c in ("X", "F")
        ]
        return np.stack([np.abs(mean_since_detection(v, dd)) for v in z], axis=-1)
    cv = runs["CV"].transpose("run", "time").values
    dp = (runs["P1"] - runs["P2"]).transpose("run", "time").values
    if covariates == "inputs":
        dcv = np.diff(cv, axis=1, prepend=cv[:, :1])
        return np.stack([trailing_std(v, window) for v in (cv, dcv, dp)], axis=-1)
    s = np.sign(dp) * np.sqrt(np.abs(dp))
    hats = [stream[f"{c}_hat"].transpose("run", "time").values for c in ("X", "F")]
    return np.stack([variance_since_detection(v, dd) for v in (hats[0], s, hats[1])], -1)


def family_seconds(diagnoser, runs, window: int, covariates: str) -> dict[str, np.ndarray]:
    """The uncalibrated group probabilities, true groups and excitation covariates of the
    detected seconds after the onset of every run of one campaign."""
    from bayes_fdi.datasets import CHANNELS

    stream = diagnoser.run(runs[list(CHANNELS)])
    proba = stream["group_proba"].transpose("run", "time", "group").values
    dd = stream["DD"].transpose("run", "time").values.astype(bool)
    labels = [str(g) for g in stream["group"].values]
    group_of = {f: j for j, g in enumerate(labels) for f in g.split("|")}
    cov = covariates_of(runs, stream, window, covariates)
    t = runs["time"].values
    out: dict[str, list] = {"proba": [], "true": [], "cov": []}
    for r, (state, onset) in enumerate(
        zip(runs["state"].values.astype(str), runs["onset"].values, strict=True)
    ):
        if state not in group_of:  # a fault the isolation does not classify
            continue
        keep = (t >= onset) & dd[r] & np.isfinite(proba[r]).all(axis=1)
        keep &= np.isfinite(cov[r]).all(axis=1)
        out["proba"].append(proba[r][keep])
        out["true"].append(np.full(int(keep.sum()), group_of[state]))
        out["cov"].append(cov[r][keep])
    return {k: np.concatenate(v) for k, v in out.items()}


def scaled(log_p: np.ndarray, log_t: np.ndarray) -> np.ndarray:
    """Probabilities ``softmax(log_p / T)`` row by row, ``T = exp(log_t)``."""
    from scipy.special import log_softmax

    return np.exp(log_softmax(log_p / np.exp(log_t)[:, None], axis=1))


def fit_input_temperature(log_p, true, design) -> np.ndarray:
    """Weights ``w`` of ``log T = design @ w`` that maximise the likelihood of ``true``."""
    from scipy.optimize import minimize
    from scipy.special import log_softmax

    rows = np.arange(true.size)

    def nll(w):
        return -log_softmax(log_p / np.exp(design @ w)[:, None], axis=1)[rows, true].mean()

    return minimize(nll, np.zeros(design.shape[1]), method="L-BFGS-B").x


def scores(proba, true, labels) -> dict[str, float]:
    from bayes_fdi.calibration import expected_calibration_error

    return {
        "accuracy": float(np.mean(proba.argmax(axis=1) == true)),
        "confidence": float(np.mean(proba.max(axis=1))),
        "ece": float(expected_calibration_error(true, proba, classes=labels, n_bins=15).value),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", help="a model file (default: fit the default model)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--window", type=int, default=120)
    parser.add_argument("--covariates", choices=tuple(COVARIATES), default="inputs")
    parser.add_argument("--heldout-seed", type=int, default=601)
    args = parser.parse_args()
    from bayes_fdi.calibration import TemperatureScaler
    from bayes_fdi.campaigns.cache import campaign_file
    from bayes_fdi.campaigns.parsing import load_campaign
    from bayes_fdi.campaigns.simulation import simulate_campaign
    from bayes_fdi.default_diagnoser import fit_online_diagnoser, simulate_online_campaigns
    from bayes_fdi.deployment.fitting import load_online_model

    t0 = time.process_time()
    if args.model:
        diagnoser = load_online_model(args.model)
    else:
        diagnoser = fit_online_diagnoser(seed=args.seed, progress=False, calibration="temperature")
    model_scaler = diagnoser.isolator_.calibrator_
    temperature = diagnoser.isolator_.temperature()
    if temperature is None:
        raise SystemExit("the model's group probabilities are not recalibrated by a temperature")
    diagnoser.isolator_.calibrator_ = None  # the classifier's own group probabilities
    campaigns = simulate_online_campaigns(seed=args.seed, progress=False)["calibration"]
    labels = list(diagnoser.isolator_.group_labels_)
    classes = list(range(len(labels)))
    families = [str(ds.attrs["campaign"]) for ds in campaigns]
    seconds = [family_seconds(diagnoser, ds, args.window, args.covariates) for ds in campaigns]
    # the DGen family's runs with a seed neither the training nor the benchmark uses: the
    # nominal benchmark's excitation
    held = family_seconds(
        diagnoser,
        simulate_campaign(
            load_campaign(campaign_file(DGEN_FILE)), seed=args.heldout_seed, progress=False
        ),
        args.window,
        args.covariates,
    )
    names, cov_floor = COVARIATES[args.covariates], COVARIATE_FLOOR[args.covariates]
    for s in (*seconds, held):
        s["log_p"] = np.log(np.maximum(s["proba"], model_scaler.floor))
        s["design"] = np.column_stack(
            [np.ones(s["true"].size), np.log(np.maximum(s["cov"], cov_floor))]
        )

    def pooled(key: str, parts) -> np.ndarray:
        return np.concatenate([seconds[j][key] for j in parts])

    rows = []
    for k, family in enumerate(families):
        s = seconds[k]
        others = [j for j in range(len(families)) if j != k]
        one = TemperatureScaler(classes=classes).fit(
            pooled("proba", others), pooled("true", others)
        )
        w = fit_input_temperature(
            pooled("log_p", others), pooled("true", others), pooled("design", others)
        )
        rows.append({
            "family": family,
            "seconds": int(s["true"].size),
            "covariate_medians": dict(zip(names, np.median(s["cov"], 0).tolist(), strict=True)),
            "own_temperature": scores(model_scaler.transform(s["proba"]), s["true"], classes),
            "left_out_temperature": float(one.temperature_),
            "left_out": scores(one.transform(s["proba"]), s["true"], classes),
            "left_out_input_weights": w.tolist(),
            "left_out_input": scores(scaled(s["log_p"], s["design"] @ w), s["true"], classes),
        })  # fmt: skip
    everything = range(len(families))
    all_true = pooled("true", everything)
    all_own = model_scaler.transform(pooled("proba", everything))
    # both temperatures fitted on all seven files, scored on the held-out DGen runs
    w_all = fit_input_temperature(
        pooled("log_p", everything), all_true, pooled("design", everything)
    )
    heldout = {
        "seed": args.heldout_seed,
        "seconds": int(held["true"].size),
        "model_temperature": scores(model_scaler.transform(held["proba"]), held["true"], classes),
        "input_weights": w_all.tolist(),
        "input_temperature": scores(scaled(held["log_p"], held["design"] @ w_all), held["true"],
                                    classes),
        "input_temperature_in_sample": [
            scores(scaled(s["log_p"], s["design"] @ w_all), s["true"], classes)["ece"]
            for s in seconds
        ],
    }  # fmt: skip
    result = {
        "model_temperature": temperature,
        "groups": labels,
        "window": args.window,
        "covariates": args.covariates,
        "seed": args.seed,
        "all": scores(all_own, all_true, classes),
        "families": rows,
        "heldout_dgen": heldout,
        "cpu_seconds": time.process_time() - t0,
    }
    print(
        f"groups: {' · '.join(labels)}; the model's temperature {temperature:.3f}; "
        f"excitation covariates: {', '.join(names)}"
    )
    print(
        "| family | seconds | accuracy | confidence | ECE (model's T) | left out: T | ECE | "
        "ECE, T from the excitation |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        own, lo, li = r["own_temperature"], r["left_out"], r["left_out_input"]
        print(f"| {r['family']} | {r['seconds']} | {own['accuracy']:.3f} | "
              f"{own['confidence']:.3f} | {own['ece']:.3f} | {r['left_out_temperature']:.2f} | "
              f"{lo['ece']:.3f} | {li['ece']:.3f} |")  # fmt: skip
    a = result["all"]
    mean = {k: float(np.mean([r[k]["ece"] for r in rows])) for k in ("left_out", "left_out_input")}
    print(f"| all | {all_true.size} | {a['accuracy']:.3f} | {a['confidence']:.3f} | "
          f"{a['ece']:.3f} | | {mean['left_out']:.3f} (mean) | {mean['left_out_input']:.3f} "
          "(mean) |")  # fmt: skip
    result["mean_left_out_ece"] = mean
    h = heldout
    print(
        f"held-out {DGEN_FILE} runs (seed {h['seed']}, {h['seconds']} s): accuracy "
        f"{h['model_temperature']['accuracy']:.3f}; the model's temperature: confidence "
        f"{h['model_temperature']['confidence']:.3f}, ECE {h['model_temperature']['ece']:.3f}; "
        "the excitation's temperature fitted on all seven files: confidence "
        f"{h['input_temperature']['confidence']:.3f}, ECE {h['input_temperature']['ece']:.3f} "
        "(on the seven files themselves: "
        + ", ".join(f"{e:.3f}" for e in h["input_temperature_in_sample"])
        + ")"
    )
    out = ROOT / "benchmarks" / "out"
    out.mkdir(parents=True, exist_ok=True)
    from bayes_fdi.atomic import write_text

    write_text(out / f"calibration_families-{args.covariates}.json", json.dumps(result, indent=2))
    print(f"{result['cpu_seconds']:.0f} CPU s")


if __name__ == "__main__":
    main()

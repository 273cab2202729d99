"""The default online diagnoser on held-out runs of its own training excitation families.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/heldout_families.py \
        [--model FILE | --small] [--training excitation-mix|dgen] \
        [--physics-inputs command_lag,valve_law] [--f-widths 0.05,0.1,0.2] \
        [--std-coverage 0.95] [--lag-speed-limits] [--lag-as-mean] [--law-as-mean] \
        [--std-bins speed|novelty|command-novelty] [--detector cusum|variance-hold] \
        [--leave-out sine-sum|step-ramp|level-loop] \
        [--save FILE] [--runs 8] [--duration 900] [--fault-runs 1] [--fault-duration 600] \
        [--seed 900]

Fault-free part: ``--runs`` runs of ``--duration`` s per family (the DGen sines with run-to-run
variation, and the three excitation families of `bayes_fdi.actuator.excitation`: sums of sines,
steps and ramps, a PI level loop), simulated with seeds ``--seed`` .. ``--seed + 3`` (below
1000 and away from every training seed, so neither a training nor an evaluation set). After each
run's first 120 s (the start-up), per family: the RMS of the standardised residuals
``z = (y - y_hat) / std`` of X and F (1 on the training distribution if the predictive standard
deviations are calibrated), the share of seconds with DD on, DD's rising edges per hour, and
the shares of CLEAR and DAZZLED seconds.

Fault part (``--fault-runs`` > 0): every fault f1..f19 at strength 1.0 from t = 300 s after the
diagnoser's fit proof (`fault_onset`: 900 s for the default model, whose proof is 600 s; 300 s
for a model without one) in ``--fault-runs`` runs per family, each ``--fault-duration`` s plus
the proof's seconds, so that the faulty part lasts ``--fault-duration`` - 300 s: the share of
runs detected after the onset, the median detection time, the share of the detected runs whose
DD stayed on from the first detection to the run's end, and the share of detected seconds whose
diagnosed group holds the true fault (a group-level r_ti over the runs).

Without ``--model`` the script fits the diagnoser (`fit_online_diagnoser` with ``--training``
and ``--physics-inputs``, by default the training's own, ``""`` for none; the normal models'
``--std-coverage``, ``--lag-speed-limits``, ``--lag-as-mean``, ``--law-as-mean`` and
``--std-bins``, see `DynamicNormalModels`; ``--detector``: the online diagnoser's, by default
the training's, `DEFAULT_DETECTORS`;
``--leave-out FAMILY``: without that family's campaign files, which then plays an excitation the
normal models never saw; ``--save``: write it to a model file, e.g. for the benchmark). Results
go to stdout and ``benchmarks/out/heldout_families.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np
import xarray as xr

ROOT = Path(__file__).resolve().parents[1]
FAMILIES = ("dgen", "sine-sum", "step-ramp", "level-loop")
START_UP = 120
FAULT_ONSET = 300.0


def family_inputs(family: str, n_runs: int, duration: int, seed: int) -> xr.Dataset:
    """Fault-free inputs of ``family`` (the generators' defaults)."""
    from bayes_fdi.actuator import benchmark_inputs
    from bayes_fdi.actuator.excitation import (
        level_loop_inputs,
        sine_sum_inputs,
        step_ramp_inputs,
    )

    if family == "dgen":
        return benchmark_inputs(n_runs, duration, seed=seed, vary=True)
    make = {"sine-sum": sine_sum_inputs, "step-ramp": step_ramp_inputs,
            "level-loop": level_loop_inputs}[family]  # fmt: skip
    return make(n_runs, duration, seed=seed)


def fault_free_figures(diagnoser, runs: xr.Dataset) -> dict[str, float]:
    from bayes_fdi.diagnosis.normal_models.dynamic import standardised_residuals

    stream = diagnoser.run(runs)
    keep = slice(START_UP, None)
    out = {}
    for y in ("X", "F"):
        _, z = standardised_residuals(
            runs[y].values[:, keep], stream[f"{y}_hat"].values[:, keep],
            stream[f"{y}_hat_std"].values[:, keep],
        )  # fmt: skip
        out[f"z_rms_{y}"] = float(np.sqrt(np.nanmean(z**2)))
        r = runs[y].values[:, keep] - stream[f"{y}_hat"].values[:, keep]
        out[f"r_rms_{y}"] = float(np.sqrt(np.nanmean(r**2)))
    dd = stream["DD"].values[:, keep]
    hours = dd.size / 3600.0
    edges = np.sum(dd[:, 1:] & ~dd[:, :-1]) + np.sum(dd[:, 0])
    status = stream["status"].values[:, keep]
    out.update(
        dd_share=float(dd.mean()),
        alarms_per_hour=float(edges / hours),
        clear_share=float(np.mean(status == "CLEAR")),
        dazzled_share=float(np.mean(status == "DAZZLED")),
    )
    return out


def fault_onset(diagnoser) -> float:
    """The faults' onset: `FAULT_ONSET` s after the diagnoser's fit proof (``fit_proof_seconds``,
    0 for a model without one), so that a detection can be named rather than answered "model
    mismatch" because the stream has not yet seen the model fit."""
    return FAULT_ONSET + float(getattr(diagnoser, "fit_proof_seconds", 0) or 0)


def fault_figures(
    diagnoser, runs: xr.Dataset, faults: list[str], onset: float = FAULT_ONSET
) -> dict[str, float]:
    stream = diagnoser.run(runs)
    t = runs["time"].values
    after = t >= onset
    groups = json.loads(stream.attrs["groups"])
    detected, kept, delays, right, seconds = 0, 0, [], 0, 0
    for r, fault in enumerate(faults):
        dd = stream["DD"].values[r] & after
        if not dd.any():
            continue
        detected += 1
        first = int(np.argmax(dd))
        kept += int(dd[first:].all())
        delays.append(float(t[first] - onset))
        state = stream["state"].values[r][dd]
        right += int(sum(fault in groups.get(s, ()) for s in state))
        seconds += int(dd.sum())
    return {
        "detected_share": detected / len(faults),
        "kept_on_share": kept / detected if detected else float("nan"),
        "median_t_dt": float(np.median(delays)) if delays else float("nan"),
        "group_r_ti": right / seconds if seconds else float("nan"),
    }


def _physics(args: argparse.Namespace) -> tuple[str, ...] | None:
    """``--physics-inputs`` as a tuple; None (the training's own) when not given."""
    if args.physics_inputs is None:
        return None
    return tuple(n for n in args.physics_inputs.split(",") if n)


def _normal_models(args: argparse.Namespace) -> dict:
    """``normal_models=`` of the fit when ``--f-widths``, ``--std-coverage``,
    ``--lag-speed-limits``, ``--lag-as-mean``, ``--law-as-mean`` or ``--std-bins`` is given
    (the training's other settings)."""
    options = (args.f_widths, args.std_coverage, args.lag_speed_limits, args.lag_as_mean,
               args.law_as_mean, args.std_bins)  # fmt: skip
    if not any(o not in ("", None, False) for o in options):
        return {}
    from bayes_fdi.default_diagnoser import DEFAULT_PHYSICS_INPUTS, DEFAULT_STD_BINS
    from bayes_fdi.diagnosis.normal_models import DynamicNormalModels

    physics = _physics(args)
    physics = DEFAULT_PHYSICS_INPUTS[args.training] if physics is None else physics
    coverage = args.std_coverage if args.std_coverage is not None else (
        0.9 if args.training != "dgen" else None)  # fmt: skip
    grid = tuple(float(w) for w in args.f_widths.split(",") if w)
    widths = {"f_widths": grid} if grid else {}
    return {"normal_models": DynamicNormalModels(
        physics_inputs=physics, std_coverage=coverage, lag_speed_limits=args.lag_speed_limits,
        lag_as_mean=args.lag_as_mean, law_as_mean=args.law_as_mean,
        std_bins=args.std_bins or DEFAULT_STD_BINS[args.training], random_state=0, **widths,
    )}  # fmt: skip


def _leave_out(training: str, family: str) -> str:
    """The name of ``training`` without the campaign files of ``family`` (registered in
    `TRAININGS`, `DEFAULT_PHYSICS_INPUTS`, `DEFAULT_STD_BINS` and `DEFAULT_DETECTORS` under
    that name for this process)."""
    from bayes_fdi.default_diagnoser import (
        DEFAULT_DETECTORS,
        DEFAULT_PHYSICS_INPUTS,
        DEFAULT_STD_BINS,
        TRAININGS,
    )

    if family not in FAMILIES[1:]:
        raise SystemExit(f"--leave-out must be one of {', '.join(FAMILIES[1:])}")
    kept = {k: tuple(f for f in files if not f[0].endswith(family))
            for k, files in TRAININGS[training].items()}  # fmt: skip
    if kept == TRAININGS[training]:
        raise SystemExit(f"the training {training!r} has no campaign files of {family!r}")
    name = f"{training}-without-{family}"
    TRAININGS[name] = kept
    DEFAULT_PHYSICS_INPUTS[name] = DEFAULT_PHYSICS_INPUTS[training]
    DEFAULT_STD_BINS[name] = DEFAULT_STD_BINS[training]
    DEFAULT_DETECTORS[name] = DEFAULT_DETECTORS[training]
    return name


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", help="a model file of bayes-fdi fit (default: fit one)")
    parser.add_argument("--small", action="store_true", help="fit the small default model")
    parser.add_argument("--training", default="excitation-mix", help="training of the diagnoser")
    parser.add_argument("--physics-inputs", default=None, help="comma-separated physics inputs")
    parser.add_argument("--f-widths", default="", help="flow model's width grid (comma-separated)")
    parser.add_argument(
        "--std-coverage",
        type=float,
        default=None,
        help="coverage of the normal models' std factors (default: the training's)",
    )
    parser.add_argument(
        "--lag-speed-limits",
        action="store_true",
        help="the command lag limits the stem's speed (fitted limits)",
    )
    parser.add_argument(
        "--lag-as-mean",
        action="store_true",
        help="the position model learns X minus the lagged command",
    )
    parser.add_argument(
        "--law-as-mean",
        action="store_true",
        help="the flow model learns F minus the valve law's flow (needs the valve_law input)",
    )
    parser.add_argument(
        "--std-bins",
        default=None,
        choices=("speed", "novelty", "command-novelty"),
        help="what bins the normal models' std factors: speed, novelty or command-novelty "
        "(default: the training's)",
    )
    parser.add_argument(
        "--leave-out",
        default=None,
        help="fit without this training family's campaign files: sine-sum, step-ramp or level-loop",
    )
    parser.add_argument(
        "--detector",
        default=None,
        choices=("cusum", "variance-hold"),
        help="the diagnoser's detector (default: the training's)",
    )
    parser.add_argument("--save", help="write the fitted diagnoser to this model file")
    parser.add_argument("--runs", type=int, default=8)
    parser.add_argument("--duration", type=int, default=900)
    parser.add_argument("--fault-runs", type=int, default=1)
    parser.add_argument("--fault-duration", type=int, default=600)
    parser.add_argument("--seed", type=int, default=900)
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "out" / "heldout_families.json"))
    args = parser.parse_args()
    if not (0 <= args.seed and args.seed + len(FAMILIES) + 60 < 1000):
        raise SystemExit("--seed must keep every seed below 1000 (away from the benchmark's)")
    from bayes_fdi.actuator import Fault, simulate
    from bayes_fdi.actuator.faults import FAULT_NAMES
    from bayes_fdi.campaigns.spec import FAULT_DIRECTION
    from bayes_fdi.diagnosis import OnlineDiagnoser

    if args.model:
        diagnoser = OnlineDiagnoser.load(args.model)
    else:
        from bayes_fdi.default_diagnoser import fit_online_diagnoser

        t_fit = time.process_time()
        normal_models = _normal_models(args)  # the named training's settings
        detector = {"detector": args.detector} if args.detector else {}
        if args.leave_out:
            args.training = _leave_out(args.training, args.leave_out)
        diagnoser = fit_online_diagnoser(
            small=args.small, progress=False, training=args.training,
            physics_inputs=_physics(args), **normal_models, **detector,
        )  # fmt: skip
        print(f"fitted in {time.process_time() - t_fit:.0f} CPU s; threshold "
              f"{diagnoser.threshold_:.2f}, DGN0 {', '.join(diagnoser.undetectable_) or 'none'}; "
              f"widths {diagnoser.normal_models_.widths_}, command lag "
              f"{getattr(diagnoser.normal_models_, 'command_lag_', None)}", flush=True)  # fmt: skip
        if args.save:
            diagnoser.save(args.save)
    results: dict[str, dict[str, float]] = {}
    t0 = time.process_time()
    for k, family in enumerate(FAMILIES):
        seed = args.seed + k
        drive = family_inputs(family, args.runs, args.duration, seed)
        runs = simulate(drive, None, seed=seed + 20)
        results[family] = fault_free_figures(diagnoser, runs)
        if args.fault_runs > 0:
            faults = [f for f in FAULT_NAMES for _ in range(args.fault_runs)]
            onset = fault_onset(diagnoser)
            duration = args.fault_duration + int(onset - FAULT_ONSET)
            drive = family_inputs(family, len(faults), duration, seed + 40)
            plan = [Fault(f, float(FAULT_DIRECTION[f]), onset, "abrupt", 0.0) for f in faults]
            runs = simulate(drive, plan, seed=seed + 60)
            results[family].update(fault_figures(diagnoser, runs, faults, onset))
        print(family, {k: round(v, 4) for k, v in results[family].items()}, flush=True)
    print(f"load average {os.getloadavg()[0]:.1f}; {time.process_time() - t0:.0f} CPU s")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()

"""False alarms in fault-free hours, draw by draw, under DGen's inputs and each shift family.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/fault_free_draws.py [--model FILE] \
        [--excitations dgen,chirp,flow-loop,telegraph] [--seeds 5002-5009] [--hours 8] \
        [--json PATH]

The benchmarks judge the false-alarm target (at most one alarm in 8 fault-free hours) on one
draw of 8 hours per excitation: under DGen's sines the inputs never change from draw to draw
(only the noise does), but a shift family draws its inputs (set points, steps, the level loop's
demand) with the seed, so one draw may pass or fail by what it happens to visit. This script
draws ``--hours`` fault-free hours with each seed of ``--seeds`` (a range ``A-B`` or a comma list;
by default eight seeds in the selection range, apart from the training's (below 1000) and the
benchmarks' (10 000 and up)), for each excitation, as the benchmarks draw them
(`~bayes_fdi.benchmark.scenarios.fault_free_hours`,
`~bayes_fdi.benchmark.shift.family_fault_free`), runs the model (``--model``, or the cached
default model) over them and prints per draw the alarms after the set-up zone (rising edges of
DD, an alarm still on when the set-up zone ends counting one, as the benchmarks count them),
the share of seconds with DD on, and what the model answered while it was on (its states, and
the seconds it was BLURRED: a confident fault), then per excitation the draws within the target
(at most one alarm in 8 hours and DD on at most 1 % of the time) and the mean alarms per 8 hours.
Results to stdout and ``--json`` (default ``benchmarks/out/fault_free_draws.json``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from calibration_by_fault_kind import fault_free_alarms  # sibling script

ROOT = Path(__file__).resolve().parents[1]
__all__ = ["main", "parse_seeds", "summary"]

#: The target: at most this many alarms in 8 fault-free hours, and DD on at most this share of
#: the time (the benchmarks' `~bayes_fdi.benchmark.report_detection.fault_free_target`).
MAX_ALARMS_PER_8H = 1
MAX_DD_ON = 0.01


def parse_seeds(text: str) -> list[int]:
    """``"A-B"`` (inclusive) or ``"a,b,c"`` as a list of seeds."""
    if "-" in text and "," not in text:
        low, high = (int(v) for v in text.split("-"))
        if high < low:
            raise ValueError(f"--seeds: empty range {text!r}")
        return list(range(low, high + 1))
    return [int(v) for v in text.split(",")]


def summary(draws: list[dict], hours: float) -> dict:
    """Draws within the target (alarms scaled to 8 hours at most `MAX_ALARMS_PER_8H` and DD on
    at most `MAX_DD_ON` of the time), the mean alarms per 8 hours and the mean share of DD on
    over the draws."""
    per_8h = [d["alarms"] * 8.0 / hours for d in draws]
    return {
        "n_draws": len(draws),
        "within_target": sum(
            a <= MAX_ALARMS_PER_8H and d["dd_on"] <= MAX_DD_ON
            for a, d in zip(per_8h, draws, strict=True)
        ),
        "mean_alarms_per_8h": float(np.mean(per_8h)),
        "mean_dd_on": float(np.mean([d["dd_on"] for d in draws])),
        "blurred_seconds": int(sum(d.get("blurred", 0) for d in draws)),
    }


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default=None, help="a model file (default: the default model)")
    parser.add_argument("--excitations", default="dgen,chirp,flow-loop,telegraph")
    parser.add_argument("--seeds", default="5002-5009")
    parser.add_argument("--hours", type=float, default=8.0)
    parser.add_argument("--json", default=None, help="where to write the results")
    args = parser.parse_args(argv)
    from bayes_fdi.benchmark.scenarios import T_ON, fault_free_hours
    from bayes_fdi.benchmark.shift import family_fault_free, shift_families
    from bayes_fdi.deployment.fitting import default_model, load_online_model
    from bayes_fdi.reporting import write_json

    seeds = parse_seeds(args.seeds)
    if min(seeds) < 1000 or max(seeds) >= 10_000:
        raise SystemExit("--seeds: use seeds in [1000, 10000), apart from training and evaluation")
    families = {f.name: f for f in shift_families()}
    names = args.excitations.split(",")
    unknown = [n for n in names if n != "dgen" and n not in families]
    if unknown:
        raise SystemExit(f"--excitations: dgen or {', '.join(families)}; got {unknown}")
    diagnoser = load_online_model(args.model) if args.model else default_model(progress=False)
    t0 = time.process_time()
    result = {"model": args.model or "default", "hours": args.hours, "seeds": seeds}
    print("| excitation | seed | alarms | DD on | answers while on (s) | BLURRED (s) |")
    print("|---|---:|---:|---:|---|---:|")
    for name in names:
        draws = []
        for seed in seeds:
            if name == "dgen":
                runs = fault_free_hours(args.hours, seed=seed)
            else:
                runs = family_fault_free(families[name], args.hours, warmup=T_ON, seed=seed)
            found = fault_free_alarms(diagnoser, runs, T_ON, answers=True)
            draws.append({"seed": seed, **found})
            d = draws[-1]
            said = ", ".join(f"{k} {v}" for k, v in list(d["answers"].items())[:4]) or "-"
            print(
                f"| {name} | {seed} | {d['alarms']} | {100 * d['dd_on']:.1f} % | {said} | "
                f"{d['blurred']} |",
                flush=True,
            )
        result[name] = {"draws": draws, **summary(draws, args.hours)}
    result["cpu_seconds"] = time.process_time() - t0
    for name in names:
        s = result[name]
        print(
            f"{name}: {s['within_target']} of {s['n_draws']} draws within the target (at most "
            f"{MAX_ALARMS_PER_8H} alarm in 8 h, DD on at most {100 * MAX_DD_ON:g} %); "
            f"{s['mean_alarms_per_8h']:.2f} alarms per 8 h on average, DD on "
            f"{100 * s['mean_dd_on']:.1f} % of the time"
        )
    print(f"{result['cpu_seconds']:.0f} CPU s")
    out = Path(args.json) if args.json else ROOT / "benchmarks" / "out" / "fault_free_draws.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    write_json(result, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

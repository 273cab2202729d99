"""The group probabilities' calibration of a diagnoser, abrupt and incipient faults apart.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/calibration_by_fault_kind.py [--model FILE] \
        [--seeds 5000,5001] [--excitation dgen|chirp|flow-loop|telegraph] [--fault-free-hours 8]

The benchmark's group-level ECE pools the detected faulty seconds of every scenario (at most
600 a run). This script scores the same sample on the 44 Step-I scenarios with noise seeds that
neither the training (below 1000) nor the benchmark's evaluation (10 000 and up) uses (default
5000 and 5001), with the benchmark's own collector (`bayes_fdi.benchmark.collection`), and
reports the top-label ECE, accuracy and mean confidence of the abrupt scenarios' seconds, of the
incipient scenarios' and of both together, the same by the signature's age (seconds since the
detection: `AGE_EDGES`), the scenarios whose named group is most often wrong, and the faulty
seconds answered with a wrong group at p > 0.9 (confident wrong), by
scenario. Beside them, the detection on the same runs: the big abrupt scenarios detected in
every seed, the runs whose DD stays on from its first rising edge, the first detection's median
per scenario, the fault-free parts' median r_fd; and ``--fault-free-hours H`` (0: none)
fault-free hours simulated with the seed after the last of ``--seeds``, with the alarms in them
(`alarms_after`: rising edges of DD, an alarm still on when the set-up zone ends counting
one). ``--excitation`` runs all of it under a shift family of ``sim/shift-*.toml``
(`selection_inputs`: its inputs drawn with the first seed, the noise of each scenario with the
first seed plus its position) instead of DGen's sines. ``--model``: a
model file (default: the default model, fitted and cached on first use). Results go to stdout
and ``benchmarks/out/calibration_by_fault_kind.json`` (``calibration_by_fault_kind-FAMILY.json``
under a shift family).
"""

from __future__ import annotations

import argparse
import itertools
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: Noise seeds of the selection runs: neither training (< 1000) nor evaluation (>= 10 000).
SELECTION_SEEDS = (5000, 5001)
#: Edges (s since the detection) of the age bins of the accuracy and confidence table.
AGE_EDGES = (0.0, 10.0, 30.0, 100.0, 300.0, 600.0, 1200.0, float("inf"))
#: Where the results are written.
OUT = ROOT / "benchmarks" / "out" / "calibration_by_fault_kind.json"


def selection_inputs(family, seeds, duration: int):
    """The shift ``family``'s `~bayes_fdi.benchmark.shift.ShiftInputs` for selection
    ``seeds``: inputs drawn with the first seed, each scenario's noise with the first seed plus
    its position (the shift benchmark draws the same way with seeds of its own)."""
    from bayes_fdi.benchmark.shift import ShiftInputs

    first = int(seeds[0])
    return ShiftInputs(
        family, seeds, duration, first_seed=first, input_seed=first, noise_seed=first
    )


def _summary(col, n_bootstrap: int) -> dict:
    from bayes_fdi.benchmark.collection import group_calibration

    cal = group_calibration(col, n_bootstrap, seed=0, figure=None)
    keys = ("n_seconds", "n_runs", "ece", "ci_low", "ci_high", "accuracy", "mean_confidence")
    return {k: cal[k] for k in keys if k in cal}


def collect(diagnoser, scenarios, seeds, simulate_runs=None) -> tuple[dict, list[dict]]:
    """Stream every scenario with every seed through ``diagnoser`` and collect the benchmark's
    calibration sample three ways: ``{"abrupt": ..., "incipient": ..., "all": ...}``
    (`~bayes_fdi.benchmark.collection.RunCollector`), and one row per run that gave calibration
    seconds (its scenario, seed, true group, the group it names most often, accuracy and mean
    confidence of its seconds). ``simulate_runs(scenario, seeds)``: the runs of a scenario
    (default: `~bayes_fdi.benchmark.scenarios.simulate_scenario` under DGen's inputs)."""
    from bayes_fdi.benchmark.collection import RunCollector
    from bayes_fdi.benchmark.scenarios import simulate_scenario, strip_truth

    simulate_runs = simulate_runs or simulate_scenario

    collectors = {k: RunCollector(seed=0) for k in ("abrupt", "incipient", "all")}
    per_run = []
    for scenario in scenarios:
        stream = diagnoser.run(strip_truth(simulate_runs(scenario, seeds)))
        kind = collectors["abrupt" if scenario.mode == "abrupt" else "incipient"]
        for i, seed in enumerate(seeds):
            one = stream.isel(run=i)
            n_before = len(kind.proba)
            kind.add(scenario, seed, one)
            collectors["all"].add(scenario, seed, one)
            if len(kind.proba) > n_before:  # this run gave calibration seconds
                proba, true = kind.proba[-1], kind.true[-1]
                named = np.argmax(proba, axis=1)
                per_run.append(
                    {
                        "scenario": scenario.name,
                        "seed": int(seed),
                        "seconds": int(true.size),
                        "true_group": kind.labels[int(true[0])],
                        "named": kind.labels[int(np.bincount(named).argmax())],
                        "accuracy": float(np.mean(named == true)),
                        "confidence": float(np.mean(np.max(proba, axis=1))),
                    }
                )
    return collectors, per_run


def by_age(collector, edges=AGE_EDGES) -> list[dict]:
    """Accuracy and mean confidence of ``collector``'s calibration sample per bin of the
    signature's age (``[low, high)`` s since the detection), bins without seconds left out:
    where the probabilities are under- (accuracy above confidence) or over-confident."""
    if not collector.proba:
        return []
    proba = np.concatenate(collector.proba)
    true = np.concatenate(collector.true)
    age = np.concatenate(collector.age)
    right = proba.argmax(axis=1) == true
    top = proba.max(axis=1)
    rows = []
    for low, high in itertools.pairwise(edges):
        m = (age >= low) & (age < high)
        if m.any():
            rows.append({"low": low, "high": high, "seconds": int(m.sum()),
                         "accuracy": float(right[m].mean()),
                         "mean_confidence": float(top[m].mean())})  # fmt: skip
    return rows


def detection_summary(collector) -> dict:
    """The detection on ``collector``'s runs: ``big_abrupt`` (scenario name -> seeds, seeds
    with a first detection, seeds whose DD stayed on from it, median first-detection time in s
    or None), ``detected_every_seed`` and ``kept`` / ``detected_runs`` over those scenarios,
    ``median_r_fd`` and ``runs_r_fd_above`` (0.01) over every run."""
    from bayes_fdi.benchmark.report_detection import scenario_name

    big: dict[str, dict] = {}
    for row in collector.rows:
        if row["mode"] != "abrupt" or row["size"] != "big":
            continue
        first = row["first_detection"]
        e = big.setdefault(scenario_name(row), {"seeds": 0, "detected": 0, "kept": 0, "t": []})
        e["seeds"] += 1
        if first["t_dt_first"] >= 0:
            e["detected"] += 1
            e["kept"] += int(bool(first["dd_permanent"]))
            e["t"].append(first["t_dt_first"])
    for e in big.values():
        e["t_dt_first_median"] = float(np.median(e.pop("t"))) if e["detected"] else None
    r_fd = [row["indices"]["r_fd"] for row in collector.rows]
    return {
        "big_abrupt": big,
        "detected_every_seed": sum(e["detected"] == e["seeds"] for e in big.values()),
        "detected_runs": sum(e["detected"] for e in big.values()),
        "kept": sum(e["kept"] for e in big.values()),
        "median_r_fd": float(np.median(r_fd)) if r_fd else float("nan"),
        "runs_r_fd_above": sum(r > 0.01 for r in r_fd),
    }


def alarms_after(time, dd, warmup: float) -> dict:
    """Alarms and the share of seconds with DD on after ``warmup`` s, counted as the benchmarks
    count them: the rising edges of DD after the warm-up, an alarm still on when the warm-up
    ends counting one."""
    from bayes_fdi.scoring.decision_signals import decision_high, rising_edges

    after = np.asarray(time, dtype=np.float64) >= warmup
    on = decision_high(dd)[after]
    return {"alarms": rising_edges(on), "dd_on": float(np.mean(on))}


def fault_free_alarms(diagnoser, runs, warmup: float, *, answers: bool = False) -> dict:
    """`alarms_after` of the diagnoser's stream over the fault-free ``runs`` (one run); with
    ``answers``, also ``answers`` (the stream's state in the seconds with DD on after the
    warm-up: state -> seconds) and ``blurred`` (those seconds with a confident status,
    BLURRED)."""
    from bayes_fdi.datasets import CHANNELS
    from bayes_fdi.scoring.decision_signals import decision_high

    stream = diagnoser.run(runs[list(CHANNELS)]).isel(run=0)
    time, dd = stream["time"].values, stream["DD"].values
    out = alarms_after(time, dd, warmup)
    if answers:
        on = decision_high(dd) & (np.asarray(time, dtype=np.float64) >= warmup)
        states = np.asarray(stream["state"].values).astype(str)[on]
        status = np.asarray(stream["status"].values).astype(str)[on]
        names, counts = np.unique(states, return_counts=True)
        order = np.argsort(-counts, kind="stable")
        out["answers"] = {str(names[i]): int(counts[i]) for i in order}
        out["blurred"] = int(np.sum(status == "BLURRED"))
    return out


def confident_wrong_summary(collector) -> dict:
    """The faulty seconds answered with a wrong group at p > 0.9 (the benchmark's confident
    wrong count) over every run of ``collector``: ``seconds``, ``faulty_seconds``, ``share``,
    and ``scenarios`` (scenario name -> its seconds, most first; those with any)."""
    from bayes_fdi.benchmark.report_detection import scenario_name

    per: dict[str, int] = {}
    for row in collector.rows:
        if row["confident_wrong_seconds"]:
            name = scenario_name(row)
            per[name] = per.get(name, 0) + row["confident_wrong_seconds"]
    total = collector.faulty_seconds
    return {
        "seconds": collector.confident_wrong,
        "faulty_seconds": total,
        "share": collector.confident_wrong / total if total else float("nan"),
        "scenarios": dict(sorted(per.items(), key=lambda kv: -kv[1])),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default=None, help="a model file (default: the default model)")
    parser.add_argument("--seeds", default=",".join(str(s) for s in SELECTION_SEEDS))
    parser.add_argument("--bootstrap", type=int, default=200)
    parser.add_argument("--excitation", default="dgen", help="dgen, or a shift family's name")
    parser.add_argument("--fault-free-hours", type=float, default=0.0)
    args = parser.parse_args()
    from bayes_fdi.benchmark.scenarios import SCENARIOS, T_ON, fault_free_hours
    from bayes_fdi.benchmark.shift import shift_families
    from bayes_fdi.deployment.fitting import default_model, load_online_model
    from bayes_fdi.reporting import write_json

    seeds = [int(s) for s in args.seeds.split(",")]
    if min(seeds) < 1000 or max(seeds) >= 10_000:
        raise SystemExit("--seeds: use seeds in [1000, 10000), apart from training and evaluation")
    families = {f.name: f for f in shift_families()}
    if args.excitation != "dgen" and args.excitation not in families:
        raise SystemExit(f"--excitation: dgen or one of {', '.join(families)}")
    diagnoser = load_online_model(args.model) if args.model else default_model(progress=True)
    t0 = time.process_time()
    simulate_runs, free = None, None
    free_seed, hours = max(seeds) + 1, args.fault_free_hours
    if args.excitation != "dgen":
        longest = max(round(s.t_hor) for s in SCENARIOS)
        shifted = selection_inputs(families[args.excitation], seeds, longest)
        simulate_runs = shifted.simulate
        if hours > 0:
            free = shifted.fault_free(hours, warmup=T_ON, seed=free_seed)
    elif hours > 0:
        free = fault_free_hours(hours, seed=free_seed)
    collectors, per_run = collect(diagnoser, SCENARIOS, seeds, simulate_runs)
    result = {
        "seeds": seeds,
        "model": args.model or "default",
        "cpu_seconds": time.process_time() - t0,
        **{k: _summary(c, args.bootstrap) for k, c in collectors.items()},
        "by_age": {k: by_age(c) for k, c in collectors.items()},
        "confident_wrong": confident_wrong_summary(collectors["all"]),
        "detection": detection_summary(collectors["all"]),
        "excitation": args.excitation,
        "runs": per_run,
    }
    if free is not None:
        result["fault_free"] = {
            "hours": hours, "seed": free_seed, **fault_free_alarms(diagnoser, free, T_ON)
        }  # fmt: skip
    print("| scenarios | seconds | runs | ECE [95 % interval] | accuracy | mean confidence |")
    print("|---|---:|---:|---|---:|---:|")
    for name in ("abrupt", "incipient", "all"):
        s = result[name]
        print(
            f"| {name} | {s['n_seconds']} | {s['n_runs']} | {s['ece']:.3f} [{s['ci_low']:.3f}, "
            f"{s['ci_high']:.3f}] | {s['accuracy']:.3f} | {s['mean_confidence']:.3f} |"
        )
    print("\n| scenarios | seconds since the detection | seconds | accuracy | mean confidence |")
    print("|---|---|---:|---:|---:|")
    for name in ("abrupt", "incipient", "all"):
        for b in result["by_age"][name]:
            print(
                f"| {name} | {b['low']:g}-{b['high']:g} | {b['seconds']} | {b['accuracy']:.3f} "
                f"| {b['mean_confidence']:.3f} |"
            )
    print("\nruns whose seconds are named wrong most often:")
    for row in sorted(per_run, key=lambda r: r["accuracy"])[:12]:
        print(
            f"  {row['scenario']} (seed {row['seed']}): true {row['true_group']}, named "
            f"{row['named']}; right in {row['accuracy']:.0%} at confidence {row['confidence']:.2f}"
        )
    cw = result["confident_wrong"]
    print(
        f"\nconfident (p > 0.9) wrong group: {cw['seconds']} of {cw['faulty_seconds']} faulty "
        f"seconds ({100 * cw['share']:.3f} %)"
    )
    for name, seconds in cw["scenarios"].items():
        print(f"  {name}: {seconds} s")
    det = result["detection"]
    print(
        f"\ndetection: big abrupt scenarios detected in every seed {det['detected_every_seed']} "
        f"of {len(det['big_abrupt'])}; DD kept on from the first detection in {det['kept']} of "
        f"{det['detected_runs']} detected runs; median r_fd {det['median_r_fd']:.3f} "
        f"({det['runs_r_fd_above']} runs above 0.01)"
    )
    medians = {name: e["t_dt_first_median"] for name, e in det["big_abrupt"].items()}
    print(
        "  first detection, median s: "
        + "; ".join(f"{name} {'-' if t is None else f'{t:g}'}" for name, t in medians.items())
    )
    if "fault_free" in result:
        ff = result["fault_free"]
        print(
            f"{ff['hours']:g} fault-free hours (seed {ff['seed']}): {ff['alarms']} alarms, "
            f"DD on {100 * ff['dd_on']:.2f} %"
        )
    result["cpu_seconds"] = time.process_time() - t0
    print(f"\n{result['cpu_seconds']:.0f} CPU s")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    out = OUT if args.excitation == "dgen" else OUT.with_name(f"{OUT.stem}-{args.excitation}.json")
    write_json(result, out)


if __name__ == "__main__":
    main()

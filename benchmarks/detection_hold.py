"""The detection decision's hold: DD permanence, detection times and false alarms, hold 0 vs on.

Fits the default online diagnoser once (``--small``: the quick version), then scores the same
fitted models with the detection decision's hold at 0 (plain hysteresis) and at the fitted
value (`bayes_fdi.diagnosis.detection.decision.CLEAR_HOLD`), swapping only the decision:

- on the training campaigns' abrupt fault runs (seeds below 1000): for the runs detected after
  the onset, how often DD drops after its first detection and the longest drop, the in-fault
  gaps the hold must bridge;
- on the DAMADICS benchmark's scenarios (``run_benchmark``, evaluation seeds >= 10 000):
  per scenario t_dt (last rising edge) and t_dt_first, the share of detected big abrupt runs
  whose DD stays on, median r_fd;
- on ``--hours`` simulated fault-free hours: alarms and the share of time DD is on.

Usage (repository root)::

    OMP_NUM_THREADS=1 PYTHONPATH=$PWD .venv/bin/python benchmarks/detection_hold.py --small
    OMP_NUM_THREADS=1 PYTHONPATH=$PWD .venv/bin/python benchmarks/detection_hold.py --seeds 10

Writes ``--out`` (default ``benchmarks/out/detection_hold``): ``detection_hold.json`` and one
benchmark report per hold.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from bayes_fdi.benchmark.harness import run_benchmark
from bayes_fdi.benchmark.report_detection import first_detection_summary
from bayes_fdi.benchmark.scenarios import SCENARIOS, fault_free_hours
from bayes_fdi.datasets import CHANNELS
from bayes_fdi.default_diagnoser import fit_online_diagnoser, simulate_online_campaigns
from bayes_fdi.diagnosis.detection.decision import CLEAR_HOLD, DetectionDecision
from bayes_fdi.scoring.decision_signals import decision_high, rising_edges


def with_hold(diagnoser: Any, hold: int) -> Any:
    """``diagnoser`` with its decision's hold set to ``hold`` (everything else unchanged)."""
    d = diagnoser.decision_
    diagnoser.decision_ = DetectionDecision(d.threshold, d.clear, d.n_channels, hold)
    diagnoser.reset()
    return diagnoser


def training_gaps(diagnoser: Any, runs: list) -> dict[str, Any]:
    """DD drops after the first detection on abrupt training fault runs of strength >= 0.5."""
    drops, longest, detected = 0, [], 0
    for ds in runs:
        keep = (np.asarray(ds["profile"].values).astype(str) == "abrupt") & (
            np.asarray(ds["strength"].values, dtype=float) >= 0.5
        )
        if not keep.any():
            continue
        part = ds.isel(run=np.flatnonzero(keep))
        stream = diagnoser.run(part[list(CHANNELS)].reset_coords(drop=True))
        t = stream["time"].values
        for r in range(part.sizes["run"]):
            dd = decision_high(stream["DD"].values[r]) & (t >= float(part["onset"].values[r]))
            if not dd.any():
                continue
            detected += 1
            after = dd[int(np.argmax(dd)) :]
            if not after.all():
                drops += 1
                off = np.flatnonzero(~after)
                runs_off = np.split(off, np.flatnonzero(np.diff(off) > 1) + 1)
                inner = [len(g) for g in runs_off if g[-1] < after.size - 1]
                longest.append(max(inner) if inner else int(off.size))
    return {"detected": detected, "dropped": drops, "longest_drops": sorted(longest)}


def fault_free(diagnoser: Any, hours: float) -> dict[str, Any]:
    ds = fault_free_hours(hours)
    stream = diagnoser.run(ds[list(CHANNELS)].reset_coords(drop=True)).isel(run=0)
    dd = decision_high(stream["DD"].values)[stream["time"].values >= ds.attrs["warmup"]]
    return {"hours": hours, "alarms": rising_edges(dd), "r_fd": float(dd.mean())}


def scores(results: dict[str, Any]) -> dict[str, Any]:
    """The benchmark's detection figures of one hold."""
    firsts = first_detection_summary(results)
    t_dt: dict[str, list[float]] = {}
    for row in results["scenarios"]:
        name = " ".join(p for p in (row["fault"], row["mode"], row.get("size")) if p)
        t_dt.setdefault(name, []).append(row["indices"]["t_dt"])
    big = [n for n in firsts if n.endswith("abrupt big")]
    detected = sum(firsts[n]["detected"] for n in big)
    kept = sum(firsts[n]["kept"] for n in big)
    return {
        "median_r_fd": float(np.median([r["indices"]["r_fd"] for r in results["scenarios"]])),
        "big_abrupt_detected_runs": detected,
        "big_abrupt_kept_runs": kept,
        "per_scenario": {
            n: {"t_dt": sorted(t_dt[n]), **firsts[n]} for n in firsts if firsts[n]["detected"]
        },
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--small", action="store_true")
    parser.add_argument("--seeds", type=int, default=None)
    parser.add_argument("--hours", type=float, default=8.0)
    parser.add_argument("--out", default="benchmarks/out/detection_hold")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    c0 = time.process_time()
    diagnoser = fit_online_diagnoser(seed=0, small=args.small, progress=False)
    fit_cpu = time.process_time() - c0
    training = simulate_online_campaigns(seed=0, small=args.small, progress=False)["train"]
    n_seeds = args.seeds or (2 if args.small else 10)
    scenarios = [s.truncated(2400) for s in SCENARIOS] if args.small else None
    report: dict[str, Any] = {
        "small": args.small,
        "seeds": n_seeds,
        "threshold": diagnoser.threshold_,
        "clear_level": diagnoser.clear_level_,
        "fit_cpu_s": fit_cpu,
    }
    for hold in (0, CLEAR_HOLD):
        with_hold(diagnoser, hold)
        c0 = time.process_time()
        results = run_benchmark(
            diagnoser,
            out / f"hold_{hold}",
            n_seeds=n_seeds,
            scenarios=scenarios,
            hours=args.hours,
            real_hour=False,
            figures=False,
            progress=False,
        )
        report[f"hold_{hold}"] = {
            "training": training_gaps(diagnoser, training),
            "fault_free": fault_free(diagnoser, args.hours),
            **scores(results),
            "cpu_s": time.process_time() - c0,
        }
    (out / "detection_hold.json").write_text(json.dumps(report, indent=1))
    for hold in (0, CLEAR_HOLD):
        r = report[f"hold_{hold}"]
        print(
            f"hold {hold:3d} s: training abrupt runs (strength >= 0.5) dropped after first "
            f"detection {r['training']['dropped']} of {r['training']['detected']} (longest drops "
            f"{r['training']['longest_drops'][-5:]} s); benchmark big abrupt kept on "
            f"{r['big_abrupt_kept_runs']} of {r['big_abrupt_detected_runs']}; median r_fd "
            f"{r['median_r_fd']:.4f}; fault-free {r['fault_free']['hours']:g} h: "
            f"{r['fault_free']['alarms']} alarm(s), DD on {100 * r['fault_free']['r_fd']:.3f} %"
        )
        for name, e in r["per_scenario"].items():
            print(
                f"    {name:22s} t_dt {e['t_dt']}  t_dt_first median {e['median']:.0f} "
                f"[{e['min']:.0f}, {e['max']:.0f}]  kept {e['kept']}/{e['detected']}"
            )


if __name__ == "__main__":
    main()

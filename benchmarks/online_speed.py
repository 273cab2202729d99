"""Speed of the online diagnoser against its targets: ``run`` samples per CPU second and
``update`` milliseconds per sample, one thread.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/online_speed.py \
        [--model FILE | --small] [--hours 2] [--updates 20000]

- ``run``: a simulated recording of ``--hours`` hours in runs of 1 h (half fault-free, half with
  an abrupt fault at 900 s, so the isolation path runs too), processed by ``run``; CPU seconds
  of the process (``time.process_time``), best of 3. Target >= 20 000 samples/s.
- ``update``: ``--updates`` seconds of the faulty runs fed one at a time through ``update``; the
  median and 99th percentile of the per-call time and the mean CPU time per call. Target
  <= 1 ms/sample. The records are checked equal to ``run``'s stream (state, probability).
- ``chunks``: ``run`` on the same recording in 60-s chunks carrying the state, against one call
  (the cost of chunking; the streams must be identical).

The model: ``--model FILE`` (``bayes-fdi fit``), ``--small`` fits the small default settings
(seconds), otherwise the full default model is fitted (about a minute and a half). The machine
may be shared: the load average is printed. Results go to stdout and
``benchmarks/out/online_speed.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

import numpy as np
import xarray as xr

ROOT = Path(__file__).resolve().parents[1]
CHANNELS = ("CV", "P1", "P2", "T1", "X", "F")


def _recording(hours: float) -> xr.Dataset:
    from bayes_fdi.actuator import Fault, benchmark_inputs, simulate

    n = max(2, round(hours))
    faults = ["f1", "f7", "f13", "f17", "f18", "f19"]
    specs = [None if i % 2 == 0 else Fault(faults[i // 2 % len(faults)], 0.75, 900.0)
             for i in range(n)]  # fmt: skip
    rec = simulate(benchmark_inputs(n, 3600, seed=50_000, vary=True), specs, seed=50_000)
    return rec[list(CHANNELS)]


def _best_cpu(fn, repeats: int = 3) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeats):
        c0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - c0)
    return best, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", default=None)
    parser.add_argument("--small", action="store_true")
    parser.add_argument("--hours", type=float, default=2.0)
    parser.add_argument("--updates", type=int, default=20_000)
    args = parser.parse_args()

    from bayes_fdi.diagnosis import OnlineDiagnoser

    if args.model:
        model, source = OnlineDiagnoser.load(args.model), args.model
    else:
        from bayes_fdi.default_diagnoser import fit_online_diagnoser

        model = fit_online_diagnoser(small=args.small, progress=False)
        source = f"fit_online_diagnoser(small={args.small})"
    rec = _recording(args.hours)
    n = rec.sizes["run"] * rec.sizes["time"]
    model.run(rec.isel(run=[0, 1], time=slice(0, 100)))  # compile (numba cache) before timing
    cpu_run, stream = _best_cpu(lambda: model.run(rec))

    def chunked():
        parts, state = [], None
        for a in range(0, rec.sizes["time"], 60):
            part, state = model.run(rec.isel(time=slice(a, a + 60)), state=state,
                                    return_state=True)  # fmt: skip
            parts.append(part)
        return xr.concat(parts, dim="time")

    cpu_chunks, joined = _best_cpu(chunked, repeats=1)
    for name in ("DD", "state", "probability", "stat_X", "stat_F"):
        np.testing.assert_array_equal(joined[name].values, stream[name].values)

    faulty = [i for i in range(rec.sizes["run"]) if i % 2 == 1]
    per_call, cpu_total, done = [], 0.0, 0
    for r in faulty:
        model.reset()
        values = {c: rec[c].values[r] for c in CHANNELS}
        states, probs = [], []
        c0 = time.process_time()
        for t in range(rec.sizes["time"]):
            if done >= args.updates:
                break
            sample = {c: float(values[c][t]) for c in CHANNELS}
            w0 = time.perf_counter()
            record = model.update(sample)
            per_call.append(time.perf_counter() - w0)
            states.append(record.state)
            probs.append(record.probability)
            done += 1
        cpu_total += time.process_time() - c0
        k = len(states)
        np.testing.assert_array_equal(states, stream["state"].values[r, :k].astype(str))
        np.testing.assert_array_equal(probs, stream["probability"].values[r, :k])
        if done >= args.updates:
            break
    ms = np.asarray(per_call) * 1e3
    result = {
        "model": source,
        "load_average": os.getloadavg(),
        "threads": {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "NUMBA_NUM_THREADS")},
        "run": {"samples": n, "cpu_s": cpu_run, "samples_per_cpu_s": n / cpu_run},
        "chunks_60s": {"cpu_s": cpu_chunks, "samples_per_cpu_s": n / cpu_chunks},
        "update": {
            "calls": int(ms.size),
            "median_ms": float(statistics.median(ms)),
            "p99_ms": float(np.percentile(ms, 99)),
            "mean_cpu_ms": 1e3 * cpu_total / max(done, 1),
        },
    }
    print(json.dumps(result, indent=2))
    out = ROOT / "benchmarks" / "out"
    out.mkdir(parents=True, exist_ok=True)
    (out / "online_speed.json").write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()

"""Speed of the actuator simulator on the paper-simulated campaign, and fast-vs-reference agreement.

Times one ``simulate`` call on 3,800 runs x 350 s (20 states x 190 runs; DGen inputs with
run-to-run phase/amplitude variation; abrupt faults of magnitude U[0.5, 1] with the benchmark's
direction, present from t = 0, as ``sim/paper-simulated.toml``), prints runs/s and PASS/FAIL
against the 60 s target, then simulates a subset with both integrators and prints how far the
fast path is from the 2.5 ms RK4 reference (RMS over each run, in full-scale units) next to the
measurement noise.

Run: ``OMP_NUM_THREADS=1 PYTHONPATH=. python benchmarks/actuator_speed.py [--quick]``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

TARGET_S = 60.0


def _campaign(n_per_state: int, duration: int, seed: int):
    from bayes_fdi.actuator import FAULT_NAMES, Fault, benchmark_inputs
    from bayes_fdi.campaigns.spec import FAULT_DIRECTION

    states = ["fn", *FAULT_NAMES]
    n = n_per_state * len(states)
    inputs = benchmark_inputs(n_runs=n, duration=duration, vary=True, seed=seed)
    rng = np.random.default_rng(seed)
    faults = []
    for state in np.repeat(states, n_per_state):
        if state == "fn":
            faults.append(None)
            continue
        sign = FAULT_DIRECTION[str(state)]
        faults.append(Fault(str(state), sign * rng.uniform(0.5, 1.0), onset=0.0))
    return inputs, faults


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="10 runs per state instead of 190")
    parser.add_argument("--runs-per-state", type=int, default=None)
    parser.add_argument("--check-per-state", type=int, default=2, help="runs compared per state")
    args = parser.parse_args(argv)
    per_state = args.runs_per_state or (10 if args.quick else 190)

    t0 = time.perf_counter()
    from bayes_fdi.actuator import NOISE_STD, simulate

    inputs, faults = _campaign(per_state, 350, seed=2026)
    # first call: numba compiles (or loads its cache) - reported separately
    simulate(inputs.isel(run=[0, 1]), faults[:2], seed=0)
    simulate(inputs.isel(run=[0, 1]), faults[:2], seed=0, integrator="reference")
    t_first = time.perf_counter() - t0

    n = inputs.sizes["run"]
    t0, c0 = time.perf_counter(), time.process_time()
    simulate(inputs, faults, seed=0)
    elapsed, cpu = time.perf_counter() - t0, time.process_time() - c0
    threads = os.environ.get("NUMBA_NUM_THREADS", str(os.cpu_count()))
    print(f"import + compile/cache load + 2 small calls: {t_first:.1f} s")
    print(f"fast path: {n} runs x 350 s in {elapsed:.2f} s = {n / elapsed:.0f} runs/s "
          f"(numba threads: {threads}, cpus: {os.cpu_count()}); CPU time {cpu:.2f} s, "
          f"load average {os.getloadavg()[0]:.1f}")  # fmt: skip
    if per_state == 190:
        verdict = "PASS" if elapsed <= TARGET_S else "FAIL"
        print(f"{verdict}: target <= {TARGET_S:.0f} s for the 3,800-run campaign")
    else:
        scaled = elapsed * 3800 / n
        print(f"(quick run; {scaled:.1f} s extrapolated to 3,800 runs, target {TARGET_S:.0f} s)")

    k = args.check_per_state
    idx = np.concatenate([np.arange(s * per_state, s * per_state + k) for s in range(20)])
    sub = inputs.isel(run=idx)
    sub_faults = [faults[i] for i in idx]
    t0 = time.perf_counter()
    fast = simulate(sub, sub_faults, noise=False)
    t_fast = time.perf_counter() - t0
    t0 = time.perf_counter()
    ref = simulate(sub, sub_faults, noise=False, integrator="reference")
    t_ref = time.perf_counter() - t0
    print(f"agreement subset: {idx.size} runs; fast {t_fast:.2f} s, reference {t_ref:.2f} s "
          f"(speed-up x{t_ref / t_fast:.1f})")  # fmt: skip
    print(f"RMS(fast - reference) per run, full-scale units (noise sigma = {NOISE_STD:.4f}):")
    print("state      X' max     F' max")
    states = [str(s) for s in fast.state.values]
    for state in dict.fromkeys(states):
        rows = [i for i, s in enumerate(states) if s == state]
        ex = max(np.sqrt(np.mean((fast.X.values[r] - ref.X.values[r]) ** 2)) for r in rows)
        ef = max(np.sqrt(np.mean((fast.F.values[r] - ref.F.values[r]) ** 2)) for r in rows)
        flag = "" if max(ex, ef) <= NOISE_STD else "  > noise (hunting or dead-zone drift)"
        print(f"{state:6s} {ex:10.5f} {ef:10.5f}{flag}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The digital twin on the real Lublin hour: calibration, held-out check, fit time and scaling.

1. Fits `ActuatorTwin` on the first half of the real hour and checks it on the second: 95 %
   posterior predictive coverage of X and F (target 90-98 %), RMS error of the posterior
   predictive mean against the nominal model's (target: at or below), and what the data
   identify (posterior against prior standard deviation, PSIS-weighted moments, the strongest
   posterior correlations).
2. Times fits of 1 h (the whole hour), and of longer recordings made of copies of the hour (one
   run per copy): with every window fitted (``max_fit_seconds=None``) to show how the cost
   grows, and with the default rule (evenly spaced windows holding about 1 h) for 24 h. Targets:
   1 h well under 5 min, 24 h within 15 min, on the 2-core reference machine.

Run: ``OMP_NUM_THREADS=1 PYTHONPATH=. python benchmarks/twin_fit.py [--quick]`` (``--quick``:
no scaling runs beyond 2 h).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np
import xarray as xr

TARGET_1H_S = 300.0
TARGET_24H_S = 900.0


def _timed(make, *args, **kwargs):
    t0, c0 = time.perf_counter(), time.process_time()
    out = make(*args, **kwargs)
    return out, time.perf_counter() - t0, time.process_time() - c0


def _copies(hour: xr.Dataset, n: int) -> xr.Dataset:
    return hour.isel(run=[0] * n).assign_coords(run=np.arange(n))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="no scaling runs beyond 2 h")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    from bayes_fdi.datasets import load_lublin_example
    from bayes_fdi.twin import ActuatorTwin, identification

    hour = load_lublin_example()
    ActuatorTwin(window=300, n_draws=20).fit(hour.isel(time=slice(0, 300)))  # compile, warm up
    print(f"cpus: {os.cpu_count()}, load average {os.getloadavg()[0]:.1f}")

    first, second = hour.isel(time=slice(0, 1800)), hour.isel(time=slice(1800, 3600))
    twin, wall, cpu = _timed(ActuatorTwin(random_state=args.seed).fit, first)
    check, c_wall, _ = _timed(twin.check, second, n_draws=200, seed=args.seed)
    lap = twin.laplace_
    print(f"\n## Fit on the first half hour, check on the second (seed {args.seed})\n")
    print(f"fit: {wall:.1f} s wall, {cpu:.1f} s CPU; {lap.iterations} mode-search steps, "
          f"converged {lap.converged}, Newton decrement {lap.newton_decrement:.3f} nats; "
          f"PSIS k = {twin.pareto_k_:.2f}, ESS {twin.importance_ess_:.0f} of "
          f"{twin.n_draws}; check {c_wall:.1f} s")  # fmt: skip
    print("\n| channel | 95 % coverage | interval width | RMS twin | RMS nominal |")
    print("|---|---|---|---|---|")
    for c in ("X", "F"):
        print(f"| {c} | {100 * check.coverage[c]:.1f} % | {100 * check.width[c]:.2f} % | "
              f"{100 * check.rms[c]:.2f} % | {100 * check.rms_nominal[c]:.2f} % |")  # fmt: skip
    table, names, corr = identification(twin.inference_data_)
    print("\n| parameter | prior mean ± sd | posterior mean ± sd | sd ratio | PSIS-weighted |")
    print("|---|---|---|---|---|")
    for r in table:
        print(f"| {r.name} | {r.prior_mean:.4g} ± {r.prior_sd:.3g} | {r.posterior_mean:.4g} ± "
              f"{r.posterior_sd:.3g} | {r.ratio:.3f} | {r.weighted_mean:.4g} ± "
              f"{r.weighted_sd:.3g} |")  # fmt: skip
    pairs = [(abs(corr[i, j]), names[i], names[j], corr[i, j])
             for i in range(len(names)) for j in range(i)]  # fmt: skip
    strong = sorted(pairs, reverse=True)[:6]
    print("\nstrongest posterior correlations: "
          + ", ".join(f"{a}/{b} {c:+.2f}" for _, a, b, c in strong))  # fmt: skip
    ok = all(0.90 <= check.coverage[c] <= 0.98 and check.rms[c] <= check.rms_nominal[c]
             for c in ("X", "F"))  # fmt: skip

    print("\n## Fit time and scaling (copies of the real hour, one run each)\n")
    print("| recording | windows fitted | wall s | CPU s | steps | target |")
    print("|---|---|---|---|---|---|")
    cases = [("1 h", 1, 3600), ("2 h, all windows", 2, None)]
    if not args.quick:
        cases += [("4 h, all windows", 4, None), ("24 h, default rule", 24, 3600)]
    for label, n, limit in cases:
        model = ActuatorTwin(random_state=args.seed, max_fit_seconds=limit)
        fitted, wall, cpu = _timed(model.fit, _copies(hour, n))
        target = {"1 h": TARGET_1H_S, "24 h, default rule": TARGET_24H_S}.get(label)
        verdict = "" if target is None else ("PASS" if wall <= target else "FAIL")
        ok &= verdict != "FAIL"
        print(f"| {label} | {len(fitted.windows_)} x {fitted.window} s | {wall:.1f} | "
              f"{cpu:.1f} | {fitted.laplace_.iterations} | {verdict} |")  # fmt: skip
    print(f"\nload average at the end: {os.getloadavg()[0]:.1f}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

"""Healthy data for timing ``bayes-fdi commission``: hours of a valve in a level loop.

Simulates ``--hours`` of the nominal DAMADICS actuator under the level-loop excitation
(`bayes_fdi.actuator.excitation.level_loop_inputs`: a PI level controller, set-point changes,
drifting demand and supply pressure) and writes them as one recording in the project's netCDF
format, ready for ``bayes-fdi commission FILE --out MODEL.npz``::

    OMP_NUM_THREADS=1 PYTHONPATH=$PWD .venv/bin/python benchmarks/commissioning_data.py \\
        --hours 24 --out benchmarks/out/healthy_24h.nc
    time .venv/bin/bayes-fdi commission benchmarks/out/healthy_24h.nc --out benchmarks/out/x.npz

The speed targets (docs/commissioning.md): one hour commissioned in at most 5 min, 24 h in at
most 15 min.
"""

from __future__ import annotations

import argparse
import time

from bayes_fdi.actuator import simulate
from bayes_fdi.actuator.excitation import level_loop_inputs
from bayes_fdi.datasets import save_dataset


def healthy_hours(hours: float, seed: int = 0):
    """``hours`` of healthy level-loop operation of the nominal valve (one run, 1 Hz)."""
    inputs = level_loop_inputs(1, round(3600 * hours), seed=seed).drop_vars("level")
    return simulate(inputs, seed=seed)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=24.0, help="hours to simulate")
    parser.add_argument("--seed", type=int, default=0, help="seed of the inputs and noise")
    parser.add_argument("--out", required=True, help="netCDF file to write")
    args = parser.parse_args()
    t0 = time.perf_counter()
    ds = healthy_hours(args.hours, args.seed)
    save_dataset(ds, args.out)
    print(f"wrote {args.out}: {ds.sizes['time']} s simulated in {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()

"""Run every benchmark of the project: ``make bench`` (or ``python benchmarks/run.py``).

Each benchmark module in this folder exposes ``main(argv) -> int`` and prints its own table
with ratios against the peers it measures in the same run. Single-threaded BLAS is enforced
here (``OMP_NUM_THREADS=1``), as on the 2-core reference machine.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
from pathlib import Path

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[var] = "1"

HERE = Path(__file__).resolve().parent
BENCHMARKS = {
    "rvm": "rvm_fit.py",
    "actuator": "actuator_speed.py",
    "cli": "cli_latency.py",
}


def _load(name: str, filename: str):
    spec = importlib.util.spec_from_file_location(f"benchmarks_{name}", HERE / filename)
    module = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    spec.loader.exec_module(module)
    return module


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("which", nargs="*", choices=[*BENCHMARKS, []], help="benchmarks to run")
    parser.add_argument("--quick", action="store_true", help="small sizes (smoke run)")
    args = parser.parse_args(argv)
    status = 0
    for name in args.which or list(BENCHMARKS):
        print(f"\n=== benchmark: {name} ===", flush=True)
        module = _load(name, BENCHMARKS[name])
        status |= int(module.main(["--quick"] if args.quick else []) or 0)
    return status


if __name__ == "__main__":
    sys.exit(main())

"""The DAMADICS benchmark (nominal or ``--shift``) of an online diagnoser saved in a model file.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/model_file_benchmark.py MODEL --out DIR \
        [--shift] [--small] [--seeds N]

``bayes-fdi benchmark`` fits the default diagnoser; this script benchmarks another fitted one
(e.g. one written by ``benchmarks/heldout_families.py --save`` with another training or other
normal-model inputs) with the same harness, scenarios, seeds and report. ``--small``: the
scenarios cut at 2400 s, 1 fault-free hour, 2 seeds unless ``--seeds``. The CPU seconds of the
run go to stderr.
"""

from __future__ import annotations

import argparse
import os
import sys
import time


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="a model file of a fitted OnlineDiagnoser")
    parser.add_argument("--out", required=True, help="output folder (created)")
    parser.add_argument("--shift", action="store_true", help="the shift benchmark")
    parser.add_argument("--small", action="store_true", help="the quick version")
    parser.add_argument("--seeds", type=int, default=None)
    args = parser.parse_args()
    from bayes_fdi.benchmark.harness import run_benchmark
    from bayes_fdi.benchmark.scenarios import SCENARIOS
    from bayes_fdi.benchmark.shift import run_shift_benchmark
    from bayes_fdi.diagnosis import OnlineDiagnoser

    diagnoser = OnlineDiagnoser.load(args.model)
    t0 = time.process_time()
    run = run_shift_benchmark if args.shift else run_benchmark
    run(
        diagnoser,
        args.out,
        n_seeds=args.seeds if args.seeds is not None else (2 if args.small else 10),
        scenarios=[s.truncated(2400) for s in SCENARIOS] if args.small else None,
        hours=1.0 if args.small else 8.0,
        progress=False,
        settings={"small": bool(args.small), "model_file": os.path.basename(args.model)},
    )
    sys.stderr.write(
        f"{'shift ' if args.shift else ''}benchmark of {args.model}: "
        f"{time.process_time() - t0:.0f} CPU s, load average {os.getloadavg()[0]:.1f}\n"
    )


if __name__ == "__main__":
    main()

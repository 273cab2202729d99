"""Command-line latency: ``bayes-fdi COMMAND --help`` and a usage error, per command, against
``python -c pass`` and ``python -c "import argparse"`` measured in the same run.

    .venv/bin/python benchmarks/cli_latency.py [--repeats 5]

Each command runs in a fresh process (the installed ``bayes-fdi`` entry point's interpreter,
``python -m bayes_fdi``); the wall time of each run is measured and the median over
``--repeats`` is reported, with its ratio to the bare interpreter's start. Target: help and
usage errors of every command in under 1 s. The machine's load average is printed beside the
figures (a shared machine inflates them).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

from bayes_fdi.cli import COMMANDS

TARGET_S = 1.0


def _median_wall(argv: list[str], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        subprocess.run(argv, capture_output=True, check=False)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="one repeat")
    args = parser.parse_args(argv)
    repeats = 1 if args.quick else args.repeats
    python = [sys.executable]
    bare = _median_wall([*python, "-c", "pass"], repeats)
    argparse_only = _median_wall([*python, "-c", "import argparse"], repeats)
    print(f"load average {os.getloadavg()[0]:.2f}; median of {repeats} run(s), wall seconds")
    print(f"python -c pass: {bare:.3f} s; python -c 'import argparse': {argparse_only:.3f} s")
    print("| command | --help (s) | usage error (s) | help / bare python | target <= 1 s |")
    print("|---|---:|---:|---:|---|")
    worst = 0.0
    for name in COMMANDS:
        cli = [*python, "-m", "bayes_fdi", name]
        help_s = _median_wall([*cli, "--help"], repeats)
        usage_s = _median_wall([*cli, "--no-such-option"], repeats)
        worst = max(worst, help_s, usage_s)
        met = "met" if max(help_s, usage_s) <= TARGET_S else "**not met**"
        print(f"| {name} | {help_s:.3f} | {usage_s:.3f} | {help_s / bare:.1f} | {met} |")
    print(f"slowest: {worst:.3f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())

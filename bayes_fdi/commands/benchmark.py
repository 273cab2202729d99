"""``bayes-fdi benchmark``: options of the DAMADICS benchmark, of the commissioning benchmark and
of the shift benchmark.

The work is `bayes_fdi.benchmark.harness.run_from_cli` (with ``--commissioning``,
`bayes_fdi.benchmark.commissioning.run_from_cli`; with ``--shift``,
`bayes_fdi.benchmark.shift.run_from_cli`); it is imported when the command runs.
"""

from __future__ import annotations

import argparse

from bayes_fdi.cli_arguments import ISOLATION_CHOICES

__all__ = ["configure_parser", "run_from_cli"]

#: Perturbed plants of the commissioning benchmark: full and ``--small`` (as its settings,
#: `bayes_fdi.benchmark.commissioning.FULL` and ``SMALL``; a test keeps them equal).
PLANTS_FULL, PLANTS_SMALL = 5, 1


def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Options of ``bayes-fdi benchmark``."""
    parser.add_argument("--out", required=True, help="output folder (created)")
    parser.add_argument(
        "--seeds",
        type=int,
        default=None,
        help="noise seeds per scenario (default 10; 2 with --small; with --commissioning: "
        "seeds per plant and scenario, default 2, 1 with --small)",
    )
    parser.add_argument(
        "--small",
        action="store_true",
        help="quick version: small training, 2 seeds, horizons cut at 2400 s, "
        "1 fault-free hour (with --commissioning: 1 plant, 1 seed, lighter commissioning); "
        "not the benchmark's numbers",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.add_argument(
        "--commissioning",
        action="store_true",
        help="the commissioning benchmark instead: the real hour (commissioned on its first "
        "half, faults transplanted onto the second) and perturbed plants (commissioned on 1 h, "
        "then the 44 scenarios), the default model beside",
    )
    parser.add_argument(
        "--shift",
        action="store_true",
        help="the shift benchmark instead: the 44 scenarios and the fault-free hours under each "
        "excitation family of sim/shift-*.toml (inputs no training campaign uses), one report "
        "per family and a summary",
    )
    parser.add_argument(
        "--plants",
        type=int,
        default=None,
        help=f"with --commissioning: perturbed plants (default {PLANTS_FULL}; "
        f"{PLANTS_SMALL} with --small)",
    )
    parser.add_argument(
        "--isolation",
        choices=ISOLATION_CHOICES,
        default=None,
        help="with --commissioning: the commissioned diagnosers' isolation classifier (default "
        "tree: the k-means tree of RVCs; forest: a random forest)",
    )


def run_from_cli(args: argparse.Namespace) -> int:
    """Run the benchmark the options name."""
    from bayes_fdi.benchmark.harness import run_from_cli as run_benchmark_from_cli

    return run_benchmark_from_cli(args)

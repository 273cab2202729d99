"""``bayes-fdi reproduce``: options and entry point of the paper's reproduction.

The job itself is `bayes_fdi.paper.reproduce.reproduce`; it is imported when the command runs.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from bayes_fdi.cli_arguments import UsageError

__all__ = ["configure_parser", "run_from_cli"]


def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Add the ``reproduce`` command's options to ``parser``."""
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder")
    parser.add_argument("--seed", type=int, default=0, help="simulation and model seed")
    parser.add_argument(
        "--cache-dir",
        default=".cache/datasets",
        metavar="DIR",
        help="folder of cached simulated datasets (default: .cache/datasets)",
    )
    parser.add_argument(
        "--small",
        action="store_true",
        help="a small, fast version (fewer runs per state) for tests and CI",
    )
    parser.add_argument(
        "--campaign",
        action="append",
        metavar="TOML",
        help="campaign file or shipped name to run instead of the paper's two "
        "(repeatable; default: paper-simulated and paper-lublin)",
    )
    parser.add_argument(
        "--states",
        default=None,
        help="comma-separated states of the paper protocol "
        "(default: the paper's ten, fn,f1,f2,f3,f6,f11,f12,f15,f17,f18)",
    )
    parser.add_argument(
        "--dynamic-lags",
        default=None,
        metavar="SECONDS",
        help="comma-separated lags (s) of CV for the beyond-the-paper dynamic normal models "
        "(default: those of the dynamic pipeline, 1,2; empty string: skip that part)",
    )
    parser.add_argument(
        "--quiet",
        "--no-progress",
        dest="no_progress",
        action="store_true",
        help="no progress messages",
    )


def run_from_cli(args: argparse.Namespace) -> int:
    """Run `bayes_fdi.paper.reproduce.reproduce` from parsed arguments; print the headlines."""
    from bayes_fdi.campaigns.cache import campaign_file
    from bayes_fdi.paper.reproduce import reproduce
    from bayes_fdi.paper.setup import ALL_STATES, DATASETS, DYNAMIC_LAGS, PAPER_STATES

    states_text = args.states if args.states is not None else ",".join(PAPER_STATES)
    states = [s.strip() for s in states_text.split(",") if s.strip()]
    unknown = sorted(set(states) - set(ALL_STATES))
    if unknown:
        raise UsageError(f"--states: unknown state(s) {unknown}; use fn, f1..f19")
    if args.dynamic_lags is None:
        lags = DYNAMIC_LAGS
    else:
        try:
            lags = tuple(float(v) for v in args.dynamic_lags.split(",") if v.strip())
        except ValueError:
            raise UsageError(
                f"--dynamic-lags must be comma-separated seconds, got {args.dynamic_lags!r}"
            ) from None
    for name in args.campaign or ():
        try:  # every campaign is found before any work starts
            campaign_file(name)
        except ValueError as exc:
            raise UsageError(f"--campaign: {exc}") from None
    results = reproduce(
        args.out,
        dynamic_lags=lags,
        seed=args.seed,
        cache_dir=args.cache_dir,
        small=args.small,
        states=states,
        progress=not args.no_progress,
        datasets=tuple(args.campaign) if args.campaign else DATASETS,
    )
    print(f"report: {Path(args.out) / 'report.md'}")
    for name, ds in results["datasets"].items():
        acc = ", ".join(f"{m.upper()} {100 * ds[m]['accuracy']:.2f} %" for m in ("rvm", "svm"))
        print(f"{name}: {acc}")
    return 0

"""``bayes-fdi commission``: learn a valve from its healthy recordings and write its model.

The recordings are read in declared units (`bayes_fdi.datasets.read_recording`) and commissioned
(`bayes_fdi.commissioning.commission`: the valve's normal models and detector, its digital twin,
a fault library transplanted onto its data, the isolation); the model file is what
``bayes-fdi diagnose --model`` reads, and ``MODEL.md`` / ``MODEL.json`` beside it hold the
commissioning report.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path
from typing import Any

from bayes_fdi.cli_arguments import ISOLATION_CHOICES, input_file, output_file

__all__ = ["commission_and_save", "configure_parser", "run_from_cli"]


def commission_and_save(
    healthy: Any,
    out: str | os.PathLike,
    *,
    seed: int = 0,
    normal_samples: int | str = 2000,
    isolation: str = "tree",
    progress: bool = True,
) -> Any:
    """Commission on ``healthy`` and write the model file ``out`` with its report beside it
    (``out`` without its suffix, plus ``.md`` and ``.json``); returns the `Commissioning`
    (``normal_samples`` and ``isolation`` as `~bayes_fdi.commissioning.commission`'s)."""
    from bayes_fdi import model_files
    from bayes_fdi.commissioning import commission
    from bayes_fdi.commissioning.report import write_report

    done = commission(
        healthy,
        seed=seed,
        normal_samples=normal_samples,
        isolation=isolation,
        progress=progress,
    )
    model_files.save(done.diagnoser, out)
    write_report(done.report, Path(out).with_suffix(""))
    return done


def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``bayes-fdi commission``."""
    from bayes_fdi.deployment.fitting import add_normal_samples_argument, add_reading_arguments

    parser.add_argument(
        "recordings",
        nargs="+",
        type=input_file,
        metavar="HEALTHY",
        help="fault-free recordings of the valve (an hour or more is best)",
    )
    parser.add_argument(
        "--out",
        required=True,
        type=output_file(".npz"),
        help="model file to write (.npz); its report goes beside it (.md, .json)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of every draw (default 0)")
    add_normal_samples_argument(parser)
    parser.add_argument(
        "--isolation",
        choices=ISOLATION_CHOICES,
        default="tree",
        help="isolation classifier: the k-means tree of RVCs (default) or a random forest, "
        "which names more faults' groups right on the perturbed plants",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress")
    add_reading_arguments(parser)


def run_from_cli(args: argparse.Namespace) -> int:
    """Run ``bayes-fdi commission``."""
    from bayes_fdi.deployment.fitting import read_for_fitting, reading_options

    t0 = time.perf_counter()
    options = reading_options(args)
    healthy = [read_for_fitting(p, options) for p in args.recordings]
    done = commission_and_save(
        healthy,
        args.out,
        seed=args.seed,
        normal_samples=args.normal_samples or 2000,
        isolation=args.isolation,
        progress=not args.quiet,
    )
    report = done.report
    print(
        f"wrote {args.out} (report {Path(args.out).with_suffix('.md')}): commissioned on "
        f"{report['healthy']['seconds']} s in {time.perf_counter() - t0:.0f} s; "
        f"{len(report['groups'])} isolability groups; not detectable here: "
        f"{', '.join(report['undetectable']) or 'none'}"
    )
    if text := report.get("normal_models", {}).get("text"):
        print(f"  normal models {text}")
    return 0

"""``bayes-fdi calibration-report``: options and entry point of the calibration report.

The report itself is `bayes_fdi.calibration.report.write_calibration_report`; it and the
diagnoser are imported when the command runs.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

__all__ = ["configure_parser", "run_from_cli"]


def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``bayes-fdi calibration-report``."""
    parser.add_argument("--train", required=True, help="training dataset (.nc)")
    parser.add_argument("--test", required=True, help="test dataset (.nc)")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument(
        "--calibration", default=None, help="held-out dataset (.nc) to fit the recalibrators on"
    )
    parser.add_argument("--method", choices=("rvm", "svm"), default="rvm")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--n-bins", type=int, default=15)
    parser.add_argument("--n-bootstrap", type=int, default=500)
    parser.add_argument(
        "--n-folds",
        type=int,
        default=5,
        help="cross-fitting folds on the test runs when no --calibration is given (default 5)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")


def _build_diagnoser(method: str, seed: int) -> Any:
    """A fresh diagnoser of the chosen method (RVM defaults or SVM nodes)."""
    from bayes_fdi.diagnosis import FaultDiagnoser, svm_fault_diagnoser

    if method == "rvm":
        return FaultDiagnoser(random_state=seed)
    return svm_fault_diagnoser(random_state=seed)


def run_from_cli(args: argparse.Namespace) -> int:
    """Fit a diagnoser on ``--train`` (fn runs + all labelled runs); report on ``--test``."""
    import numpy as np

    from bayes_fdi.calibration.report import write_calibration_report
    from bayes_fdi.datasets import load_dataset

    train = load_dataset(args.train)
    test = load_dataset(args.test)
    cal = load_dataset(args.calibration) if args.calibration else None
    if "state" not in train.coords:
        raise ValueError(f"{args.train} has no per-run 'state' coordinate")
    normal = train.isel(run=np.flatnonzero(train["state"].values == "fn"))
    if normal.sizes["run"] == 0:
        raise ValueError(f"{args.train} has no fault-free ('fn') runs to fit the normal models")
    from bayes_fdi.progress import busy

    with busy(f"fitting the {args.method.upper()} diagnoser", enabled=not args.quiet):
        diagnoser = _build_diagnoser(args.method, args.seed).fit(normal, train)
    with busy("diagnosing the test runs and writing the report", enabled=not args.quiet):
        path = write_calibration_report(
            diagnoser,
            test,
            args.out,
            calibration_runs=cal,
            n_bins=args.n_bins,
            n_bootstrap=args.n_bootstrap,
            seed=args.seed,
            n_folds=args.n_folds,
            title=f"Calibration report ({args.method.upper()}, test {Path(args.test).name})",
        )
    print(path)
    return 0

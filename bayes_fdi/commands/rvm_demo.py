"""``bayes-fdi rvm-demo``: fit an RVR on noisy sinc data and print what it found.

Tipping's classic example: ``y = sin(x)/x + noise`` on ``[-10, 10]``.  The command prints
the number of relevance vectors, the RMSE against the noise-free function, the estimated
noise level, the log evidence, the coverage of the 95 % predictive interval and the
fit time.

Imports the command-line helpers of the foundation only; the estimator
(:class:`~bayes_fdi.rvm.RVR`) is imported when the command runs.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from bayes_fdi.cli_arguments import non_negative_float, non_negative_int

__all__ = ["configure_parser", "run_from_cli", "sinc_data", "width_argument"]


def sinc_data(
    n: int, noise: float, seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Noisy sinc training data and a noise-free test grid ``(X, y, X_test, f_test)``."""
    rng = np.random.default_rng(seed)
    X = rng.uniform(-10.0, 10.0, (n, 1))
    y = np.sinc(X[:, 0] / np.pi) + noise * rng.standard_normal(n)
    X_test = np.linspace(-10.0, 10.0, 1000)[:, None]
    return X, y, X_test, np.sinc(X_test[:, 0] / np.pi)


def width_argument(text: str) -> float | str:
    """argparse type of an RBF width: a finite number > 0, or ``auto``."""
    if text == "auto":
        return text
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number > 0 or 'auto', got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a number > 0 or 'auto', got {text!r}")
    return value


def _training_points(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 2:
        raise argparse.ArgumentTypeError(f"must be at least 2, got {value}")
    if value > 100_000:
        raise argparse.ArgumentTypeError(
            f"at most 100000 for a demo (an RVM on n points needs O(n^2) memory), got {value}"
        )
    return value


def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Add the ``rvm-demo`` options to ``parser``."""
    parser.add_argument(
        "--n", type=_training_points, default=500, help="training points (default 500)"
    )
    parser.add_argument(
        "--noise", type=non_negative_float, default=0.1, help="noise sd (default 0.1)"
    )
    parser.add_argument(
        "--width", type=width_argument, default=2.0, help="RBF width sigma, or 'auto' (default 2.0)"
    )
    parser.add_argument("--method", choices=("fast", "em"), default="fast")
    parser.add_argument("--seed", type=non_negative_int, default=0, help="random seed (default 0)")
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")


def run_from_cli(args: argparse.Namespace) -> int:
    """Run the demo; returns the exit status."""
    from bayes_fdi.rvm import RVR

    X, y, X_test, f_test = sinc_data(args.n, args.noise, args.seed)
    model = RVR(width=args.width, method=args.method)
    from bayes_fdi.progress import busy

    start = time.perf_counter()
    with busy(f"fitting the RVR ({args.method}, width {args.width})", enabled=not args.quiet):
        model.fit(X, y)
    elapsed = time.perf_counter() - start
    rmse = float(np.sqrt(np.mean((model.predict(X_test) - f_test) ** 2)))
    mean_train, std_train = model.predict(X, return_std=True)
    covered = float(np.mean(np.abs(y - mean_train) <= 1.96 * std_train))
    print(f"RVR on noisy sinc: n={args.n}, noise sd={args.noise}, method={args.method}")
    print(f"  relevance vectors : {len(model.relevance_indices_)} of {args.n}")
    print(f"  width (sigma)     : {model.width_:.4g}")
    print(f"  RMSE vs sinc      : {rmse:.4f}")
    print(f"  noise sd estimate : {model.noise_std_:.4f}")
    print(f"  95% PI coverage   : {covered:.3f} (training points)")
    print(f"  log evidence      : {model.log_evidence_:.3f}")
    print(f"  iterations        : {model.n_iter_}")
    print(f"  fit time          : {elapsed:.3f} s")
    return 0

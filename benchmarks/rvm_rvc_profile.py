"""Where an RVC fit's CPU time goes: the Laplace inner loop against the fast solver's outer loop.

Usage::

    OMP_NUM_THREADS=1 PYTHONPATH=$PWD python benchmarks/rvm_rvc_profile.py [--problems tree,moons]

Two fits, each in this process on one thread, timed on the process CPU clock:

- ``tree``: the diagnoser's isolation classifier,
  ``HierarchicalClassifier(RVC(kernel="rbf", width=2.0))`` (a k-means tree of binary RVCs), on
  ``--per-class`` rows of each of ``--classes`` two-dimensional Gaussian classes (the default
  features are two residual means); the centres are drawn so that some classes overlap, as faults
  with the same residual signature do;
- ``moons``: one binary ``RVC(kernel="rbf", width=0.5)`` on ``--n-moons`` noisy two-moons points.

The solver's steps are timed by wrapping them where ``bayes_fdi.rvm.sbl.bernoulli`` looks them
up (wall time under a loaded machine would not mean much, so the wrappers read
``time.process_time``): the Laplace mode finding (``posterior_mode``: Newton/IRLS to rounding
level, the Hessian's Cholesky factor, covariance and evidence), the screening products and
factors of every candidate (``screen`` less its mode), the verified choice of the action with
the contending candidates' exact factors (``verified_action``), and the rest (the action's
bookkeeping, the design and kernel, the tree). Written by hand: a benchmark of this package's
own solver steps.
"""

from __future__ import annotations

import argparse
import functools
import sys
import time
from collections import defaultdict
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["main", "moons_problem", "tree_problem"]


def tree_problem(classes: int, per_class: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``classes`` two-dimensional Gaussian classes of ``per_class`` rows each (unit spread,
    centres uniform in ``[-6, 6]^2``, so some overlap)."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-6.0, 6.0, (classes, 2))
    X = np.concatenate([c + rng.standard_normal((per_class, 2)) for c in centres])
    y = np.repeat([f"c{k:02d}" for k in range(classes)], per_class)
    return X, y


def moons_problem(n: int, seed: int = 0, noise: float = 0.3) -> tuple[np.ndarray, np.ndarray]:
    """``n`` two-moons points with Gaussian noise ``noise`` (labels 0 / 1, half each)."""
    rng = np.random.default_rng(seed)
    half = n // 2
    a = rng.uniform(0.0, np.pi, half)
    b = rng.uniform(0.0, np.pi, n - half)
    X = np.concatenate(
        [np.c_[np.cos(a), np.sin(a)], np.c_[1.0 - np.cos(b), 0.5 - np.sin(b)]]
    ) + noise * rng.standard_normal((n, 2))
    y = np.r_[np.zeros(half, dtype=int), np.ones(n - half, dtype=int)]
    return X, y


class StepTimer:
    """Own CPU seconds (less the wrapped steps called inside) and calls of the wrapped steps."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)
        self._inner: list[float] = []  # CPU seconds of wrapped steps inside each open step

    def wrap(self, name: str, func: Callable[..., Any]) -> Callable[..., Any]:
        """``func`` timed under ``name``."""

        @functools.wraps(func)
        def timed(*args: Any, **kwargs: Any) -> Any:
            self._inner.append(0.0)
            c0 = time.process_time()
            try:
                return func(*args, **kwargs)
            finally:
                total = time.process_time() - c0
                self.seconds[name] += total - self._inner.pop()
                self.calls[name] += 1
                if self._inner:
                    self._inner[-1] += total

        return timed

    def count(self, name: str, func: Callable[..., Any]) -> Callable[..., Any]:
        """``func`` with its calls counted under ``name`` (not timed)."""

        @functools.wraps(func)
        def counted(*args: Any, **kwargs: Any) -> Any:
            self.calls[name] += 1
            return func(*args, **kwargs)

        return counted


STEPS = {
    "posterior_mode": "Laplace mode: Newton/IRLS, Hessian factor, covariance, evidence",
    "screen": "screening products and factors of every candidate",
    "verified_action": "verified choice of the action (exact factors of the contenders)",
    "fast_bernoulli": "the rest of the solver (first column, the action's bookkeeping)",
}


def profiled_fit(kind: str, args: argparse.Namespace) -> tuple[float, StepTimer, str]:
    """Fit ``kind`` with the solver's steps wrapped; the fit's CPU seconds, the timer and a
    description of the fit."""
    import bayes_fdi.rvm.classification as classification
    import bayes_fdi.rvm.sbl.bernoulli as bernoulli
    import bayes_fdi.rvm.sbl.laplace as laplace
    from bayes_fdi.diagnosis.isolation.tree import HierarchicalClassifier
    from bayes_fdi.rvm import RVC

    timer = StepTimer()
    run_cls = bernoulli._FastBernoulliRun
    saved = (
        bernoulli.posterior_mode,
        bernoulli.verified_action,
        run_cls.screen,
        classification.fast_bernoulli,
        laplace.factor_precision,
    )
    laplace.factor_precision = timer.count("newton", saved[4])
    bernoulli.posterior_mode = timer.wrap("posterior_mode", saved[0])
    bernoulli.verified_action = timer.wrap("verified_action", saved[1])
    run_cls.screen = timer.wrap("screen", saved[2])
    classification.fast_bernoulli = timer.wrap("fast_bernoulli", saved[3])
    try:
        if kind == "tree":
            X, y = tree_problem(args.classes, args.per_class, args.seed)
            model: Any = HierarchicalClassifier(RVC(kernel="rbf", width=2.0), random_state=0)
            what = f"tree: {args.classes} classes x {args.per_class} rows, width 2.0"
        else:
            X, y = moons_problem(args.n_moons, args.seed)
            model = RVC(kernel="rbf", width=0.5)
            what = f"moons: N = {args.n_moons}, width 0.5"
        c0 = time.process_time()
        model.fit(X, y)
        cpu = time.process_time() - c0
        if kind == "moons":
            what += f", {len(model.relevance_indices_)} RVs, {model.n_iter_} iterations"
        else:
            n_iter = sum(int(node.estimator.n_iter_) for node in model.nodes_)
            what += f", {len(model.nodes_)} nodes, {n_iter} iterations in all"
    finally:
        (
            bernoulli.posterior_mode,
            bernoulli.verified_action,
            run_cls.screen,
            classification.fast_bernoulli,
            laplace.factor_precision,
        ) = saved
    return cpu, timer, what


def report(cpu: float, timer: StepTimer, what: str) -> str:
    """A Markdown table of the steps' own CPU seconds and shares of the fit."""
    steps = timer.calls["newton"] / max(timer.calls["posterior_mode"], 1)
    what += f"; {steps:.1f} Newton steps per mode"
    lines = [f"{what}: {cpu:.2f} CPU s", "", "| step | calls | CPU s | share |"]
    lines.append("|:--|--:|--:|--:|")
    inside = 0.0
    for name, label in STEPS.items():
        sec = timer.seconds[name]
        inside += sec
        lines.append(f"| {label} | {timer.calls[name]} | {sec:.2f} | {100 * sec / cpu:.0f} % |")
    rest = cpu - inside
    lines.append(
        f"| outside the solver (design, kernel, tree) | | {rest:.2f} | {100 * rest / cpu:.0f} % |"
    )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problems", default="tree,moons")
    ap.add_argument("--classes", type=int, default=20)
    ap.add_argument("--per-class", type=int, default=80)
    ap.add_argument("--n-moons", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    for kind in args.problems.split(","):
        cpu, timer, what = profiled_fit(kind, args)
        print(report(cpu, timer, what), flush=True)
        print(flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

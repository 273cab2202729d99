"""Evidence of the fast fit, the polished fit (``RVR(polish=True)``), the re-estimation
(``method="em"``) and scikit-learn's ``ARDRegression`` on the same fixed RBF designs.

The designs are those of the RVM benchmark's smooth problem (``rvm_fit.make_data``, the first N
training rows, RBF width 0.5, one column per sample), without and with a leading bias column,
fitted as precomputed designs (``RVR(kernel="precomputed", bias=False)``) so that every method
sees exactly the same basis. Every log evidence is recomputed here by numpy on the N x N
marginal covariance at the method's hyperparameters (``log N(y | 0, I / beta + Phi A^-1 Phi^T)``);
CPU seconds are those of the fit (one thread).

Usage::

    OMP_NUM_THREADS=1 PYTHONPATH=$PWD .venv/bin/python benchmarks/rvm_polish.py \\
        --sizes 200,400,1000,2000 --em-max 1000 --ard-max 200
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from rvm_fit import make_data, rbf_kernel_sigma

from bayes_fdi.rvm import RVR

SIGMA = 0.5


def log_evidence(Phi: np.ndarray, alpha: np.ndarray, beta: float, y: np.ndarray) -> float:
    """``log N(y | 0, I / beta + Phi diag(1 / alpha) Phi^T)`` by numpy (N x N)."""
    C = np.eye(len(y)) / beta + (Phi / alpha) @ Phi.T
    _, logdet = np.linalg.slogdet(C)
    return float(-0.5 * (len(y) * np.log(2 * np.pi) + logdet + y @ np.linalg.solve(C, y)))


def fit_rvr(D: np.ndarray, y: np.ndarray, **params) -> tuple[float, int, float]:
    """(log evidence, basis size, CPU s) of an RVR on the precomputed design ``D``."""
    t0 = time.process_time()
    m = RVR(kernel="precomputed", bias=False, **params).fit(D, y)
    cpu = time.process_time() - t0
    idx = m.relevance_indices_
    return log_evidence(D[:, idx], m.alpha_, m.beta_, y), len(idx), cpu


def fit_ard(D: np.ndarray, y: np.ndarray) -> tuple[float, int, float]:
    """The same for scikit-learn's ARDRegression (no intercept: the design holds any bias)."""
    from sklearn.linear_model import ARDRegression

    t0 = time.process_time()
    ard = ARDRegression(fit_intercept=False, max_iter=10000, tol=1e-8, threshold_lambda=1e8)
    ard.fit(D, y)
    cpu = time.process_time() - t0
    keep = ard.lambda_ < 1e8
    return log_evidence(D[:, keep], ard.lambda_[keep], ard.alpha_, y), int(keep.sum()), cpu


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="200,400,1000,2000", help="training sizes N")
    ap.add_argument("--em-max", type=int, default=1000, help="largest N fitted by em")
    ap.add_argument("--ard-max", type=int, default=200, help="largest N fitted by ARDRegression")
    args = ap.parse_args(argv)
    sizes = [int(s) for s in args.sizes.split(",") if s]
    data = make_data(max(sizes))
    print("| N | bias | fast | polished (gain) | em | ARDRegression | CPU s: fast / polished |")
    print("|---:|:---|---:|---:|---:|---:|---:|")
    for n in sizes:
        X, y = data["X_train"][:n], data["y_train"][:n]
        K = rbf_kernel_sigma(X, X, SIGMA)
        for bias in (False, True):
            D = np.hstack([np.ones((n, 1)), K]) if bias else K
            fast = fit_rvr(D, y)
            pol = fit_rvr(D, y, polish=True)
            em = fit_rvr(D, y, method="em") if n <= args.em_max else None
            ard = fit_ard(D, y) if n <= args.ard_max else None

            def cell(r: tuple[float, int, float] | None) -> str:
                return "–" if r is None else f"{r[0]:.2f} ({r[1]} RVs)"

            print(
                f"| {n} | {'yes' if bias else 'no'} | {cell(fast)} | {pol[0]:.2f} "
                f"({pol[0] - fast[0]:+.2f}) | {cell(em)} | {cell(ard)} | "
                f"{fast[2]:.2f} / {pol[2]:.2f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()

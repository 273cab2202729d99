"""Fit-time and memory benchmark of ``RVR(method="fast")`` on a smooth 3-input problem.

Run single-threaded: ``OMP_NUM_THREADS=1 PYTHONPATH=. python benchmarks/rvm_speed.py [N ...]``.
Prints, per N: fit CPU and wall seconds, peak RSS (MiB), number of relevance vectors, test RMSE
against the noise-free function and whether the kernel matrix was materialised (as a
float32 screening copy from N = 2000 on; otherwise it is recomputed in row blocks).
"""

from __future__ import annotations

import resource
import sys
import time

import numpy as np
import torch

from bayes_fdi.rvm import RVR


def problem(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Noisy smooth function of 3 inputs on the unit cube (train and noise-free test)."""
    rng = np.random.default_rng(seed)

    def f(X: np.ndarray) -> np.ndarray:
        return np.sin(3 * X[:, 0]) * np.cos(2 * X[:, 1]) + 0.5 * X[:, 2] ** 2

    X = rng.uniform(0, 1, (n, 3))
    y = f(X) + 0.05 * rng.standard_normal(n)
    Xt = rng.uniform(0, 1, (2000, 3))
    return X, y, Xt, f(Xt)


def main(sizes: list[int]) -> None:
    torch.set_num_threads(1)
    print(
        f"{'N':>6} {'cpu_s':>6} {'wall_s':>7} {'peak_MiB':>9} {'n_rv':>5} {'rmse':>8} {'dense':>6}"
    )
    for n in sizes:
        X, y, Xt, ft = problem(n)
        model = RVR(width=0.3)
        t0, c0 = time.perf_counter(), time.process_time()
        model.fit(X, y)
        dt, cpu = time.perf_counter() - t0, time.process_time() - c0
        rmse = float(np.sqrt(np.mean((model.predict(Xt) - ft) ** 2)))
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        dense = n * n * 8 <= model.max_kernel_bytes  # float64 kernel matrix held in memory
        n_rv = len(model.relevance_indices_)
        print(f"{n:>6} {cpu:>6.2f} {dt:>7.2f} {peak:>9.0f} {n_rv:>5} {rmse:>8.4f} {dense!s:>6}")


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [1000, 5000, 7000])

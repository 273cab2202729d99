"""CPU profile of one ``bayes_fdi`` RVR fit on the benchmark data (companion of rvm_fit.py).

Usage (after ``benchmarks/rvm_fit.py`` has written its data)::

    OMP_NUM_THREADS=1 PYTHONPATH=$PWD python benchmarks/rvm_profile.py 5000 [--sigma 0.5]

Profiles with ``cProfile`` on the process CPU clock (``time.process_time``), so that a loaded
machine does not distort the shares, and prints the 20 most expensive functions by own time.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import resource
import sys
import time
from pathlib import Path

import numpy as np

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("n", type=int)
    ap.add_argument("--sigma", type=float, default=0.5)
    ap.add_argument("--data", type=Path, default=Path(__file__).parent / "out" / "rvm_fit_data.npz")
    args = ap.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    from bayes_fdi.rvm import RVR

    with np.load(args.data) as d:
        X, y = d["X_train"][: args.n], d["y_train"][: args.n]
    model = RVR(kernel="rbf", width=args.sigma, method="fast", bias=True)
    prof = cProfile.Profile(time.process_time)
    c0 = time.process_time()
    prof.enable()
    model.fit(X, y)
    prof.disable()
    cpu = time.process_time() - c0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(
        f"N={args.n}: fit {cpu:.2f} CPU s, {len(model.relevance_indices_)} RV, "
        f"{model.n_iter_} iterations, peak RSS {peak:.0f} MB"
    )
    pstats.Stats(prof).sort_stats("tottime").print_stats(20)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The memory-traffic floor of a fast (Tipping & Faul) RVR fit on this machine, against the
RVM speed targets (companion of ``rvm_fit.py``).

Usage::

    OMP_NUM_THREADS=1 PYTHONPATH=$PWD .venv/bin/python benchmarks/rvm_floor.py \
        --problems sinc,smooth --sizes 5000

For each fit it counts what any implementation of the algorithm must do on the same path of
actions, and times the fastest way this machine does each piece, in the same process:

* every **addition** of column ``b_i`` needs ``B^T b_i`` (``N x N_B`` reads, the new column of
  the cache ``B^T Phi``). The fit's products (the first column's and one per addition) are
  counted, and one is timed exactly as the solver makes it: BLAS ``dsymv`` on the held float64
  kernel matrix, which reads one triangle (from ``N`` about 15 800 on, the screening copy's
  product, ``docs/rvm.md``);
* every **iteration** updates the factors ``S, Q`` of all ``N_B`` candidates, which reads the
  ``N_B x M`` cache once (``v_j = beta B^T Phi Sigma_j``; Tipping & Faul 2003, "Fast marginal
  likelihood maximisation for sparse Bayesian models", AISTATS). The active-set size ``M`` of
  each iteration is recorded, and a float64 GEMV of ``N_B x M_max`` is timed;
  ``t(M) = t(M_max) M / M_max`` understates a GEMV of ``M`` columns (its fixed cost does not scale
  down), so the sum over iterations is a lower bound.

The floor is the sum of the two. It leaves out everything else (noise updates, Cholesky,
candidate selection, Python), so a fit cannot be faster than it on this machine and path;
fewer products or iterations would need a different path of actions. The streaming floor
times each product as the faster of the solver's product and a float32 GEMV streaming as many
bytes as the product must read (one triangle of the float64 matrix, or the whole screening
copy): what a product kernel, however written, needs at this machine's memory bandwidth. The
float32 floor reads a float32 triangle for each product and a float32 cache: what screening in
float32 would read, before the exact re-checks its ~1e-4 relative error (``N 2^-24``) would
force on the decisions.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from rvm_fit import PROBLEMS, make_data

__all__ = ["SAVED", "main", "measure"]

#: where ``--json`` also saves its measurements (every field, for the record)
SAVED = Path(__file__).parent / "out" / "rvm_floor.json"


def _best_of(fn, repeats: int) -> float:
    """Fastest of ``repeats`` timed calls (seconds), after one warm-up call."""
    fn()
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _stream_seconds(nbytes: int) -> float:
    """Fastest float32 GEMV over a matrix of ``nbytes`` (seconds): streaming that many bytes."""
    import torch

    matrix = torch.ones(max(1, nbytes // 4096), 1024, dtype=torch.float32)
    return _best_of(lambda: matrix @ matrix[0], 10)


def measure(problem: str, n: int) -> dict[str, float]:
    """Fit ``RVR`` on ``make_data(n, problem=problem)`` (the benchmark's data, not nested) and
    return its CPU seconds, the counted products and iterations, and the floors (module
    docstring)."""
    import torch

    import bayes_fdi.rvm.sbl.gaussian as gaussian_module  # the module whose decision is counted
    from bayes_fdi.rvm import RVR
    from bayes_fdi.rvm.sbl import Design

    torch.set_num_threads(1)
    spec = PROBLEMS[problem]
    data = make_data(n, problem=problem)
    X, y = data["X_train"], data["y_train"]

    products = [0]
    sizes: list[int] = []
    designs: list[Design] = []
    rmatmul, decide = Design.rmatmul, gaussian_module.lazy_verified_action

    def counted_rmatmul(self, V, *, exact=True):
        # the screening products B^T b_i: the first column's and one per addition (B^T t is
        # an exact product, made once, by the copy's build at large N)
        if V.shape[1] == 1 and not exact:
            products[0] += 1
            if not designs:
                designs.append(self)
        return rmatmul(self, V, exact=exact)

    last_state: list[object] = [None]

    def counted_decide(*args, **kwargs):
        # (..., act_t, alpha, addable, exact): ``exact`` is made afresh each iteration, and a
        # second call in the same iteration (bounds too loose, screened afresh) is not counted
        if args[-1] is not last_state[0]:
            last_state[0] = args[-1]
            sizes.append(int(args[-3].numel()))
        return decide(*args, **kwargs)

    Design.rmatmul = counted_rmatmul
    gaussian_module.lazy_verified_action = counted_decide
    try:
        c0 = time.process_time()
        model = RVR(kernel="rbf", width=spec.sigma, method="fast", bias=True).fit(X, y)
        cpu = time.process_time() - c0
    finally:
        Design.rmatmul = rmatmul
        gaussian_module.lazy_verified_action = decide

    design = designs[0]
    v = torch.randn(n, 1, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    t_product = _best_of(lambda: design.rmatmul(v, exact=False), 10)
    # the bytes one product must read, and how long a float32 GEMV takes to stream as many
    if design.screen_copy is not None:
        nbytes = design.screen_copy.nbytes
    elif design.kernel is not None:  # dsymv reads one triangle
        nbytes = design.F.element_size() * n * (n + 1) // 2
    else:
        nbytes = design.F.numel() * design.F.element_size()
    t_stream = _stream_seconds(nbytes)
    m_max = max(sizes)
    cache = torch.randn(design.n_basis, m_max, dtype=torch.float64)
    w = torch.randn(m_max, dtype=torch.float64)
    t_gemv = _best_of(lambda: cache @ w, 50)
    cache32, w32 = cache.float(), w.float()
    t_gemv32 = _best_of(lambda: cache32 @ w32, 50)
    # had the products read a float32 triangle and the cache been float32
    t_stream32 = _stream_seconds(4 * n * (n + 1) // 2)
    n_products = products[0]
    products_s = n_products * t_product
    streams_s = n_products * min(t_product, t_stream)
    updates_s = t_gemv * sum(sizes) / m_max
    float32_s = n_products * t_stream32 + t_gemv32 * sum(sizes) / m_max
    return {
        "cpu_s": cpu,
        "iterations": float(model.n_iter_),
        "decisions": float(len(sizes)),
        "relevance_vectors": float(len(model.relevance_indices_)),
        "log_evidence": float(model.log_evidence_),
        "products": float(n_products),
        "product_ms": 1e3 * t_product,
        "mean_M": float(np.mean(sizes)),
        "M_max": float(m_max),
        "gemv_ms_at_M_max": 1e3 * t_gemv,
        "floor_products_s": products_s,
        "floor_updates_s": updates_s,
        "floor_s": products_s + updates_s,
        "product_mb": nbytes / 1e6,
        "stream_ms": 1e3 * t_stream,
        "floor_streaming_s": streams_s + updates_s,
        "floor_float32_s": float32_s,
        "target_s": float(spec.targets.fit_seconds.get(n, float("nan"))),
    }


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point: one Markdown table row per fit."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problems", default="sinc,smooth")
    ap.add_argument("--sizes", default="5000")
    ap.add_argument(
        "--json",
        action="store_true",
        help=f"print one JSON list of the measurements (also saved as {SAVED})",
    )
    args = ap.parse_args(argv)
    if args.json:
        from bayes_fdi.atomic import write_text

        runs = [(p, int(s)) for p in args.problems.split(",") for s in args.sizes.split(",")]
        text = json.dumps([{"problem": p, "n": n, **measure(p, n)} for p, n in runs])
        SAVED.parent.mkdir(parents=True, exist_ok=True)
        write_text(SAVED, text + "\n")
        print(text)
        return 0
    print(
        "| problem | N | fit CPU s | iterations | mean M | RVs | products x ms (MB read) | "
        "floor as made: products + updates = s | streaming floor s | float32 floor s | target s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for problem in args.problems.split(","):
        for n in (int(s) for s in args.sizes.split(",")):
            r = measure(problem, n)
            print(
                f"| {problem} | {n} | {r['cpu_s']:.2f} | {r['iterations']:.0f} | "
                f"{r['mean_M']:.0f} | {r['relevance_vectors']:.0f} | "
                f"{r['products']:.0f} x {r['product_ms']:.2f} ({r['product_mb']:.0f}) | "
                f"{r['floor_products_s']:.2f} + {r['floor_updates_s']:.2f} = {r['floor_s']:.2f} | "
                f"{r['floor_streaming_s']:.2f} | {r['floor_float32_s']:.2f} | "
                f"{r['target_s']:g} |",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""One RVM fit in a fresh process, for ``benchmarks/rvm_fit.py``.

Run by the benchmark driver, never imported by the library. It needs only the standard library
and numpy at import time, so it runs both in the project's environment (``bayes_fdi``) and in
the peers' environment (``benchmarks/.venv-peers``: sklearn-rvm, fastrvm, scikit-learn).

Usage::

    python benchmarks/rvm_worker.py --method fastrvm --data benchmarks/out/rvm_fit_data.npz \
        --n 5000 --sigma 0.5 --out result.json

After the fit it computes each method's *log evidence*: the exact log marginal likelihood
``log N(y | 0, I / beta + Phi diag(1/alpha) Phi^T)`` of the hyperparameters the method returns
(its active basis on the training inputs, ``alpha``, ``beta``), by one numpy formula for every
method (:func:`log_evidence`), and the value the method reports itself where it has one
(fastrvm's last ``scores_`` entry, to which the ``-N/2 log 2 pi`` that SparseBayes omits is
added).

Memory is measured with ``resource.getrusage(RUSAGE_SELF).ru_maxrss`` (peak resident set size of
this process, in KiB on Linux): once after imports and data loading (``rss_before_fit_mb``) and
once right after ``fit`` (``peak_rss_mb``). ``fit`` time is measured around the estimator's ``fit``
call only (which for every method includes building the kernel matrix) both as wall time
(``time.perf_counter``, ``fit_s``) and as CPU time of the process (user + system over all its
threads, ``fit_cpu_s``); on a shared machine the CPU time is the robust one.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import resource
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["METHOD_BUILDERS", "log_evidence", "main", "run_fit"]

Evidence = tuple[float | None, float | None]


def _maxrss_mb() -> float:
    """Peak resident set size of this process so far, in MiB (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _cpu_seconds() -> float:
    """User + system CPU time of this process (all its threads), in seconds."""
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


def _gamma(sigma: float) -> float:
    # sklearn's rbf kernel is exp(-gamma ||x - z||^2); ours is exp(-||x - z||^2 / (2 sigma^2)).
    return 1.0 / (2.0 * sigma * sigma)


def log_evidence(Phi: np.ndarray, alpha: np.ndarray, beta: float, y: np.ndarray) -> float:
    """Exact ``log N(y | 0, I / beta + Phi diag(1/alpha) Phi^T)`` by Woodbury, ``O(N M^2)``."""
    N = y.shape[0]
    H = np.diag(alpha) + beta * (Phi.T @ Phi)
    L = np.linalg.cholesky(H)
    z = np.linalg.solve(L, beta * (Phi.T @ y))
    logdet_C = -N * np.log(beta) + 2.0 * np.log(np.diag(L)).sum() - np.log(alpha).sum()
    return float(-0.5 * (N * np.log(2.0 * np.pi) + logdet_C + beta * (y @ y) - z @ z))


def _rbf(X: np.ndarray, Z: np.ndarray, sigma: float) -> np.ndarray:
    d2 = (X * X).sum(1)[:, None] + (Z * Z).sum(1)[None, :] - 2.0 * X @ Z.T
    return np.exp(-np.maximum(d2, 0.0) * _gamma(sigma))


def _build_ours(sigma: float, *, polish: bool = False) -> tuple[Any, Callable[[Any], int], str]:
    import torch

    torch.set_num_threads(1)
    try:
        torch.set_num_interop_threads(1)
    except RuntimeError:  # already set in this process
        pass
    import bayes_fdi
    from bayes_fdi.rvm import RVR

    model = RVR(kernel="rbf", width=sigma, method="fast", bias=True, polish=polish)
    version = f"bayes_fdi {getattr(bayes_fdi, '__version__', '?')}, torch {torch.__version__}"
    return model, lambda m: len(m.relevance_indices_), version


def _evidence_ours(model: Any, X: np.ndarray, y: np.ndarray, sigma: float) -> Evidence:
    idx = np.asarray(model.relevance_indices_)
    Phi = _rbf(X, X[idx], sigma)
    if model.alpha_.size > idx.size:  # the bias is in the model (its column first)
        Phi = np.hstack([np.ones((X.shape[0], 1)), Phi])
    exact = log_evidence(Phi, np.asarray(model.alpha_), float(model.beta_), y)
    return exact, float(model.log_evidence_)


def _build_fastrvm(sigma: float) -> tuple[Any, Callable[[Any], int], str]:
    from importlib.metadata import version

    import fastrvm
    from fastrvm import _rvr

    model = fastrvm.RVR(kernel="rbf", gamma=_gamma(sigma), fit_intercept=True)
    # fastrvm keeps only part of the solver's result (the bias precision is dropped): record
    # the whole result dict on the way through, without changing the call
    binding = _rvr._sparsebayes_bindings.SparseBayes

    class _Recorder:
        def __init__(self, *args: Any) -> None:
            self._solver = binding(*args)

        def inference(self, basis: Any, targets: Any) -> Any:
            result = self._solver.inference(basis, targets)
            _FASTRVM_RESULT.clear()
            _FASTRVM_RESULT.update(result)
            return result

    _rvr._sparsebayes_bindings = _BindingProxy(_rvr._sparsebayes_bindings, _Recorder)
    return model, lambda m: int(m.n_relevance_), f"fastrvm {version('fastrvm')}"


_FASTRVM_RESULT: dict[str, Any] = {}


class _BindingProxy:
    """The fastrvm binding module with ``SparseBayes`` replaced by a recording wrapper."""

    def __init__(self, module: Any, solver: Any) -> None:
        self._module, self.SparseBayes = module, solver

    def __getattr__(self, name: str) -> Any:
        return getattr(self._module, name)


def _evidence_fastrvm(model: Any, X: np.ndarray, y: np.ndarray, sigma: float) -> Evidence:
    N = X.shape[0]
    reported = float(model.scores_[-1]) - 0.5 * N * np.log(2.0 * np.pi)
    res = _FASTRVM_RESULT
    if not res:
        return None, reported
    idx = np.asarray(res["relevant_idx"]).ravel()
    cols = [np.ones(N) if i == N else _rbf(X, X[[i]], sigma)[:, 0] for i in idx]
    Phi = np.stack(cols, axis=1)
    alpha = np.asarray(res["alpha"], dtype=np.float64).ravel()
    return log_evidence(Phi, alpha, float(res["beta"]), y), reported


def _evidence_none(model: Any, X: np.ndarray, y: np.ndarray, sigma: float) -> Evidence:
    return None, None


def _build_sklearn_rvm(sigma: float) -> tuple[Any, Callable[[Any], int], str]:
    from importlib.metadata import version

    from sklearn_rvm import EMRVR

    model = EMRVR(kernel="rbf", gamma=_gamma(sigma), bias_used=True)
    return model, lambda m: len(m.relevance_), f"sklearn-rvm {version('sklearn-rvm')}"


class _ARDKernelRegression:
    """Tipping's RVM written as scikit-learn's ``ARDRegression`` on the RBF design matrix.

    The RVM is ARD regression with one kernel column per training point; ``ARDRegression``
    (MacKay updates, generic solver) therefore fits the same model with a different optimiser.
    The kernel matrix is built inside ``fit`` as the RVM packages do.
    """

    def __init__(self, sigma: float) -> None:
        self.sigma = sigma

    def fit(self, X: np.ndarray, y: np.ndarray) -> _ARDKernelRegression:
        from sklearn.linear_model import ARDRegression
        from sklearn.metrics.pairwise import rbf_kernel

        self.X_ = X
        self.model_ = ARDRegression(fit_intercept=True).fit(
            rbf_kernel(X, X, gamma=_gamma(self.sigma)), y
        )
        return self

    def predict(self, X: np.ndarray) -> np.ndarray:
        from sklearn.metrics.pairwise import rbf_kernel

        return self.model_.predict(rbf_kernel(X, self.X_, gamma=_gamma(self.sigma)))

    def n_rv(self) -> int:
        # ARDRegression keeps coef_ for every column; pruned ones are exactly zero.
        return int(np.count_nonzero(self.model_.coef_))


def _build_sklearn_ard(sigma: float) -> tuple[Any, Callable[[Any], int], str]:
    from importlib.metadata import version

    model = _ARDKernelRegression(sigma)
    return model, lambda m: m.n_rv(), f"scikit-learn {version('scikit-learn')} ARDRegression"


#: exact / reported log evidence of a fitted model (None where not available: sklearn-rvm
#: rescales its basis internally and ARDRegression leaves the intercept unregularised)
EVIDENCE: dict[str, Callable[[Any, np.ndarray, np.ndarray, float], Evidence]] = {
    "bayes_fdi": _evidence_ours,
    "bayes_fdi-polish": _evidence_ours,
    "fastrvm": _evidence_fastrvm,
    "sklearn-rvm": _evidence_none,
    "sklearn-ard": _evidence_none,
}

METHOD_BUILDERS: dict[str, Callable[[float], tuple[Any, Callable[[Any], int], str]]] = {
    "bayes_fdi": _build_ours,
    "bayes_fdi-polish": lambda sigma: _build_ours(sigma, polish=True),
    "fastrvm": _build_fastrvm,
    "sklearn-rvm": _build_sklearn_rvm,
    "sklearn-ard": _build_sklearn_ard,
}


def _threads_in_use() -> int | None:
    """Largest thread count of any BLAS/OpenMP pool loaded in this process (threadpoolctl)."""
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return None
    info = threadpool_info()
    return max((int(p.get("num_threads", 1)) for p in info), default=1)


def run_fit(method: str, data_path: str, n: int, sigma: float) -> dict[str, Any]:
    """Fit ``method`` on the first ``n`` training rows of ``data_path`` and measure it.

    Returns a JSON-serialisable dict with ``fit_s``, ``predict_s``, ``peak_rss_mb``,
    ``rss_before_fit_mb``, ``n_rv``, ``rmse`` (against the noisy held-out targets), ``rmse_f``
    (against the noise-free function on the same test inputs) and ``version``.
    """
    if method not in METHOD_BUILDERS:
        raise ValueError(f"unknown method {method!r}; expected one of {sorted(METHOD_BUILDERS)}")
    with np.load(data_path) as data:
        if n > data["X_train"].shape[0]:
            raise ValueError(f"n={n} exceeds the {data['X_train'].shape[0]} training rows stored")
        X = np.ascontiguousarray(data["X_train"][:n])
        y = np.ascontiguousarray(data["y_train"][:n])
        X_test = np.ascontiguousarray(data["X_test"])
        y_test = np.ascontiguousarray(data["y_test"])
        f_test = np.ascontiguousarray(data["f_test"])
    model, count_rv, version = METHOD_BUILDERS[method](sigma)
    gc.collect()
    rss_before = _maxrss_mb()
    load1 = os.getloadavg()[0]
    cpu0 = _cpu_seconds()
    t0 = time.perf_counter()
    model.fit(X, y)
    fit_s = time.perf_counter() - t0
    fit_cpu_s = _cpu_seconds() - cpu0
    peak = _maxrss_mb()
    t0 = time.perf_counter()
    pred = np.asarray(model.predict(X_test), dtype=np.float64).reshape(-1)
    predict_s = time.perf_counter() - t0
    exact, reported = EVIDENCE[method](model, X, y, sigma)
    return {
        "method": method,
        "n": n,
        "sigma": sigma,
        "status": "ok",
        "fit_s": fit_s,
        "fit_cpu_s": fit_cpu_s,
        "load1": load1,
        "predict_s": predict_s,
        "peak_rss_mb": peak,
        "rss_before_fit_mb": rss_before,
        "n_rv": count_rv(model),
        "log_evidence": exact,
        "log_evidence_reported": reported,
        "rmse": float(np.sqrt(np.mean((pred - y_test) ** 2))),
        "rmse_f": float(np.sqrt(np.mean((pred - f_test) ** 2))),
        "version": version,
        "python": sys.version.split()[0],
        "threads": _threads_in_use(),
        "cpu_affinity": sorted(os.sched_getaffinity(0)),
    }


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; writes the result dict as JSON to ``--out``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--method", required=True, choices=sorted(METHOD_BUILDERS))
    parser.add_argument("--data", required=True)
    parser.add_argument("--n", type=int, required=True)
    parser.add_argument("--sigma", type=float, required=True)
    parser.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    result = run_fit(args.method, args.data, args.n, args.sigma)
    with open(args.out, "w", encoding="utf-8") as fh:
        json.dump(result, fh)
    return 0


if __name__ == "__main__":
    sys.exit(main())

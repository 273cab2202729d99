"""RVM regression benchmark: bayes_fdi's ``RVR`` against the RVM packages on PyPI.

One command (from the repository root, in the project's environment)::

    OMP_NUM_THREADS=1 PYTHONPATH=$PWD python benchmarks/rvm_fit.py            # both problems
    OMP_NUM_THREADS=1 PYTHONPATH=$PWD python benchmarks/rvm_fit.py --quick    # smallest sizes

Two problems (:data:`PROBLEMS`): ``smooth``, the project's smooth 3-input function on
``[-1, 1]^3`` (N = 500 ... 20000, RBF sigma 0.5), and ``sinc``, ``sum_j sin(x_j) / x_j`` on
``[-10, 10]^3`` (N = 2000 ... 20000, sigma sqrt(5)), which needs hundreds of relevance vectors.

Every fit runs in a fresh, single-threaded subprocess (``benchmarks/rvm_worker.py``) on the same
seeded data (written once to ``benchmarks/out/rvm_fit_data.npz``), with the same RBF width for
every method. ``bayes_fdi`` runs in this interpreter's environment; the peers run in
``benchmarks/.venv-peers``, which this script creates on first use (``pip install`` of the
pinned :data:`PEER_REQUIREMENTS`). Each peer fit has a time limit and a resident-memory guard and
is reported as ``timeout``/``OOM`` instead of hanging; a peer is skipped at a size where the
extrapolation of its own measurements at smaller sizes already exceeds a limit, and the table says
so. Results go to stdout and to ``benchmarks/out/rvm_fit.md`` and ``benchmarks/out/rvm_fit.json``.

Kernel convention. bayes_fdi's ``RVR(width=sigma)`` uses ``k(x, z) = exp(-||x - z||^2 / (2
sigma^2))``. fastrvm, sklearn-rvm and the ARD reference all call scikit-learn's
``pairwise_kernels(..., metric="rbf", gamma=g)``, i.e. ``exp(-g ||x - z||^2)``, so they get
``g = 1 / (2 sigma^2)`` (:func:`sigma_to_gamma`).

Timing. ``fit`` is timed around the estimator's ``fit`` call (kernel matrix included for every
method) as CPU time of the worker process (user + system, all threads; the number used for the
ratios and targets, robust on a shared machine) and as wall time. Fits shorter than
``--repeat-below`` seconds are repeated in fresh processes (up to ``--repeats``) and the fastest
is kept. Peak memory is the worker's peak resident set size, ``getrusage(RUSAGE_SELF).ru_maxrss``
read right after ``fit`` (interpreter and imports included; the largest over repeats).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "DEFAULT_SIGMA",
    "METHODS",
    "PEER_REQUIREMENTS",
    "PROBLEMS",
    "QUICK_SIZES",
    "SIZES",
    "TARGETS",
    "Method",
    "Problem",
    "Targets",
    "add_ratios",
    "check_targets",
    "ensure_peer_env",
    "extrapolate_fit_seconds",
    "extrapolate_peak_mb",
    "format_report",
    "format_table",
    "main",
    "make_data",
    "measure_floor",
    "rbf_kernel_sigma",
    "render_saved",
    "replace_marked_block",
    "run_worker",
    "sigma_to_gamma",
    "sinc_sum",
    "skip_reason",
    "snapshot_source",
    "summarise_repeats",
    "target_function",
]

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
OUT_DIR = HERE / "out"
PEER_VENV = HERE / ".venv-peers"
WORKER = HERE / "rvm_worker.py"

#: Versions verified to install and run together on Python 3.11 (peers' own environment only).
PEER_REQUIREMENTS: tuple[str, ...] = (
    "sklearn-rvm==0.1.1",
    "fastrvm==0.1.5",
    "scikit-learn==1.9.1",
    "numpy==2.4.6",
    "scipy==1.17.1",
    "threadpoolctl==3.8.0",
)

SIZES: tuple[int, ...] = (500, 2000, 5000, 7000, 20000)
QUICK_SIZES: tuple[int, ...] = (500, 2000)
#: RBF width sigma. On this function it is at the evidence plateau (log marginal likelihood of
#: fastrvm's fits at N = 2000 and 5000 within 1 nat over sigma = 0.5 ... 0.7; 0.2 and 1.0 are
#: clearly worse): see benchmarks/README.md.
DEFAULT_SIGMA = 0.5
N_TEST = 2000
NOISE_STD = 0.1
SEED = 0
WALL_FACTOR = 3.0
THREAD_ENV = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "VECLIB_MAXIMUM_THREADS": "1",
    "NUMEXPR_NUM_THREADS": "1",
}


# --------------------------------------------------------------------------------------------
# data and kernel convention
# --------------------------------------------------------------------------------------------
def target_function(X: np.ndarray) -> np.ndarray:
    """Smooth 3-input test function ``sin(pi x1) cos(pi x2 / 2) + x3^2 / 2`` on ``[-1, 1]^3``."""
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != 3:
        raise ValueError(f"X must have shape (n, 3), got {X.shape}")
    return np.sin(np.pi * X[:, 0]) * np.cos(0.5 * np.pi * X[:, 1]) + 0.5 * X[:, 2] ** 2


def sinc_sum(X: np.ndarray) -> np.ndarray:
    """The sinc-sum test function ``sum_j sin(x_j) / x_j`` (1 at ``x_j = 0``) of 3 inputs."""
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != 3:
        raise ValueError(f"X must have shape (n, 3), got {X.shape}")
    return np.sinc(X / np.pi).sum(1)


def make_data(
    n_train: int,
    n_test: int = N_TEST,
    *,
    noise_std: float = NOISE_STD,
    seed: int = SEED,
    problem: str = "smooth",
) -> dict[str, np.ndarray]:
    """Seeded benchmark data: inputs uniform on the problem's cube, Gaussian noise of ``noise_std``.

    The benchmark generates the set once for its largest N and fits size N on the first N rows,
    so the sizes are nested. The test set does not depend on ``n_train`` (separate random
    stream), so every size is scored on the same points.

    Returns
    -------
    dict
        ``X_train`` (n_train, 3), ``y_train``, ``f_train`` (noise-free), ``X_test`` (n_test, 3),
        ``y_test``, ``f_test``, ``noise_std`` and ``seed`` (0-d arrays).
    """
    if n_train < 1 or n_test < 1:
        raise ValueError(f"n_train and n_test must be positive, got {n_train}, {n_test}")
    if not (np.isfinite(noise_std) and noise_std >= 0):
        raise ValueError(f"noise_std must be finite and >= 0, got {noise_std}")
    if problem not in PROBLEMS:
        raise ValueError(f"unknown problem {problem!r}; expected one of {sorted(PROBLEMS)}")
    spec = PROBLEMS[problem]
    train_rng, test_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
    out: dict[str, np.ndarray] = {}
    for name, rng, n in (("train", train_rng, n_train), ("test", test_rng, n_test)):
        X = rng.uniform(spec.low, spec.high, size=(n, 3))
        f = spec.function(X)
        out[f"X_{name}"] = X
        out[f"f_{name}"] = f
        out[f"y_{name}"] = f + noise_std * rng.standard_normal(n)
    out["noise_std"] = np.asarray(noise_std)
    out["seed"] = np.asarray(seed)
    return out


def sigma_to_gamma(sigma: float) -> float:
    """scikit-learn ``gamma`` of the RBF kernel with width ``sigma``: ``1 / (2 sigma^2)``.

    ``exp(-gamma ||x - z||^2) == exp(-||x - z||^2 / (2 sigma^2))``; fastrvm and sklearn-rvm pass
    ``gamma`` to ``sklearn.metrics.pairwise.pairwise_kernels(metric="rbf")``.
    """
    if not (np.isfinite(sigma) and sigma > 0):
        raise ValueError(f"sigma must be finite and > 0, got {sigma}")
    return 1.0 / (2.0 * sigma * sigma)


def rbf_kernel_sigma(X: np.ndarray, Z: np.ndarray, sigma: float) -> np.ndarray:
    """bayes_fdi's RBF kernel matrix ``exp(-||x - z||^2 / (2 sigma^2))`` (reference, numpy)."""
    d2 = ((np.asarray(X)[:, None, :] - np.asarray(Z)[None, :, :]) ** 2).sum(-1)
    return np.exp(-d2 / (2.0 * sigma * sigma))


# --------------------------------------------------------------------------------------------
# methods and targets
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Method:
    """A benchmarked implementation.

    ``env`` is ``"ours"`` (this interpreter) or ``"peers"`` (``benchmarks/.venv-peers``).
    ``exponent`` is the assumed growth of fit time with N used to decide skips before a method has
    two measured sizes; ``dense`` says the method materialises the N x N kernel matrix (its
    memory is then extrapolated as ``a + b N^2`` from its own measurements).
    """

    name: str
    env: str
    label: str
    exponent: float
    dense: bool


METHODS: dict[str, Method] = {
    m.name: m
    for m in (
        Method("bayes_fdi", "ours", "bayes_fdi RVR (fast, torch)", 2.0, False),
        Method("bayes_fdi-polish", "ours", "bayes_fdi RVR (fast + polish)", 2.0, False),
        Method("fastrvm", "peers", "fastrvm 0.1.5 (C++ SparseBayes)", 2.0, True),
        Method("sklearn-rvm", "peers", "sklearn-rvm 0.1.1 EMRVR (EM)", 3.0, True),
        Method("sklearn-ard", "peers", "scikit-learn ARDRegression on the RBF design", 3.0, True),
    )
}
OURS = "bayes_fdi"


@dataclass(frozen=True)
class Targets:
    """Acceptance targets for bayes_fdi's fits.

    ``fit_seconds``: CPU seconds at N; ``peak_mb``: peak RSS at N; ``rmse_ratio``: test RMSE /
    the best peer's at every N; ``speedup``: at N, the fastest peer's CPU seconds / ours;
    ``evidence``: whether the log evidence must be at least every peer's that reports one;
    ``fastrvm_ratio``: at N, the most our CPU seconds / fastrvm's in the same run may be;
    ``floor_ratio`` and ``streaming_floor_ratio``: at N, the most our CPU seconds / the float64
    or the streaming floor of ``rvm_floor.py`` may be (checked where ``--floor`` measured it).
    """

    fit_seconds: Mapping[int, float]
    peak_mb: Mapping[int, float]
    rmse_ratio: float
    speedup: Mapping[int, float] = field(default_factory=dict)
    evidence: bool = False
    fastrvm_ratio: Mapping[int, float] = field(default_factory=dict)
    floor_ratio: Mapping[int, float] = field(default_factory=dict)
    streaming_floor_ratio: Mapping[int, float] = field(default_factory=dict)


@dataclass(frozen=True)
class Problem:
    """A benchmark problem: inputs uniform on ``[low, high]^3``, targets ``function(X) + noise``."""

    name: str
    function: Callable[[np.ndarray], np.ndarray]
    low: float
    high: float
    sigma: float
    sizes: tuple[int, ...]
    quick_sizes: tuple[int, ...]
    targets: Targets
    description: str


TARGETS = Targets(
    fit_seconds={5000: 0.5},
    peak_mb={20000: 4096.0},
    rmse_ratio=1.02,
    evidence=True,
    fastrvm_ratio={2000: 0.5, 5000: 0.5, 7000: 0.5},
    floor_ratio={5000: 2.0},
)
SINC_TARGETS = Targets(
    fit_seconds={5000: 2.5, 20000: 30.0},
    peak_mb={20000: 2048.0},
    rmse_ratio=1.02,
    speedup={5000: 15.0},
    evidence=True,
    fastrvm_ratio={2000: 0.5, 5000: 0.5, 7000: 0.5},
    floor_ratio={5000: 2.0},
    streaming_floor_ratio={20000: 2.0},
)
PROBLEMS: dict[str, Problem] = {
    p.name: p
    for p in (
        Problem(
            "smooth",
            target_function,
            -1.0,
            1.0,
            DEFAULT_SIGMA,
            SIZES,
            QUICK_SIZES,
            TARGETS,
            "y = sin(pi x1) cos(pi x2 / 2) + x3^2 / 2 + e, x ~ U[-1, 1]^3",
        ),
        Problem(
            "sinc",
            sinc_sum,
            -10.0,
            10.0,
            math.sqrt(5.0),
            (2000, 5000, 7000, 20000),
            (2000,),
            SINC_TARGETS,
            "y = sum_j sin(x_j) / x_j + e, x ~ U[-10, 10]^3",
        ),
    )
}


# --------------------------------------------------------------------------------------------
# peers' environment and workers
# --------------------------------------------------------------------------------------------
def ensure_peer_env(venv: Path = PEER_VENV, *, quiet: bool = True) -> Path:
    """Create ``venv`` with the pinned peers if it is missing; return its python."""
    python = venv / "bin" / "python"
    stamp = venv / ".rvm_fit_requirements"
    wanted = "\n".join(PEER_REQUIREMENTS)
    if python.exists() and stamp.exists() and stamp.read_text() == wanted:
        return python
    print(f"[rvm_fit] creating peers' environment {venv} ...", file=sys.stderr)
    if not python.exists():
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    pip = [str(python), "-m", "pip", "install", "--disable-pip-version-check"]
    if quiet:
        pip.append("-q")
    subprocess.run([*pip, *PEER_REQUIREMENTS], check=True)
    stamp.write_text(wanted)
    return python


def _rss_mb(pid: int) -> float:
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except (FileNotFoundError, ProcessLookupError, ValueError):
        pass
    return 0.0


def _cpu_s(pid: int) -> float:
    """CPU seconds (user + system, all threads) of a running process, from /proc."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
            fields = fh.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (FileNotFoundError, ProcessLookupError, ValueError, IndexError):
        return 0.0


def run_worker(
    python: str | Path,
    method: str,
    data_path: Path,
    n: int,
    sigma: float,
    *,
    timeout_s: float,
    mem_limit_mb: float,
    ours_root: Path = ROOT,
    tmp_dir: Path | None = None,
) -> dict[str, Any]:
    """Run one fit in a fresh single-threaded process, guarded by a time and an RSS limit.

    The process is killed when its CPU time exceeds ``timeout_s`` (so that a loaded machine does
    not turn a slow fit into a timeout), when its wall time exceeds ``WALL_FACTOR * timeout_s``,
    or when its resident set exceeds ``mem_limit_mb``. ``ours_root`` goes first on the worker's
    ``PYTHONPATH`` (the ``bayes_fdi`` source to benchmark); scratch files go to ``tmp_dir``.

    Returns the worker's result dict (``status == "ok"``) or a dict with ``status`` one of
    ``"timeout"``, ``"OOM"``, ``"error"`` and a ``detail`` string.
    """
    env = dict(os.environ)
    env.update(THREAD_ENV)
    extra = env.get("PYTHONPATH")
    env["PYTHONPATH"] = str(ours_root) + (os.pathsep + extra if extra else "")
    with tempfile.TemporaryDirectory(prefix="rvm_fit_", dir=tmp_dir) as tmp_name:
        tmp = str(Path(tmp_name).resolve())
        out = Path(tmp) / "result.json"
        err_path = Path(tmp) / "stderr.txt"
        data_arg = str(Path(data_path).resolve())
        cmd = [str(python), str(WORKER), "--method", method, "--data", data_arg]
        cmd += ["--n", str(n), "--sigma", repr(float(sigma)), "--out", str(out)]
        with open(err_path, "w", encoding="utf-8") as err:
            proc = subprocess.Popen(cmd, env=env, stdout=err, stderr=err, cwd=tmp)
            t0 = time.monotonic()
            status, detail, max_rss = None, "", 0.0
            while proc.poll() is None:
                max_rss = max(max_rss, _rss_mb(proc.pid))
                if max_rss > mem_limit_mb:
                    status, detail = "OOM", f"RSS > {mem_limit_mb:.0f} MB guard"
                elif _cpu_s(proc.pid) > timeout_s:
                    status, detail = "timeout", f"> {timeout_s:.0f} CPU s"
                elif time.monotonic() - t0 > WALL_FACTOR * timeout_s:
                    status, detail = "timeout", f"> {WALL_FACTOR * timeout_s:.0f} wall s"
                if status is not None:
                    proc.kill()
                    proc.wait()
                    break
                time.sleep(0.05)
        base = {"method": method, "n": n, "sigma": sigma}
        if status is not None:
            detail += f"; RSS reached {max_rss:.0f} MB" if status == "timeout" else ""
            return {**base, "status": status, "detail": detail, "watch_rss_mb": max_rss}
        if proc.returncode != 0 or not out.exists():
            lines = [ln for ln in err_path.read_text().splitlines() if ln.strip()]
            last = lines[-1] if lines else f"exit code {proc.returncode}"
            return {**base, "status": "error", "detail": last[-200:]}
        return json.loads(out.read_text())


def summarise_repeats(results: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Combine repeated fits of one method at one N: fastest CPU time, largest peak memory.

    All repeats must have succeeded and agree on the fitted model (``n_rv``, ``rmse``), which
    a deterministic fit guarantees; otherwise a ``ValueError`` says so.
    """
    if not results:
        raise ValueError("no results to summarise")
    if any(r.get("status") != "ok" for r in results):
        raise ValueError("only successful fits can be summarised")
    if len({(r["n_rv"], round(r["rmse"], 12)) for r in results}) != 1:
        raise ValueError("repeated fits disagree (non-deterministic fit?)")
    best = dict(min(results, key=lambda r: r["fit_cpu_s"]))
    best["peak_rss_mb"] = max(r["peak_rss_mb"] for r in results)
    best["repeats"] = len(results)
    best["fit_cpu_s_all"] = [r["fit_cpu_s"] for r in results]
    best["fit_s_all"] = [r["fit_s"] for r in results]
    return best


def _ok(rows: Iterable[Mapping[str, Any]], method: str) -> list[Mapping[str, Any]]:
    return sorted(
        (r for r in rows if r["method"] == method and r.get("status") == "ok"), key=lambda r: r["n"]
    )


def extrapolate_fit_seconds(history: Sequence[Mapping[str, Any]], n: int, exponent: float) -> float:
    """Predict CPU seconds at ``n`` from a method's successful fits at smaller sizes.

    Power law through the largest measured size; the exponent is the one between the two
    largest sizes, clipped to ``[1.5, 3]``, or ``exponent`` when only one size is measured.
    Returns 0 without history.
    """
    hist = sorted((r for r in history if r["n"] < n), key=lambda r: r["n"])
    if not hist:
        return 0.0
    last = hist[-1]
    p = exponent
    if len(hist) >= 2:
        prev = hist[-2]
        if prev["fit_cpu_s"] > 0 and last["fit_cpu_s"] > 0 and last["n"] > prev["n"]:
            p = math.log(last["fit_cpu_s"] / prev["fit_cpu_s"]) / math.log(last["n"] / prev["n"])
            p = min(max(p, 1.5), 3.0)
    return float(last["fit_cpu_s"] * (n / last["n"]) ** p)


def extrapolate_peak_mb(history: Sequence[Mapping[str, Any]], n: int) -> float:
    """Predict peak RSS at ``n`` for a dense-kernel method: base + (peak - base) * (n / n_last)^2.

    ``base`` is the RSS before ``fit`` (interpreter, imports, data). Returns 0 without history.
    """
    hist = sorted((r for r in history if r["n"] < n), key=lambda r: r["n"])
    if not hist:
        return 0.0
    last = hist[-1]
    base = last["rss_before_fit_mb"]
    return float(base + max(last["peak_rss_mb"] - base, 0.0) * (n / last["n"]) ** 2)


def skip_reason(
    method: Method,
    n: int,
    rows: Sequence[Mapping[str, Any]],
    *,
    timeout_s: float,
    mem_limit_mb: float,
) -> str | None:
    """Why ``method`` is not run at ``n`` given the results so far, or ``None`` to run it.

    bayes_fdi is never skipped (the limits still guard it). A peer is skipped when it failed
    (timeout/OOM) at a smaller size, when its extrapolated fit time exceeds ``timeout_s``, or,
    for a dense-kernel peer, when its extrapolated peak memory exceeds ``mem_limit_mb``.
    """
    if method.env == "ours":
        return None
    failed = [r for r in rows if r["method"] == method.name and r["n"] < n]
    failed = [r for r in failed if r.get("status") in ("timeout", "OOM")]
    if failed:
        r = min(failed, key=lambda r: r["n"])
        return f"{r['status']} at N={r['n']}"
    hist = _ok(rows, method.name)
    t = extrapolate_fit_seconds(hist, n, method.exponent)
    if t > timeout_s:
        return f"est. {t:.0f} s > {timeout_s:.0f} s limit"
    if method.dense:
        mb = extrapolate_peak_mb(hist, n)
        if mb > mem_limit_mb:
            return f"est. {mb / 1024:.1f} GB > {mem_limit_mb / 1024:.0f} GB guard"
    return None


# --------------------------------------------------------------------------------------------
# ratios, targets, report
# --------------------------------------------------------------------------------------------
def _best_evidence(row: Mapping[str, Any]) -> float | None:
    """A peer's log evidence for the comparison: the larger of the exact value of its returned
    hyperparameters and the value it reports itself (whichever it provides)."""
    values = [row.get(k) for k in ("log_evidence", "log_evidence_reported")]
    values = [v for v in values if v is not None and math.isfinite(v)]
    return max(values) if values else None


def add_ratios(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Return copies of ``rows`` with ratios to the best peer at the same N (and problem).

    ``time_ratio`` = fit CPU seconds / those of the fastest successful peer; ``rmse_ratio`` =
    test RMSE / the lowest test RMSE among successful peers; ``rmse_f_ratio`` likewise for the
    RMSE against the noise-free function; ``evidence_gap`` = log evidence - the largest peer
    log evidence (exact or reported, see :func:`_best_evidence`). ``best_peer_time`` and
    ``best_peer_rmse`` name the peers. ``fastrvm_ratio`` = fit CPU seconds / fastrvm's at the
    same N (same run); ``floor_ratio`` = fit CPU seconds / the row's ``floor_s``, the float64
    floor of ``benchmarks/rvm_floor.py`` (``--floor``), where measured, and
    ``streaming_floor_ratio`` the same for ``floor_streaming_s``. Ratios are ``None``
    where the row or every peer at that N failed.
    """
    out = [dict(r) for r in rows]
    for r in out:
        peers = [
            p
            for p in out
            if p["n"] == r["n"]
            and p.get("problem") == r.get("problem")
            and p.get("status") == "ok"
            and METHODS[p["method"]].env == "peers"
        ]
        r["time_ratio"] = r["rmse_ratio"] = r["rmse_f_ratio"] = r["evidence_gap"] = None
        r["best_peer_time"] = r["best_peer_rmse"] = r["fastrvm_ratio"] = r["floor_ratio"] = None
        r["streaming_floor_ratio"] = None
        if r.get("status") == "ok" and r.get("floor_s"):
            r["floor_ratio"] = r["fit_cpu_s"] / r["floor_s"]
        if r.get("status") == "ok" and r.get("floor_streaming_s"):
            r["streaming_floor_ratio"] = r["fit_cpu_s"] / r["floor_streaming_s"]
        if not peers or r.get("status") != "ok":
            continue
        fastrvm = [p for p in peers if p["method"] == "fastrvm"]
        if fastrvm:
            r["fastrvm_ratio"] = r["fit_cpu_s"] / fastrvm[0]["fit_cpu_s"]
        evidences = [_best_evidence(p) for p in peers if _best_evidence(p) is not None]
        if evidences and r.get("log_evidence") is not None:
            r["evidence_gap"] = r["log_evidence"] - max(evidences)
        fastest = min(peers, key=lambda p: p["fit_cpu_s"])
        accurate = min(peers, key=lambda p: p["rmse"])
        accurate_f = min(peers, key=lambda p: p["rmse_f"])
        r["time_ratio"] = r["fit_cpu_s"] / fastest["fit_cpu_s"]
        r["rmse_ratio"] = r["rmse"] / accurate["rmse"]
        r["rmse_f_ratio"] = r["rmse_f"] / accurate_f["rmse_f"]
        r["best_peer_time"] = fastest["method"]
        r["best_peer_rmse"] = accurate["method"]
    return out


def check_targets(
    rows: Sequence[Mapping[str, Any]], targets: Targets = TARGETS, method: str = OURS
) -> list[dict[str, Any]]:
    """Evaluate ``targets`` for ``method`` on rows that carry ratios (see :func:`add_ratios`).

    Returns one dict per applicable check: ``n``, ``what``, ``limit``, ``value`` and
    ``verdict`` (``"PASS"``, ``"FAIL"``, or ``"n/a"`` when the fit did not finish or no peer
    finished at that N for the RMSE check).
    """
    checks: list[dict[str, Any]] = []
    for r in sorted((r for r in rows if r["method"] == method), key=lambda r: r["n"]):
        ok = r.get("status") == "ok"
        n = r["n"]
        if n in targets.fit_seconds:
            lim = targets.fit_seconds[n]
            val = r["fit_cpu_s"] if ok else None
            verdict = "FAIL" if not ok else ("PASS" if val <= lim else "FAIL")
            checks.append(
                {"n": n, "what": "fit CPU s", "limit": lim, "value": val, "verdict": verdict}
            )
        if n in targets.peak_mb:
            lim = targets.peak_mb[n]
            val = r["peak_rss_mb"] if ok else None
            verdict = "FAIL" if not ok else ("PASS" if val <= lim else "FAIL")
            checks.append(
                {"n": n, "what": "peak MB", "limit": lim, "value": val, "verdict": verdict}
            )
        if n in targets.speedup:
            lim = targets.speedup[n]
            tr = r.get("time_ratio")
            val = 1.0 / tr if ok and tr else None
            verdict = "FAIL" if not ok else ("n/a" if val is None else _verdict(val >= lim))
            checks.append(
                {
                    "n": n,
                    "what": "speed-up vs fastest peer",
                    "limit": lim,
                    "value": val,
                    "verdict": verdict,
                }
            )
        checks += _ratio_checks(r, targets)
        ratio = r.get("rmse_ratio")
        if not ok:
            verdict = "FAIL"
        elif ratio is None:
            verdict = "n/a"
        else:
            verdict = "PASS" if ratio <= targets.rmse_ratio else "FAIL"
        checks.append(
            {
                "n": n,
                "what": "test RMSE / best peer",
                "limit": targets.rmse_ratio,
                "value": ratio,
                "verdict": verdict,
            }
        )
        if targets.evidence:
            gap = r.get("evidence_gap")
            verdict = "FAIL" if not ok else ("n/a" if gap is None else _verdict(gap >= 0.0))
            checks.append(
                {
                    "n": n,
                    "what": "log evidence - best peer's",
                    "limit": 0.0,
                    "value": gap,
                    "verdict": verdict,
                }
            )
    return checks


_RATIO_TARGETS = (
    ("fastrvm_ratio", "time / fastrvm"),
    ("floor_ratio", "time / float64 floor"),
    ("streaming_floor_ratio", "time / streaming floor"),
)


def _ratio_checks(r: Mapping[str, Any], targets: Targets) -> list[dict[str, Any]]:
    """The checks of the ratio targets (at most ``limit``) of one row: FAIL where the fit did
    not finish, n/a where the ratio was not measured (no fastrvm fit, no ``--floor``)."""
    checks = []
    for key, what in _RATIO_TARGETS:
        limits: Mapping[int, float] = getattr(targets, key)
        if r["n"] not in limits:
            continue
        lim, val = limits[r["n"]], r.get(key)
        if r.get("status") != "ok":
            verdict = "FAIL"
        else:
            verdict = "n/a" if val is None else _verdict(val <= lim)
        checks.append({"n": r["n"], "what": what, "limit": lim, "value": val, "verdict": verdict})
    return checks


def _verdict(ok: bool) -> str:
    return "PASS" if ok else "FAIL"


def _fmt(x: Any, spec: str) -> str:
    return "–" if x is None else format(x, spec)


def _fmt_evidence(r: Mapping[str, Any]) -> str:
    exact, reported = r.get("log_evidence"), r.get("log_evidence_reported")
    if exact is None and reported is None:
        return "–"
    if exact is None:
        return f"({reported:.1f} reported)"
    if reported is None or abs(reported - exact) <= 0.05 + 1e-9 * abs(exact):
        return f"{exact:.1f}"
    return f"{exact:.1f} ({reported:.1f} reported)"


def format_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """Markdown table, one line per (N, method), rows ordered by N then method order.

    Columns: N, method, fit CPU s, fit wall s, peak MB, n RV, test RMSE, RMSE vs f (noise-free),
    log evidence (exact, of the returned hyperparameters; with the method's own value where it
    differs), time ratio and RMSE ratio to the best peer, time ratio to fastrvm and to the
    float64 and streaming floors (``--floor``; the two floors differ where the solver's product
    reads the screening copy). Failed or skipped fits show their status.
    """
    order = {name: i for i, name in enumerate(METHODS)}
    head = (
        "| N | method | fit s (CPU) | fit s (wall) | peak MB | n RV | test RMSE | RMSE vs f "
        "| log evidence | time / fastest peer | RMSE / best peer | time / fastrvm "
        "| time / float64 floor | time / streaming floor |"
    )
    lines = [head, "|---:|:---|" + "---:|" * 12]
    for r in sorted(rows, key=lambda r: (r["n"], order.get(r["method"], 99))):
        name = r["method"]
        if r.get("status") != "ok":
            status = r.get("status", "?")
            detail = f" ({r['detail']})" if r.get("detail") else ""
            lines.append(f"| {r['n']} | {name} | {status}{detail} |" + "  |" * 11)
            continue
        lines.append(
            f"| {r['n']} | {name} | {r['fit_cpu_s']:.2f} | {r['fit_s']:.2f} "
            f"| {r['peak_rss_mb']:.0f} | {r['n_rv']} | {r['rmse']:.4f} | {r['rmse_f']:.4f} "
            f"| {_fmt_evidence(r)} "
            f"| {_fmt(r.get('time_ratio'), '.3f')} | {_fmt(r.get('rmse_ratio'), '.3f')} "
            f"| {_fmt(r.get('fastrvm_ratio'), '.3f')} | {_fmt(r.get('floor_ratio'), '.2f')} "
            f"| {_fmt(r.get('streaming_floor_ratio'), '.2f')} |"
        )
    return "\n".join(lines)


def format_report(rows: Sequence[Mapping[str, Any]], meta: Mapping[str, Any]) -> str:
    """Full Markdown report: setup, then per problem a results table and the target checks.

    The report goes into the documentation, which describes the product as it is: the run's
    date and source revision stay in the saved ``rvm_fit.json`` (``meta``), not in the report.
    """
    rows = add_ratios(rows)
    problems = list(dict.fromkeys(r.get("problem", "smooth") for r in rows)) or ["smooth"]
    parts = [
        "### RVM regression fit benchmark",
        "",
        f"{meta.get('cpu', '')} · load average at start "
        f"{meta.get('load_start', '–')}, at end {meta.get('load_end', '–')} · "
        f"single-threaded fresh process per fit · {meta.get('n_test')} test points · "
        f"noise std {meta.get('noise_std')} · seed {meta.get('seed')}",
    ]
    for name in problems:
        prob = PROBLEMS[name]
        sub = [r for r in rows if r.get("problem", "smooth") == name]
        sigma = meta.get("sigmas", {}).get(name, meta.get("sigma", prob.sigma))
        parts += [
            "",
            f"**{name}**: {prob.description}; RBF sigma = {sigma:.6g} "
            f"(sklearn gamma = {sigma_to_gamma(sigma):.4g})",
            "",
            format_table(sub),
            "",
            "| N | target | limit | bayes_fdi | verdict |",
            "|---:|:---|---:|---:|:---|",
        ]
        for c in check_targets(sub, prob.targets):
            parts.append(
                f"| {c['n']} | {c['what']} | {c['limit']:g} | {_fmt(c['value'], '.3f')} "
                f"| {c['verdict']} |"
            )
    versions = sorted({r["version"] for r in rows if r.get("status") == "ok" and "version" in r})
    if versions:
        parts += ["", "Versions: " + "; ".join(versions) + "."]
    if meta.get("command"):
        total = f" (total {meta['total_s']:.0f} s wall)" if meta.get("total_s") else ""
        parts += ["", f"Command: `{meta['command']}`{total}."]
    return "\n".join(parts) + "\n"


BEGIN_MARK = "<!-- rvm_fit:begin (generated by benchmarks/rvm_fit.py --update-docs) -->"
END_MARK = "<!-- rvm_fit:end -->"
DOC_FILES = (HERE / "README.md", ROOT / "docs" / "rvm-benchmark.md")


def replace_marked_block(text: str, block: str) -> str:
    """Replace the text between :data:`BEGIN_MARK` and :data:`END_MARK` (exactly once each)."""
    if text.count(BEGIN_MARK) != 1 or text.count(END_MARK) != 1:
        raise ValueError("expected exactly one begin and one end marker")
    head, rest = text.split(BEGIN_MARK)
    _, tail = rest.split(END_MARK)
    return f"{head}{BEGIN_MARK}\n{block.strip()}\n{END_MARK}{tail}"


# --------------------------------------------------------------------------------------------
# driver
# --------------------------------------------------------------------------------------------
def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def snapshot_source(rev: str, out: Path) -> Path:
    """Extract ``bayes_fdi/`` at git revision ``rev`` into ``out/src-<sha>``; return that folder.

    The benchmark then measures a fixed commit even while the working tree is being edited.
    """
    sha = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short", rev],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    dest = out / f"src-{sha}"
    if not (dest / "SOURCE_COMMIT").exists():
        dest.mkdir(parents=True, exist_ok=True)
        archive = subprocess.run(
            ["git", "-C", str(ROOT), "archive", sha, "bayes_fdi"], capture_output=True, check=True
        ).stdout
        subprocess.run(["tar", "-x", "-C", str(dest)], input=archive, check=True)
        (dest / "SOURCE_COMMIT").write_text(f"git {sha}\n")
    return dest


def render_saved(path: Path) -> str:
    """The Markdown report of a saved ``rvm_fit.json`` (rows, meta)."""
    payload = json.loads(Path(path).read_text())
    rows = [
        {k: v for k, v in r.items() if not k.endswith("_ratio") and not k.startswith("best_")}
        for r in payload["rows"]
    ]
    return format_report(rows, payload["meta"])


def _source_description(root: Path) -> str:
    """The benchmarked bayes_fdi source: ``root/SOURCE_COMMIT`` (a snapshot) or its git HEAD."""
    marker = root / "SOURCE_COMMIT"
    if marker.exists():
        return marker.read_text().strip()
    try:
        rev = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--", "bayes_fdi"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return str(root)
    return f"git {rev}" + (" + uncommitted changes in bayes_fdi/" if dirty else "")


def measure_floor(problem: str, n: int, ours_root: Path) -> dict[str, float]:
    """``floor_s`` (float64) and ``floor_streaming_s`` of ``benchmarks/rvm_floor.py`` for one
    problem and size, measured in a fresh single-threaded process (one more fit, on
    ``make_data(n)``: the floor counts that fit's products and iterations), and every other
    measurement of that process as ``floor_detail``."""
    env = {**os.environ, **THREAD_ENV, "PYTHONPATH": str(ours_root)}
    cmd = [sys.executable, str(HERE / "rvm_floor.py"), "--problems", problem]
    proc = subprocess.run(
        [*cmd, "--sizes", str(n), "--json"], env=env, capture_output=True, text=True, check=True
    )
    result = json.loads(proc.stdout.splitlines()[-1])[0]
    print(
        f"[rvm_fit] {problem} N={n:>6} float64 floor {result['floor_s']:.2f} s "
        f"(streaming {result['floor_streaming_s']:.2f} s)",
        file=sys.stderr,
        flush=True,
    )
    detail = {k: v for k, v in result.items() if k not in ("problem", "n")}
    return {
        "floor_s": result["floor_s"],
        "floor_streaming_s": result["floor_streaming_s"],
        "floor_detail": detail,
    }


def _parse_sizes(text: str) -> tuple[int, ...]:
    sizes = tuple(int(s) for s in text.split(",") if s.strip())
    if not sizes or min(sizes) < 10:
        raise argparse.ArgumentTypeError(f"sizes must be integers >= 10, got {text!r}")
    return sizes


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point (see the module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smallest sizes only (smoke run)")
    ap.add_argument(
        "--problems", default=",".join(PROBLEMS), help=f"subset of {','.join(PROBLEMS)}"
    )
    ap.add_argument("--sizes", type=_parse_sizes, help="comma-separated N, e.g. 500,2000,5000")
    ap.add_argument("--methods", default=",".join(METHODS), help=f"subset of {','.join(METHODS)}")
    ap.add_argument(
        "--sigma", type=float, help="RBF width (all methods; default: the problem's own)"
    )
    ap.add_argument("--timeout", type=float, default=300.0, help="per-fit limit, s")
    ap.add_argument("--mem-limit-gb", type=float, default=12.0, help="per-fit RSS guard, GB")
    ap.add_argument("--repeats", type=int, default=3, help="max fits per (method, N)")
    ap.add_argument(
        "--repeat-below", type=float, default=10.0, help="repeat only fits faster than this (s)"
    )
    ap.add_argument("--seed", type=int, default=SEED)
    ap.add_argument("--n-test", type=int, default=N_TEST)
    ap.add_argument("--out", type=Path, default=OUT_DIR, help="output folder")
    ap.add_argument("--peers-python", type=Path, help="python of an existing peers' environment")
    ap.add_argument(
        "--ours-root",
        type=Path,
        default=ROOT,
        help="folder holding the bayes_fdi package to benchmark (e.g. a snapshot of a commit)",
    )
    ap.add_argument(
        "--ours-commit",
        help="benchmark bayes_fdi as of this git revision (extracted under --out), not the tree",
    )
    ap.add_argument(
        "--floor",
        action="store_true",
        help="also measure bayes_fdi's float64 floor (benchmarks/rvm_floor.py) at each N",
    )
    ap.add_argument(
        "--update-docs",
        action="store_true",
        help="write the report into benchmarks/README.md and docs/rvm-benchmark.md",
    )
    ap.add_argument(
        "--render",
        type=Path,
        nargs="+",
        metavar="JSON",
        help="run nothing: re-render saved rvm_fit.json results (several: one section each)",
    )
    args = ap.parse_args(argv)
    if args.render:
        report = "\n".join(render_saved(path) for path in args.render)
        print(report)
        if args.update_docs:
            for path in DOC_FILES:
                path.write_text(replace_marked_block(path.read_text(), report))
        return 0

    problems = [p for p in args.problems.split(",") if p]
    if unknown := [p for p in problems if p not in PROBLEMS]:
        ap.error(f"unknown problems {unknown}")
    methods = [METHODS[m] for m in args.methods.split(",") if m]
    if unknown := [m for m in args.methods.split(",") if m and m not in METHODS]:
        ap.error(f"unknown methods {unknown}")
    if args.sigma is not None:
        sigma_to_gamma(args.sigma)  # validates
    mem_limit_mb = args.mem_limit_gb * 1024.0
    args.out.mkdir(parents=True, exist_ok=True)

    if args.ours_commit:
        args.ours_root = snapshot_source(args.ours_commit, args.out)
    pythons = {"ours": Path(sys.executable)}
    if any(m.env == "peers" for m in methods):
        pythons["peers"] = args.peers_python or ensure_peer_env()

    sigmas = {p: args.sigma if args.sigma is not None else PROBLEMS[p].sigma for p in problems}
    meta = {
        "date": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "cpu": f"{_cpu_name()}, {os.cpu_count()} cores",
        "load_start": f"{os.getloadavg()[0]:.1f}",
        "sigmas": sigmas,
        "n_test": args.n_test,
        "noise_std": NOISE_STD,
        "seed": args.seed,
        "problems": problems,
        "timeout_s": args.timeout,
        "mem_limit_mb": mem_limit_mb,
        "python": platform.python_version(),
        "bayes_fdi_source": _source_description(args.ours_root.resolve()),
        "command": " ".join(["python", "benchmarks/rvm_fit.py", *(argv or sys.argv[1:])]),
    }
    rows: list[dict[str, Any]] = []
    t_start = time.monotonic()
    for name in problems:
        prob = PROBLEMS[name]
        sizes = args.sizes or (prob.quick_sizes if args.quick else prob.sizes)
        data_path = args.out / f"rvm_fit_data_{name}.npz"
        # always the set for the problem's largest default size, so that a --sizes/--quick run
        # fits exactly the rows (and scores on the test set) of the full run
        data = make_data(max(*sizes, *prob.sizes), args.n_test, seed=args.seed, problem=name)
        np.savez(data_path, **data)
        done: list[dict[str, Any]] = []
        for n in sizes:
            for method in methods:
                reason = skip_reason(
                    method, n, done, timeout_s=args.timeout, mem_limit_mb=mem_limit_mb
                )
                if reason is not None:
                    row = {"method": method.name, "n": n, "status": "skipped", "detail": reason}
                    done.append({**row, "problem": name})
                    print(
                        f"[rvm_fit] {name} N={n:>6} {method.name:<12} skipped: {reason}",
                        file=sys.stderr,
                    )
                    continue
                results: list[dict[str, Any]] = []
                for _ in range(max(args.repeats, 1)):
                    res = run_worker(
                        pythons[method.env],
                        method.name,
                        data_path,
                        n,
                        sigmas[name],
                        timeout_s=args.timeout,
                        mem_limit_mb=mem_limit_mb,
                        ours_root=args.ours_root.resolve(),
                        tmp_dir=args.out,
                    )
                    if res.get("status") != "ok":
                        results = [res]
                        break
                    results.append(res)
                    if res["fit_cpu_s"] >= args.repeat_below:
                        break
                ok = results[0].get("status") == "ok"
                row = {**(summarise_repeats(results) if ok else results[0]), "problem": name}
                done.append(row)
                if row.get("status") == "ok":
                    ev = row.get("log_evidence")
                    msg = (
                        f"fit {row['fit_cpu_s']:.2f} s CPU ({row['fit_s']:.2f} s wall, "
                        f"x{row['repeats']}), {row['peak_rss_mb']:.0f} MB, {row['n_rv']} RV, "
                        f"RMSE {row['rmse']:.4f}, log evidence {_fmt(ev, '.2f')}"
                    )
                else:
                    msg = f"{row['status']}: {row.get('detail', '')}"
                print(
                    f"[rvm_fit] {name} N={n:>6} {method.name:<12} {msg}",
                    file=sys.stderr,
                    flush=True,
                )
            ours = [r for r in done if r["n"] == n and r["method"] == OURS]
            if args.floor and ours and ours[0].get("status") == "ok":
                ours[0].update(measure_floor(name, n, args.ours_root.resolve()))
        rows += done
    meta["load_end"] = f"{os.getloadavg()[0]:.1f}"
    meta["total_s"] = round(time.monotonic() - t_start, 1)

    report = format_report(rows, meta)
    print(report)
    (args.out / "rvm_fit.md").write_text(report)
    payload = {"meta": meta, "rows": add_ratios(rows)}
    (args.out / "rvm_fit.json").write_text(json.dumps(payload, indent=1))
    if args.update_docs:
        for path in DOC_FILES:
            path.write_text(replace_marked_block(path.read_text(), report))
            print(f"[rvm_fit] updated {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

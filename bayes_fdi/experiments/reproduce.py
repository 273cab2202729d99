"""``bayes-fdi reproduce``: the paper's experiments, end to end, in one command.

For each dataset (``paper-simulated``: the DAMADICS actuator driven by sine inputs;
``paper-lublin``: the model driven by the real Lublin Actuator-3 hour) this module

1. simulates the campaign (or loads it from the netCDF cache, keyed by the campaign file's
   SHA-256, the seed and the ``small`` flag);
2. splits every state's runs: the first ``n_train`` (20, as the paper) train, the rest test;
3. fits the normal models (RVR, on the fault-free training runs) and computes the two
   residual features ``mean_r1``, ``mean_r2`` of every run;
4. trains the paper's classifier (a k-means designed tree of RVM classifiers) and the SVM
   baseline (the same tree with SVMs) on the same training features, and scores both on the
   test runs: identification ratios, confusion, log loss, Brier score, top-label ECE, fit and
   predict times, relevance/support vectors per node;
5. goes beyond the paper: the same pipeline on all 20 states, with a data-driven analysis of
   which states the two features can separate and which form groups no classifier can split.

Everything is written to ``--out DIR``: ``report.md`` (and the PNG figures it links) and
``results.json``. Same seed, same numbers.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import math
import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.datasets import STATES, load_dataset, save_dataset, validate_dataset

__all__ = [
    "ALL_STATES",
    "DATASETS",
    "DYNAMIC_LAGS",
    "N_TRAIN",
    "PAPER_GROUPS",
    "PAPER_STATES",
    "REGRESSION_WIDTHS",
    "SEPARABILITY_THRESHOLD",
    "SMALL_DURATION",
    "SMALL_RUNS_PER_STATE",
    "brier_score",
    "calibration_headlines",
    "campaign_file",
    "classification_metrics",
    "configure_parser",
    "find_groups",
    "group_metrics",
    "load_or_simulate",
    "node_classifier",
    "paired_comparison",
    "pairwise_separability",
    "reproduce",
    "run_from_cli",
    "select_regression_width",
    "single_threaded",
    "split_train_test",
    "tree_nodes",
]

#: The ten states the paper diagnoses (Section 5).
PAPER_STATES: tuple[str, ...] = ("fn", "f1", "f2", "f3", "f6", "f11", "f12", "f15", "f17", "f18")
#: All twenty states (fault-free and the 19 DAMADICS faults).
ALL_STATES: tuple[str, ...] = STATES
#: Groups of states whose residuals the paper found alike (end of its Section 3.2).
PAPER_GROUPS: tuple[tuple[str, ...], ...] = (
    ("fn", "f4", "f5", "f8", "f9", "f14"),
    ("f1", "f7", "f10", "f16"),
    ("f2", "f19"),
    ("f6", "f13"),
)
#: The two campaigns of the paper.
DATASETS: tuple[str, ...] = ("paper-simulated", "paper-lublin")
#: Training runs per state (the paper: 20 groups train, the rest test).
N_TRAIN: int = 20
#: Two states are "not separable" when a nearest-neighbour classifier trained on their
#: training features alone misclassifies at least this fraction of them (leave-one-out,
#: balanced). See :func:`pairwise_separability`.
SEPARABILITY_THRESHOLD: float = 0.15
#: Neighbours of the k-NN used by :func:`pairwise_separability`.
SEPARABILITY_NEIGHBOURS: int = 5
#: Candidate RBF widths of the normal models; the one of largest summed log evidence (X and F
#: models, on a subsample of the fault-free training samples) is used. See
#: :func:`select_regression_width`.
REGRESSION_WIDTHS: tuple[float, ...] = (0.05, 0.1, 0.2, 0.4, 0.8)
#: Fault-free samples used to choose the width (the final models use every sample).
REGRESSION_WIDTH_SAMPLES: int = 600
#: Gaussian kernel width of every node classifier (the paper: sigma = 2).
NODE_WIDTH: float = 2.0
#: Lags (s) of the extra normal-model inputs ``CV(t - L)`` of the "beyond the paper" dynamic
#: pipeline. Chosen on the fault-free *training* runs only (log evidence and the spread of
#: held-out run-mean residuals, see docs/diagnosis.md): ``(1, 2, 3)`` ranks first there but
#: keeps about 200 relevance vectors per Lublin model and fits about 9x slower; ``(1, 2)`` is
#: the runner-up at a fraction of the cost.
DYNAMIC_LAGS: tuple[float, ...] = (1.0, 2.0)
#: ``small=True``: runs per state (20 train + 4 test) ...
SMALL_RUNS_PER_STATE: int = 24
#: ... and seconds per run (the paper: 350).
SMALL_DURATION: int = 120


# ----------------------------------------------------------------------------- progress
class _Progress:
    """Stage messages on stderr (one line per long step, with elapsed time)."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.t0 = time.perf_counter()

    def __call__(self, message: str) -> None:
        if self.enabled:
            elapsed = time.perf_counter() - self.t0
            print(f"[reproduce {elapsed:7.1f} s] {message}", file=sys.stderr, flush=True)


@contextlib.contextmanager
def single_threaded() -> Iterator[None]:
    """Run torch and the BLAS libraries on one thread inside the block, then restore.

    The fast RVM solvers add basis functions one at a time, choosing the best by comparing
    floating-point gains; the last bits of a matrix product depend on how many threads summed
    it, and a different last bit can tip one choice and with it the whole fit. With one thread
    the same seed gives the same numbers on every machine (the fits here are small, so the cost
    is modest).
    """
    # threadpoolctl limits the thread pools of libraries already loaded: load them all first.
    import scipy.linalg  # noqa: F401
    import sklearn.cluster
    import sklearn.svm  # noqa: F401
    import torch
    from threadpoolctl import threadpool_limits

    import bayes_fdi.diagnosis
    import bayes_fdi.rvm  # noqa: F401

    n_threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with threadpool_limits(limits=1):
            yield
    finally:
        torch.set_num_threads(n_threads)


# ----------------------------------------------------------------------------- datasets
def campaign_file(name: str | os.PathLike) -> Path:
    """Locate a campaign TOML file.

    Parameters
    ----------
    name
        A path to a ``.toml`` file, or a shipped campaign name (``"paper-simulated"``,
        ``"paper-lublin"``) looked up in ``./sim/`` and then in the ``sim/`` folder next to the
        installed package (the source checkout).

    Returns
    -------
    pathlib.Path
    """
    path = Path(name)
    if path.suffix == ".toml":
        if not path.is_file():
            raise ValueError(f"campaign file {os.fspath(path)!r} does not exist")
        return path
    from bayes_fdi.experiments.shipped_campaigns import campaign_folder

    candidates = [
        Path.cwd() / "sim" / f"{name}.toml",
        Path(__file__).resolve().parents[2] / "sim" / f"{name}.toml",
        campaign_folder() / f"{name}.toml",  # the package data of an installed bayes_fdi
    ]
    for c in candidates:
        if c.is_file():
            return c
    raise ValueError(
        f"campaign {os.fspath(name)!r} not found (looked in {', '.join(map(str, candidates))})"
    )


def _file_hash(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _simulator_hash() -> str:
    """SHA-256 over the simulator's source files (so a changed model never reuses a cache)."""
    from bayes_fdi import actuator
    from bayes_fdi.experiments import campaigns

    files = [*sorted(Path(actuator.__file__).parent.glob("*.py")), Path(campaigns.__file__)]
    digest = hashlib.sha256()
    for f in files:
        digest.update(f.name.encode())
        digest.update(f.read_bytes())
    return digest.hexdigest()


def load_or_simulate(
    campaign: str | os.PathLike,
    *,
    seed: int = 0,
    cache_dir: str | os.PathLike | None = ".cache/datasets",
    small: bool = False,
    progress: bool = True,
) -> tuple[xr.Dataset, dict[str, Any]]:
    """Simulate a campaign, or load it from the netCDF cache.

    The cache file name holds the campaign name, the first 16 hex digits of the SHA-256 of the
    campaign file, 8 of the simulator's source code, the seed and ``small``; any change to the
    campaign file or to the actuator model makes a new entry.

    Parameters
    ----------
    campaign
        Campaign name or TOML path (see :func:`campaign_file`).
    seed
        Simulation seed.
    cache_dir
        Folder of cached datasets; ``None`` disables the cache.
    small
        Shrink the campaign (see :func:`_small_campaign`) for tests, notebooks and CI.
    progress
        Show the simulator's progress bar.

    Returns
    -------
    dataset : xarray.Dataset
    info : dict
        ``campaign`` (name), ``campaign_file``, ``campaign_sha256``, ``cache_file`` (or None),
        ``cached`` (bool), ``simulate_seconds`` (0 when cached).
    """
    from bayes_fdi.experiments import campaigns

    path = campaign_file(campaign)
    digest = _file_hash(path)
    name = path.stem
    info: dict[str, Any] = {
        "campaign": name,
        "campaign_file": os.fspath(path),
        "campaign_sha256": digest,
        "cache_file": None,
        "cached": False,
        "simulate_seconds": 0.0,
    }
    cache_path = None
    if cache_dir is not None:
        suffix = "-small" if small else ""
        code = _simulator_hash()[:8]
        info["simulator_sha256_8"] = code
        cache_path = Path(cache_dir) / f"{name}-{digest[:16]}-{code}-seed{int(seed)}{suffix}.nc"
        info["cache_file"] = os.fspath(cache_path)
        if cache_path.is_file():
            ds = load_dataset(cache_path)
            info["cached"] = True
            return ds, info
    spec = campaigns.load_campaign(path)
    if small:
        spec = _small_campaign(spec)
    import torch

    # The simulator's parallel (numba/OpenMP) kernels raise torch's intra-op thread count for
    # the whole process; restore it so that the models fitted next compute exactly as they do
    # on a cached dataset (summation order depends on the thread count).
    n_threads = torch.get_num_threads()
    t0 = time.perf_counter()
    try:
        ds = campaigns.simulate_campaign(spec, seed=int(seed), progress=progress)
    finally:
        torch.set_num_threads(n_threads)
    info["simulate_seconds"] = time.perf_counter() - t0
    validate_dataset(ds, require=("CV", "P1", "P2", "T1", "X", "F"))
    if cache_path is not None:
        cache_path.parent.mkdir(parents=True, exist_ok=True)
        tmp = cache_path.with_suffix(".tmp.nc")
        save_dataset(ds, tmp)
        os.replace(tmp, cache_path)
    return ds, info


def _small_campaign(spec: Any) -> Any:
    """Small variant: :data:`SMALL_RUNS_PER_STATE` runs per state of :data:`SMALL_DURATION` s."""
    return spec.replace(
        runs_per_state=SMALL_RUNS_PER_STATE, duration=min(int(spec.duration), SMALL_DURATION)
    )


def split_train_test(
    ds: xr.Dataset, *, n_train: int = N_TRAIN, states: Sequence[str] | None = None
) -> tuple[xr.Dataset, xr.Dataset]:
    """Per state, the first ``n_train`` runs (in run order) train and the rest test.

    Parameters
    ----------
    ds
        Dataset with a ``state`` run coordinate.
    n_train
        Training runs per state.
    states
        States to keep (default: every state present). Each must have more than ``n_train``
        runs.

    Returns
    -------
    train, test : xarray.Dataset
        Subsets of ``ds`` (runs in their original order).
    """
    if "state" not in ds.coords:
        raise ValueError("dataset has no 'state' coordinate to split on")
    if n_train < 1:
        raise ValueError(f"n_train must be at least 1, got {n_train}")
    labels = np.asarray(ds["state"].values).astype(str)
    present = list(dict.fromkeys(labels))
    if states is None:
        states = present
    missing = [s for s in states if s not in present]
    if missing:
        raise ValueError(f"dataset has no runs of state(s) {missing} (has {present})")
    train_idx, test_idx = [], []
    for s in states:
        idx = np.flatnonzero(labels == s)
        if idx.size <= n_train:
            raise ValueError(
                f"state {s!r} has {idx.size} runs; need more than n_train={n_train} "
                "(the rest are the test runs)"
            )
        train_idx.append(idx[:n_train])
        test_idx.append(idx[n_train:])
    train = np.sort(np.concatenate(train_idx))
    test = np.sort(np.concatenate(test_idx))
    return ds.isel(run=train), ds.isel(run=test)


# ----------------------------------------------------------------------------- metrics
def _check_proba(y_true: Sequence[str], proba: np.ndarray, classes: Sequence[str]) -> np.ndarray:
    proba = np.asarray(proba, dtype=np.float64)
    if proba.ndim != 2 or proba.shape != (len(y_true), len(classes)):
        raise ValueError(
            f"proba must have shape ({len(y_true)}, {len(classes)}), got {proba.shape}"
        )
    if not np.isfinite(proba).all() or (proba < -1e-12).any():
        raise ValueError("proba must hold finite non-negative probabilities")
    if not np.allclose(proba.sum(axis=1), 1.0, atol=1e-6):
        raise ValueError("every row of proba must sum to 1")
    unknown = sorted(set(map(str, y_true)) - set(map(str, classes)))
    if unknown:
        raise ValueError(f"labels {unknown} are not among the classes {list(classes)}")
    return proba


def brier_score(y_true: Sequence[str], proba: np.ndarray, classes: Sequence[str]) -> float:
    """Multi-class Brier score: mean over runs of ``sum_k (p_k - [y = k])^2`` (0 best, 2 worst).

    Parameters
    ----------
    y_true
        True labels.
    proba
        ``(n, n_classes)`` probabilities in the order of ``classes``.
    classes
        Class names.
    """
    proba = _check_proba(y_true, proba, classes)
    col = {str(c): i for i, c in enumerate(classes)}
    onehot = np.zeros_like(proba)
    onehot[np.arange(len(y_true)), [col[str(y)] for y in y_true]] = 1.0
    return float(np.mean(np.sum((proba - onehot) ** 2, axis=1)))


def _ece(y_true: Sequence[str], proba: np.ndarray, classes: Sequence[str]) -> float:
    """Top-label expected calibration error (the one call site of bayes_fdi.calibration)."""
    from bayes_fdi.calibration import expected_calibration_error

    return float(
        expected_calibration_error(
            np.asarray(y_true).astype(str), proba, classes=list(classes), n_bins=15
        ).value
    )


def classification_metrics(
    y_true: Sequence[str],
    proba: np.ndarray,
    classes: Sequence[str],
    *,
    y_pred: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Identification ratios, confusion and probabilistic scores of a set of test runs.

    Parameters
    ----------
    y_true
        True states.
    proba
        ``(n, n_classes)`` predicted distributions in the order of ``classes``.
    classes
        Class names.
    y_pred
        Predicted labels (default: the argmax of ``proba``).

    Returns
    -------
    dict
        ``accuracy``; ``per_class`` (state -> identification ratio, in ``classes`` order);
        ``confusion`` (``classes``, ``matrix`` with true states as rows);
        ``log_loss`` (natural log, probabilities clipped at 1e-15), ``brier``
        (:func:`brier_score`), ``ece`` (top-label, 15 equal-width bins).
    """
    from sklearn.metrics import confusion_matrix

    classes = [str(c) for c in classes]
    y_true = np.asarray(y_true).astype(str)
    proba = _check_proba(y_true, proba, classes)
    if y_pred is None:
        y_pred = np.asarray(classes)[np.argmax(proba, axis=1)]
    y_pred = np.asarray(y_pred).astype(str)
    cm = confusion_matrix(y_true, y_pred, labels=classes)
    support = cm.sum(axis=1)
    per_class = {
        c: (float(cm[i, i] / support[i]) if support[i] else float("nan"))
        for i, c in enumerate(classes)
    }
    col = {c: i for i, c in enumerate(classes)}
    p_true = proba[np.arange(y_true.size), [col[s] for s in y_true]]
    return {
        "accuracy": float(np.mean(y_true == y_pred)),
        "per_class": per_class,
        "confusion": {"classes": classes, "matrix": cm.astype(int).tolist()},
        "log_loss": float(-np.mean(np.log(np.clip(p_true, 1e-15, 1.0)))),
        "brier": brier_score(y_true, proba, classes),
        "ece": _ece(y_true, proba, classes),
    }


# ----------------------------------------------------------------------------- groups
def pairwise_separability(
    features: np.ndarray,
    labels: Sequence[str],
    *,
    states: Sequence[str] | None = None,
    n_neighbors: int = SEPARABILITY_NEIGHBOURS,
) -> tuple[list[str], np.ndarray]:
    """Pairwise confusion of states from their features alone.

    For each pair of states ``(a, b)`` a ``k``-nearest-neighbour classifier (``k`` =
    ``n_neighbors``, Euclidean distance on features standardised over all given runs) is
    evaluated by leave-one-out on the runs of ``a`` and ``b`` only; the entry is its balanced
    error rate (mean of the two per-state error rates). A nearest-neighbour rule makes no
    assumption on the shape of a state's feature cloud (a fault of varying strength draws a
    curve, not a Gaussian blob); its error estimates how much the two states' feature
    distributions overlap (asymptotically at most twice the Bayes error for k = 1, and close to
    it for moderate k). Identical distributions give about 0.5, disjoint ones 0.

    Parameters
    ----------
    features
        ``(n, d)`` features.
    labels
        ``n`` state names.
    states
        States to compare (default: in order of first appearance).
    n_neighbors
        ``k`` of the k-NN rule (reduced to the pair's run count minus one when larger).

    Returns
    -------
    states : list of str
    error : numpy.ndarray
        ``(k, k)`` symmetric balanced leave-one-out error; diagonal 0.
    """
    X = np.asarray(features, dtype=np.float64)
    y = np.asarray(labels).astype(str)
    if X.ndim != 2 or X.shape[0] != y.shape[0]:
        raise ValueError(
            f"features must be (n, d) with one label per row; got {X.shape}, {y.shape}"
        )
    if not np.isfinite(X).all():
        raise ValueError("features contain NaN or inf")
    states = list(dict.fromkeys(y)) if states is None else [str(s) for s in states]
    scale = X.std(axis=0)
    scale[scale == 0] = 1.0
    Z = (X - X.mean(axis=0)) / scale
    k = len(states)
    error = np.zeros((k, k))
    for i in range(k):
        for j in range(i + 1, k):
            mask = (y == states[i]) | (y == states[j])
            if (y == states[i]).sum() < 2 or (y == states[j]).sum() < 2:
                raise ValueError(f"states {states[i]!r} and {states[j]!r} need >= 2 runs each")
            Zp, is_i = Z[mask], y[mask] == states[i]
            k_eff = min(int(n_neighbors), Zp.shape[0] - 1)
            d2 = ((Zp[:, None, :] - Zp[None, :, :]) ** 2).sum(axis=-1)
            np.fill_diagonal(d2, np.inf)  # leave the run itself out
            nearest = np.argsort(d2, axis=1, kind="stable")[:, :k_eff]
            votes_i = is_i[nearest].sum(axis=1)
            # majority vote; a tie (possible only for even k) goes to states[i]
            pred_i = votes_i * 2 >= k_eff if k_eff % 2 == 0 else votes_i * 2 > k_eff
            err = 0.5 * (np.mean(~pred_i[is_i]) + np.mean(pred_i[~is_i]))
            error[i, j] = error[j, i] = err
    return states, error


def find_groups(
    states: Sequence[str],
    error: np.ndarray,
    *,
    threshold: float = SEPARABILITY_THRESHOLD,
    linkage: str = "complete",
) -> list[list[str]]:
    """Groups of states that the features cannot tell apart.

    Two states are *confusable* when ``error[a, b] >= threshold``.

    - ``linkage="complete"`` (default): agglomerative clustering in which two groups merge only
      if every pair of their states is confusable; at each step the two groups with the largest
      smallest pairwise error merge (ties: the earliest states). Every group is thus a set of
      mutually confusable states.
    - ``linkage="single"``: connected components of the confusability graph. It chains: a fault
      whose strength range makes it look like fn when weak and like f1 when strong links fn and
      f1, though the two are perfectly separable.

    Parameters
    ----------
    states
        State names, in the order of ``error``.
    error
        ``(k, k)`` symmetric pairwise error (see :func:`pairwise_separability`).
    threshold
        Confusability threshold.
    linkage
        ``"complete"`` or ``"single"``.

    Returns
    -------
    list of list of str
        Groups in order of their first state; states within a group in ``states`` order.
        Singletons are the separable states.
    """
    error = np.asarray(error, dtype=np.float64)
    k = len(states)
    if error.shape != (k, k):
        raise ValueError(f"error must be ({k}, {k}), got {error.shape}")
    if not np.allclose(error, error.T, equal_nan=False):
        raise ValueError("error must be symmetric")
    if linkage not in ("complete", "single"):
        raise ValueError(f"linkage must be 'complete' or 'single', got {linkage!r}")
    clusters: list[list[int]] = [[i] for i in range(k)]
    while len(clusters) > 1:
        best, pair = -np.inf, None
        for a in range(len(clusters)):
            for b in range(a + 1, len(clusters)):
                block = error[np.ix_(clusters[a], clusters[b])]
                score = block.min() if linkage == "complete" else block.max()
                if score > best:
                    best, pair = score, (a, b)
        if pair is None or best < threshold:
            break
        a, b = pair
        clusters[a] = sorted(clusters[a] + clusters[b])
        del clusters[b]
    clusters.sort(key=min)
    return [[str(states[i]) for i in c] for c in clusters]


def group_metrics(
    y_true: Sequence[str],
    proba: np.ndarray,
    classes: Sequence[str],
    groups: Sequence[Sequence[str]],
    *,
    y_pred: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Scores of a classifier when states are only identifiable up to their group.

    Parameters
    ----------
    y_true, proba, classes, y_pred
        As in :func:`classification_metrics`.
    groups
        Groups of states (every class in exactly one group).

    Returns
    -------
    dict
        ``separable_states`` (states alone in their group), ``separable_accuracy`` (accuracy
        on the test runs of separable states; NaN if none), ``group_accuracy`` (fraction of
        runs whose predicted state is in the true state's group), ``group_mass`` (mean
        probability the classifier puts on the true state's group), ``per_state_group_mass``
        (the same per true state).
    """
    classes = [str(c) for c in classes]
    y_true = np.asarray(y_true).astype(str)
    proba = _check_proba(y_true, proba, classes)
    group_of: dict[str, int] = {}
    for g, members in enumerate(groups):
        for s in members:
            if str(s) in group_of:
                raise ValueError(f"state {s!r} is in more than one group")
            group_of[str(s)] = g
    missing = [c for c in classes if c not in group_of]
    if missing:
        raise ValueError(f"classes {missing} are in no group")
    if y_pred is None:
        y_pred = np.asarray(classes)[np.argmax(proba, axis=1)]
    y_pred = np.asarray(y_pred).astype(str)
    col_group = np.array([group_of[c] for c in classes])
    true_group = np.array([group_of[s] for s in y_true])
    mass = np.array([proba[n, col_group == true_group[n]].sum() for n in range(len(y_true))])
    separable = [str(g[0]) for g in groups if len(g) == 1]
    sep_mask = np.isin(y_true, separable)
    pred_group = np.array([group_of[s] for s in y_pred])
    return {
        "separable_states": separable,
        "separable_accuracy": (
            float(np.mean(y_true[sep_mask] == y_pred[sep_mask])) if sep_mask.any() else math.nan
        ),
        "group_accuracy": float(np.mean(pred_group == true_group)),
        "group_mass": float(mass.mean()),
        "per_state_group_mass": {
            s: float(mass[y_true == s].mean()) for s in classes if (y_true == s).any()
        },
    }


# ----------------------------------------------------------------------------- pipelines
def select_regression_width(
    normal_runs: xr.Dataset,
    *,
    widths: Sequence[float] = REGRESSION_WIDTHS,
    max_samples: int = REGRESSION_WIDTH_SAMPLES,
    seed: int = 0,
    input_lags: Sequence[float] = (),
) -> tuple[float, dict[float, float]]:
    """RBF width of the normal models by maximum evidence over a grid.

    Both normal models (``X`` and ``F`` on ``(CV, sqrt(P1 - P2), T1)``) are fitted with each
    candidate width on the same random subsample of the fault-free samples; the width with the
    largest summed log marginal likelihood wins
    (:func:`bayes_fdi.diagnosis.width_search.evidence_grid_search`,
    also the default width search of :class:`bayes_fdi.diagnosis.normal_models.NormalModels`).
    (``RVR(width="auto")`` searches down to much smaller widths, where a fit on thousands of
    samples keeps hundreds of basis functions and takes minutes; the grid stays where the
    evidence peaks on these data.)

    Parameters
    ----------
    normal_runs
        Fault-free runs.
    widths
        Candidate widths.
    max_samples
        Subsample size.
    seed
        Subsample seed.
    input_lags
        Lags (seconds) of extra inputs ``CV(t - L)`` of the normal models
        (:func:`bayes_fdi.diagnosis.model_inputs.model_inputs`); default ``()``, the paper's inputs.

    Returns
    -------
    width : float
    log_evidence : dict
        Width -> summed log evidence.
    """
    from bayes_fdi.diagnosis import evidence_grid_search, model_inputs
    from bayes_fdi.rvm import RVR

    U, _ = model_inputs(normal_runs, warn=False, input_lags=input_lags)
    targets = {c: np.asarray(normal_runs[c].transpose("run", "time").values).ravel() for c in "XF"}
    ok = np.isfinite(U).all(axis=1) & np.isfinite(targets["X"]) & np.isfinite(targets["F"])
    idx = np.flatnonzero(ok)
    if idx.size < 10:
        raise ValueError(f"only {idx.size} finite fault-free samples to choose the width")
    res = evidence_grid_search(
        lambda w: RVR(kernel="rbf", width=w),
        U[idx],
        {c: t[idx] for c, t in targets.items()},
        widths,
        max_samples=max_samples,
        rng=np.random.default_rng(seed),
    )
    return res.width, res.log_evidence


def node_classifier(kind: str = "rvm", *, width: float = NODE_WIDTH) -> Any:
    """The binary classifier at each tree node (the paper's Gaussian kernel, sigma = 2).

    Used inside :class:`bayes_fdi.diagnosis.tree.HierarchicalClassifier` with
    ``node_scaling=True``: each
    node standardises its own training samples first, so ``sigma`` means "``sigma`` standard
    deviations of this node's data" at every depth — the root separates far-apart groups of
    states, the deepest nodes states a few hundredths apart, and one width fits both.

    Parameters
    ----------
    kind
        ``"rvm"`` (:class:`bayes_fdi.rvm.RVC`) or ``"svm"``
        (:func:`bayes_fdi.diagnosis.baselines.svm_classifier`: C = 1, Platt-scaled probabilities).
    width
        Gaussian kernel width sigma.
    """
    if kind == "rvm":
        from bayes_fdi.rvm import RVC

        return RVC(kernel="rbf", width=width)
    if kind == "svm":
        from bayes_fdi.diagnosis.baselines import svm_classifier

        return svm_classifier(sigma=width)
    raise ValueError(f"kind must be 'rvm' or 'svm', got {kind!r}")


def _tree(kind: str, seed: int) -> Any:
    from bayes_fdi.diagnosis.tree import HierarchicalClassifier

    return HierarchicalClassifier(node_classifier(kind), node_scaling=True, random_state=seed)


def _n_vectors(est: Any) -> int | None:
    final = est.steps[-1][1] if hasattr(est, "steps") else est
    for attr in ("relevance_vectors_", "support_vectors_"):
        vec = getattr(final, attr, None)
        if vec is not None:
            return int(np.shape(vec)[0])
    return None


def tree_nodes(clf: Any, prefix: str) -> list[dict[str, Any]]:
    """Nodes of a fitted HierarchicalClassifier as plain dicts (breadth first, root first).

    Each has ``name`` (``prefix`` + number), ``left``, ``right``, ``classes``, ``vectors``
    (relevance or support vectors, also inside a :func:`node_classifier` pipeline) and
    ``samples`` (the node's training samples).
    """
    out = []
    for node in clf.nodes_:
        n_vec = node.n_vectors if node.n_vectors is not None else _n_vectors(node.estimator)
        out.append(
            {
                "name": f"{prefix}{node.index + 1}",
                "left": [str(c) for c in node.left],
                "right": [str(c) for c in node.right],
                "classes": [str(c) for c in (*node.left, *node.right)],
                "vectors": None if n_vec is None else int(n_vec),
                "samples": int(node.n_samples),
            }
        )
    return out


def _tree_text(nodes: list[dict[str, Any]], prefix: str) -> str:
    """The fitted tree as text with vectors/samples per node."""
    from bayes_fdi.experiments.reproduce_report import tree_text

    return tree_text(nodes, prefix=prefix)


def _fit_tree(
    make: Callable[[], Any], X_train: np.ndarray, y_train: np.ndarray, X_test: np.ndarray
) -> tuple[Any, Any, np.ndarray, float, float]:
    """Standardise (training mean/std), fit a tree classifier, predict; time both steps."""
    from sklearn.preprocessing import StandardScaler

    scaler = StandardScaler().fit(X_train)
    t0 = time.perf_counter()
    clf = make().fit(scaler.transform(X_train), y_train)
    fit_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    proba = np.asarray(clf.predict_proba(scaler.transform(X_test)), dtype=np.float64)
    predict_s = time.perf_counter() - t0
    return clf, scaler, proba, fit_s, predict_s


def _state_key(state: str) -> tuple[int, int]:
    """Sort key of the paper's tables: f1, f2, ..., f19, then fn."""
    return (1, 0) if state == "fn" else (0, int(state[1:]))


def paired_comparison(
    y_true: Sequence[str], pred_a: Sequence[str], pred_b: Sequence[str]
) -> dict[str, Any]:
    """Exact McNemar test of two classifiers scored on the same runs.

    Only the runs on which exactly one classifier is right carry information: under the null
    hypothesis of equal accuracy each of them is equally likely to favour either, so the
    count ``a_only`` is Binomial(``a_only + b_only``, 1/2).

    Returns
    -------
    dict
        ``a_only`` (runs only the first gets right), ``b_only``, ``both``, ``neither``
        and ``p_value`` (two-sided exact binomial; 1 when no run is discordant).
    """
    from scipy.stats import binomtest

    y = np.asarray(y_true).astype(str)
    ra = np.asarray(pred_a).astype(str) == y
    rb = np.asarray(pred_b).astype(str) == y
    a_only, b_only = int(np.sum(ra & ~rb)), int(np.sum(~ra & rb))
    n = a_only + b_only
    return {
        "a_only": a_only,
        "b_only": b_only,
        "both": int(np.sum(ra & rb)),
        "neither": int(np.sum(~ra & ~rb)),
        "p_value": float(binomtest(a_only, n, 0.5).pvalue) if n else 1.0,
    }


def _method_result(
    clf: Any, y_test: np.ndarray, proba: np.ndarray, fit_s: float, predict_s: float, prefix: str
) -> dict[str, Any]:
    fitted = [str(c) for c in clf.classes_]
    classes = sorted(fitted, key=_state_key)
    proba = proba[:, [fitted.index(c) for c in classes]]
    out = classification_metrics(y_test, proba, classes)
    out["nodes"] = tree_nodes(clf, prefix)
    out["tree"] = _tree_text(out["nodes"], prefix)
    out["fit_seconds"] = float(fit_s)
    out["predict_seconds"] = float(predict_s)
    return out


def _strength_ranges(ds: xr.Dataset) -> dict[str, dict[str, Any]]:
    labels = np.asarray(ds["state"].values).astype(str)
    strength = np.asarray(ds["strength"].values, dtype=np.float64)
    profile = np.asarray(ds["profile"].values).astype(str)
    out = {}
    for s in dict.fromkeys(labels):
        m = labels == s
        out[s] = {
            "runs": int(m.sum()),
            "min": float(strength[m].min()),
            "max": float(strength[m].max()),
            "profiles": sorted(set(profile[m])),
        }
    return out


def _residual_examples(
    res: xr.Dataset, labels: np.ndarray, states: Sequence[str]
) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """First test run of each of ``states`` (present ones): (time, r1, r2)."""
    t = np.asarray(res["time"].values, dtype=np.float64)
    out = {}
    for s in states:
        idx = np.flatnonzero(labels == s)
        if idx.size:
            i = int(idx[0])
            out[s] = (t, res["r1"].values[i].copy(), res["r2"].values[i].copy())
    return out


def evaluate_dataset(
    ds: xr.Dataset,
    *,
    states: Sequence[str] = PAPER_STATES,
    n_train: int = N_TRAIN,
    seed: int = 0,
    all_states: bool = True,
    progress: Callable[[str], None] | None = None,
    diagnoser: Any = None,
    input_lags: Sequence[float] = (),
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The paper's protocol (and the 20-state extension) on one dataset.

    Parameters
    ----------
    ds
        Labelled runs of the states (each with more than ``n_train`` runs).
    states
        States of the paper protocol (must include ``"fn"``).
    n_train
        Training runs per state (first in run order); the rest test.
    seed
        Seed of the models (tree design, subsampling, SVM Platt scaling).
    all_states
        Also run the pipeline on every state present (see :func:`pairwise_separability`).
    progress
        Callable receiving stage messages.
    diagnoser
        Unfitted :class:`~bayes_fdi.diagnosis.FaultDiagnoser` for the RVM method. Default: RVR
        normal models with the width of :func:`select_regression_width` and a k-means tree
        (``node_scaling=True``) of :func:`node_classifier` ``("rvm")`` nodes — the
        diagnoser's default tree. The SVM baseline is the same tree of ``("svm")`` nodes on the
        RVM pipeline's features.
    input_lags
        Lags (s) of extra normal-model inputs ``CV(t - L)`` of the default diagnoser (dynamic
        normal models, beyond the paper; see
        :class:`bayes_fdi.diagnosis.normal_models.NormalModels`).
        Default ``()``: the paper's static inputs.

    Returns
    -------
    results : dict
        JSON-ready: ``rvm`` and ``svm`` metrics (:func:`classification_metrics` plus ``nodes``,
        ``tree``, ``fit_seconds``, ``predict_seconds``), ``split``, ``strength``, ``timing``
        and, with ``all_states``, ``all_states`` (pairwise separability, groups, per-state and
        group scores of both methods).
    artifacts : dict
        Arrays for the figures: ``features``/``labels`` of the paper states' test runs,
        ``residuals`` examples (time, r1, r2 of the first test run of fn, f1, f2, f15),
        ``rvm_predict`` (features -> labels), ``train_features`` and ``train_labels``
        (training runs of every state), ``diagnoser`` (the fitted RVM
        :class:`~bayes_fdi.diagnosis.FaultDiagnoser`) and ``test_runs`` (the paper states'
        test runs).

    Notes
    -----
    Torch and BLAS run on one thread here (:func:`single_threaded`), so the same seed gives
    the same numbers on any machine.
    """
    with single_threaded():
        return _evaluate_dataset(
            ds,
            states=states,
            n_train=n_train,
            seed=seed,
            all_states=all_states,
            progress=progress,
            diagnoser=diagnoser,
            input_lags=input_lags,
        )


def _evaluate_dataset(
    ds: xr.Dataset,
    *,
    states: Sequence[str],
    n_train: int,
    seed: int,
    all_states: bool,
    progress: Callable[[str], None] | None,
    diagnoser: Any,
    input_lags: Sequence[float],
) -> tuple[dict[str, Any], dict[str, Any]]:
    from bayes_fdi.diagnosis import FaultDiagnoser
    from bayes_fdi.diagnosis.features import extract_features

    say = progress or (lambda _msg: None)
    states = [str(s) for s in states]
    if "fn" not in states:
        raise ValueError("the paper protocol needs the fault-free state 'fn' among the states")
    present = list(dict.fromkeys(np.asarray(ds["state"].values).astype(str)))
    every = [s for s in ALL_STATES if s in present] if all_states else states
    train, test = split_train_test(ds, n_train=n_train, states=every)
    y_train_all = np.asarray(train["state"].values).astype(str)
    y_test_all = np.asarray(test["state"].values).astype(str)
    in_paper_train = np.isin(y_train_all, states)
    in_paper_test = np.isin(y_test_all, states)
    normal = train.isel(run=np.flatnonzero(y_train_all == "fn"))
    timing: dict[str, float] = {}
    if diagnoser is None:
        say("normal-model kernel width by maximum evidence")
        t0 = time.perf_counter()
        width, evidence = select_regression_width(normal, seed=seed, input_lags=input_lags)
        timing["regression_width"] = time.perf_counter() - t0
        from bayes_fdi.rvm import RVR

        diagnoser = FaultDiagnoser(
            regressor=RVR(kernel="rbf", width=width),
            classifier=_tree("rvm", seed),
            random_state=seed,
            input_lags=tuple(input_lags),
        )
        regression = {"width": width, "log_evidence": evidence}
    elif len(input_lags):
        raise ValueError("give input_lags to the diagnoser itself when passing a diagnoser")
    else:
        regression = {}
    say(f"fitting the RVM pipeline (normal models on {normal.sizes['run']} fault-free runs)")
    diag = diagnoser.fit(normal, train.isel(run=np.flatnonzero(in_paper_train)))
    timing.update({f"rvm_fit_{k}": float(v) for k, v in diag.fit_seconds_.items()})

    say(f"residuals and features of {test.sizes['run']} test runs")
    t0 = time.perf_counter()
    res_test = diag.normal_models_.residuals(test)
    feats_test, _ = extract_features(res_test, diag.feature_names_)
    timing["test_residuals"] = time.perf_counter() - t0
    if all_states and len(every) > len(states):
        t0 = time.perf_counter()
        extra = train.isel(run=np.flatnonzero(~in_paper_train))
        feats_extra, _ = extract_features(diag.normal_models_.residuals(extra), diag.feature_names_)
        timing["extra_train_residuals"] = time.perf_counter() - t0
        feats_train_all = np.empty((train.sizes["run"], feats_extra.shape[1]))
        feats_train_all[in_paper_train] = diag.training_features_
        feats_train_all[~in_paper_train] = feats_extra
    else:
        feats_train_all = diag.training_features_
    for name, F in (("training", feats_train_all), ("test", feats_test)):
        if not np.isfinite(F).all():
            raise ValueError(f"non-finite residual features in the {name} runs")

    X_tr, y_tr = diag.training_features_, np.asarray(diag.training_labels_).astype(str)
    X_te, y_te = feats_test[in_paper_test], y_test_all[in_paper_test]
    say(f"RVM tree on {X_tr.shape[0]} training runs: predicting {X_te.shape[0]} test runs")
    t0 = time.perf_counter()
    proba = diag.predict_features(X_te)
    rvm_predict_s = time.perf_counter() - t0
    results: dict[str, Any] = {
        "rvm": _method_result(
            diag.classifier_, y_te, proba, diag.fit_seconds_["classifier"], rvm_predict_s, "RVM"
        )
    }

    say("SVM tree on the same features")

    def make_svm() -> Any:
        return _tree("svm", seed)

    svm, _, proba_svm, fit_s, pred_s = _fit_tree(make_svm, X_tr, y_tr, X_te)
    results["svm"] = _method_result(svm, y_te, proba_svm, fit_s, pred_s, "SVM")
    results["paired"] = paired_comparison(
        y_te,
        np.asarray(diag.classes_).astype(str)[np.argmax(proba, axis=1)],
        np.asarray(svm.classes_).astype(str)[np.argmax(proba_svm, axis=1)],
    )
    results["split"] = {
        "n_train_per_state": int(n_train),
        "train_runs": {s: int((y_tr == s).sum()) for s in states},
        "test_runs": {s: int((y_te == s).sum()) for s in states},
        "normal_model_runs": int(normal.sizes["run"]),
        "normal_model_samples": int(diag.normal_models_.n_train_samples_),
    }
    results["normal_models"] = {
        **regression,
        "input_lags": [float(v) for v in diag.normal_models_.input_lags_],
        "relevance_vectors": {k: _n_vectors(r) for k, r in diag.normal_models_.regressors_.items()},
        "noise_std": {
            k: float(r.beta_**-0.5)
            for k, r in diag.normal_models_.regressors_.items()
            if getattr(r, "beta_", None)
        },
    }
    results["strength"] = _strength_ranges(ds)
    results["features"] = list(diag.feature_names_)

    artifacts: dict[str, Any] = {
        "features": X_te,
        "labels": y_te,
        "rvm_predict": lambda F: diag.classes_[np.argmax(diag.predict_features(F), axis=1)],
        "residuals": _residual_examples(res_test, y_test_all, ("fn", "f1", "f2", "f15")),
        "train_features": feats_train_all,
        "train_labels": y_train_all,
        "diagnoser": diag,
        "test_runs": test.isel(run=np.flatnonzero(in_paper_test)),
    }

    if all_states:
        say(f"pairwise separability of {len(every)} states on their training features")
        t0 = time.perf_counter()
        sep_states, error = pairwise_separability(feats_train_all, y_train_all, states=every)
        groups = find_groups(sep_states, error)
        timing["separability"] = time.perf_counter() - t0
        block: dict[str, Any] = {
            "states": sep_states,
            "pairwise_error": error,
            "threshold": SEPARABILITY_THRESHOLD,
            "n_neighbors": SEPARABILITY_NEIGHBOURS,
            "groups": groups,
            "paper_groups": [list(g) for g in PAPER_GROUPS],
        }
        if len(every) > len(states):
            say(f"RVM and SVM trees on all {len(every)} states")

            def make_rvm() -> Any:
                return _tree("rvm", seed)

            for method, make, prefix in (("rvm", make_rvm, "RVM"), ("svm", make_svm, "SVM")):
                clf, _, p, fit_s, pred_s = _fit_tree(make, feats_train_all, y_train_all, feats_test)
                m = _method_result(clf, y_test_all, p, fit_s, pred_s, prefix)
                m.update(group_metrics(y_test_all, p, [str(c) for c in clf.classes_], groups))
                block[method] = m
        results["all_states"] = block
    results["timing"] = timing
    return results, artifacts


# ----------------------------------------------------------------------------- calibration
def _ece_headline(e: dict[str, Any]) -> dict[str, Any]:
    keys = ("value", "ci_low", "ci_high", "debiased", "noise_floor")
    return {k: e.get(k) for k in keys}


def calibration_headlines(
    diagnoser: Any,
    test_runs: xr.Dataset,
    out_dir: str | os.PathLike,
    *,
    seed: int = 0,
    real_record: xr.Dataset | None = None,
    n_bootstrap: int = 500,
    n_folds: int = 5,
    title: str = "Calibration report",
) -> dict[str, Any]:
    """Write the calibration report of a fitted diagnoser and return its headline figures.

    Parameters
    ----------
    diagnoser
        Fitted :class:`~bayes_fdi.diagnosis.FaultDiagnoser`.
    test_runs
        Labelled held-out runs (their ``fn`` runs score the normal models).
    out_dir
        Folder of the full report (:func:`bayes_fdi.calibration.report.write_calibration_report`).
    seed
        Seed of the bootstrap and of the cross-fitted recalibration.
    real_record
        A real fault-free record (e.g. the Lublin hour): the normal models, configured as the
        diagnoser's, are fitted on its first half (width chosen there by
        :func:`select_regression_width`) and scored on its second half.
    n_bootstrap
        Bootstrap resamples of the ECE intervals.
    n_folds
        Cross-fitting folds of the recalibration (each test run is recalibrated by
        recalibrators fitted on the other folds; see
        :func:`bayes_fdi.calibration.report.recalibrate`).
    title
        Heading of the full report.

    Returns
    -------
    dict
        ``report`` (path of ``report.md`` relative to the parent of ``out_dir``),
        ``recalibration`` (method, fitted parameters), ``before`` and ``after``
        (``accuracy``, ``log_loss``, ``ece``: top-label, 15 equal-width bins, with bootstrap
        interval, debiased value and noise floor), ``selected`` (recalibrators chosen in the
        folds), ``ece_by_binning`` (before/after with other bin counts and equal-mass bins),
        ``coverage`` (per output, each level:
        nominal, coverage, mean width, on the fault-free test runs) and, with
        ``real_record``, ``real_record_coverage`` (the same on its second half).
    """
    from sklearn.base import clone

    from bayes_fdi.calibration.report import (
        RECALIBRATORS,
        _write_report,
        split_in_time,
        time_split_summary,
    )

    out = Path(out_dir)
    with single_threaded():
        path, cal = _write_report(
            diagnoser,
            test_runs,
            out,
            calibration_runs=None,
            n_bins=15,
            n_bootstrap=n_bootstrap,
            seed=seed,
            title=title,
            n_folds=n_folds,
            methods=RECALIBRATORS,
        )
        head: dict[str, Any] = {
            "report": f"{out.name}/{path.name}",
            "recalibration": cal["recalibration"],
        }
        for when in ("before", "after"):
            d = cal["whole_tree"][when]
            head[when] = {
                "accuracy": d["accuracy"],
                "log_loss": d["log_loss"],
                "ece": _ece_headline(d["ece"]),
            }
        head["selected"] = sorted(set(cal["recalibration"].get("selected", [])))
        head["ece_by_binning"] = [
            {
                "strategy": b["strategy"],
                "n_bins": b["n_bins"],
                "before": _ece_headline(b["before"]),
                "after": _ece_headline(b["after"]),
            }
            for b in cal.get("ece_binning", [])
        ]
        head["coverage"] = {k: v["coverage"] for k, v in cal.get("normal_models", {}).items()}
        if real_record is not None:
            first, _ = split_in_time(real_record, 0.5)
            model = clone(diagnoser.normal_models_)
            width, _ = select_regression_width(first, seed=seed, input_lags=model.input_lags)
            regressor = model.regressor
            if regressor is not None and "width" in regressor.get_params():
                model.set_params(regressor=clone(regressor).set_params(width=width))
            hour = time_split_summary(model, real_record)
            head["real_record_coverage"] = {k: hour[k]["coverage"] for k in ("X", "F") if k in hour}
            head["real_record_width"] = float(width)
    return head


# ----------------------------------------------------------------------------- main job
def reproduce(
    out_dir: str | os.PathLike,
    *,
    seed: int = 0,
    cache_dir: str | os.PathLike | None = ".cache/datasets",
    small: bool = False,
    states: Sequence[str] = PAPER_STATES,
    progress: bool = True,
    datasets: Sequence[str | os.PathLike | xr.Dataset] = DATASETS,
    dynamic_lags: Sequence[float] = DYNAMIC_LAGS,
) -> dict[str, Any]:
    """Run the paper's experiments and write ``report.md``, figures and ``results.json``.

    Parameters
    ----------
    out_dir
        Output folder (created if needed).
    seed
        Seed of the simulations and of the models; the same seed gives the same numbers.
    cache_dir
        Folder of cached simulated datasets (``None``: always simulate).
    small
        Small campaigns for tests, notebooks and CI: :data:`SMALL_RUNS_PER_STATE` runs per
        state (20 train, 4 test) of :data:`SMALL_DURATION` s; the numbers are then rougher
        than with the paper's sizes.
    states
        States of the paper protocol (default the paper's ten).
    progress
        Show progress on stderr.
    datasets
        Campaigns to run: names or TOML paths (simulated or cached), or datasets already in
        the project's format (named by their ``campaign`` attribute).
    dynamic_lags
        Beyond the paper: run the whole pipeline a second time with dynamic normal models,
        ``CV(t - L)`` for these lags (s) as extra inputs (default :data:`DYNAMIC_LAGS`);
        ``()`` skips it.

    Returns
    -------
    dict
        The content of ``results.json``: ``bayes_fdi_version``, ``seed``, ``small``,
        ``states``, ``datasets`` (name -> :func:`evaluate_dataset` results plus ``campaign``
        info) and ``seconds`` (total wall-clock).
    """
    from bayes_fdi import __version__
    from bayes_fdi.experiments import reproduce_report as rep

    t_start = time.perf_counter()
    say = _Progress(progress)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    results: dict[str, Any] = {
        "bayes_fdi_version": __version__,
        "seed": int(seed),
        "seeds": {"simulation": int(seed), "models": int(seed)},
        "small": bool(small),
        "states": [str(s) for s in states],
        "n_train_per_state": N_TRAIN,
        "dynamic_lags": [float(v) for v in dynamic_lags],
        "datasets": {},
    }
    figures: dict[str, dict[str, str]] = {}
    for i, item in enumerate(datasets):
        if isinstance(item, xr.Dataset):
            ds = validate_dataset(item, require=("CV", "P1", "P2", "T1", "X", "F"))
            name = str(ds.attrs.get("campaign") or f"dataset-{i + 1}")
            info = {"campaign": name, "campaign_file": None, "cached": False}
        else:
            name = os.fspath(item)
            say(f"{name}: loading or simulating the campaign")
            ds, info = load_or_simulate(
                item, seed=seed, cache_dir=cache_dir, small=small, progress=progress
            )
        if "simulate_seconds" in info:
            how = "cached" if info["cached"] else f"simulated in {info['simulate_seconds']:.0f} s"
        else:
            how = "given"
        say(f"{name}: {ds.sizes['run']} runs x {ds.sizes['time']} s ({how})")
        key = info["campaign"]
        res, art = evaluate_dataset(
            ds, states=states, seed=seed, progress=lambda m, k=key: say(f"{k}: {m}")
        )
        res["campaign"] = info
        say(f"{key}: calibration report")
        real = None
        if str(ds.attrs.get("source", "")) == "lublin-example":
            from bayes_fdi.datasets import load_lublin_example

            real = load_lublin_example()

        def calibrate(
            artifacts: dict[str, Any], suffix: str, what: str, k: str = key, real: Any = real
        ) -> Any:
            return calibration_headlines(
                artifacts["diagnoser"],
                artifacts["test_runs"],
                out / f"{k}{suffix}-calibration",
                seed=seed,
                real_record=real,
                title=f"{k}: calibration of the {what} on its test runs",
            )

        res["calibration"] = calibrate(art, "", "RVM pipeline")
        if len(dynamic_lags):
            lags = tuple(float(v) for v in dynamic_lags)
            say(f"{key}: beyond the paper: dynamic normal models with CV lagged {lags} s")
            dyn, dyn_art = evaluate_dataset(
                ds,
                states=states,
                seed=seed,
                input_lags=lags,
                progress=lambda m, k=key: say(f"{k} (dynamic): {m}"),
            )
            dyn["calibration"] = calibrate(dyn_art, "-dynamic", "dynamic RVM pipeline")
            res["dynamic"] = {k: v for k, v in dyn.items() if k != "strength"}
        results["datasets"][key] = res
        say(f"{key}: figures")
        figs = {
            "residuals": rep.plot_residuals(
                art["residuals"], out / f"{key}-residuals.png", title=f"{key}: residuals"
            ).name,
            "features": rep.plot_features(
                art["features"],
                art["labels"],
                out / f"{key}-features.png",
                predict=art["rvm_predict"],
                title=f"{key}: test-run features and the RVM tree's decisions",
            ).name,
        }
        if "all_states" in res:
            figs["all_features"] = rep.plot_features(
                art["train_features"],
                art["train_labels"],
                out / f"{key}-all-states.png",
                title=f"{key}: training-run features of every state",
            ).name
        figures[key] = figs
    results["seconds"] = time.perf_counter() - t_start
    results["figures"] = figures
    results = rep.to_jsonable(results)
    (out / "report.md").write_text(rep.render_report(results))
    rep.write_json(results, out / "results.json")
    say(f"done in {results['seconds']:.0f} s: {out / 'report.md'}")
    return results


# ----------------------------------------------------------------------------- CLI
def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Add the ``reproduce`` command's options to ``parser``."""
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder")
    parser.add_argument("--seed", type=int, default=0, help="simulation and model seed")
    parser.add_argument(
        "--cache-dir",
        default=".cache/datasets",
        metavar="DIR",
        help="folder of cached simulated datasets (default: .cache/datasets)",
    )
    parser.add_argument(
        "--small",
        action="store_true",
        help="a small, fast version (fewer runs per state) for tests and CI",
    )
    parser.add_argument(
        "--campaign",
        action="append",
        metavar="TOML",
        help="campaign file or shipped name to run instead of the paper's two "
        "(repeatable; default: paper-simulated and paper-lublin)",
    )
    parser.add_argument(
        "--states",
        default=",".join(PAPER_STATES),
        help="comma-separated states of the paper protocol (default: the paper's ten)",
    )
    parser.add_argument(
        "--dynamic-lags",
        default=",".join(f"{v:g}" for v in DYNAMIC_LAGS),
        metavar="SECONDS",
        help="comma-separated lags (s) of CV for the beyond-the-paper dynamic normal models "
        "(default: %(default)s; empty string: skip that part)",
    )
    parser.add_argument(
        "--quiet", "--no-progress", dest="no_progress", action="store_true",
        help="no progress messages",
    )  # fmt: skip


def run_from_cli(args: argparse.Namespace) -> int:
    """Run :func:`reproduce` from parsed arguments; print where the report is."""
    states = [s.strip() for s in args.states.split(",") if s.strip()]
    unknown = sorted(set(states) - set(ALL_STATES))
    if unknown:
        raise SystemExit(f"bayes-fdi reproduce: unknown state(s) {unknown}; use fn, f1..f19")
    try:
        lags = tuple(float(v) for v in args.dynamic_lags.split(",") if v.strip())
    except ValueError:
        raise SystemExit(
            f"bayes-fdi reproduce: --dynamic-lags must be comma-separated seconds, "
            f"got {args.dynamic_lags!r}"
        ) from None
    results = reproduce(
        args.out,
        dynamic_lags=lags,
        seed=args.seed,
        cache_dir=args.cache_dir,
        small=args.small,
        states=states,
        progress=not args.no_progress,
        datasets=tuple(args.campaign) if args.campaign else DATASETS,
    )
    print(f"report: {Path(args.out) / 'report.md'}")
    for name, ds in results["datasets"].items():
        acc = ", ".join(f"{m.upper()} {100 * ds[m]['accuracy']:.2f} %" for m in ("rvm", "svm"))
        print(f"{name}: {acc}")
    return 0

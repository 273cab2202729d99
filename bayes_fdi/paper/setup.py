"""The paper's set-up: its states, the normal models' kernel width, the tree's node classifiers.

Constants of the protocol (`PAPER_STATES`, `NODE_WIDTH`, the width grid and the lags of the
dynamic normal models), `select_regression_width` (the normal models' RBF width by maximum
evidence), `node_classifier` (RVM or SVM at each tree node), `tree_nodes` (a fitted tree as
plain dicts) and `single_threaded` (the block in which ``reproduce`` fits its models).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.datasets import STATES
from bayes_fdi.diagnosis.isolation.tree import n_vectors

__all__ = [
    "ALL_STATES",
    "DATASETS",
    "DYNAMIC_LAGS",
    "NODE_WIDTH",
    "N_TRAIN",
    "PAPER_STATES",
    "REGRESSION_WIDTHS",
    "REGRESSION_WIDTH_SAMPLES",
    "fit_tree",
    "node_classifier",
    "select_regression_width",
    "single_threaded",
    "tree_classifier",
    "tree_nodes",
]

#: The two campaigns of the paper.
DATASETS: tuple[str, ...] = ("paper-simulated", "paper-lublin")
#: Training runs per state (the paper: 20 groups train, the rest test).
N_TRAIN: int = 20


#: The ten states the paper diagnoses (Section 5).
PAPER_STATES: tuple[str, ...] = ("fn", "f1", "f2", "f3", "f6", "f11", "f12", "f15", "f17", "f18")

#: All twenty states (fault-free and the 19 DAMADICS faults).
ALL_STATES: tuple[str, ...] = STATES

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


@contextlib.contextmanager
def single_threaded() -> Iterator[None]:
    """Run torch and the BLAS libraries on one thread inside the block, then restore.

    Every fit already runs on one thread (`bayes_fdi.rvm.threads`); this block also covers
    what lies between the fits (predictions, residuals, features, the SVM baseline), so that
    ``reproduce`` computes the same way whatever the caller's thread settings.
    """
    # threadpoolctl limits the thread pools of libraries already loaded: load them all first.
    import scipy.linalg  # noqa: F401
    import sklearn.cluster
    import sklearn.svm  # noqa: F401

    import bayes_fdi.diagnosis
    import bayes_fdi.rvm  # noqa: F401
    from bayes_fdi.rvm.threads import fit_threads

    with fit_threads(1):
        yield


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
    (:func:`bayes_fdi.diagnosis.normal_models.width_search.evidence_grid_search`,
    also the default width search of
    :class:`bayes_fdi.diagnosis.normal_models.static.NormalModels`). (``RVR(width="auto")`` searches
    down to much smaller widths, where a fit on thousands of samples keeps hundreds of basis
    functions and takes minutes; the grid stays where the evidence peaks on these data.)

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
        (:func:`bayes_fdi.diagnosis.normal_models.inputs.model_inputs`); default ``()``, the paper's
        inputs.

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

    Used inside :class:`bayes_fdi.diagnosis.isolation.tree.HierarchicalClassifier` with
    ``node_scaling=True``: each
    node standardises its own training samples first, so ``sigma`` means "``sigma`` standard
    deviations of this node's data" at every depth — the root separates far-apart groups of
    states, the deepest nodes states a few hundredths apart, and one width fits both.

    Parameters
    ----------
    kind
        ``"rvm"`` (:class:`bayes_fdi.rvm.RVC`) or ``"svm"``
        (:func:`bayes_fdi.diagnosis.isolation.svm.svm_classifier`: C = 1, Platt-scaled
        probabilities).
    width
        Gaussian kernel width sigma.
    """
    if kind == "rvm":
        from bayes_fdi.rvm import RVC

        return RVC(kernel="rbf", width=width)
    if kind == "svm":
        from bayes_fdi.diagnosis.isolation.svm import svm_classifier

        return svm_classifier(sigma=width)
    raise ValueError(f"kind must be 'rvm' or 'svm', got {kind!r}")


def tree_classifier(kind: str, seed: int) -> Any:
    """An unfitted tree of `node_classifier` nodes (``"rvm"`` or ``"svm"``), scaled per node."""
    from bayes_fdi.diagnosis.isolation.tree import HierarchicalClassifier

    return HierarchicalClassifier(node_classifier(kind), node_scaling=True, random_state=seed)


def tree_nodes(clf: Any, prefix: str) -> list[dict[str, Any]]:
    """Nodes of a fitted HierarchicalClassifier as plain dicts (breadth first, root first).

    Each has ``name`` (``prefix`` + number), ``left``, ``right``, ``classes``, ``vectors``
    (relevance or support vectors, also inside a :func:`node_classifier` pipeline) and
    ``samples`` (the node's training samples).
    """
    out = []
    for node in clf.nodes_:
        n_vec = node.n_vectors if node.n_vectors is not None else n_vectors(node.estimator)
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


def fit_tree(
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

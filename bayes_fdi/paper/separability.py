"""Which states can the two mean residuals separate? Pairwise k-NN confusion and groups.

`pairwise_separability` scores every pair of states by the balanced leave-one-out error of a
k-nearest-neighbour rule on their training features; `find_groups` clusters states whose pairs
are all confusable; `group_metrics` scores a classifier when states are only identifiable up to
their group.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from bayes_fdi.calibration.metrics import check_proba

__all__ = [
    "PAPER_GROUPS",
    "SEPARABILITY_NEIGHBOURS",
    "SEPARABILITY_THRESHOLD",
    "find_groups",
    "group_metrics",
    "pairwise_separability",
]


#: Groups of states whose residuals the paper found alike (end of its Section 3.2).
PAPER_GROUPS: tuple[tuple[str, ...], ...] = (
    ("fn", "f4", "f5", "f8", "f9", "f14"),
    ("f1", "f7", "f10", "f16"),
    ("f2", "f19"),
    ("f6", "f13"),
)

#: Two states are "not separable" when a nearest-neighbour classifier trained on their
#: training features alone misclassifies at least this fraction of them (leave-one-out,
#: balanced). See :func:`pairwise_separability`.
SEPARABILITY_THRESHOLD: float = 0.15

#: Neighbours of the k-NN used by :func:`pairwise_separability`.
SEPARABILITY_NEIGHBOURS: int = 5


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
    from bayes_fdi.diagnosis.isolation.isolator import isolability_groups

    return isolability_groups(states, error, threshold=threshold, linkage=linkage)


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
    _, proba, _ = check_proba(y_true, proba, classes)
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

"""Binary calibration of every node of a hierarchical classifier on the samples of its classes."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np

from bayes_fdi.calibration.metrics import ECEResult, brier, expected_calibration_error, log_loss

__all__ = ["NodeCalibration", "node_calibration"]


class NodeCalibration(NamedTuple):
    """Binary calibration of one tree node on the samples of its classes.

    ``right`` is the positive outcome: the node's probability is ``P(right | x)``.
    ``ece`` is the top-label ECE of the node's 2-class distribution (None when the node has
    no test samples, then the scores are NaN).
    """

    index: int
    left: tuple
    right: tuple
    n_samples: int
    ece: ECEResult | None
    log_loss: float
    brier: float
    accuracy: float


def _default_p_right(node: Any, X: np.ndarray) -> np.ndarray:
    """P(right) from a node's estimator, whose positive class (right) is labelled 1/True.

    A node that standardises its inputs (``node.scaler``, as the tree's ``node_scaling``
    does) gets them standardised exactly as in the tree's own prediction.
    """
    est = node.estimator
    scaler = getattr(node, "scaler", None)
    if scaler is not None:
        X = scaler.transform(X)
    proba = np.asarray(est.predict_proba(X), dtype=np.float64)
    labels = list(np.asarray(getattr(est, "classes_", [0, 1])).tolist())
    for pos in (1, True, "right"):
        if pos in labels:
            return proba[:, labels.index(pos)]
    raise ValueError(
        f"cannot tell which column of node {node.left} | {node.right} is 'right' from "
        f"classes_={labels}; pass p_right=..."
    )


def node_calibration(
    nodes: Sequence[Any],
    X: Any,
    y_true: Any,
    *,
    n_bins: int = 10,
    strategy: str = "uniform",
    n_bootstrap: int = 0,
    random_state: int | None = None,
    p_right: Callable[[Any, np.ndarray], np.ndarray] | None = None,
) -> list[NodeCalibration]:
    """Calibration of every node of a hierarchical classifier.

    Each node separates the classes ``node.left`` from ``node.right`` with a binary
    ``node.estimator``; it is evaluated on the samples whose true label is in either group,
    with outcome "label in right" and the node's probability ``P(right | x)``.

    Parameters
    ----------
    nodes
        The tree's nodes (objects with ``.left``, ``.right`` (class collections) and
        ``.estimator``), e.g. ``diagnoser.classifier_.nodes_``.
    X
        The classifier's input features, shape ``(n, d)``.
    y_true
        True class labels, shape ``(n,)``.
    n_bins, strategy, n_bootstrap, random_state
        As in :func:`expected_calibration_error`.
    p_right
        ``p_right(node, X) -> (m,)`` probability of the right group; default: the column of
        ``node.estimator.predict_proba`` whose label in ``estimator.classes_`` is 1/True.

    Returns
    -------
    list of NodeCalibration
        In the order of ``nodes``.
    """
    X = np.asarray(X, dtype=np.float64)
    y = np.asarray(y_true)
    if X.ndim != 2 or X.shape[0] != y.shape[0]:
        raise ValueError(f"X must be (n, d) with n = len(y_true) = {y.shape[0]}, got {X.shape}")
    if not np.all(np.isfinite(X)):
        raise ValueError("X contains NaN or inf")
    get_p = p_right or _default_p_right
    out = []
    for i, node in enumerate(nodes):
        left, right = tuple(node.left), tuple(node.right)
        in_left, in_right = np.isin(y, left), np.isin(y, right)
        mask = in_left | in_right
        m = int(mask.sum())
        if m == 0:
            nan = float("nan")
            out.append(NodeCalibration(i, left, right, 0, None, nan, nan, nan))
            continue
        p1 = np.clip(np.asarray(get_p(node, X[mask]), dtype=np.float64), 0.0, 1.0)
        target = in_right[mask].astype(int)
        p2 = np.column_stack([1.0 - p1, p1])
        ece = expected_calibration_error(
            target, p2, classes=[0, 1], n_bins=n_bins,
            strategy=strategy if m >= n_bins else "uniform",
            n_bootstrap=n_bootstrap, random_state=random_state,
        )  # fmt: skip
        out.append(
            NodeCalibration(
                index=i,
                left=left,
                right=right,
                n_samples=m,
                ece=ece,
                log_loss=log_loss(target, p2, classes=[0, 1]),
                brier=brier(target, p2, classes=[0, 1], scale_by_half=True),
                accuracy=float(np.mean((p1 > 0.5) == (target == 1))),
            )
        )
    return out

"""The k-means design of a classification tree: `design_tree`, recursive 2-means on centroids.

`bayes_fdi.diagnosis.isolation.tree.HierarchicalClassifier` builds its tree here by default
(``structure="kmeans"``), as the paper did: the class centroids of the training features are
split in two by 2-means, recursively. Up to `MAX_EXACT_SPLIT` classes the split is exact (every
two-way partition scored); ties within `INERTIA_RTOL` go to a fixed order, so the same tree comes
out on any machine. Written by hand: scikit-learn's `~sklearn.cluster.KMeans` (used beyond
`MAX_EXACT_SPLIT` classes) finds a local optimum from random starts, not the exact split.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from sklearn.cluster import KMeans

__all__ = ["INERTIA_RTOL", "MAX_EXACT_SPLIT", "design_tree", "plain_label"]


def plain_label(x: Any) -> Any:
    """A class label as a plain Python value (a numpy scalar's ``item()``), as trees hold them."""
    return x.item() if isinstance(x, np.generic) else x


#: Two 2-means partitions whose inertias differ by less than this fraction are a tie, broken by
#: a canonical order of the partitions (see `_split_centroids`). Centroids computed on two BLAS
#: code paths differ in their last bits (relative 1e-16 .. 1e-13 after the residual models), so a
#: real difference between two partitions is many orders of magnitude above this, and a tie (by
#: symmetry, or two partitions equally good) is resolved the same way on every machine.
INERTIA_RTOL: float = 1e-9
#: Up to this many classes every two-way partition of a node's centroids is scored (2**(k-1) of
#: them, about half a million for 20 classes, in chunks); beyond, seeded k-means restarts.
MAX_EXACT_SPLIT: int = 20
_CHUNK = 1 << 13  # 8192 partitions per block: fits the cache, 0.07 s CPU for 20 classes


def _inertia(points: np.ndarray, mask: np.ndarray) -> float:
    """Within-cluster sum of squares of the two-way partition ``mask`` (elementwise numpy)."""
    total = 0.0
    for side in (mask, ~mask):
        group = points[side]
        total += float(((group - group.mean(axis=0)) ** 2).sum())
    return total


def _all_partitions(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every two-way partition (row 0 on the ``True`` side) and its inertia, chunk by chunk.

    Returns the masks and inertias of the partitions within `INERTIA_RTOL` of the lowest.
    """
    k = points.shape[0]
    Z = points - points.mean(axis=0)  # centred: the sums below do not cancel
    total = float((Z**2).sum())
    col_sum = Z.sum(axis=0)
    shifts = np.arange(k - 1)
    best = np.inf
    kept: list[tuple[np.ndarray, np.ndarray]] = []
    for start in range(0, 1 << (k - 1), _CHUNK):
        codes = np.arange(start, min(start + _CHUNK, 1 << (k - 1)))
        # bit i of the code sends row i + 1 to the False side; row 0 stays on the True side
        masks = np.ones((codes.size, k), dtype=bool)
        masks[:, 1:] = ((codes[:, None] >> shifts) & 1) == 0
        n_a = masks.sum(axis=1)
        ok = n_a < k  # both sides non-empty
        masks, n_a = masks[ok], n_a[ok]
        s_a = masks.astype(np.float64) @ Z
        s_b = col_sum - s_a
        inertia = total - (s_a**2).sum(axis=1) / n_a - (s_b**2).sum(axis=1) / (k - n_a)
        low = float(inertia.min())
        if low < best:
            best = low
        kept.append((masks, inertia))
    tol = INERTIA_RTOL * max(abs(best), 1e-300)
    masks = np.concatenate([m[v <= best + tol] for m, v in kept])
    return masks, np.concatenate([v[v <= best + tol] for _, v in kept])


def _split_centroids(centroids: np.ndarray, n_init: int, random_state: int | None) -> np.ndarray:
    """Boolean mask of one side of a 2-means split of ``centroids`` (guarded, deterministic).

    The split minimises the within-cluster sum of squares (the k-means objective, k = 2).
    Up to `MAX_EXACT_SPLIT` classes every two-way partition is scored, so the optimum is
    found exactly; beyond, k-means (Lloyd, k-means++ initialisation) runs from ``n_init``
    seeded starts (`sklearn.cluster.KMeans`) and each partition found is scored by its inertia
    recomputed from the partition. Inertias within a relative `INERTIA_RTOL` of the lowest are
    ties, won by the partition whose mask (oriented so that row 0 is ``True``) is
    lexicographically largest. The choice thus depends neither on the order the candidates are
    found in nor on the last bits of sums.
    """
    k = centroids.shape[0]
    if k == 2:
        return np.array([True, False])
    if np.unique(centroids, axis=0).shape[0] < 2:
        # Degenerate: split off the class farthest (mean distance) from the others.
        d = np.sqrt(((centroids[:, None, :] - centroids[None, :, :]) ** 2).sum(-1))
        far = int(np.argmax(d.sum(axis=1)))
        mask = np.zeros(k, dtype=bool)
        mask[far] = True
        return mask
    if k <= MAX_EXACT_SPLIT:
        tied, _ = _all_partitions(centroids)
        return np.array(max(tuple(bool(v) for v in m) for m in tied))
    found: dict[tuple[bool, ...], float] = {}
    seeds = np.random.default_rng(random_state).integers(0, 2**31 - 1, size=max(1, n_init))
    for seed in seeds:
        labels = KMeans(n_clusters=2, n_init=1, random_state=int(seed)).fit_predict(centroids)
        mask = labels == labels[0]
        key = tuple(bool(m) for m in mask)
        if not mask.all() and key not in found:
            found[key] = _inertia(centroids, mask)
    best = min(found.values())
    return np.array(max(key for key, v in found.items() if v <= best + INERTIA_RTOL * abs(best)))


def design_tree(
    centroids: np.ndarray,
    classes: Any,
    *,
    counts: np.ndarray | None = None,
    variances: np.ndarray | None = None,
    n_init: int = 10,
    random_state: int | None = 0,
) -> tuple | Any:
    """Design a binary tree over ``classes`` by recursive 2-means on their centroids.

    At each node the class centroids are split in two by 2-means: the two-way partition of
    least within-cluster sum of squares, found exactly (every partition scored) up to
    `MAX_EXACT_SPLIT` classes, by k-means with ``n_init`` seeded restarts beyond; near-ties
    within a relative `INERTIA_RTOL` go to a fixed order of the partitions, so the same tree
    comes out on any machine. If the centroids are all identical, the first class is split off.
    The smaller group goes left; on equal sizes, the group holding the class listed first goes
    left.

    With ``counts`` and ``variances`` (per-class sample counts and per-feature variances), each
    split is made on centroids divided by the per-feature standard deviation of the node's own
    samples (pooled from the class statistics, as a ``StandardScaler`` fitted on them would
    compute it), matching classifiers that standardise per node.

    Parameters
    ----------
    centroids
        ``(n_classes, n_features)`` class centroids.
    classes
        The class labels, in the row order of ``centroids``.
    counts, variances
        Optional ``(n_classes,)`` sample counts and ``(n_classes, n_features)`` variances.
    n_init, random_state
        k-means restarts and seed.

    Returns
    -------
    tuple or label
        Nested pairs of labels (a single label when there is one class).
    """
    centroids = np.asarray(centroids, dtype=np.float64)
    classes = [plain_label(c) for c in classes]
    if centroids.ndim != 2 or centroids.shape[0] != len(classes):
        raise ValueError("centroids must be (n_classes, n_features), one row per class")
    if len(classes) == 0:
        raise ValueError("no classes to build a tree over")
    if (counts is None) != (variances is None):
        raise ValueError("give both counts and variances, or neither")
    if counts is not None:
        counts = np.asarray(counts, dtype=np.float64)
        variances = np.asarray(variances, dtype=np.float64)
        if counts.shape != (len(classes),) or variances.shape != centroids.shape:
            raise ValueError("counts must be (n_classes,) and variances like centroids")
    order = list(range(len(classes)))

    def node_centroids(rows: list[int]) -> np.ndarray:
        c = centroids[rows]
        if counts is None:
            return c
        w = counts[rows][:, None]
        mean = (w * c).sum(0) / w.sum()
        var = (w * (variances[rows] + (c - mean) ** 2)).sum(0) / w.sum()
        std = np.sqrt(var)
        std[~(std > 1e-300)] = 1.0  # constant feature: left unscaled, as StandardScaler does
        return c / std

    def build(rows: list[int]) -> Any:
        if len(rows) == 1:
            return classes[rows[0]]
        mask = _split_centroids(node_centroids(rows), n_init, random_state)
        a = [r for r, m in zip(rows, mask, strict=True) if m]
        b = [r for r, m in zip(rows, mask, strict=True) if not m]
        if len(b) < len(a) or (len(a) == len(b) and min(b) < min(a)):
            a, b = b, a
        return (build(a), build(b))

    return build(order)

"""The compiled predictor of a k-means tree of binary RBF relevance vector classifiers.

The online diagnoser evaluates its isolation tree once a second, sample by sample (``update``)
or over a whole recording (``run``), and the two must give the same numbers exactly. `LeanTree`
holds a `~bayes_fdi.diagnosis.isolation.tree.HierarchicalClassifier` whose nodes are binary RBF
`~bayes_fdi.rvm.RVC` (moderated or not) behind their per-node standardisation as flat arrays,
built from its *public* fitted attributes only (``nodes_``, ``tree_``, and each node's
``relevance_vectors_``, ``mean_``, ``covariance_``, ``width_``), and `tree_proba` evaluates the
class probabilities of one row in compiled loops with a fixed summation order (products along
the root-to-leaf paths), so a row's result never depends on the batch around it. They agree
with ``predict_proba`` to rounding (tested).

Written by hand: no library compiles an RVM tree's probabilities per sample.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from bayes_fdi.diagnosis.normal_models.compiled import rbf_width

__all__ = ["LeanTree", "TreeArrays", "lean_tree_or_none", "tree_proba"]


class TreeArrays(NamedTuple):
    """The arrays of a `LeanTree` that `tree_proba` takes (its fields but the class names)."""

    centres: np.ndarray
    offsets: np.ndarray
    weights: np.ndarray
    woffsets: np.ndarray
    covariances: np.ndarray
    coffsets: np.ndarray
    has_bias: np.ndarray
    inv_two_w2: np.ndarray
    scaler_mean: np.ndarray
    scaler_scale: np.ndarray
    moderated: bool
    paths: np.ndarray


class LeanTree(NamedTuple):
    """A `HierarchicalClassifier` of binary RBF RVC nodes as flat arrays.

    Node ``n`` owns rows ``offsets[n]:offsets[n + 1]`` of ``centres`` and
    ``woffsets[n]:woffsets[n + 1]`` of ``weights`` (bias first when ``has_bias[n]``); its
    covariance is ``covariances[coffsets[n]:coffsets[n + 1]]`` reshaped square. ``paths[c]``
    lists ``(node, side)`` pairs from the root to class ``c`` (-1 padding), side 1 = right.
    """

    classes: np.ndarray
    centres: np.ndarray
    offsets: np.ndarray
    weights: np.ndarray
    woffsets: np.ndarray
    covariances: np.ndarray
    coffsets: np.ndarray
    has_bias: np.ndarray
    inv_two_w2: np.ndarray
    scaler_mean: np.ndarray
    scaler_scale: np.ndarray
    moderated: bool
    paths: np.ndarray

    @classmethod
    def from_classifier(cls, tree: Any) -> LeanTree:
        """Build from a fitted `HierarchicalClassifier` with binary RBF RVC nodes."""
        from bayes_fdi.rvm import RVC

        nodes = tree.nodes_
        d = int(tree.n_features_in_)
        centres, offsets, weights, woffsets, covs, coffsets = [], [0], [], [0], [], [0]
        has_bias, inv, means, scales, moderated = [], [], [], [], set()
        for node in nodes:
            est = node.estimator
            if not isinstance(est, RVC) or getattr(est, "estimators_", None):
                raise ValueError("lean trees need binary RVC nodes")
            if list(np.asarray(est.classes_).tolist()) != [0, 1]:
                raise ValueError(f"node {node.index}: classes {est.classes_}, expected [0, 1]")
            width = rbf_width(est)
            c = np.asarray(est.relevance_vectors_, dtype=np.float64).reshape(-1, d)
            w = np.asarray(est.mean_, dtype=np.float64).ravel()
            bias = w.size == c.shape[0] + 1
            centres.append(c)
            offsets.append(offsets[-1] + c.shape[0])
            weights.append(w)
            woffsets.append(woffsets[-1] + w.size)
            covs.append(np.asarray(est.covariance_, dtype=np.float64).ravel())
            coffsets.append(coffsets[-1] + w.size * w.size)
            has_bias.append(bias)
            inv.append(0.5 / (width * width))
            moderated.add(bool(est.moderated))
            if node.scaler is None:
                means.append(np.zeros(d))
                scales.append(np.ones(d))
            else:
                means.append(np.asarray(node.scaler.mean_, dtype=np.float64))
                scales.append(np.asarray(node.scaler.scale_, dtype=np.float64))
        if len(moderated) > 1:
            raise ValueError("lean trees need all nodes moderated or none")
        classes = np.asarray(tree.classes_)
        col = {c: i for i, c in enumerate(classes.tolist())}
        paths = []

        def walk(sub: Any, index: int | None, path: list[tuple[int, int]]) -> None:
            if index is None:
                paths.append((col[sub.item() if isinstance(sub, np.generic) else sub], path))
                return
            node = nodes[index]
            walk(sub[0], node.left_child, [*path, (index, 0)])
            walk(sub[1], node.right_child, [*path, (index, 1)])

        walk(tree.tree_, 0 if nodes else None, [])
        depth = max(len(p) for _, p in paths)
        table = np.full((classes.size, max(depth, 1), 2), -1, dtype=np.int64)
        for k, path in paths:
            for j, (n, side) in enumerate(path):
                table[k, j] = (n, side)
        cat = np.concatenate
        return cls(
            classes=classes,
            centres=np.ascontiguousarray(cat(centres) if centres else np.empty((0, d))),
            offsets=np.asarray(offsets, dtype=np.int64),
            weights=cat(weights) if weights else np.empty(0),
            woffsets=np.asarray(woffsets, dtype=np.int64),
            covariances=cat(covs) if covs else np.empty(0),
            coffsets=np.asarray(coffsets, dtype=np.int64),
            has_bias=np.asarray(has_bias, dtype=np.bool_),
            inv_two_w2=np.asarray(inv, dtype=np.float64),
            scaler_mean=np.ascontiguousarray(np.reshape(means, (len(nodes), d))),
            scaler_scale=np.ascontiguousarray(np.reshape(scales, (len(nodes), d))),
            moderated=bool(moderated.pop()) if moderated else True,
            paths=table,
        )

    def arrays(self) -> TreeArrays:
        """The arrays `tree_proba` takes."""
        return TreeArrays(
            centres=self.centres,
            offsets=self.offsets,
            weights=self.weights,
            woffsets=self.woffsets,
            covariances=self.covariances,
            coffsets=self.coffsets,
            has_bias=self.has_bias,
            inv_two_w2=self.inv_two_w2,
            scaler_mean=self.scaler_mean,
            scaler_scale=self.scaler_scale,
            moderated=self.moderated,
            paths=self.paths,
        )

    def predict_proba(self, X: Any) -> np.ndarray:
        """Class probabilities ``(n, n_classes)`` of the rows of ``X``."""
        X = np.ascontiguousarray(np.asarray(X, dtype=np.float64))
        out = np.empty((X.shape[0], self.classes.size))
        tree = self.arrays()
        scratch = np.empty(max(1, int(np.diff(self.woffsets).max(initial=1))))
        right = np.empty(self.offsets.size - 1)
        z = np.empty(X.shape[1])
        for i in range(X.shape[0]):
            tree_proba(X[i], tree, scratch, right, z, out[i])
        return out


def lean_tree_or_none(classifier: Any) -> LeanTree | None:
    """`LeanTree.from_classifier` when the classifier allows it, else None (e.g. SVM nodes)."""
    try:
        return LeanTree.from_classifier(classifier)
    except (ValueError, AttributeError, TypeError):
        return None


# one compiled pass over the nodes and the paths, clearer whole than cut into pieces
@njit(cache=True, error_model="numpy")
def tree_proba(x, tree, phi, right, z, out):  # pragma: no cover - compiled
    """Class probabilities of one feature row ``x`` under ``tree`` (`TreeArrays`) into ``out``;
    ``phi``, ``right``, ``z``: scratch of the largest node's weights, the nodes, the features."""
    centres, offsets, covs = tree.centres, tree.offsets, tree.covariances
    weights, woffsets, coffsets = tree.weights, tree.woffsets, tree.coffsets
    scaler_mean, scaler_scale, paths = tree.scaler_mean, tree.scaler_scale, tree.paths
    n_nodes = offsets.size - 1
    d = x.size
    for n in range(n_nodes):
        for j in range(d):
            z[j] = (x[j] - scaler_mean[n, j]) / scaler_scale[n, j]
        off = 0
        if tree.has_bias[n]:
            phi[0] = 1.0
            off = 1
        c0 = offsets[n]
        m = offsets[n + 1] - c0
        for i in range(m):
            d2 = 0.0
            for j in range(d):
                diff = z[j] - centres[c0 + i, j]
                d2 += diff * diff
            phi[off + i] = math.exp(-d2 * tree.inv_two_w2[n])
        k = off + m
        w0 = woffsets[n]
        cv0 = coffsets[n]
        mean = 0.0
        for i in range(k):
            mean += phi[i] * weights[w0 + i]
        quad = 0.0
        for i in range(k):
            row = 0.0
            for j in range(k):
                row += covs[cv0 + i * k + j] * phi[j]
            quad += phi[i] * row
        if quad < 0.0:
            quad = 0.0
        a = mean / math.sqrt(1.0 + math.pi * quad / 8.0) if tree.moderated else mean
        right[n] = 1.0 / (1.0 + math.exp(-a))
    n_classes, depth = paths.shape[0], paths.shape[1]
    for c in range(n_classes):
        p = 1.0
        for j in range(depth):
            node = paths[c, j, 0]
            if node < 0:
                break
            if paths[c, j, 1] == 1:
                p *= right[node]
            else:
                p *= 1.0 - right[node]
        out[c] = p

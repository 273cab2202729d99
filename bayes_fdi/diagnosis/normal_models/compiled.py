"""Compiled one-sample predictors of fitted RVMs, for the online diagnoser's per-second path.

The online diagnoser evaluates its normal models and its isolation tree once a second, sample
by sample (``update``) or over a whole recording (``run``), and the two must give the same
numbers exactly. Calling the estimators' torch ``predict`` per sample costs tens of
microseconds of overhead, and a batched matrix product need not round like a single-row one.
These predictors are built from the estimators' *public* fitted attributes only
(``relevance_vectors_``, ``mean_``, ``covariance_``, ``beta_``, ``width_``; for a
`~bayes_fdi.diagnosis.isolation.tree.HierarchicalClassifier` its ``nodes_`` and ``tree_``) and
evaluate one sample at a time in compiled loops with a fixed summation order, so a sample's result
never depends on the batch around it. They agree with ``predict(X, return_std=True)`` and
``predict_proba`` to rounding (tested).

- `LeanRVR`: predictive mean and variance ``1/beta + phi^T Sigma phi`` of an RBF
  `~bayes_fdi.rvm.RVR`.
- `LeanTree`: class probabilities of a `HierarchicalClassifier` whose nodes are binary RBF
  `~bayes_fdi.rvm.RVC` (moderated or not) behind their per-node standardisation, multiplied
  along the root-to-leaf paths.

Written by hand: no library compiles an RVM's predictive distribution per sample.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba import njit

__all__ = ["LeanRVR", "LeanTree", "lean_tree_or_none", "rvr_predict", "tree_proba"]


def _rbf_width(est: Any) -> float:
    """The RBF width of a fitted RVM (ValueError for other kernels)."""
    from bayes_fdi.rvm.kernels import RBF

    kernel = est.get_params()["kernel"]
    if not (kernel == "rbf" or isinstance(kernel, RBF)):
        raise ValueError(f"lean predictors need an RBF kernel, got {kernel!r}")
    width = getattr(est, "width_", None)
    if width is None or not math.isfinite(float(width)) or width <= 0:
        raise ValueError(f"the fitted estimator has no usable width_ ({width!r})")
    return float(width)


class LeanRVR(NamedTuple):
    """An RBF relevance vector regression as plain arrays.

    Attributes
    ----------
    centres : numpy.ndarray
        ``(m, d)`` relevance vectors.
    weights : numpy.ndarray
        ``(b + m,)`` posterior mean weights, the bias first when ``b = 1``.
    covariance : numpy.ndarray
        ``(b + m, b + m)`` posterior covariance.
    has_bias : bool
    noise_var : float
        ``1 / beta``.
    width : float
        RBF width.
    """

    centres: np.ndarray
    weights: np.ndarray
    covariance: np.ndarray
    has_bias: bool
    noise_var: float
    width: float

    @classmethod
    def from_estimator(cls, est: Any) -> LeanRVR:
        """Build from a fitted `~bayes_fdi.rvm.RVR` (public attributes only)."""
        width = _rbf_width(est)
        centres = np.ascontiguousarray(est.relevance_vectors_, dtype=np.float64)
        weights = np.ascontiguousarray(est.mean_, dtype=np.float64).ravel()
        has_bias = weights.size == centres.shape[0] + 1
        if not has_bias and weights.size != centres.shape[0]:
            raise ValueError("mean_ does not match relevance_vectors_")
        cov = np.ascontiguousarray(est.covariance_, dtype=np.float64)
        return cls(centres, weights, cov, bool(has_bias), float(1.0 / est.beta_), width)

    def predict(self, U: Any) -> tuple[np.ndarray, np.ndarray]:
        """Predictive mean and standard deviation of the rows of ``U`` ``(n, d)``."""
        U = np.ascontiguousarray(np.asarray(U, dtype=np.float64))
        mean = np.empty(U.shape[0])
        var = np.empty(U.shape[0])
        phi = np.empty(self.weights.size)
        for i in range(U.shape[0]):
            mean[i], var[i] = rvr_predict(U[i], *self._args(), phi)
        return mean, np.sqrt(var)

    def _args(self) -> tuple:
        return (
            self.centres,
            self.weights,
            self.covariance,
            self.has_bias,
            self.noise_var,
            0.5 / (self.width * self.width),
        )


@njit(cache=True, error_model="numpy")
def rvr_predict(u, centres, weights, cov, has_bias, noise_var, inv_two_w2, phi):  # pragma: no cover
    """Mean and variance of one input row ``u`` (``phi``: scratch of the weights' size)."""
    off = 0
    if has_bias:
        phi[0] = 1.0
        off = 1
    m, d = centres.shape
    for i in range(m):
        d2 = 0.0
        for j in range(d):
            diff = u[j] - centres[i, j]
            d2 += diff * diff
        phi[off + i] = math.exp(-d2 * inv_two_w2)
    n = off + m
    mean = 0.0
    for i in range(n):
        mean += phi[i] * weights[i]
    quad = 0.0
    for i in range(n):
        row = 0.0
        for j in range(n):
            row += cov[i, j] * phi[j]
        quad += phi[i] * row
    if quad < 0.0:
        quad = 0.0
    return mean, noise_var + quad


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
            width = _rbf_width(est)
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

    def args(self) -> tuple:
        """The arrays `tree_proba` takes, in order."""
        return (
            self.centres,
            self.offsets,
            self.weights,
            self.woffsets,
            self.covariances,
            self.coffsets,
            self.has_bias,
            self.inv_two_w2,
            self.scaler_mean,
            self.scaler_scale,
            self.moderated,
            self.paths,
        )

    def predict_proba(self, X: Any) -> np.ndarray:
        """Class probabilities ``(n, n_classes)`` of the rows of ``X``."""
        X = np.ascontiguousarray(np.asarray(X, dtype=np.float64))
        out = np.empty((X.shape[0], self.classes.size))
        scratch = np.empty(max(1, int(np.diff(self.woffsets).max(initial=1))))
        right = np.empty(self.offsets.size - 1)
        z = np.empty(X.shape[1])
        for i in range(X.shape[0]):
            tree_proba(X[i], *self.args(), scratch, right, z, out[i])
        return out


def lean_tree_or_none(classifier: Any) -> LeanTree | None:
    """`LeanTree.from_classifier` when the classifier allows it, else None (e.g. SVM nodes)."""
    try:
        return LeanTree.from_classifier(classifier)
    except (ValueError, AttributeError, TypeError):
        return None


@njit(cache=True, error_model="numpy")
def tree_proba(
    x, centres, offsets, weights, woffsets, covs, coffsets, has_bias, inv_two_w2,
    scaler_mean, scaler_scale, moderated, paths, phi, right, z, out,
):  # pragma: no cover - compiled  # fmt: skip
    """Class probabilities of one feature row ``x`` into ``out``."""
    n_nodes = offsets.size - 1
    d = x.size
    for n in range(n_nodes):
        for j in range(d):
            z[j] = (x[j] - scaler_mean[n, j]) / scaler_scale[n, j]
        off = 0
        if has_bias[n]:
            phi[0] = 1.0
            off = 1
        c0 = offsets[n]
        m = offsets[n + 1] - c0
        for i in range(m):
            d2 = 0.0
            for j in range(d):
                diff = z[j] - centres[c0 + i, j]
                d2 += diff * diff
            phi[off + i] = math.exp(-d2 * inv_two_w2[n])
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
        a = mean / math.sqrt(1.0 + math.pi * quad / 8.0) if moderated else mean
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

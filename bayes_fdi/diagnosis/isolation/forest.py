"""A random forest of isolation signatures, kept as flat arrays and evaluated compiled.

`ForestClassifier` fits scikit-learn's `~sklearn.ensemble.RandomForestClassifier` and keeps
only what its trees decide with: each node's split feature and threshold, its children, and
each leaf's class proportions (stored sparsely: a leaf of a few signatures holds one or two
classes). A model file thus holds plain arrays, which load with any scikit-learn, and
`forest_proba` evaluates the class probabilities of a row in compiled loops, the mean of its
leaves' proportions in tree order, so a row's result never depends on the rows around it. It
agrees with the fitted forest's ``predict_proba`` to rounding (tested).

A commissioned diagnoser may name its faults with it (`bayes_fdi.commissioning.commission`,
``isolation="forest"``), and so may the default model (`bayes_fdi.default_diagnoser`
``fit_online_diagnoser(isolation="forest")``): splits on one feature at a time ignore the scale
of the signatures, whose magnitudes span orders (a residual shift of 0.1 or of 80 noise standard
deviations), and the features a fault does not move. Unlike the k-means tree of RVCs, whose
probabilities fall towards even odds away from its training signatures, a forest can be
confident about a signature unlike all of them.

Written by hand: the per-row compiled evaluation of the fitted trees; the fit is
scikit-learn's.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_is_fitted, validate_data

__all__ = ["ForestArrays", "ForestClassifier", "forest_proba"]


class ForestArrays(NamedTuple):
    """The arrays of a fitted `ForestClassifier` that `forest_proba` takes."""

    roots: np.ndarray
    feature: np.ndarray
    threshold: np.ndarray
    left: np.ndarray
    right: np.ndarray
    offsets: np.ndarray
    leaf_class: np.ndarray
    leaf_proba: np.ndarray


class ForestClassifier(ClassifierMixin, BaseEstimator):
    """Random forest classifier stored as flat arrays, with a compiled ``predict_proba``.

    Parameters
    ----------
    n_estimators
        Trees in the forest.
    min_samples_leaf
        Fewest training rows in a leaf (larger: smoother probabilities, smaller file).
    max_features
        Features tried at each split (scikit-learn's meaning).
    random_state
        Seed of the bootstrap samples and the features tried.

    Attributes
    ----------
    classes_ : numpy.ndarray
        Class labels, sorted.
    n_features_in_ : int
    roots_ : numpy.ndarray
        ``(n_trees + 1,)`` int64: tree ``t`` owns nodes ``roots_[t]:roots_[t + 1]``.
    feature_, threshold_, left_, right_ : numpy.ndarray
        Per node (int32 features and children, the children as absolute node indices, -1 at
        a leaf; float64 thresholds): go left when the feature, rounded to float32 as
        scikit-learn does, is at most the threshold.
    leaf_offsets_ : numpy.ndarray
        ``(n_nodes + 1,)`` int64: node ``n``'s class proportions are entries
        ``leaf_offsets_[n]:leaf_offsets_[n + 1]`` of ``leaf_class_`` / ``leaf_proba_`` (none
        for a split node).
    leaf_class_, leaf_proba_ : numpy.ndarray
        The leaves' non-zero class proportions (class index, proportion).
    """

    def __init__(
        self,
        n_estimators: int = 300,
        min_samples_leaf: int = 3,
        max_features: Any = "sqrt",
        random_state: int | None = None,
    ):
        self.n_estimators = n_estimators
        self.min_samples_leaf = min_samples_leaf
        self.max_features = max_features
        self.random_state = random_state

    def fit(self, X: Any, y: Any) -> ForestClassifier:
        """Fit the forest on ``(X, y)`` and keep its trees as arrays."""
        from sklearn.ensemble import RandomForestClassifier

        X, y = validate_data(self, X, y, dtype=np.float64)
        check_classification_targets(y)
        forest = RandomForestClassifier(
            n_estimators=int(self.n_estimators),
            min_samples_leaf=int(self.min_samples_leaf),
            max_features=self.max_features,
            random_state=self.random_state,
            n_jobs=1,
        ).fit(X, y)
        self.classes_ = forest.classes_
        roots, feature, threshold, left, right = [0], [], [], [], []
        counts, classes, proba = [], [], []
        for tree in (e.tree_ for e in forest.estimators_):
            start = roots[-1]
            leaf = tree.children_left == -1
            feature.append(np.where(leaf, -1, tree.feature).astype(np.int32))
            threshold.append(np.asarray(tree.threshold, dtype=np.float64))
            left.append(np.where(leaf, -1, tree.children_left + start).astype(np.int32))
            right.append(np.where(leaf, -1, tree.children_right + start).astype(np.int32))
            value = np.asarray(tree.value[:, 0, :], dtype=np.float64)
            share = value / value.sum(axis=1, keepdims=True)
            share[~leaf] = 0.0  # a split node holds no proportions
            node, cls = np.nonzero(share > 0.0)  # row by row: each leaf's entries together
            counts.append(np.bincount(node, minlength=tree.node_count))
            classes.append(cls.astype(np.int32))
            proba.append(share[node, cls])
            roots.append(start + tree.node_count)
        self.roots_ = np.asarray(roots, dtype=np.int64)
        self.feature_ = np.concatenate(feature)
        self.threshold_ = np.concatenate(threshold)
        self.left_ = np.concatenate(left)
        self.right_ = np.concatenate(right)
        self.leaf_offsets_ = np.concatenate([[0], np.cumsum(np.concatenate(counts))]).astype(
            np.int64
        )
        self.leaf_class_ = np.concatenate(classes)
        self.leaf_proba_ = np.concatenate(proba)
        return self

    def arrays(self) -> ForestArrays:
        """The fitted arrays `forest_proba` takes."""
        check_is_fitted(self, "roots_")
        return ForestArrays(
            self.roots_,
            self.feature_,
            self.threshold_,
            self.left_,
            self.right_,
            self.leaf_offsets_,
            self.leaf_class_,
            self.leaf_proba_,
        )

    def predict_proba(self, X: Any) -> np.ndarray:
        """Class probabilities ``(n, n_classes)``: the mean over the trees of the class
        proportions in the leaf each row reaches."""
        check_is_fitted(self, "roots_")
        X = np.ascontiguousarray(validate_data(self, X, dtype=np.float64, reset=False))
        out = np.empty((X.shape[0], self.classes_.size))
        _forest_rows(X, self.arrays(), out)
        return out

    def predict(self, X: Any) -> np.ndarray:
        """The most probable class of each row."""
        proba = self.predict_proba(X)  # first: it refuses an unfitted forest
        return self.classes_[np.argmax(proba, axis=1)]


@njit(cache=True)
def forest_proba(x, forest, out):  # pragma: no cover - compiled
    """Class probabilities of one row ``x`` under ``forest`` (`ForestArrays`) into ``out``: the
    mean over the trees, in tree order, of the class proportions of the leaf ``x`` reaches."""
    feature, threshold, left, right = forest.feature, forest.threshold, forest.left, forest.right
    for c in range(out.size):
        out[c] = 0.0
    n_trees = forest.roots.size - 1
    for t in range(n_trees):
        n = forest.roots[t]
        while left[n] >= 0:
            # scikit-learn compares the float32 feature with the float64 threshold
            if np.float64(np.float32(x[feature[n]])) <= threshold[n]:
                n = left[n]
            else:
                n = right[n]
        for k in range(forest.offsets[n], forest.offsets[n + 1]):
            out[forest.leaf_class[k]] += forest.leaf_proba[k]
    for c in range(out.size):
        out[c] /= n_trees


@njit(cache=True)
def _forest_rows(X, forest, out):  # pragma: no cover - compiled
    """`forest_proba` of every row of ``X`` into the rows of ``out``."""
    for i in range(X.shape[0]):
        forest_proba(X[i], forest, out[i])

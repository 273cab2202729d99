"""The scoring of ``benchmarks/isolation_nodes.py``, checked by hand."""

from __future__ import annotations

import numpy as np
import pytest
from benchmark_scripts import load_benchmark

from bayes_fdi.diagnosis.isolation.tree import HierarchicalClassifier

tool = load_benchmark("isolation_nodes")


def test_node_balanced_accuracy_weighs_every_class_of_the_node_alike():
    # a: 2 of 3 rows left (right side is wrong for a); b: 1 of 1 right; c: 0 of 2 right
    y = np.array(["a", "a", "a", "b", "c", "c", "z"])
    p_right = np.array([0.1, 0.2, 0.9, 0.7, 0.4, 0.5, 1.0])
    got = tool.node_balanced_accuracy(p_right, y, ("a",), ("b", "c"))
    assert got == pytest.approx((2 / 3 + 1 + 0) / 3)
    # a class of the node absent from the rows is not counted
    assert tool.node_balanced_accuracy(p_right[:4], y[:4], ("a",), ("b", "c")) == pytest.approx(
        (2 / 3 + 1) / 2
    )


def test_classifier_scores_by_hand():
    classes = ["f1", "f2", "f3"]
    groups = [("f1", "f2"), ("f3",)]
    y = np.array(["f1", "f1", "f2", "f3"])
    proba = np.array(
        [
            [0.6, 0.3, 0.1],  # f1 named f1: right fault, right group
            [0.2, 0.75, 0.05],  # f1 named f2: wrong fault, right group at 0.95
            [0.05, 0.0, 0.95],  # f2 named f3: wrong group at p 0.95 -> confident wrong
            [0.3, 0.3, 0.4],  # f3 named f3 by fault, but group f1|f2 has 0.6: wrong group
        ]
    )
    s = tool.classifier_scores(proba, classes, y, groups)
    assert s["fault"] == pytest.approx((1 / 2 + 0 + 1) / 3)
    assert s["group"] == pytest.approx((1 + 0 + 0) / 3)
    assert s["confident_wrong"] == pytest.approx(1 / 4)


def test_node_rows_read_each_nodes_own_classifier():
    rng = np.random.default_rng(0)
    centres = {"a": (-3.0, 0.0), "b": (3.0, 0.0), "c": (3.0, 4.0)}
    X = np.vstack([rng.normal(c, 0.5, (30, 2)) for c in centres.values()])
    y = np.repeat(list(centres), 30)
    tree = HierarchicalClassifier().fit(X, y)
    rows = tool.node_rows(tree, (X, y), (X, y))
    assert [r["node"] for r in rows] == [n.index for n in tree.nodes_]
    for r, node in zip(rows, tree.nodes_, strict=True):
        assert r["rows"] == node.n_samples
        assert (r["left"], r["right"]) == (list(node.left), list(node.right))
        # well separated clusters: every node's RVC and forest send every row to its side
        assert r["rvc_train"] == r["rvc_heldout"] == r["forest_heldout"] == 1.0


def test_feature_spread_is_each_features_percentiles():
    from bayes_fdi.diagnosis.isolation.signatures import ISOLATION_FEATURES

    X = np.tile(np.arange(101.0)[:, None], (1, len(ISOLATION_FEATURES)))
    X[:, 1] *= -2.0
    spread = tool.feature_spread(X)
    assert list(spread) == list(ISOLATION_FEATURES)
    assert spread[ISOLATION_FEATURES[0]] == pytest.approx([1.0, 25.0, 75.0, 99.0])
    assert spread[ISOLATION_FEATURES[1]] == pytest.approx([-198.0, -150.0, -50.0, -2.0])

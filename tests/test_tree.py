"""Tests of the hierarchical classifier: tree design, probability propagation, fitted tree."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.linear_model import LogisticRegression
from sklearn.preprocessing import StandardScaler
from sklearn.utils.estimator_checks import estimator_checks_generator

from bayes_fdi.diagnosis import svm_classifier
from bayes_fdi.diagnosis.isolation.tree import PAPER_TREE, HierarchicalClassifier, _leaves
from bayes_fdi.diagnosis.isolation.tree_design import design_tree


def blobs(centres: dict, n: int, rng: np.random.Generator, scale: float = 0.1):
    X = np.concatenate(
        [np.asarray(c, float) + scale * rng.standard_normal((n, len(c))) for c in centres.values()]
    )
    y = np.repeat(np.array(list(centres), dtype=object), n)
    return X, y


# ----------------------------------------------------------------------------- design
def test_design_tree_one_dimensional_pairs():
    # Two tight pairs far apart: the root separates the pairs; equal sizes -> the group with
    # the first-listed class goes left.
    tree = design_tree(np.array([[0.0], [1.0], [10.0], [11.0]]), ["a", "b", "c", "d"])
    assert tree == (("a", "b"), ("c", "d"))


def test_design_tree_outlier_split_first_then_pairs():
    # Hand analysis: d (far right) alone costs SSE 101 vs >= 5000 for any other split, so the
    # root is d | rest (smaller group left); then {a,b} | {c,e} (SSE 1 vs 100).
    centroids = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 10.0], [100.0, 0.0], [1.0, 10.0]])
    tree = design_tree(centroids, ["a", "b", "c", "d", "e"], random_state=3)
    assert tree == ("d", (("a", "b"), ("c", "e")))


def test_design_tree_degenerate_identical_centroids():
    # k-means cannot split identical centroids: the farthest class (first on ties) goes off.
    assert design_tree(np.zeros((3, 2)), ["x", "y", "z"]) == ("x", ("y", "z"))
    # Two identical + one distinct: the distinct one is split off first.
    assert design_tree(np.array([[0.0], [0.0], [5.0]]), [1, 2, 3]) == (3, (1, 2))


def test_kmeans_tree_learnt_from_data_matches_design(rng):
    centres = {"a": (0, 0), "b": (1, 0), "c": (0, 10), "d": (100, 0), "e": (1, 10)}
    X, y = blobs(centres, 15, rng)
    clf = HierarchicalClassifier(LogisticRegression(), node_scaling=False).fit(X, y)
    assert clf.tree_ == ("d", (("a", "b"), ("c", "e")))
    assert [n.index for n in clf.nodes_] == [0, 1, 2, 3]
    root = clf.nodes_[0]
    assert root.left == ("d",) and set(root.right) == {"a", "b", "c", "e"}
    assert root.n_samples == 75 and clf.nodes_[2].n_samples == 30


def test_node_scaled_design_splits_standardised_node_samples(rng):
    # Second implementation: at every node, standardise that node's own samples, take the
    # class centroids and let design_tree choose the first split; it must be the node's split.
    centres = {"a": (0, 0), "b": (0.3, 0), "c": (0, 3), "d": (60, 0), "e": (0.3, 3), "g": (60, 9)}
    X, y = blobs(centres, 12, rng, scale=0.2)
    clf = HierarchicalClassifier(LogisticRegression()).fit(X, y)
    for node in clf.nodes_:
        classes = sorted(node.left + node.right)
        in_node = np.isin(y, classes)
        Z = StandardScaler().fit_transform(X[in_node])
        cents = np.stack([Z[y[in_node] == c].mean(axis=0) for c in classes])
        top = design_tree(cents, classes)
        if not isinstance(top, tuple):
            continue
        first = {tuple(sorted(_leaves(top[0]))), tuple(sorted(_leaves(top[1])))}
        assert first == {tuple(sorted(node.left)), tuple(sorted(node.right))}
        np.testing.assert_allclose(node.scaler.mean_, X[in_node].mean(axis=0))


def test_node_scaling_makes_the_tree_affine_invariant(rng):
    centres = {"a": (0, 0), "b": (1, 0.2), "c": (0, 3), "d": (40, 0)}
    X, y = blobs(centres, 15, rng, scale=0.5)
    Xt = rng.normal(scale=5.0, size=(30, 2))
    scale, shift = np.array([1e-3, 50.0]), np.array([7.0, -2.0])
    a = HierarchicalClassifier(LogisticRegression()).fit(X, y)
    b = HierarchicalClassifier(LogisticRegression()).fit(X * scale + shift, y)
    assert a.tree_ == b.tree_
    # each node standardises its samples, so both trees' classifiers see the same numbers up
    # to rounding (~1e-15) and fit the same model; 1e-6 leaves room for the logistic solver
    # stopping one step apart
    np.testing.assert_allclose(
        a.predict_proba(Xt), b.predict_proba(Xt * scale + shift), rtol=1e-6, atol=1e-9
    )


def test_design_is_seeded_and_reproducible(rng):
    centroids = rng.normal(size=(8, 2))
    labels = [f"c{i}" for i in range(8)]
    assert design_tree(centroids, labels, random_state=5) == design_tree(
        centroids, labels, random_state=5
    )


# ----------------------------------------------------------------------------- paper tree
PAPER_NODES = [  # the paper's section 4.2 text: RVM1 .. RVM9, left vs right
    ({"f17"}, {"f1", "f2", "f3", "f6", "f11", "f12", "f15", "f18", "fn"}),
    ({"f1"}, {"f2", "f3", "f6", "f11", "f12", "f15", "f18", "fn"}),
    ({"f3", "f6", "f18"}, {"f2", "f11", "f12", "f15", "fn"}),
    ({"f3"}, {"f6", "f18"}),
    ({"f15"}, {"f2", "f11", "f12", "fn"}),
    ({"f6"}, {"f18"}),
    ({"fn"}, {"f2", "f11", "f12"}),
    ({"f11"}, {"f2", "f12"}),
    ({"f2"}, {"f12"}),
]
# The paper's Table 3 training sample counts per node (20 runs per state).
PAPER_SAMPLES = [200, 180, 160, 60, 100, 40, 80, 60, 40]


def test_paper_figure20_tree_is_expressible(rng):
    states = ["f1", "f2", "f3", "f6", "f11", "f12", "f15", "f17", "f18", "fn"]
    centres = {s: rng.normal(scale=3.0, size=2) for s in states}
    X, y = blobs(centres, 20, rng, scale=0.5)
    clf = HierarchicalClassifier(svm_classifier(), structure=PAPER_TREE).fit(X, y)
    assert len(clf.nodes_) == 9
    got = [(set(n.left), set(n.right)) for n in clf.nodes_]
    assert got == PAPER_NODES
    assert [n.n_samples for n in clf.nodes_] == PAPER_SAMPLES
    for node in clf.nodes_:
        assert node.n_vectors == len(node.estimator.support_vectors_)
        assert 0 < node.n_vectors <= node.n_samples
    text = clf.export_text(names="SVM")
    assert text.splitlines()[0].startswith("SVM1: f17 vs f1, f3, f6, f18, f15, fn, f11, f2, f12  [")
    assert "SVM9: f2 vs f12  [" in text
    assert text.count("\n") == 9 + 10 - 1  # one line per node and per leaf


# ----------------------------------------------------------------------------- probabilities
def test_predict_proba_is_product_along_paths(rng):
    centres = {"a": (0, 0), "b": (1, 0), "c": (0, 10), "d": (100, 0), "e": (1, 10)}
    X, y = blobs(centres, 15, rng, scale=1.0)
    clf = HierarchicalClassifier(
        LogisticRegression(C=0.1), structure=("d", (("a", "b"), ("c", "e")))
    )
    clf.fit(X, y)
    Xt = rng.normal(scale=20.0, size=(40, 2))

    def right(k):  # hand computation from each node's own scaler and estimator
        node = clf.nodes_[k]
        Z = (Xt - node.scaler.mean_) / node.scaler.scale_
        return node.estimator.predict_proba(Z)[:, list(node.estimator.classes_).index(1)]

    p0, p1, p2, p3 = (right(k) for k in range(4))
    expected = {
        "a": p0 * (1 - p1) * (1 - p2),
        "b": p0 * (1 - p1) * p2,
        "c": p0 * p1 * (1 - p3),
        "d": 1 - p0,
        "e": p0 * p1 * p3,
    }
    proba = clf.predict_proba(Xt)
    assert list(clf.classes_) == ["a", "b", "c", "d", "e"]
    for j, c in enumerate(clf.classes_):
        # the same products of the same node probabilities: rounding only
        np.testing.assert_allclose(proba[:, j], expected[c], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(proba.sum(axis=1), 1.0, atol=1e-12)
    np.testing.assert_array_equal(clf.predict(Xt), clf.classes_[proba.argmax(axis=1)])
    np.testing.assert_allclose(clf.node_probabilities(Xt), np.column_stack([p0, p1, p2, p3]))


def test_two_classes_int_labels_single_node(rng):
    X = np.concatenate([rng.normal(-2, 1, (30, 3)), rng.normal(2, 1, (30, 3))])
    y = np.repeat([7, 3], 30)
    clf = HierarchicalClassifier(LogisticRegression(), node_scaling=False).fit(X, y)
    assert len(clf.nodes_) == 1 and list(clf.classes_) == [3, 7]
    assert clf.nodes_[0].scaler is None
    lr = LogisticRegression().fit(X, np.where(y == clf.nodes_[0].right[0], 1, 0))
    # With two classes the tree is the node itself: same probabilities as a direct fit.
    p_right = lr.predict_proba(X)[:, 1]
    right_col = list(clf.classes_).index(clf.nodes_[0].right[0])
    np.testing.assert_allclose(clf.predict_proba(X)[:, right_col], p_right, rtol=1e-10)
    assert clf.nodes_[0].n_vectors is None
    # blobs 4 sd apart along the diagonal of 3 dimensions: Bayes error Phi(-2 sqrt(3)) = 3e-4
    assert (clf.predict(X) == y).mean() > 0.95


def test_learns_separable_multiclass_problem(rng):
    centres = {s: (3.0 * np.cos(k), 3.0 * np.sin(k)) for k, s in enumerate("pqrstu")}
    X, y = blobs(centres, 30, rng, scale=0.4)
    Xt, yt = blobs(centres, 30, rng, scale=0.4)
    clf = HierarchicalClassifier(svm_classifier(sigma=2.0)).fit(X, y)
    # neighbouring centres 2 * 3 * sin(0.5) = 2.88 apart, 3.6 sd of the blobs to the midpoint:
    # the Bayes accuracy is above 0.999; 0.97 allows 5 errors in 180 runs
    assert (clf.predict(Xt) == yt).mean() > 0.97
    assert np.allclose(clf.predict_proba(Xt).sum(axis=1), 1.0)


# ----------------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    "structure, match",
    [
        (("a", ("b", "z")), "missing"),
        (("a", ("b", "b")), "more than once"),
        (("a", "b", "c"), "pair"),
        ("spectral", "kmeans"),
    ],
)
def test_bad_structures_raise(structure, match, rng):
    X, y = blobs({"a": (0, 0), "b": (5, 0), "c": (0, 5)}, 5, rng)
    with pytest.raises(ValueError, match=match):
        HierarchicalClassifier(LogisticRegression(), structure=structure).fit(X, y)


def test_one_class_and_nan_raise(rng):
    X = rng.normal(size=(10, 2))
    with pytest.raises(ValueError, match="at least 2 classes"):
        HierarchicalClassifier(LogisticRegression()).fit(X, np.zeros(10))
    X[0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        HierarchicalClassifier(LogisticRegression()).fit(X, np.arange(10) % 2)


def _sklearn_checks():
    # scikit-learn's API checks, minus the array-API one (needs SCIPY_ARRAY_API; it would skip).
    for est in (
        HierarchicalClassifier(LogisticRegression()),
        HierarchicalClassifier(LogisticRegression(), node_scaling=False),
        HierarchicalClassifier(svm_classifier(sigma=1.0)),
    ):
        for estimator, check in estimator_checks_generator(est, legacy=True):
            name = getattr(check, "func", check).__name__
            if "array_api" not in name:
                yield pytest.param(
                    estimator, check, id=f"{type(est.base_estimator).__name__}-{name}"
                )


@pytest.mark.parametrize("estimator, check", list(_sklearn_checks()))
def test_sklearn_compatible(estimator, check):
    check(estimator)

"""Hierarchical (binary-tree) multi-class classifier, as in the paper's Figure 20.

Each internal node of the tree splits its set of classes into a left and a right group and holds
a binary probabilistic classifier trained on the samples of its classes only (left = 0,
right = 1). A class probability is the product of the node probabilities along the root-to-leaf
path,

    p(c | x) = product over the nodes n on the path to c of p_n(side of c at n | x),

so the leaves carry a full class distribution that sums to one; ``predict`` is its argmax.

The tree is either designed from the data by recursive 2-means on the class centroids of the
training features (as the paper did; `bayes_fdi.diagnosis.isolation.tree_design`) or given
explicitly as a nested tuple of labels. The
paper's tree is `PAPER_TREE`::

    ("f17", ("f1", (("f3", ("f6", "f18")), ("f15", ("fn", ("f11", ("f2", "f12")))))))

By default each node standardises the features of its own training samples before its
classifier (``node_scaling=True``), so a fixed kernel width means the same at every level.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin, clone
from sklearn.preprocessing import StandardScaler
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_is_fitted, validate_data

from bayes_fdi.diagnosis.isolation.tree_design import design_tree, plain_label
from bayes_fdi.rvm.threads import limit_fit_threads

__all__ = [
    "PAPER_TREE",
    "HierarchicalClassifier",
    "TreeNode",
    "n_vectors",
]

#: The paper's Figure 20 tree over its ten states.
PAPER_TREE: tuple = (
    "f17",
    ("f1", (("f3", ("f6", "f18")), ("f15", ("fn", ("f11", ("f2", "f12")))))),
)


class TreeNode(NamedTuple):
    """One fitted internal node of a `HierarchicalClassifier`.

    Attributes
    ----------
    index : int
        Node number in breadth-first order, root = 0 (node k is the paper's RVM(k+1)).
    depth : int
        Root depth 0.
    left, right : tuple
        Classes sent to the left (binary label 0) and right (label 1) branches.
    left_child, right_child : int or None
        Index of the child node, or None where the branch is a leaf (a single class).
    estimator : object
        The fitted binary classifier.
    scaler : sklearn.preprocessing.StandardScaler or None
        The node's feature standardisation (``node_scaling=True``), applied before
        ``estimator``.
    n_vectors : int or None
        Number of relevance vectors (``relevance_vectors_``) or support vectors
        (``support_vectors_``) of ``estimator``; None if it exposes neither.
    n_samples : int
        Training samples the node was fitted on (those of its classes).
    """

    index: int
    depth: int
    left: tuple
    right: tuple
    left_child: int | None
    right_child: int | None
    estimator: Any
    scaler: StandardScaler | None
    n_vectors: int | None
    n_samples: int


def _leaves(structure: Any) -> list:
    if isinstance(structure, tuple):
        if len(structure) != 2:
            raise ValueError(
                f"each internal node of a tree structure must be a pair, got {structure!r}"
            )
        return _leaves(structure[0]) + _leaves(structure[1])
    return [structure]


class HierarchicalClassifier(ClassifierMixin, BaseEstimator):
    """Binary-tree multi-class classifier with a probabilistic binary classifier at each node.

    Parameters
    ----------
    base_estimator
        Unfitted binary probabilistic classifier (``fit``, ``predict_proba``), cloned at every
        node. ``None``: ``bayes_fdi.rvm.RVC(kernel="rbf", width=2.0)`` (the paper's method).
        For the paper's SVM baseline use `bayes_fdi.diagnosis.isolation.svm.svm_classifier`.
    structure
        ``"kmeans"`` (design the tree by recursive 2-means on the class centroids of the
        training features, see `~bayes_fdi.diagnosis.isolation.tree_design.design_tree`) or a
        nested tuple of pairs of class labels (e.g. `PAPER_TREE`) that must hold every
        training class exactly once.
    node_scaling
        Standardise the features of each node's training samples (a ``StandardScaler`` per
        node, fitted on the samples of the node's classes) before its classifier, and design
        the k-means splits on the same node-standardised scale. A fixed kernel width (the
        paper's sigma = 2) then means the same at every level of the tree, however much the
        classes near the root (e.g. f17's large flow residual) stretch the feature range.
        ``False``: features are used as given at every node.
    n_init
        k-means restarts per split of more than
        `~bayes_fdi.diagnosis.isolation.tree_design.MAX_EXACT_SPLIT` classes (smaller splits are
        found exactly).
    random_state
        Seed of those k-means restarts.

    Attributes
    ----------
    classes_ : numpy.ndarray
        Sorted class labels; columns of `predict_proba`.
    tree_ : tuple or label
        The tree actually used, as nested pairs of labels.
    nodes_ : list of TreeNode
        Fitted internal nodes, breadth-first (root first), numbered as the paper's RVM1..RVMn.
    n_features_in_ : int
    """

    def __init__(
        self,
        base_estimator: Any = None,
        *,
        structure: str | tuple = "kmeans",
        node_scaling: bool = True,
        n_init: int = 10,
        random_state: int | None = 0,
    ) -> None:
        self.base_estimator = base_estimator
        self.structure = structure
        self.node_scaling = node_scaling
        self.n_init = n_init
        self.random_state = random_state

    def _base(self) -> Any:
        if self.base_estimator is not None:
            return self.base_estimator
        from bayes_fdi.rvm import RVC

        return RVC(kernel="rbf", width=2.0)

    @limit_fit_threads
    def fit(self, X: Any, y: Any) -> HierarchicalClassifier:
        """Design (or check) the tree and fit one binary classifier per internal node.

        Parameters
        ----------
        X
            ``(n_samples, n_features)`` features.
        y
            ``(n_samples,)`` class labels (strings or integers); at least two classes.

        Returns
        -------
        HierarchicalClassifier
            ``self``.
        """
        X, y = validate_data(self, X, y)
        check_classification_targets(y)
        classes = np.unique(y)
        if classes.size < 2:
            raise ValueError(
                f"HierarchicalClassifier needs at least 2 classes; got 1 class ({classes[0]!r})"
            )
        self.classes_ = classes
        self.tree_ = self._tree(X, y, classes)
        self.nodes_ = self._fit_nodes(X, y, self.tree_)
        return self

    def _tree(self, X: np.ndarray, y: np.ndarray, classes: np.ndarray) -> Any:
        """The tree over ``classes``: designed by k-means, or the given ``structure`` checked."""
        class_list = [plain_label(c) for c in classes]
        if isinstance(self.structure, str):
            if self.structure != "kmeans":
                raise ValueError(
                    f"structure must be 'kmeans' or a nested tuple, got {self.structure!r}"
                )
            centroids = np.stack([X[y == c].mean(axis=0) for c in classes])
            stats = {}
            if self.node_scaling:
                stats = {
                    "counts": np.array([(y == c).sum() for c in classes]),
                    "variances": np.stack([X[y == c].var(axis=0) for c in classes]),
                }
            return design_tree(
                centroids,
                class_list,
                n_init=self.n_init,
                random_state=self.random_state,
                **stats,
            )
        if isinstance(self.structure, tuple):
            leaves = _leaves(self.structure)
            dup = sorted({str(c) for c in leaves if leaves.count(c) > 1})
            if dup:
                raise ValueError(f"tree structure lists class(es) {dup} more than once")
            missing = [c for c in class_list if c not in leaves]
            extra = [c for c in leaves if c not in class_list]
            if missing or extra:
                raise ValueError(
                    f"tree structure does not match the training classes: missing {missing}, "
                    f"not in the training data {extra}"
                )
            return self.structure
        raise ValueError(
            f"structure must be 'kmeans' or a nested tuple, got {type(self.structure)}"
        )

    def _fit_nodes(self, X: np.ndarray, y: np.ndarray, tree: Any) -> list[TreeNode]:
        """One fitted binary classifier per internal node of ``tree``, breadth-first."""
        base = self._base()
        # Number internal nodes breadth-first (root = 0), as the paper numbers RVM1..RVM9.
        internal: list[tuple[tuple[int, ...], Any, int]] = []
        queue: list[tuple[tuple[int, ...], Any, int]] = [((), tree, 0)]
        while queue:
            path, sub, depth = queue.pop(0)
            if isinstance(sub, tuple):
                internal.append((path, sub, depth))
                queue.append(((*path, 0), sub[0], depth + 1))
                queue.append(((*path, 1), sub[1], depth + 1))
        index_of = {path: i for i, (path, _, _) in enumerate(internal)}
        nodes: list[TreeNode] = []
        for path, sub, depth in internal:
            left, right = tuple(_leaves(sub[0])), tuple(_leaves(sub[1]))
            in_left = np.isin(y, np.array(left, dtype=y.dtype))
            in_node = in_left | np.isin(y, np.array(right, dtype=y.dtype))
            Xn = X[in_node]
            scaler = StandardScaler().fit(Xn) if self.node_scaling else None
            est = clone(base)
            est.fit(
                Xn if scaler is None else scaler.transform(Xn), np.where(in_left[in_node], 0, 1)
            )
            nodes.append(
                TreeNode(
                    index=index_of[path],
                    depth=depth,
                    left=left,
                    right=right,
                    left_child=index_of.get((*path, 0)),
                    right_child=index_of.get((*path, 1)),
                    estimator=est,
                    scaler=scaler,
                    n_vectors=n_vectors(est),
                    n_samples=int(in_node.sum()),
                )
            )
        return nodes

    def _node_right_proba(self, node: TreeNode, X: np.ndarray) -> np.ndarray:
        if node.scaler is not None:
            X = node.scaler.transform(X)
        proba = np.asarray(node.estimator.predict_proba(X), dtype=np.float64)
        cls = list(np.asarray(node.estimator.classes_).tolist())
        if 1 not in cls:  # cannot happen: both sides have training samples
            raise ValueError(f"node {node.index} estimator has classes {cls}, expected [0, 1]")
        return proba[:, cls.index(1)]

    def node_probabilities(self, X: Any) -> np.ndarray:
        """Right-branch probability of every node, ``(n_samples, n_nodes)`` in node order."""
        check_is_fitted(self, "nodes_")
        X = validate_data(self, X, reset=False)
        if not self.nodes_:
            return np.empty((X.shape[0], 0))
        return np.column_stack([self._node_right_proba(n, X) for n in self.nodes_])

    def predict_proba(self, X: Any) -> np.ndarray:
        """Class probabilities: products of node probabilities along root-to-leaf paths.

        Parameters
        ----------
        X
            ``(n_samples, n_features)``.

        Returns
        -------
        numpy.ndarray
            ``(n_samples, n_classes)`` in ``classes_`` order; rows sum to 1.
        """
        right = self.node_probabilities(X)
        out = np.zeros((right.shape[0], self.classes_.size))
        col = {c: i for i, c in enumerate(self.classes_.tolist())}

        def walk(sub: Any, index: int | None, mass: np.ndarray) -> None:
            if index is None:
                out[:, col[plain_label(sub)]] = mass
                return
            node = self.nodes_[index]
            p = right[:, index]
            walk(sub[0], node.left_child, mass * (1.0 - p))
            walk(sub[1], node.right_child, mass * p)

        walk(self.tree_, 0, np.ones(right.shape[0]))
        return out

    def predict_log_proba(self, X: Any) -> np.ndarray:
        """Logarithm of `predict_proba`."""
        with np.errstate(divide="ignore"):
            return np.log(self.predict_proba(X))

    def predict(self, X: Any) -> np.ndarray:
        """Most probable class (argmax of `predict_proba`)."""
        proba = self.predict_proba(X)
        return self.classes_[np.argmax(proba, axis=1)]

    def export_text(self, *, names: str = "RVM") -> str:
        """The fitted tree as text, like the paper's Figure 20 and Tables 3/5.

        Parameters
        ----------
        names
            Node name prefix (``"RVM"`` -> RVM1, RVM2, ...; ``"SVM"`` for the baseline).

        Returns
        -------
        str
            One line per node (``RVMk: left vs right  [vectors/samples]``) and per leaf,
            drawn as a tree (left branch first).
        """
        check_is_fitted(self, "nodes_")

        def fmt(group: tuple) -> str:
            return ", ".join(str(c) for c in group)

        lines: list[str] = []

        def walk(sub: Any, index: int | None, prefix: str, branch: str, cont: str) -> None:
            if index is None:
                lines.append(f"{prefix}{branch}{sub}")
                return
            node = self.nodes_[index]
            vec = "?" if node.n_vectors is None else str(node.n_vectors)
            lines.append(
                f"{prefix}{branch}{names}{index + 1}: {fmt(node.left)} vs {fmt(node.right)}"
                f"  [{vec}/{node.n_samples}]"
            )
            walk(sub[0], node.left_child, prefix + cont, "├── ", "│   ")
            walk(sub[1], node.right_child, prefix + cont, "└── ", "    ")

        walk(self.tree_, 0, "", "", "")
        return "\n".join(lines)


def n_vectors(est: Any) -> int | None:
    """Relevance or support vectors of a fitted node classifier (also the last step of a
    pipeline); None for a classifier without either."""
    final = est.steps[-1][1] if hasattr(est, "steps") else est
    for attr in ("relevance_vectors_", "support_vectors_"):
        vec = getattr(final, attr, None)
        if vec is not None:
            return int(np.shape(vec)[0])
    return None

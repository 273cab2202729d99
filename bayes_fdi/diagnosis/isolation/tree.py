"""Hierarchical (binary-tree) multi-class classifier, as in the paper's Figure 20.

Each internal node of the tree splits its set of classes into a left and a right group and holds
a binary probabilistic classifier trained on the samples of its classes only (left = 0,
right = 1). A class probability is the product of the node probabilities along the root-to-leaf
path,

    p(c | x) = product over the nodes n on the path to c of p_n(side of c at n | x),

so the leaves carry a full class distribution that sums to one; ``predict`` is its argmax.

The tree is either designed from the data by recursive 2-means on the class centroids of the
training features (as the paper did) or given explicitly as a nested tuple of labels. The
paper's tree is `PAPER_TREE`::

    ("f17", ("f1", (("f3", ("f6", "f18")), ("f15", ("fn", ("f11", ("f2", "f12")))))))

By default each node standardises the features of its own training samples before its
classifier (``node_scaling=True``), so a fixed kernel width means the same at every level.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin, clone
from sklearn.cluster import KMeans
from sklearn.preprocessing import StandardScaler
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_is_fitted, validate_data

from bayes_fdi.rvm.threads import limit_fit_threads

__all__ = [
    "INERTIA_RTOL",
    "MAX_EXACT_SPLIT",
    "PAPER_TREE",
    "HierarchicalClassifier",
    "TreeNode",
    "design_tree",
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


def _label(x: Any) -> Any:
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
    classes = [_label(c) for c in classes]
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
        training features, see `design_tree`) or a nested tuple of pairs of class labels
        (e.g. `PAPER_TREE`) that must hold every training class exactly once.
    node_scaling
        Standardise the features of each node's training samples (a ``StandardScaler`` per
        node, fitted on the samples of the node's classes) before its classifier, and design
        the k-means splits on the same node-standardised scale. A fixed kernel width (the
        paper's sigma = 2) then means the same at every level of the tree, however much the
        classes near the root (e.g. f17's large flow residual) stretch the feature range.
        ``False``: features are used as given at every node.
    n_init
        k-means restarts per split of more than `MAX_EXACT_SPLIT` classes (smaller splits are
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
        class_list = [_label(c) for c in classes]
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
            tree = design_tree(
                centroids,
                class_list,
                n_init=self.n_init,
                random_state=self.random_state,
                **stats,
            )
        elif isinstance(self.structure, tuple):
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
            tree = self.structure
        else:
            raise ValueError(
                f"structure must be 'kmeans' or a nested tuple, got {type(self.structure)}"
            )
        self.tree_ = tree
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
        self.nodes_ = nodes
        return self

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
                out[:, col[_label(sub)]] = mass
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

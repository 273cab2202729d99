"""Markdown tables of the reproduction laid out like the paper's (Feng & Wang, Tables 2-9).

- :func:`confusion_table` — rows are the true states (``f1(170)``), columns the identified
  states, then ``Correct Num`` and ``Identification ratio``, with the overall ratio;
- :func:`node_table` — one column per binary node of the tree (``RVM1`` ... ``RVM9``) with its
  split and ``RV Num/Train sample Num`` (``SV Num`` for support vector machines);
- :func:`tree_text` — the hierarchical tree as an indented outline;
- :func:`comparison_table`, :func:`per_state_table`, :func:`groups_table` — the overall
  results next to the paper's, and the all-states analysis.

Every function is pure: plain results in, Markdown out.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from bayes_fdi.reporting import format_percent, markdown_table

__all__ = [
    "PAPER_ACCURACY",
    "PAPER_NODE_VECTORS",
    "comparison_table",
    "confusion_table",
    "groups_table",
    "node_table",
    "per_state_table",
    "tree_text",
]


#: Overall identification ratios reported by the paper (Section 5, Tables 2, 4, 6, 8).
PAPER_ACCURACY: dict[str, dict[str, float]] = {
    "paper-simulated": {"rvm": 0.9960, "svm": 0.9853},
    "paper-lublin": {"rvm": 0.9686, "svm": 0.9328},
}


#: Vectors / training samples per node reported by the paper (Tables 3, 5, 7, 9), RVM1..RVM9.
PAPER_NODE_VECTORS: dict[str, dict[str, list[tuple[int, int]]]] = {
    "paper-simulated": {
        "rvm": [
            (9, 200),
            (7, 180),
            (6, 160),
            (2, 60),
            (4, 100),
            (2, 40),
            (3, 80),
            (3, 60),
            (3, 40),
        ],
        "svm": [
            (39, 200),
            (32, 180),
            (21, 160),
            (15, 60),
            (16, 100),
            (16, 40),
            (20, 80),
            (10, 60),
            (12, 40),
        ],
    },
    "paper-lublin": {
        "rvm": [
            (3, 200),
            (3, 180),
            (3, 160),
            (2, 60),
            (9, 100),
            (2, 40),
            (7, 80),
            (2, 60),
            (2, 40),
        ],
        "svm": [
            (52, 200),
            (31, 180),
            (30, 160),
            (12, 60),
            (25, 100),
            (12, 40),
            (21, 80),
            (17, 60),
            (9, 40),
        ],
    },
}


def _confusion_array(confusion: Any, classes: Sequence[str]) -> np.ndarray:
    matrix = np.asarray(confusion)
    k = len(classes)
    if matrix.shape != (k, k):
        raise ValueError(f"confusion matrix has shape {matrix.shape}, expected ({k}, {k})")
    if not np.issubdtype(matrix.dtype, np.number) or np.any(matrix < 0):
        raise ValueError("confusion matrix must hold non-negative counts")
    if not np.all(np.equal(np.mod(matrix, 1), 0)):
        raise ValueError("confusion matrix must hold integer counts")
    return matrix.astype(np.int64)


def confusion_table(confusion: Any, classes: Sequence[str]) -> str:
    """A confusion matrix as a Markdown table laid out like the paper's Table 2.

    Parameters
    ----------
    confusion
        ``(k, k)`` integer counts; row ``i`` is the true class ``classes[i]``, column ``j`` the
        identified class ``classes[j]`` (as :func:`sklearn.metrics.confusion_matrix`).
    classes
        Class names in the order of the matrix.

    Returns
    -------
    str
        Markdown: one row per true state (``name(n)``), one column per identified state, then
        ``Correct Num`` and ``Identification ratio``; a last ``overall`` row with the totals.
    """
    classes = [str(c) for c in classes]
    matrix = _confusion_array(confusion, classes)
    header = ["Testing data", *classes, "Correct Num", "Identification ratio"]
    rows = []
    for i, name in enumerate(classes):
        n = int(matrix[i].sum())
        correct = int(matrix[i, i])
        ratio = correct / n if n else float("nan")
        rows.append([f"{name}({n})", *map(int, matrix[i]), correct, format_percent(ratio)])
    total = int(matrix.sum())
    correct = int(np.trace(matrix))
    overall = correct / total if total else float("nan")
    rows.append(
        [f"overall({total})", *map(int, matrix.sum(axis=0)), correct, format_percent(overall)]
    )
    return markdown_table(header, rows)


def node_table(
    nodes: Sequence[Mapping[str, Any]],
    *,
    prefix: str = "RVM",
    vector_name: str = "RV",
    paper: Sequence[tuple[int, int]] | None = None,
) -> str:
    """Per-node sizes of a hierarchical classifier, like the paper's Tables 3, 5, 7 and 9.

    Parameters
    ----------
    nodes
        One mapping per binary node, in tree order (breadth first from the root), with keys
        ``left`` and ``right`` (class names on each side), ``vectors`` (relevance or support
        vectors kept) and ``samples`` (training samples of the node).
    prefix
        Column prefix (``"RVM"`` gives ``RVM1``, ``RVM2``, ...).
    vector_name
        ``"RV"`` or ``"SV"``, used in the row title.
    paper
        Optional ``(vectors, samples)`` per node from the paper, shown as an extra row.

    Returns
    -------
    str
        Markdown with rows ``Split``, ``<RV> Num/Train sample Num`` (and ``Paper``).
    """
    if not nodes:
        raise ValueError("no nodes to tabulate")
    header = ["Parameters", *(f"{prefix}{i + 1}" for i in range(len(nodes)))]
    split, sizes = ["Split"], [f"{vector_name} Num/Train sample Num"]
    for node in nodes:
        for key in ("left", "right", "vectors", "samples"):
            if key not in node:
                raise ValueError(f"node {node!r} lacks {key!r}")
        split.append(f"{', '.join(node['left'])} vs {', '.join(node['right'])}")
        sizes.append(f"{int(node['vectors'])}/{int(node['samples'])}")
    rows = [split, sizes]
    if paper is not None:
        cells = [f"{v}/{s}" for v, s in paper]
        cells = (cells + ["–"] * len(nodes))[: len(nodes)]
        rows.append(["Paper", *cells])
    return markdown_table(header, rows)


def tree_text(nodes: Sequence[Mapping[str, Any]], *, prefix: str = "RVM") -> str:
    """The hierarchical tree as an indented outline.

    The root is the node whose classes (``left + right``) are the most; the children of a
    node are the nodes whose class sets equal its ``left`` or ``right`` side. A side with one
    class is a leaf.

    Parameters
    ----------
    nodes
        Mappings with ``left`` and ``right`` class lists (and optionally ``vectors``/``samples``),
        numbered ``prefix1``, ``prefix2`` ... in the given order.
    prefix
        Node name prefix.

    Returns
    -------
    str
        One line per node and leaf, indented two spaces per level.
    """
    if not nodes:
        raise ValueError("no nodes to draw")
    by_set: dict[frozenset[str], int] = {}
    for i, node in enumerate(nodes):
        key = frozenset(map(str, node["left"])) | frozenset(map(str, node["right"]))
        if key in by_set:
            raise ValueError(f"two nodes split the same classes {sorted(key)}")
        by_set[key] = i
    root = max(by_set, key=len)
    lines: list[str] = []
    seen: set[int] = set()

    def walk(classes: frozenset[str], depth: int) -> None:
        pad = "  " * depth
        if len(classes) == 1:
            lines.append(f"{pad}- {next(iter(classes))}")
            return
        if classes not in by_set:
            raise ValueError(f"no node splits {sorted(classes)}")
        i = by_set[classes]
        seen.add(i)
        node = nodes[i]
        size = ""
        if "vectors" in node and "samples" in node:
            size = f" ({int(node['vectors'])}/{int(node['samples'])})"
        left, right = list(map(str, node["left"])), list(map(str, node["right"]))
        lines.append(f"{pad}- {prefix}{i + 1}{size}: {', '.join(left)} vs {', '.join(right)}")
        walk(frozenset(left), depth + 1)
        walk(frozenset(right), depth + 1)

    walk(root, 0)
    if len(seen) != len(nodes):
        orphans = sorted(set(range(len(nodes))) - seen)
        raise ValueError(f"nodes {[f'{prefix}{i + 1}' for i in orphans]} are not in the tree")
    return "\n".join(lines) + "\n"


def comparison_table(datasets: Mapping[str, Mapping[str, Any]]) -> str:
    """Overall results per dataset and method next to the paper's numbers.

    Parameters
    ----------
    datasets
        ``{dataset: {method: metrics}}`` where ``metrics`` has ``accuracy``, ``log_loss``,
        ``brier``, ``ece``, ``fit_seconds``, ``predict_seconds`` and ``nodes``.

    Returns
    -------
    str
        Markdown, one row per (dataset, method).
    """
    header = [
        "Dataset",
        "Method",
        "Identification ratio",
        "Paper",
        "Log loss",
        "Brier",
        "ECE",
        "Vectors per node",
        "Fit (s)",
        "Predict (s)",
    ]
    rows = []
    for name, methods in datasets.items():
        for method, m in methods.items():
            paper = PAPER_ACCURACY.get(name, {}).get(method, float("nan"))
            vectors = [int(n["vectors"]) for n in m.get("nodes", [])]
            span = f"{min(vectors)}–{max(vectors)}" if vectors else "–"
            rows.append(
                [
                    name,
                    method.upper(),
                    format_percent(m["accuracy"]),
                    format_percent(paper),
                    f"{m['log_loss']:.4f}",
                    f"{m['brier']:.4f}",
                    f"{m['ece']:.4f}",
                    span,
                    f"{m['fit_seconds']:.2f}",
                    f"{m['predict_seconds']:.3f}",
                ]
            )
    return markdown_table(header, rows)


def per_state_table(
    per_class: Mapping[str, float], groups: Sequence[Sequence[str]], mass: Mapping[str, float]
) -> str:
    """Per-state identification ratio with the state's group and the probability on that group.

    Parameters
    ----------
    per_class
        State -> identification ratio.
    groups
        The groups of indistinguishable states (every state in exactly one group).
    mass
        State -> mean probability the classifier puts on the state's group (test runs).
    """
    group_of = {s: g for g in groups for s in g}
    rows = []
    for state, ratio in per_class.items():
        group = group_of.get(state, [state])
        kind = "separable" if len(group) == 1 else "group " + "/".join(group)
        rows.append([state, format_percent(ratio), kind, f"{mass.get(state, float('nan')):.3f}"])
    return markdown_table(["State", "Identification ratio", "Separable?", "P(true group)"], rows)


def groups_table(
    groups: Sequence[Sequence[str]], paper_groups: Sequence[Sequence[str]] | None = None
) -> str:
    """The groups of indistinguishable states, side by side with the paper's groups.

    Parameters
    ----------
    groups
        Groups found (each a list of states); singletons are separable states.
    paper_groups
        Groups the paper reports as alike, for comparison.
    """
    found = [list(g) for g in groups if len(g) > 1]
    paper = [list(g) for g in (paper_groups or [])]
    rows = []
    for g in found:
        overlap = [p for p in paper if set(p) & set(g)]
        same = any(set(p) == set(g) for p in paper)
        note = (
            "same as the paper"
            if same
            else (
                "overlaps " + "; ".join("/".join(p) for p in overlap)
                if overlap
                else "not in the paper"
            )
        )
        rows.append(["/".join(g), note])
    for p in paper:
        if not any(set(p) & set(g) for g in found):
            rows.append(["–", "paper group " + "/".join(p) + " separable here"])
    if not rows:
        rows.append(["–", "every state is separable"])
    return markdown_table(["Group found", "Compared with the paper"], rows)

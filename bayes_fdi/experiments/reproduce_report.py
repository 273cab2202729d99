"""Turn reproduction results into Markdown tables, figures and JSON.

Every function here is pure (no fitting, no simulation): it takes plain results — the
dictionaries :func:`bayes_fdi.experiments.reproduce.reproduce` builds — and renders them. The tables
follow the layout of the paper (Feng & Wang, Tables 2-9):

- :func:`confusion_table` — rows are the true states (``f1(170)``), columns the identified
  states, then ``Correct Num`` and ``Identification ratio``, with the overall ratio;
- :func:`node_table` — one column per binary node of the tree (``RVM1`` ... ``RVM9``) with its
  split and ``RV Num/Train sample Num`` (``SV Num`` for support vector machines);
- :func:`tree_text` — the hierarchical tree as an indented outline;
- :func:`plot_residuals` — ``r1`` and ``r2`` against time for a few states (Figures 12-19);
- :func:`plot_features` — the two residual features of every run, one colour per state;
- :func:`write_json` — results as JSON with plain ``int``/``float``/``str`` values only.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "PAPER_ACCURACY",
    "PAPER_NODE_VECTORS",
    "comparison_table",
    "confusion_table",
    "format_percent",
    "groups_table",
    "markdown_table",
    "node_table",
    "per_state_table",
    "plot_features",
    "plot_residuals",
    "render_report",
    "to_jsonable",
    "tree_text",
    "write_json",
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


def format_percent(value: float, digits: int = 2) -> str:
    """Format a ratio in ``[0, 1]`` as a percentage (``0.9824 -> '98.24%'``); NaN as ``'–'``."""
    if value is None or not math.isfinite(float(value)):
        return "–"
    return f"{100.0 * float(value):.{digits}f}%"


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """Render a GitHub-flavoured Markdown table.

    Parameters
    ----------
    header
        Column titles.
    rows
        One sequence per row, each as long as ``header``; cells are converted with ``str``.

    Returns
    -------
    str
        The table, one line per row, ending with a newline.
    """
    header = [str(h) for h in header]
    if not header:
        raise ValueError("a table needs at least one column")
    for i, row in enumerate(rows):
        if len(row) != len(header):
            raise ValueError(f"row {i} has {len(row)} cells, the header has {len(header)}")

    def line(cells: Sequence[Any]) -> str:
        return "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |"

    out = [line(header), "|" + "|".join("---" for _ in header) + "|"]
    out.extend(line(row) for row in rows)
    return "\n".join(out) + "\n"


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


def to_jsonable(obj: Any) -> Any:
    """Convert results to JSON-ready values: plain ``dict``/``list``/``int``/``float``/``str``.

    numpy scalars and arrays, tuples and paths are converted; non-finite floats become ``None``
    (JSON has no NaN). Anything else raises ``ValueError`` naming its type.
    """
    if obj is None or isinstance(obj, bool | str):
        return obj
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, int | np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        value = float(obj)
        return value if math.isfinite(value) else None
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if isinstance(obj, Mapping):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [to_jsonable(v) for v in obj]
    raise ValueError(f"cannot write a {type(obj).__name__} to JSON")


def write_json(results: Mapping[str, Any], path: str | os.PathLike) -> Path:
    """Write ``results`` as indented JSON (see :func:`to_jsonable`) and return the path."""
    path = Path(path)
    path.write_text(json.dumps(to_jsonable(results), indent=2, sort_keys=False) + "\n")
    return path


def _save(fig: Any, path: str | os.PathLike) -> Path:
    """Lay out ``fig``, write it to ``path`` (PNG, 110 dpi), close it; return the path."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_residuals(
    residuals: Mapping[str, tuple[np.ndarray, np.ndarray, np.ndarray]],
    path: str | os.PathLike,
    *,
    title: str = "",
) -> Path:
    """Residuals ``r1`` and ``r2`` against time, one row per state (the paper's Figures 12-19).

    Parameters
    ----------
    residuals
        State -> ``(time, r1, r2)``, 1-D arrays of one run.
    path
        Output image (PNG).
    title
        Figure title.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    if not residuals:
        raise ValueError("no residuals to plot")
    n = len(residuals)
    fig, axes = plt.subplots(n, 2, figsize=(9, 1.9 * n + 0.6), sharex=True, squeeze=False)
    limits = [0.0, 0.0]
    for row, (state, (time, r1, r2)) in enumerate(residuals.items()):
        for col, (name, r) in enumerate((("r1", r1), ("r2", r2))):
            ax = axes[row, col]
            ax.plot(np.asarray(time), np.asarray(r), lw=0.8, color="C0" if col == 0 else "C3")
            ax.axhline(0.0, color="0.6", lw=0.6)
            ax.set_ylabel(f"{state}: {name}")
            finite = np.asarray(r)[np.isfinite(r)]
            if finite.size:
                limits[col] = max(limits[col], float(np.max(np.abs(finite))))
    for col in range(2):
        lim = 1.05 * limits[col] if limits[col] > 0 else 1.0
        for row in range(n):
            axes[row, col].set_ylim(-lim, lim)
        axes[-1, col].set_xlabel("time (s)")
    if title:
        fig.suptitle(title)
    return _save(fig, path)


def plot_features(
    features: np.ndarray,
    labels: Sequence[str],
    path: str | os.PathLike,
    *,
    feature_names: Sequence[str] = ("mean r1", "mean r2"),
    predict: Callable[[np.ndarray], np.ndarray] | None = None,
    title: str = "",
) -> Path:
    """Scatter of the two residual features, one colour per state.

    Parameters
    ----------
    features
        ``(n, 2)`` feature values.
    labels
        ``n`` state names.
    path
        Output image (PNG).
    feature_names
        Axis titles.
    predict
        Optional classifier ``predict`` (``(m, 2) -> m`` labels); its decision regions are
        shaded behind the points.
    title
        Figure title.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    features = np.asarray(features, dtype=float)
    labels = np.asarray([str(s) for s in labels])
    if features.ndim != 2 or features.shape[1] != 2:
        raise ValueError(f"features must have shape (n, 2), got {features.shape}")
    if labels.shape[0] != features.shape[0]:
        raise ValueError(f"{labels.shape[0]} labels for {features.shape[0]} feature rows")
    states = list(dict.fromkeys(labels))
    cmap = plt.get_cmap("tab20" if len(states) > 10 else "tab10")
    colour = {s: cmap(i % cmap.N) for i, s in enumerate(states)}
    fig, ax = plt.subplots(figsize=(7.5, 6))
    lo, hi = features.min(axis=0), features.max(axis=0)
    pad = 0.08 * np.maximum(hi - lo, 1e-9)
    lo, hi = lo - pad, hi + pad
    if predict is not None:
        g0, g1 = np.meshgrid(np.linspace(lo[0], hi[0], 200), np.linspace(lo[1], hi[1], 200))
        grid = np.column_stack([g0.ravel(), g1.ravel()])
        region = np.asarray(predict(grid)).astype(str).reshape(g0.shape)
        index = {s: i for i, s in enumerate(states)}
        codes = np.vectorize(lambda s: index.get(s, -1))(region).astype(float)
        codes[codes < 0] = np.nan
        from matplotlib.colors import ListedColormap

        ax.pcolormesh(
            g0,
            g1,
            codes,
            cmap=ListedColormap([colour[s] for s in states]),
            vmin=-0.5,
            vmax=len(states) - 0.5,
            alpha=0.18,
            shading="auto",
        )
    markers = "os^D"
    for i, s in enumerate(states):
        mask = labels == s
        ax.scatter(
            features[mask, 0],
            features[mask, 1],
            s=12,
            color=colour[s],
            marker=markers[(i // 10) % len(markers)],
            label=s,
        )
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_xlabel(feature_names[0])
    ax.set_ylabel(feature_names[1])
    ax.legend(fontsize=8, ncol=2, loc="best", markerscale=1.5)
    if title:
        ax.set_title(title)
    return _save(fig, path)


def _num(value: Any, fmt: str = ".4f") -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    return format(value, fmt)


def _why_below(
    name: str, method: Mapping[str, Any], all_states: Mapping[str, Any] | None, target: float
) -> list[str]:
    """Lines explaining the states identified below ``target``: whom they are confused with."""
    classes = method["confusion"]["classes"]
    matrix = np.asarray(method["confusion"]["matrix"])
    lines = []
    err = None
    if all_states is not None:
        sep_states = list(all_states["states"])
        err = np.asarray(all_states["pairwise_error"], dtype=float)
    for i, s in enumerate(classes):
        ratio = method["per_class"][s]
        if ratio is None or ratio >= target:
            continue
        wrong = sorted(
            ((int(matrix[i, j]), classes[j]) for j in range(len(classes)) if j != i),
            reverse=True,
        )
        parts = []
        for n, other in wrong:
            if n == 0:
                break
            note = f"{n} as {other}"
            if err is not None and s in sep_states and other in sep_states:
                e = err[sep_states.index(s), sep_states.index(other)]
                note += f" (pairwise k-NN error of the training features {e:.2f})"
            parts.append(note)
        lines.append(
            f"- **{s}** ({format_percent(ratio)}): " + ("; ".join(parts) if parts else "–")
        )
    return lines


def _display_path(path: str | os.PathLike) -> str:
    """``path`` relative to the working folder when inside it (reports do not leak home paths)."""
    p = Path(path)
    try:
        return p.resolve().relative_to(Path.cwd().resolve()).as_posix()
    except (ValueError, OSError):
        return p.name if p.is_absolute() else p.as_posix()


def _ece_text(e: Mapping[str, Any]) -> str:
    return (
        f"{_num(e.get('value'), '.3f')} [{_num(e.get('ci_low'), '.3f')}, "
        f"{_num(e.get('ci_high'), '.3f')}] (floor {_num(e.get('noise_floor'), '.3f')})"
    )


def _coverage_text(cov: Mapping[str, Any], level: str = "95%") -> str:
    parts = []
    for name in ("X", "F"):
        c = cov.get(name, {}).get(level)
        if c is not None:
            parts.append(f"{name} {format_percent(c['coverage'], 1)}")
    return " / ".join(parts) if parts else "–"


def calibration_table(datasets: Mapping[str, Mapping[str, Any]]) -> str:
    """Headline calibration figures per dataset (RVM pipeline), as a Markdown table.

    ``datasets`` maps a dataset name to its results with a ``calibration`` entry
    (:func:`bayes_fdi.experiments.reproduce.calibration_headlines`); datasets without one are
    skipped.
    """
    rows = []
    for name, d in datasets.items():
        c = d.get("calibration")
        if not c:
            continue
        five = next(
            (
                b
                for b in c.get("ece_by_binning", [])
                if b["strategy"] == "uniform" and b["n_bins"] == 5
            ),
            None,
        )
        rows.append(
            [
                name,
                _ece_text(c["before"]["ece"]),
                _ece_text(c["after"]["ece"]),
                f"{format_percent(c['before']['accuracy'])} → "
                f"{format_percent(c['after']['accuracy'])}",
                f"{_num(c['before']['log_loss'])} → {_num(c['after']['log_loss'])}",
                ", ".join(c.get("selected", [])) or "–",
                _ece_text(five["after"]) if five else "–",
                _coverage_text(c.get("coverage", {})),
                _coverage_text(c["real_record_coverage"]) if "real_record_coverage" in c else "–",
                f"[report]({c['report']})",
            ]
        )
    if not rows:
        return ""
    header = [
        "Dataset",
        "ECE before [95 % CI] (noise floor)",
        "ECE after recalibration",
        "Accuracy before → after",
        "Log loss before → after",
        "Recalibrator chosen",
        "ECE after, 5 bins",
        "95 % coverage, fault-free test runs",
        "95 % coverage, real record 2nd half",
        "Full report",
    ]
    return markdown_table(header, rows)


def _vectors(m: Mapping[str, Any]) -> str:
    v = [n["vectors"] for n in m.get("nodes", []) if n.get("vectors") is not None]
    return f"{min(v)}–{max(v)} ({sum(v)})" if v else "–"


def _model_size(nm: Mapping[str, Any]) -> str:
    rv, noise = nm.get("relevance_vectors", {}), nm.get("noise_std", {})
    return " / ".join(
        f"{k}: {rv[k]} RVs, std {_num(noise.get(k), '.4f')}" for k in ("X", "F") if k in rv
    )


def dynamic_section(results: Mapping[str, Any]) -> list[str]:
    """Report lines comparing the paper's static normal models with the dynamic ones.

    Uses each dataset's ``dynamic`` entry (see :func:`bayes_fdi.experiments.reproduce.reproduce`);
    empty when there is none.
    """
    datasets = {k: v for k, v in results["datasets"].items() if v.get("dynamic")}
    if not datasets:
        return []
    lags = ", ".join(f"{float(v):g}" for v in results.get("dynamic_lags", []))
    md = [
        "## Beyond the paper: dynamic normal models",
        "",
        f"The same pipeline, features (`mean_r1`, `mean_r2`), tree, seeds and runs, but the "
        f"normal models also see the command lagged by {lags} s, `CV(t - L)`: the stem follows "
        "its command with a lag, which the paper's static models `g(CV, sqrt(P1 - P2), T1)` "
        "leave in the residuals, so the fault-free runs' mean residuals scatter and weak "
        "faults hide in that scatter. The lags were chosen on the fault-free training runs "
        "only (log evidence and held-out run-mean residual spread; docs/diagnosis.md), never "
        "on test accuracy.",
        "",
    ]
    rows = []
    for name, d in datasets.items():
        dyn = d["dynamic"]
        for label, r in (("static (paper)", d), (f"dynamic ({lags} s)", dyn)):
            rvm, svm = r["rvm"], r["svm"]
            block = r.get("all_states", {})
            cal = r.get("calibration", {})
            rows.append(
                [
                    name,
                    label,
                    _model_size(r.get("normal_models", {})),
                    format_percent(rvm["accuracy"]),
                    format_percent(svm["accuracy"]),
                    (">=" if rvm["accuracy"] >= svm["accuracy"] else "<")
                    + (
                        f" (+{r['paired']['a_only']}/−{r['paired']['b_only']} runs, "
                        f"McNemar p = {r['paired']['p_value']:.2g})"
                        if r.get("paired")
                        else ""
                    ),
                    _vectors(rvm),
                    _vectors(svm),
                    format_percent(block["rvm"]["separable_accuracy"]) if "rvm" in block else "–",
                    format_percent(block["rvm"]["group_accuracy"]) if "rvm" in block else "–",
                    _num(cal.get("after", {}).get("ece", {}).get("value"), ".3f"),
                ]
            )
    header = [
        "Dataset",
        "Normal models",
        "Normal-model size, noise",
        "RVM, paper states",
        "SVM, paper states",
        "RVM vs SVM",
        "RVs per node (total)",
        "SVs per node (total)",
        "RVM, 20 states: separable states",
        "RVM, 20 states: group level",
        "ECE after recalibration",
    ]
    md += [markdown_table(header, rows), ""]
    md += [
        "The 20-state columns use each row's own groups (they change with the features): "
        "accuracy on the states that are separable, and accuracy up to the group.",
        "",
    ]
    group_rows = []
    for name, d in datasets.items():
        for label, r in (("static", d), ("dynamic", d["dynamic"])):
            block = r.get("all_states", {})
            groups = [g for g in block.get("groups", []) if len(g) > 1]
            group_rows.append([name, label, ", ".join("/".join(g) for g in groups) or "none"])
    md += [
        markdown_table(["Dataset", "Normal models", "Groups no classifier can split"], group_rows)
    ]
    for name, d in datasets.items():
        m = d["dynamic"]["rvm"]
        cal = d["dynamic"].get("calibration", {})
        md += [
            f"<details><summary>{name}, dynamic: RVM confusion on the paper states</summary>",
            "",
            confusion_table(m["confusion"]["matrix"], m["confusion"]["classes"]),
            "</details>",
            "",
        ]
        if cal:
            md += [
                f"{name}, dynamic: coverage of the 95 % intervals on fault-free test runs "
                f"{_coverage_text(cal.get('coverage', {}))}"
                + (
                    f", real record 2nd half {_coverage_text(cal['real_record_coverage'])}"
                    if "real_record_coverage" in cal
                    else ""
                )
                + f"; [calibration report]({cal['report']}).",
                "",
            ]
    return md


def _normal_models_text(nm: Mapping[str, Any]) -> str:
    if not nm:
        return ""
    out = []
    if "width" in nm:
        ev = ", ".join(f"{float(w):g}: {e:.1f}" for w, e in nm.get("log_evidence", {}).items())
        out.append(f"RBF width {nm['width']:g} by maximum evidence (summed log evidence {ev})")
    rv = nm.get("relevance_vectors", {})
    noise = nm.get("noise_std", {})
    for k in rv:
        part = f"g for {k}: {rv[k]} relevance vectors"
        if k in noise:
            part += f", noise std {noise[k]:.4f}"
        out.append(part)
    return "; " + "; ".join(out) if out else ""


def render_report(results: Mapping[str, Any]) -> str:
    """The Markdown report of a :func:`bayes_fdi.experiments.reproduce.reproduce` run.

    Parameters
    ----------
    results
        The JSON-ready results (``datasets``, ``figures``, ``seed``, ``small``, ...).

    Returns
    -------
    str
        Markdown text; figures are linked by their file names (same folder).
    """
    datasets = results["datasets"]
    figures = results.get("figures", {})
    md: list[str] = [
        "# Reproduction of Feng & Wang: SEVA actuator fault diagnosis with RVMs",
        "",
        f"bayes_fdi {results.get('bayes_fdi_version', '?')}, seed {results.get('seed')}"
        + (
            ", **small campaigns** (quick check, not the paper's sizes)"
            if results.get("small")
            else ""
        )
        + f", {_num(results.get('seconds'), '.0f')} s in total.",
        "",
        "Protocol (the paper's Section 5): per state, the first "
        f"{results.get('n_train_per_state', 20)} runs fit the normal models (fault-free runs) "
        "and train the classifiers; every other run is a test run. Features: the mean residuals "
        "`mean_r1`, `mean_r2` of each run. RVM = k-means designed tree of RVM classifiers; "
        "each node standardises its own training features and uses a Gaussian kernel with "
        "sigma = 2. SVM = the same tree with SVMs (same scaling and kernel, C = 1, Platt-scaled "
        "probabilities) on the same features.",
        "",
        "## Overall identification ratio",
        "",
        comparison_table({k: {m: v[m] for m in ("rvm", "svm")} for k, v in datasets.items()}),
    ]
    checks = []
    for name, d in datasets.items():
        paper = PAPER_ACCURACY.get(name, {}).get("rvm")
        rvm, svm = d["rvm"]["accuracy"], d["svm"]["accuracy"]
        if paper is not None:
            verdict = "meets" if rvm >= paper else "is below"
            pair = d.get("paired")
            paired = (
                f" Paired on the same test runs: only the RVM right on {pair['a_only']}, only "
                f"the SVM on {pair['b_only']} (exact McNemar p = {pair['p_value']:.2g})."
                if pair
                else ""
            )
            checks.append(
                f"- {name}: RVM {format_percent(rvm)} {verdict} the paper's "
                f"{format_percent(paper)}; "
                f"RVM {'>=' if rvm >= svm else '<'} SVM ({format_percent(svm)})." + paired
            )
        rv = [n["vectors"] for n in d["rvm"]["nodes"] if n["vectors"] is not None]
        sv = [n["vectors"] for n in d["svm"]["nodes"] if n["vectors"] is not None]
        if rv and sv:
            checks.append(
                f"- {name}: relevance vectors per node {min(rv)}–{max(rv)} "
                f"(total {sum(rv)}), support vectors per node {min(sv)}–{max(sv)} "
                f"(total {sum(sv)})."
            )
    md += [*checks, ""]
    md += [
        "Log loss (natural log) and Brier score (mean over runs of the squared distance between "
        "the probability vector and the one-hot truth, 0 best, 2 worst) score the full class "
        "distribution; ECE is the top-label expected calibration error (15 equal-width bins). "
        "Fit and predict times are for the classifier trees on the features (the normal models "
        "are shared; their time is in the per-dataset timing below).",
        "",
    ]
    cal = calibration_table(datasets)
    if cal:
        methods = {
            str(d["calibration"]["recalibration"].get("method"))
            for d in datasets.values()
            if d.get("calibration")
        }
        md += [
            "## Calibration of the RVM pipeline (headline figures)",
            "",
            cal,
            "Top-label ECE with 15 equal-width bins on the paper states' test runs, with a "
            "basic-bootstrap 95 % interval and the noise floor (the ECE a perfectly calibrated "
            "model would show with these bins and this many runs; an ECE below the floor cannot "
            "be resolved with this many runs, hence also 5 bins). Recalibration: "
            + "; ".join(sorted(methods))
            + ". Coverage: share of fault-free samples inside the normal models' central 95 % "
            "predictive interval (X / F); the real record is the Lublin hour, fitted on its "
            "first half and scored on its second. Each full report has reliability diagrams, "
            "per-node calibration, PIT histograms and coverage at 50/80/90/95 %.",
            "",
        ]
    md += dynamic_section(results)
    for name, d in datasets.items():
        figs = figures.get(name, {})
        md += [f"## {name}", ""]
        info = d.get("campaign", {})
        split = d.get("split", {})
        md += [
            f"Campaign `{_display_path(info.get('campaign_file') or name)}` "
            f"(sha256 {str(info.get('campaign_sha256', ''))[:16]}…), "
            + (
                "loaded from the cache"
                if info.get("cached")
                else f"simulated in {_num(info.get('simulate_seconds'), '.0f')} s"
            )
            + f". Normal models: {split.get('normal_model_runs', '?')} fault-free runs, "
            f"{split.get('normal_model_samples', '?')} samples"
            + _normal_models_text(d.get("normal_models", {}))
            + ".",
            "",
            "### Fault strengths used",
            "",
        ]
        rows = [
            [s, v["runs"], f"{v['min']:.3g}", f"{v['max']:.3g}", ", ".join(v["profiles"])]
            for s, v in d.get("strength", {}).items()
        ]
        if rows:
            md += [
                markdown_table(["State", "Runs", "Strength min", "Strength max", "Profiles"], rows)
            ]
        if "residuals" in figs:
            md += [
                "### Residuals (as the paper's Figures 12-19)",
                "",
                f"![residuals]({figs['residuals']})",
                "",
            ]
        for method, prefix, vname, table in (
            ("rvm", "RVM", "RV", "2/6"),
            ("svm", "SVM", "SV", "4/8"),
        ):
            m = d[method]
            md += [
                f"### {prefix}: identification results of the test runs (as Tables {table})",
                "",
                confusion_table(m["confusion"]["matrix"], m["confusion"]["classes"]),
                f"Log loss {_num(m['log_loss'])}, Brier {_num(m['brier'])}, ECE {_num(m['ece'])}; "
                f"fit {_num(m['fit_seconds'], '.2f')} s, "
                f"predict {_num(m['predict_seconds'], '.3f')} s.",
                "",
                f"### {prefix} nodes",
                "",
                node_table(
                    m["nodes"],
                    prefix=prefix,
                    vector_name=vname,
                    paper=PAPER_NODE_VECTORS.get(name, {}).get(method),
                ),
                "(`Paper` = the paper's node sizes; its tree is not necessarily the same.)",
                "",
                "```text",
                m.get("tree", tree_text(m["nodes"], prefix=prefix)).rstrip(),
                "```",
                "",
            ]
        target = PAPER_ACCURACY.get(name, {}).get("rvm")
        if target is not None:
            why = _why_below(name, d["rvm"], d.get("all_states"), target)
            md += ["### States identified below the paper's overall ratio (RVM)", ""]
            md += why if why else ["None: every state reaches it."]
            md += [""]
        if "features" in figs:
            md += [f"![features]({figs['features']})", ""]
        block = d.get("all_states")
        if block:
            md += ["### Beyond the paper: all states", ""]
            md += [
                "Two states are confusable when a 5-nearest-neighbour rule trained on the "
                "training features of just those two states misclassifies at least "
                f"{format_percent(block['threshold'], 0)} of them (leave-one-out, balanced). "
                "Groups come from complete-linkage clustering: every pair of states in a group "
                "is confusable. A group's states cannot be told apart from `mean_r1`, "
                "`mean_r2` at the paper's accuracy by any classifier; a state alone is "
                "separable.",
                "",
                groups_table(block["groups"], block.get("paper_groups")),
            ]
            for method in ("rvm", "svm"):
                if method not in block:
                    continue
                m = block[method]
                md += [
                    f"**{method.upper()} on all {len(m['confusion']['classes'])} states**: "
                    f"accuracy {format_percent(m['accuracy'])}, on the separable states "
                    f"{format_percent(m['separable_accuracy'])}, group-level accuracy "
                    f"{format_percent(m['group_accuracy'])}, mean probability on the true "
                    f"state's group {_num(m['group_mass'], '.3f')}; "
                    f"log loss {_num(m['log_loss'])}, "
                    f"ECE {_num(m['ece'])}.",
                    "",
                ]
            if "rvm" in block:
                m = block["rvm"]
                md += [
                    per_state_table(m["per_class"], block["groups"], m["per_state_group_mass"]),
                    "",
                    "<details><summary>RVM confusion on all states</summary>",
                    "",
                    confusion_table(m["confusion"]["matrix"], m["confusion"]["classes"]),
                    "</details>",
                    "",
                ]
            sep = list(block["states"])
            err = np.asarray(block["pairwise_error"], dtype=float)
            md += [
                "<details><summary>Pairwise k-NN error of the training features</summary>",
                "",
                markdown_table(
                    ["", *sep],
                    [[s, *(f"{e:.2f}" for e in err[i])] for i, s in enumerate(sep)],
                ),
                "</details>",
                "",
            ]
            if "all_features" in figs:
                md += [f"![all states]({figs['all_features']})", ""]
        timing = d.get("timing", {})
        if timing:
            md += [
                "Timing (s): " + ", ".join(f"{k} {_num(v, '.2f')}" for k, v in timing.items()),
                "",
            ]
    return "\n".join(md).rstrip() + "\n"

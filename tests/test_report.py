"""Report rendering: Markdown tables, tree outline, JSON and figures from hand-made results."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from sklearn.metrics import confusion_matrix

from bayes_fdi.paper.report_figures import plot_features, plot_residuals
from bayes_fdi.paper.report_tables import (
    PAPER_ACCURACY,
    PAPER_NODE_VECTORS,
    comparison_table,
    confusion_table,
    groups_table,
    node_table,
    per_state_table,
    tree_text,
)
from bayes_fdi.reporting import format_percent, markdown_table, to_jsonable, write_json

# The paper's Figure 20 tree (Section 4.2), breadth first: RVM1 .. RVM9.
PAPER_TREE = [
    {"left": ["f17"], "right": ["f1", "f2", "f3", "f6", "f11", "f12", "f15", "f18", "fn"]},
    {"left": ["f1"], "right": ["f2", "f3", "f6", "f11", "f12", "f15", "f18", "fn"]},
    {"left": ["f3", "f6", "f18"], "right": ["f2", "f11", "f12", "f15", "fn"]},
    {"left": ["f3"], "right": ["f6", "f18"]},
    {"left": ["f15"], "right": ["f2", "f11", "f12", "fn"]},
    {"left": ["f6"], "right": ["f18"]},
    {"left": ["fn"], "right": ["f2", "f11", "f12"]},
    {"left": ["f11"], "right": ["f2", "f12"]},
    {"left": ["f2"], "right": ["f12"]},
]


def _parse(table: str) -> list[list[str]]:
    lines = [ln for ln in table.strip().splitlines()]
    assert set(lines[1].replace("|", "")) == {"-"}
    return [[c.strip() for c in ln.strip("|").split("|")] for ln in lines[:1] + lines[2:]]


def test_format_percent():
    assert format_percent(167 / 170) == "98.24%"  # the paper's f2 ratio in Table 2
    assert format_percent(1.0) == "100.00%"
    assert format_percent(float("nan")) == "–"


def test_markdown_table_rejects_ragged_rows():
    with pytest.raises(ValueError, match="row 0 has 1 cells"):
        markdown_table(["a", "b"], [[1]])


def test_confusion_table_matches_paper_table2():
    # Rebuild the paper's Table 2 from labels and check the rendered ratios against it.
    classes = ["f1", "f2", "f3", "f6", "f11", "f12", "f15", "f17", "f18", "fn"]
    errors = {
        ("f2", "f15"): 3,
        ("f3", "f1"): 1,
        ("f3", "f15"): 1,
        ("f6", "f3"): 1,
        ("f12", "f15"): 1,
    }
    y_true, y_pred = [], []
    for c in classes:
        wrong = {p: n for (t, p), n in errors.items() if t == c}
        y_true += [c] * 170
        y_pred += [c] * (170 - sum(wrong.values()))
        for p, n in wrong.items():
            y_pred += [p] * n
    cm = confusion_matrix(y_true, y_pred, labels=classes)
    rows = _parse(confusion_table(cm, classes))
    assert rows[0] == ["Testing data", *classes, "Correct Num", "Identification ratio"]
    ratios = {r[0]: r[-1] for r in rows[1:]}
    assert ratios["f2(170)"] == "98.24%"
    assert ratios["f3(170)"] == "98.82%"
    assert ratios["f6(170)"] == "99.41%"
    assert ratios["fn(170)"] == "100.00%"
    # overall: 1693 of 1700 = 99.59 % (the paper prints 99.60 %)
    assert rows[-1][0] == "overall(1700)"
    assert rows[-1][-2] == "1693"
    assert rows[-1][-1] == format_percent(1693 / 1700)
    # column sums of the identified states
    f15_col = classes.index("f15") + 1
    assert rows[-1][f15_col] == str(170 + 3 + 1 + 1)


def test_confusion_table_validates():
    with pytest.raises(ValueError, match="shape"):
        confusion_table(np.zeros((2, 3)), ["a", "b"])
    with pytest.raises(ValueError, match="non-negative"):
        confusion_table(np.array([[1, -1], [0, 1]]), ["a", "b"])
    with pytest.raises(ValueError, match="integer"):
        confusion_table(np.array([[1.5, 0], [0, 1]]), ["a", "b"])


def test_node_table_and_paper_row():
    nodes = [
        dict(n, vectors=v, samples=s)
        for n, (v, s) in zip(PAPER_TREE, PAPER_NODE_VECTORS["paper-simulated"]["rvm"], strict=True)
    ]
    rows = _parse(node_table(nodes, paper=PAPER_NODE_VECTORS["paper-simulated"]["rvm"]))
    assert rows[0] == ["Parameters", *(f"RVM{i}" for i in range(1, 10))]
    assert rows[1][1].startswith("f17 vs f1, f2")
    assert rows[2] == [
        "RV Num/Train sample Num",
        "9/200",
        "7/180",
        "6/160",
        "2/60",
        "4/100",
        "2/40",
        "3/80",
        "3/60",
        "3/40",
    ]
    assert rows[3][1:] == rows[2][1:]
    svm = _parse(node_table(nodes, prefix="SVM", vector_name="SV"))
    assert svm[0][1] == "SVM1" and svm[2][0] == "SV Num/Train sample Num"
    with pytest.raises(ValueError, match="lacks 'vectors'"):
        node_table(PAPER_TREE)


def test_tree_text_outline_of_paper_tree():
    text = tree_text(PAPER_TREE)
    lines = text.splitlines()
    # 9 internal nodes + 10 leaves, each leaf exactly once
    assert len(lines) == 19
    leaves = sorted(ln.strip()[2:] for ln in lines if ":" not in ln)
    assert leaves == sorted(["f1", "f2", "f3", "f6", "f11", "f12", "f15", "f17", "f18", "fn"])
    assert lines[0].startswith("- RVM1: f17 vs")
    # depth of f12 in Figure 20 is 7 binary decisions (RVM1,2,3,5,7,8,9)
    f12 = next(ln for ln in lines if ln.strip() == "- f12")
    assert (len(f12) - len(f12.lstrip())) // 2 == 7
    with pytest.raises(ValueError, match="not in the tree"):
        tree_text([*PAPER_TREE, {"left": ["a"], "right": ["b"]}])
    with pytest.raises(ValueError, match="no node splits"):
        tree_text(PAPER_TREE[:-1])


def test_comparison_table_uses_paper_numbers():
    metrics = {
        "accuracy": 0.99,
        "log_loss": 0.05,
        "brier": 0.02,
        "ece": 0.01,
        "fit_seconds": 1.234,
        "predict_seconds": 0.0123,
        "nodes": [{"vectors": 3}, {"vectors": 7}],
    }
    rows = _parse(comparison_table({"paper-lublin": {"rvm": metrics}}))
    assert rows[1][:4] == [
        "paper-lublin",
        "RVM",
        "99.00%",
        format_percent(PAPER_ACCURACY["paper-lublin"]["rvm"]),
    ]
    assert rows[1][7] == "3–7"


def test_groups_and_per_state_tables():
    groups = [["fn", "f4", "f5"], ["f1", "f7"], ["f3"]]
    paper = [["fn", "f4", "f5", "f8", "f9", "f14"], ["f1", "f7", "f10", "f16"], ["f2", "f19"]]
    rows = _parse(groups_table(groups, paper))
    assert rows[1] == ["fn/f4/f5", "overlaps fn/f4/f5/f8/f9/f14"]
    assert rows[-1] == ["–", "paper group f2/f19 separable here"]
    assert _parse(groups_table([["f1", "f7"]], [["f7", "f1"]]))[1][1] == "same as the paper"
    per = _parse(per_state_table({"fn": 0.5, "f3": 1.0}, groups, {"fn": 0.97, "f3": 0.99}))
    assert per[1] == ["fn", "50.00%", "group fn/f4/f5", "0.970"]
    assert per[2] == ["f3", "100.00%", "separable", "0.990"]


def test_json_plain_values(tmp_path):
    results = {
        "acc": np.float64(0.5),
        "n": np.int64(3),
        "cm": np.eye(2, dtype=np.int64),
        "nan": float("nan"),
        "classes": ("a", "b"),
        "flag": np.bool_(True),
    }
    path = write_json(results, tmp_path / "r.json")
    back = json.loads(path.read_text())
    assert back == {
        "acc": 0.5,
        "n": 3,
        "cm": [[1, 0], [0, 1]],
        "nan": None,
        "classes": ["a", "b"],
        "flag": True,
    }
    assert isinstance(back["n"], int)
    with pytest.raises(ValueError, match="cannot write a object"):
        to_jsonable({"x": object()})


def test_figures_are_written(tmp_path, rng):
    import matplotlib.image as mpimg

    t = np.arange(350.0)
    res = {
        s: (t, rng.normal(0, 0.01, 350) + k * 0.1, rng.normal(0, 0.01, 350))
        for k, s in enumerate(["fn", "f1"])
    }
    p = plot_residuals(res, tmp_path / "res.png", title="test")
    img = mpimg.imread(p)
    assert img.shape[0] > 100 and img.shape[1] > 100 and img.std() > 0

    feats = np.vstack([rng.normal([0, 0], 0.01, (30, 2)), rng.normal([0.1, -0.1], 0.01, (30, 2))])
    labels = ["fn"] * 30 + ["f1"] * 30

    def predict(x):
        return np.where(x[:, 0] > 0.05, "f1", "fn")

    p2 = plot_features(feats, labels, tmp_path / "feat.png", predict=predict, title="features")
    assert mpimg.imread(p2).std() > 0
    with pytest.raises(ValueError, match="shape"):
        plot_features(feats[:, :1], labels, tmp_path / "x.png")
    with pytest.raises(ValueError, match="labels"):
        plot_features(feats, labels[:-1], tmp_path / "x.png")
    assert not math.isnan(float(img.mean()))

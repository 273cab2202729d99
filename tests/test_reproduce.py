"""The reproduce pipeline: split, metrics, separability groups, CLI options, and a synthetic
end-to-end evaluation whose answer is known by construction."""

from __future__ import annotations

import argparse

import numpy as np
import pytest
from sklearn.metrics import brier_score_loss

from bayes_fdi.campaigns.cache import split_train_test
from bayes_fdi.commands.reproduce import configure_parser
from bayes_fdi.datasets import make_dataset
from bayes_fdi.paper.pipeline import evaluate_dataset
from bayes_fdi.paper.scores import classification_metrics
from bayes_fdi.paper.separability import find_groups, group_metrics, pairwise_separability


def _synthetic(
    offsets: dict[str, tuple[float, float]], runs: int, n_times: int, seed: int, noise=0.01
):
    """Runs whose outputs are a known function of the inputs plus a per-state offset.

    X = CV, F = (1 - CV) * sqrt(P1 - P2) (both plus white noise), shifted by the state's
    (dX, dF) for the whole run: the mean residuals of a state are exactly its offset.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(n_times, dtype=float)
    chans = {k: [] for k in ("CV", "P1", "P2", "T1", "X", "F")}
    state = []
    for s, (dx, df) in offsets.items():
        for _ in range(runs):
            phase = rng.uniform(0, 2 * np.pi)
            cv = 0.5 + 0.25 * np.sin(2 * np.pi * 0.01 * t + phase)
            p1 = 0.875 + 0.04 * np.sin(2 * np.pi * 0.1 * t + phase)
            p2 = np.full(n_times, 0.65)
            t1 = np.full(n_times, 0.2)
            x = cv + dx + rng.normal(0, noise, n_times)
            f = (1 - cv) * np.sqrt(p1 - p2) + df + rng.normal(0, noise, n_times)
            for k, v in zip(chans, (cv, p1, p2, t1, x, f), strict=True):
                chans[k].append(v)
            state.append(s)
    return make_dataset({k: np.array(v) for k, v in chans.items()}, state=state, seed=seed)


def test_split_first_runs_of_each_state_train():
    ds = _synthetic({"fn": (0, 0), "f1": (0.1, 0)}, runs=5, n_times=4, seed=1)
    # interleave the runs so that "first in run order" is not "first in the file"
    order = np.array([0, 5, 1, 6, 2, 7, 3, 8, 4, 9])
    ds = ds.isel(run=order)
    train, test = split_train_test(ds, n_train=2)
    assert list(train["state"].values) == ["fn", "f1", "fn", "f1"]
    assert list(train["run"].values) == [0, 5, 1, 6]
    assert sorted(test["run"].values.tolist()) == [2, 3, 4, 7, 8, 9]
    train, _ = split_train_test(ds, n_train=2, states=["f1"])
    assert set(train["state"].values) == {"f1"}
    with pytest.raises(ValueError, match="need more than n_train=5"):
        split_train_test(ds, n_train=5)
    with pytest.raises(ValueError, match="no runs of state"):
        split_train_test(ds, n_train=2, states=["f7"])


def test_classification_metrics_brier_against_sklearn_binary(rng):
    p = rng.uniform(size=200)
    y = np.where(rng.uniform(size=200) < p, "b", "a")
    proba = np.column_stack([1 - p, p])
    # the multi-class Brier (sum over classes) is twice the binary one for two classes; the
    # two are summed in different orders, so they agree to rounding: 200 terms of order 1 in
    # float64 differ by at most about 200 * 2.2e-16 relative, well inside 1e-12
    expected = 2 * brier_score_loss(y == "b", p)
    assert classification_metrics(y, proba, ["a", "b"])["brier"] == pytest.approx(
        expected, rel=1e-12
    )
    k = 4
    uniform = np.full((10, k), 1 / k)
    m = classification_metrics(["c0"] * 10, uniform, [f"c{i}" for i in range(k)])
    assert m["brier"] == pytest.approx((k - 1) / k)  # (1 - 1/k)^2 + (k - 1)/k^2, by hand
    with pytest.raises(ValueError, match="sum to 1"):
        classification_metrics(["a"], np.array([[0.5, 0.6]]), ["a", "b"])
    with pytest.raises(ValueError, match="not in classes"):
        classification_metrics(["z"], np.array([[0.5, 0.5]]), ["a", "b"])


def test_classification_metrics_by_hand(rng):
    classes = ["fn", "f1", "f2"]
    y = np.array(["fn"] * 4 + ["f1"] * 3 + ["f2"] * 3)
    proba = rng.dirichlet([1, 1, 1], size=10)
    pred = np.asarray(classes)[proba.argmax(axis=1)]
    m = classification_metrics(y, proba, classes)
    assert m["accuracy"] == pytest.approx(np.mean(pred == y))
    cm = np.array(m["confusion"]["matrix"])
    assert m["confusion"]["classes"] == classes
    for i, a in enumerate(classes):
        for j, b in enumerate(classes):
            assert cm[i, j] == np.sum((y == a) & (pred == b))
        assert m["per_class"][a] == pytest.approx(np.mean(pred[y == a] == a))
    p_true = proba[np.arange(10), [classes.index(s) for s in y]]
    # scikit-learn's log loss against the textbook formula: the same ten logarithms summed in
    # another order, equal to rounding (about 1e-15 relative); 1e-9 leaves a wide margin
    assert m["log_loss"] == pytest.approx(-np.mean(np.log(p_true)), rel=1e-9)
    # top-label ECE with 15 equal-width bins, computed here independently
    conf = proba.max(axis=1)
    hit = (pred == y).astype(float)
    bins = np.clip(np.ceil(conf * 15).astype(int) - 1, 0, 14)
    ece = sum(
        abs(hit[bins == b].mean() - conf[bins == b].mean()) * np.mean(bins == b)
        for b in np.unique(bins)
    )
    assert m["ece"] == pytest.approx(ece, abs=1e-12)


def test_pairwise_separability_identical_vs_distinct(rng):
    a = rng.normal(0, 1, (40, 2))
    b = rng.normal(0, 1, (40, 2))  # same distribution as a
    c = rng.normal(0, 1, (40, 2)) + np.array([12.0, 0.0])  # far away
    X = np.vstack([a, b, c])
    y = ["a"] * 40 + ["b"] * 40 + ["c"] * 40
    states, err = pairwise_separability(X, y)
    assert states == ["a", "b", "c"]
    assert np.allclose(err, err.T) and np.all(np.diag(err) == 0)
    assert 0.3 < err[0, 1] < 0.7  # chance level for identical distributions
    assert err[0, 2] == 0.0 and err[1, 2] == 0.0
    with pytest.raises(ValueError, match="NaN or inf"):
        pairwise_separability(np.array([[np.nan, 0.0]] * 4), ["a", "a", "b", "b"])


def test_find_groups_single_linkage_chains():
    states = ["fn", "f4", "f9", "f1", "f2"]
    err = np.zeros((5, 5))
    err[0, 1] = err[1, 0] = 0.4  # fn ~ f4
    err[1, 2] = err[2, 1] = 0.2  # f4 ~ f9 (chains fn, f4, f9)
    err[3, 4] = err[4, 3] = 0.1  # below threshold
    single = find_groups(states, err, threshold=0.15, linkage="single")
    assert single == [["fn", "f4", "f9"], ["f1"], ["f2"]]
    assert find_groups(states, err, threshold=0.05, linkage="single") == [
        ["fn", "f4", "f9"],
        ["f1", "f2"],
    ]
    with pytest.raises(ValueError, match="must be"):
        find_groups(states, np.zeros((2, 2)))
    with pytest.raises(ValueError, match="symmetric"):
        find_groups(["a", "b"], np.array([[0, 0.3], [0.1, 0]]))


def test_find_groups_complete_linkage_needs_every_pair():
    # f16 looks like fn when weak and like f1 when strong: fn~f16, f16~f1, but fn !~ f1.
    states = ["fn", "f1", "f16", "f8"]
    err = np.zeros((4, 4))
    for a, b, e in [("fn", "f16", 0.2), ("f1", "f16", 0.3), ("fn", "f8", 0.45), ("f16", "f8", 0.2)]:
        i, j = states.index(a), states.index(b)
        err[i, j] = err[j, i] = e
    # single linkage chains everything; complete linkage keeps fn and f1 apart
    assert find_groups(states, err, linkage="single") == [["fn", "f1", "f16", "f8"]]
    # fn~f8 (0.45) merges first, then f1~f16 (0.3) beats {fn, f8}~f16 (min 0.2); then
    # {fn, f8} and {f1, f16} cannot merge (fn~f1 = 0)
    assert find_groups(states, err) == [["fn", "f8"], ["f1", "f16"]]
    err2 = err.copy()
    i, j = states.index("f16"), states.index("f1")
    err2[i, j] = err2[j, i] = 0.0  # f16 no longer like f1: it joins the clique {fn, f8}
    assert find_groups(states, err2) == [["fn", "f16", "f8"], ["f1"]]
    # the independent check: every pair inside every group is confusable
    for groups, e in ((find_groups(states, err), err), (find_groups(states, err2), err2)):
        for g in groups:
            idx = [states.index(s) for s in g]
            assert all(e[a, b] >= 0.15 for a in idx for b in idx if a != b)


def test_group_metrics_by_hand():
    classes = ["fn", "f4", "f1"]
    groups = [["fn", "f4"], ["f1"]]
    y = ["fn", "f4", "f1", "f1"]
    proba = np.array(
        [
            [0.3, 0.6, 0.1],  # fn predicted f4: wrong state, right group, mass 0.9
            [0.5, 0.2, 0.3],  # f4 predicted fn: right group, mass 0.7
            [0.1, 0.1, 0.8],  # f1 right, mass 0.8
            [0.6, 0.1, 0.3],  # f1 predicted fn: wrong group, mass 0.3
        ]
    )
    m = group_metrics(y, proba, classes, groups)
    assert m["separable_states"] == ["f1"]
    assert m["separable_accuracy"] == pytest.approx(0.5)
    assert m["group_accuracy"] == pytest.approx(0.75)
    assert m["group_mass"] == pytest.approx((0.9 + 0.7 + 0.8 + 0.3) / 4)
    assert m["per_state_group_mass"] == pytest.approx({"fn": 0.9, "f4": 0.7, "f1": 0.55})
    with pytest.raises(ValueError, match="in no group"):
        group_metrics(y, proba, classes, [["fn", "f4"]])
    with pytest.raises(ValueError, match="more than one group"):
        group_metrics(y, proba, classes, [["fn", "f4"], ["f1", "fn"]])


def test_cli_options():
    p = argparse.ArgumentParser()
    configure_parser(p)
    a = p.parse_args(["--out", "o"])
    assert (a.out, a.seed, a.cache_dir, a.small, a.no_progress) == (
        "o",
        0,
        ".cache/datasets",
        False,
        False,
    )
    a = p.parse_args(["--out", "o", "--seed", "3", "--small", "--no-progress"])
    assert (a.seed, a.small, a.no_progress) == (3, True, True)
    with pytest.raises(SystemExit):
        p.parse_args([])


def test_evaluate_dataset_on_known_offsets():
    # fn and f4 have the same offset (indistinguishable by construction); the others are far
    # apart relative to the noise of a run mean (0.01 / sqrt(60)).
    offsets = {
        "fn": (0.0, 0.0),
        "f1": (0.08, 0.0),
        "f2": (0.0, 0.08),
        "f3": (-0.08, -0.08),
        "f4": (0.0, 0.0),
    }
    ds = _synthetic(offsets, runs=26, n_times=60, seed=7)
    res, art = evaluate_dataset(ds, states=["fn", "f1", "f2", "f3"], n_train=20, seed=0)
    for method in ("rvm", "svm"):
        m = res[method]
        assert m["accuracy"] == 1.0
        assert m["confusion"]["classes"] == ["f1", "f2", "f3", "fn"]  # the paper's order
        assert sum(n["samples"] for n in m["nodes"][:1]) == 80  # root sees every training run
        assert len(m["nodes"]) == 3  # a binary tree over 4 classes has 3 internal nodes
        assert all(n["vectors"] >= 1 for n in m["nodes"])
    assert res["split"]["test_runs"] == {s: 6 for s in ["fn", "f1", "f2", "f3"]}
    block = res["all_states"]
    assert block["groups"] == [["fn", "f4"], ["f1"], ["f2"], ["f3"]]
    for method in ("rvm", "svm"):
        m = block[method]
        assert m["separable_states"] == ["f1", "f2", "f3"]
        assert m["separable_accuracy"] == 1.0
        assert m["group_accuracy"] == 1.0
        assert m["group_mass"] > 0.8  # chance (uniform over 5 states) would be 0.2 to 0.4
        # fn and f4 cannot be told apart: together they are right about half the time
        both = (m["per_class"]["fn"] + m["per_class"]["f4"]) / 2
        assert 0.2 <= both <= 0.8
    assert art["features"].shape == (24, 2)
    # the features are the mean residuals: close to the offsets by construction
    f1 = art["features"][art["labels"] == "f1"].mean(axis=0)
    assert f1 == pytest.approx([0.08, 0.0], abs=0.01)


def test_pairwise_separability_matches_sklearn_loo(rng):
    from sklearn.model_selection import LeaveOneOut, cross_val_predict
    from sklearn.neighbors import KNeighborsClassifier

    X = np.vstack([rng.normal(0, 1, (25, 2)), rng.normal(0.8, 1, (25, 2))])
    y = np.array(["a"] * 25 + ["b"] * 25)
    _, err = pairwise_separability(X, y, n_neighbors=5)
    Z = (X - X.mean(axis=0)) / X.std(axis=0)
    pred = cross_val_predict(KNeighborsClassifier(n_neighbors=5), Z, y, cv=LeaveOneOut())
    expected = 0.5 * (np.mean(pred[y == "a"] != "a") + np.mean(pred[y == "b"] != "b"))
    assert err[0, 1] == pytest.approx(expected)
    assert 0 < expected < 0.5


def test_paired_comparison_by_hand():
    from scipy.stats import binom

    from bayes_fdi.paper.scores import paired_comparison

    y = ["a"] * 10
    a = ["a"] * 7 + ["b"] * 3  # right on runs 0-6
    b = ["b"] * 2 + ["a"] * 6 + ["b"] * 2  # right on runs 2-7
    out = paired_comparison(y, a, b)
    assert (out["a_only"], out["b_only"], out["both"], out["neither"]) == (2, 1, 5, 2)
    # two-sided exact binomial: P(X <= 1) + P(X >= 2) for X ~ Bin(3, 1/2) = 1
    assert out["p_value"] == pytest.approx(1.0)
    y = ["a"] * 12
    a = ["a"] * 12
    b = ["b"] * 10 + ["a"] * 2
    out = paired_comparison(y, a, b)
    assert (out["a_only"], out["b_only"]) == (10, 0)
    assert out["p_value"] == pytest.approx(2 * binom.pmf(10, 10, 0.5))
    assert paired_comparison(["a"], ["a"], ["a"])["p_value"] == 1.0

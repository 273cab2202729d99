"""Which part of a commissioned valve's tree of RVCs limits its isolation: the tree or its nodes.

    OMP_NUM_THREADS=1 PYTHONPATH=. python benchmarks/isolation_nodes.py [--plants 5,6] \
        [--commission-seed 0] [--json PATH]

Each perturbed plant (by default the commissioning benchmark's selection plants 5 and 6, which its
evaluation never scores) is commissioned on its healthy hour as `bayes_fdi.commissioning.commission`
does by default (the k-means tree of RVCs). The rows its classifier was trained on are rebuilt from
the same training library (checked: a tree refitted on them gives the commissioned tree's
probabilities), and two held-out sets are transplanted that no fitting step sees: a fourth library
into the commissioning hour (seed ``10 seed + 7``, 12 runs per fault) and a library into a healthy
half hour the plant ran later (seed ``10 seed + 8``, 6 runs per fault); every detected faulty second
at least `~bayes_fdi.diagnosis.online.training.GROUP_MIN_AGE` s after its detection is scored, as
the isolability groups are found.

Printed per plant:

- the spread of the training rows' features (1st, 25th, 75th and 99th percentiles);
- **every node of the tree**: its two sides, its training rows and relevance vectors, and the
  balanced accuracy (the mean over the node's classes of the share of a class's rows sent to its
  side) of the node's RVC on its training rows and on the held-out library's rows of its classes,
  beside a random forest (scikit-learn's, 300 trees) fitted on the same node's rows;
- **whole classifiers** on both held-out sets: the tree as commissioned, the same k-means tree
  with a random forest at every node (probabilities still multiplied along the paths), and the
  flat forest of ``commission(..., isolation="forest")``; the mean over the faults of the share of
  their rows named by their fault and by their group (the commissioned groups for all three), and
  the share of rows named a wrong group at p > 0.9 (the classifiers' own probabilities, before the
  calibration's temperature).

About 2-3 CPU min per plant.
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

import numpy as np

#: Trees of the random forests fitted per node and at every node of the tree of forests.
FOREST_TREES = 300
#: Runs per fault of the held-out library transplanted into the later half hour.
NEW_RUNS_PER_FAULT = 6


def node_balanced_accuracy(p_right: np.ndarray, y: np.ndarray, left, right) -> float:
    """Mean over the node's classes (those of ``left`` and ``right`` present in ``y``) of the
    share of a class's rows sent to its side (``p_right > 0.5``: right)."""
    shares = []
    for c in (*left, *right):
        rows = y == c
        if rows.any():
            shares.append(float(np.mean((p_right[rows] > 0.5) == (c in right))))
    return float(np.mean(shares))


def classifier_scores(proba: np.ndarray, classes, y: np.ndarray, groups) -> dict[str, float]:
    """Mean over the faults in ``y`` of the share of their rows named by their fault and by
    their group, and the share of all rows named a wrong group at p > 0.9 (group
    probabilities: the fault probabilities summed within each group of ``groups``)."""
    classes = [str(c) for c in classes]
    group_of = {c: g for g, members in enumerate(groups) for c in members}
    G = np.zeros((len(classes), len(groups)))
    for j, c in enumerate(classes):
        G[j, group_of[c]] = 1.0
    pg = proba @ G
    named = np.asarray(classes)[proba.argmax(axis=1)]
    truth = np.array([group_of[c] for c in y])
    named_group = pg.argmax(axis=1)
    faults = [c for c in classes if (y == c).any()]
    return {
        "fault": float(np.mean([np.mean(named[y == c] == c) for c in faults])),
        "group": float(np.mean([np.mean(named_group[y == c] == truth[y == c]) for c in faults])),
        "confident_wrong": float(np.mean((pg.max(axis=1) > 0.9) & (named_group != truth))),
    }


def _signatures(result, plant, healthy, seed: int) -> dict[str, Any]:
    """Training rows as the commissioning fit kept them and the two held-out sets."""
    from bayes_fdi.benchmark.plant_runs import HELDOUT_SECONDS
    from bayes_fdi.benchmark.plants import healthy_run
    from bayes_fdi.commissioning import LIBRARY_FAULTS
    from bayes_fdi.commissioning.healthy import check_healthy
    from bayes_fdi.diagnosis.online.training import (
        GROUP_MIN_AGE,
        detection_components,
        stack_runs,
        training_rows,
        training_signatures,
    )
    from bayes_fdi.twin import transplant_library

    diagnoser, twin = result.diagnoser, result.twin
    report = result.report["library"]
    components = detection_components(diagnoser)
    known = [f for f in diagnoser.detection_rates_ if f not in set(diagnoser.undetectable_)]

    def library(data, library_seed: int, runs: int):
        return transplant_library(
            data, twin, faults=LIBRARY_FAULTS, runs_per_fault=runs,
            duration=report["duration"], seed=library_seed,
        )  # fmt: skip

    runs = check_healthy(stack_runs(healthy))
    X, y, _, _ = training_signatures(components, library(runs, report["seeds"][0], 12))
    keep = training_rows(y, known, diagnoser.max_signatures_per_fault, diagnoser.random_state)
    out = {"train": (X[keep], y[keep])}
    later = check_healthy(stack_runs(healthy_run(plant, HELDOUT_SECONDS, heldout=True)))
    for name, data, library_seed, n in (
        ("library", runs, 10 * seed + 7, 12),
        ("later", later, 10 * seed + 8, NEW_RUNS_PER_FAULT),
    ):
        transplants = library(data, library_seed, n)
        Xh, yh, ages, _ = training_signatures(components, transplants, per_second=True)
        rows = np.isin(yh, known) & (ages >= GROUP_MIN_AGE)
        out[name] = (Xh[rows], yh[rows])
    return out


def feature_spread(X: np.ndarray) -> dict[str, list[float]]:
    """The 1st, 25th, 75th and 99th percentiles of each isolation feature over the rows ``X``."""
    from bayes_fdi.diagnosis.isolation.signatures import ISOLATION_FEATURES

    q = np.percentile(X, [1, 25, 75, 99], axis=0)
    return {name: q[:, j].tolist() for j, name in enumerate(ISOLATION_FEATURES)}


def node_rows(tree, train, heldout) -> list[dict[str, Any]]:
    """One row per node of the fitted tree of RVCs ``tree``: its sides, rows, relevance vectors
    and balanced accuracies (its RVC on the training and the held-out rows, a forest on the
    held-out rows)."""
    from sklearn.ensemble import RandomForestClassifier

    X, y = train
    Xh, yh = heldout
    rows = []
    for node in tree.nodes_:
        classes = [*node.left, *node.right]
        fit, test = np.isin(y, classes), np.isin(yh, classes)

        def scaled(Z, node=node):
            return Z if node.scaler is None else node.scaler.transform(Z)

        def rvc(Z, node=node):
            return node.estimator.predict_proba(scaled(Z))[:, 1]

        side = np.isin(y[fit], list(node.right)).astype(int)
        forest = RandomForestClassifier(FOREST_TREES, random_state=0).fit(X[fit], side)
        accuracy = {
            "rvc_train": node_balanced_accuracy(rvc(X[fit]), y[fit], node.left, node.right),
            "rvc_heldout": node_balanced_accuracy(rvc(Xh[test]), yh[test], node.left, node.right),
            "forest_heldout": node_balanced_accuracy(
                forest.predict_proba(Xh[test])[:, 1], yh[test], node.left, node.right
            ),
        }
        rows.append(
            {
                "node": node.index,
                "left": list(node.left),
                "right": list(node.right),
                "rows": int(node.n_samples),
                "relevance_vectors": node.n_vectors,
                **accuracy,
            }
        )
    return rows


def whole_classifiers(
    tree, tree_cpu: float, train, heldout_sets, groups, seed: int
) -> dict[str, Any]:
    """The commissioned tree (``tree_cpu``: the CPU seconds of its fit on ``train``), the tree
    with a forest at every node and the flat forest, scored on each held-out set
    (`classifier_scores`), with their fit's CPU seconds."""
    from sklearn.base import clone
    from sklearn.ensemble import RandomForestClassifier

    from bayes_fdi.diagnosis.isolation import ForestClassifier

    models = {"tree of RVCs (commissioned)": (tree, tree_cpu)}
    for name, model in (
        ("tree of forests", clone(tree).set_params(
            base_estimator=RandomForestClassifier(FOREST_TREES, random_state=0))),
        ("forest", ForestClassifier(random_state=seed)),
    ):  # fmt: skip
        c0 = time.process_time()
        models[name] = (model.fit(*train), time.process_time() - c0)
    return {
        name: {
            "fit_cpu_s": cpu,
            **{
                key: classifier_scores(model.predict_proba(Xh), model.classes_, yh, groups)
                for key, (Xh, yh) in heldout_sets.items()
            },
        }
        for name, (model, cpu) in models.items()
    }


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plants", default="5,6", help="plant indices, comma-separated")
    parser.add_argument("--commission-seed", type=int, default=0)
    parser.add_argument("--json", default=None, help="write the figures here")
    args = parser.parse_args(argv)

    from sklearn.base import clone

    from bayes_fdi.benchmark.plants import draw_plant, healthy_run
    from bayes_fdi.commissioning import commission

    seed, results = args.commission_seed, {}
    for index in (int(p) for p in args.plants.split(",")):
        plant = draw_plant(index)
        healthy = healthy_run(plant, 3600)
        c0 = time.process_time()
        result = commission(healthy, seed=seed, progress=False)
        sets = _signatures(result, plant, healthy, seed)
        tree = result.diagnoser.isolator_.classifier_
        c1 = time.process_time()
        refit = clone(tree).fit(*sets["train"])
        tree_cpu = time.process_time() - c1
        X_train = sets["train"][0]
        if not np.array_equal(refit.predict_proba(X_train), tree.predict_proba(X_train)):
            raise RuntimeError("the rebuilt training rows are not the commissioned tree's")
        groups = [tuple(g) for g in result.diagnoser.groups_]
        nodes = node_rows(tree, sets["train"], sets["library"])
        held = {k: sets[k] for k in ("library", "later")}
        whole = whole_classifiers(tree, tree_cpu, sets["train"], held, groups, seed)
        print(
            f"plant {index} (commissioning seed {seed}; {time.process_time() - c0:.0f} CPU s): "
            f"{len(tree.classes_)} classified faults, groups "
            f"{' · '.join('|'.join(g) for g in groups)}; "
            f"held-out rows {len(sets['library'][1])} (library), {len(sets['later'][1])} (later)",
            flush=True,
        )
        spread = feature_spread(X_train)
        print(
            "  training rows, features' 1st, 25th, 75th, 99th percentiles: "
            + "; ".join(f"{k} " + " ".join(f"{v:.3g}" for v in q) for k, q in spread.items())
        )
        print("  node  rows  RVs  RVC train  RVC held-out  forest held-out  sides")
        for r in nodes:
            print(
                f"  {r['node']:4d} {r['rows']:5d} {r['relevance_vectors']!s:>4}"
                f"  {r['rvc_train']:9.3f}"
                f"  {r['rvc_heldout']:12.3f}  {r['forest_heldout']:15.3f}  "
                f"{'|'.join(r['left'])} vs {'|'.join(r['right'])}"
            )
        for name, scores in whole.items():
            parts = [
                f"{key}: fault {s['fault']:.3f}, group {s['group']:.3f}, "
                f"confident wrong {100 * s['confident_wrong']:.2f} %"
                for key, s in scores.items()
                if key != "fit_cpu_s"
            ]
            print(f"  {name:28s} fit {scores['fit_cpu_s']:5.1f} CPU s; " + "; ".join(parts))
        results[index] = {
            "nodes": nodes, "classifiers": whole, "groups": groups, "feature_spread": spread
        }  # fmt: skip
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump({"commission_seed": seed, "plants": results}, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

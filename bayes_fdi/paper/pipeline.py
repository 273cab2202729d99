"""The paper's protocol on one dataset (`evaluate_dataset`): normal models, features, two trees.

Fits the RVM pipeline (`bayes_fdi.diagnosis.FaultDiagnoser`) on the training runs, scores it and
the SVM baseline (the same tree of SVMs on the same features) on the test runs, and, beyond the
paper, measures which of all twenty states the two features can separate.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np
import xarray as xr

from bayes_fdi.campaigns.cache import split_train_test
from bayes_fdi.diagnosis.isolation.tree import n_vectors
from bayes_fdi.paper.report_tables import tree_text
from bayes_fdi.paper.scores import classification_metrics, paired_comparison
from bayes_fdi.paper.separability import (
    PAPER_GROUPS,
    SEPARABILITY_NEIGHBOURS,
    SEPARABILITY_THRESHOLD,
    find_groups,
    group_metrics,
    pairwise_separability,
)
from bayes_fdi.paper.setup import (
    ALL_STATES,
    N_TRAIN,
    PAPER_STATES,
    fit_tree,
    select_regression_width,
    single_threaded,
    tree_classifier,
    tree_nodes,
)

__all__ = [
    "evaluate_dataset",
]


def _state_key(state: str) -> tuple[int, int]:
    """Sort key of the paper's tables: f1, f2, ..., f19, then fn."""
    return (1, 0) if state == "fn" else (0, int(state[1:]))


def _method_result(
    clf: Any, y_test: np.ndarray, proba: np.ndarray, fit_s: float, predict_s: float, prefix: str
) -> dict[str, Any]:
    fitted = [str(c) for c in clf.classes_]
    classes = sorted(fitted, key=_state_key)
    proba = proba[:, [fitted.index(c) for c in classes]]
    out = classification_metrics(y_test, proba, classes)
    out["nodes"] = tree_nodes(clf, prefix)
    out["tree"] = tree_text(out["nodes"], prefix=prefix)
    out["fit_seconds"] = float(fit_s)
    out["predict_seconds"] = float(predict_s)
    return out


def _strength_ranges(ds: xr.Dataset) -> dict[str, dict[str, Any]]:
    labels = np.asarray(ds["state"].values).astype(str)
    strength = np.asarray(ds["strength"].values, dtype=np.float64)
    profile = np.asarray(ds["profile"].values).astype(str)
    out = {}
    for s in dict.fromkeys(labels):
        m = labels == s
        out[s] = {
            "runs": int(m.sum()),
            "min": float(strength[m].min()),
            "max": float(strength[m].max()),
            "profiles": sorted(set(profile[m])),
        }
    return out


def _residual_examples(
    res: xr.Dataset, labels: np.ndarray, states: Sequence[str]
) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """First test run of each of ``states`` (present ones): (time, r1, r2)."""
    t = np.asarray(res["time"].values, dtype=np.float64)
    out = {}
    for s in states:
        idx = np.flatnonzero(labels == s)
        if idx.size:
            i = int(idx[0])
            out[s] = (t, res["r1"].values[i].copy(), res["r2"].values[i].copy())
    return out


def evaluate_dataset(
    ds: xr.Dataset,
    *,
    states: Sequence[str] = PAPER_STATES,
    n_train: int = N_TRAIN,
    seed: int = 0,
    all_states: bool = True,
    progress: Callable[[str], None] | None = None,
    diagnoser: Any = None,
    input_lags: Sequence[float] = (),
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The paper's protocol (and the 20-state extension) on one dataset.

    Parameters
    ----------
    ds
        Labelled runs of the states (each with more than ``n_train`` runs).
    states
        States of the paper protocol (must include ``"fn"``).
    n_train
        Training runs per state (first in run order); the rest test.
    seed
        Seed of the models (tree design, subsampling, SVM Platt scaling).
    all_states
        Also run the pipeline on every state present (see :func:`pairwise_separability`).
    progress
        Callable receiving stage messages.
    diagnoser
        Unfitted :class:`~bayes_fdi.diagnosis.FaultDiagnoser` for the RVM method. Default: RVR
        normal models with the width of :func:`select_regression_width` and a k-means tree
        (``node_scaling=True``) of :func:`node_classifier` ``("rvm")`` nodes — the
        diagnoser's default tree. The SVM baseline is the same tree of ``("svm")`` nodes on the
        RVM pipeline's features.
    input_lags
        Lags (s) of extra normal-model inputs ``CV(t - L)`` of the default diagnoser (dynamic
        normal models, beyond the paper; see
        :class:`bayes_fdi.diagnosis.normal_models.static.NormalModels`).
        Default ``()``: the paper's static inputs.

    Returns
    -------
    results : dict
        JSON-ready: ``rvm`` and ``svm`` metrics (:func:`classification_metrics` plus ``nodes``,
        ``tree``, ``fit_seconds``, ``predict_seconds``), ``split``, ``strength``, ``timing``
        and, with ``all_states``, ``all_states`` (pairwise separability, groups, per-state and
        group scores of both methods).
    artifacts : dict
        Arrays for the figures: ``features``/``labels`` of the paper states' test runs,
        ``residuals`` examples (time, r1, r2 of the first test run of fn, f1, f2, f15),
        ``rvm_predict`` (features -> labels), ``train_features`` and ``train_labels``
        (training runs of every state), ``diagnoser`` (the fitted RVM
        :class:`~bayes_fdi.diagnosis.FaultDiagnoser`) and ``test_runs`` (the paper states'
        test runs).

    Notes
    -----
    Torch and BLAS run on one thread here (:func:`single_threaded`), so the same seed gives
    the same numbers on any machine.
    """
    with single_threaded():
        return _evaluate_dataset(
            ds,
            states=states,
            n_train=n_train,
            seed=seed,
            all_states=all_states,
            progress=progress,
            diagnoser=diagnoser,
            input_lags=input_lags,
        )


class _Split(NamedTuple):
    """The runs of one dataset, split by :func:`split_train_test`, and their labels."""

    train: xr.Dataset
    test: xr.Dataset
    y_train: np.ndarray  #: state of every training run (all states evaluated)
    y_test: np.ndarray  #: state of every test run
    in_paper_train: np.ndarray  #: training runs of the paper states
    in_paper_test: np.ndarray  #: test runs of the paper states
    normal: xr.Dataset  #: the fault-free training runs (the normal models' data)


def _split(ds: xr.Dataset, states: list[str], every: list[str], n_train: int) -> _Split:
    train, test = split_train_test(ds, n_train=n_train, states=every)
    y_train = np.asarray(train["state"].values).astype(str)
    y_test = np.asarray(test["state"].values).astype(str)
    return _Split(
        train=train,
        test=test,
        y_train=y_train,
        y_test=y_test,
        in_paper_train=np.isin(y_train, states),
        in_paper_test=np.isin(y_test, states),
        normal=train.isel(run=np.flatnonzero(y_train == "fn")),
    )


def _default_diagnoser(
    normal: xr.Dataset,
    *,
    seed: int,
    input_lags: Sequence[float],
    timing: dict[str, float],
    say: Callable[[str], None],
) -> tuple[Any, dict[str, Any]]:
    """The default RVM diagnoser at the width of largest evidence, and that width's record."""
    from bayes_fdi.diagnosis import FaultDiagnoser
    from bayes_fdi.rvm import RVR

    say("normal-model kernel width by maximum evidence")
    t0 = time.perf_counter()
    width, evidence = select_regression_width(normal, seed=seed, input_lags=input_lags)
    timing["regression_width"] = time.perf_counter() - t0
    diagnoser = FaultDiagnoser(
        regressor=RVR(kernel="rbf", width=width),
        classifier=tree_classifier("rvm", seed),
        random_state=seed,
        input_lags=tuple(input_lags),
    )
    return diagnoser, {"width": width, "log_evidence": evidence}


def _features(
    diag: Any, split: _Split, extra_states: bool, timing: dict[str, float]
) -> tuple[xr.Dataset, np.ndarray, np.ndarray]:
    """Test residuals, test features and the training features of every state evaluated.

    The paper states' training features are the diagnoser's own; with ``extra_states`` the
    other states' training runs get theirs from the fitted normal models.
    """
    from bayes_fdi.diagnosis.isolation.features import extract_features

    t0 = time.perf_counter()
    res_test = diag.normal_models_.residuals(split.test)
    feats_test, _ = extract_features(res_test, diag.feature_names_)
    timing["test_residuals"] = time.perf_counter() - t0
    if extra_states:
        t0 = time.perf_counter()
        extra = split.train.isel(run=np.flatnonzero(~split.in_paper_train))
        feats_extra, _ = extract_features(diag.normal_models_.residuals(extra), diag.feature_names_)
        timing["extra_train_residuals"] = time.perf_counter() - t0
        feats_train_all = np.empty((split.train.sizes["run"], feats_extra.shape[1]))
        feats_train_all[split.in_paper_train] = diag.training_features_
        feats_train_all[~split.in_paper_train] = feats_extra
    else:
        feats_train_all = diag.training_features_
    for name, F in (("training", feats_train_all), ("test", feats_test)):
        if not np.isfinite(F).all():
            raise ValueError(f"non-finite residual features in the {name} runs")
    return res_test, feats_test, feats_train_all


def _paper_methods(
    diag: Any, X_te: np.ndarray, y_te: np.ndarray, seed: int, say: Callable[[str], None]
) -> dict[str, Any]:
    """The RVM tree (fitted in ``diag``) and the SVM tree on the paper states' features."""
    X_tr, y_tr = diag.training_features_, np.asarray(diag.training_labels_).astype(str)
    say(f"RVM tree on {X_tr.shape[0]} training runs: predicting {X_te.shape[0]} test runs")
    t0 = time.perf_counter()
    proba = diag.predict_features(X_te)
    rvm_predict_s = time.perf_counter() - t0
    results: dict[str, Any] = {
        "rvm": _method_result(
            diag.classifier_, y_te, proba, diag.fit_seconds_["classifier"], rvm_predict_s, "RVM"
        )
    }
    say("SVM tree on the same features")
    svm, _, proba_svm, fit_s, pred_s = fit_tree(
        lambda: tree_classifier("svm", seed), X_tr, y_tr, X_te
    )
    results["svm"] = _method_result(svm, y_te, proba_svm, fit_s, pred_s, "SVM")
    results["paired"] = paired_comparison(
        y_te,
        np.asarray(diag.classes_).astype(str)[np.argmax(proba, axis=1)],
        np.asarray(svm.classes_).astype(str)[np.argmax(proba_svm, axis=1)],
    )
    return results


def _normal_models_record(diag: Any, regression: dict[str, Any]) -> dict[str, Any]:
    """Width, input lags, relevance vectors and noise level of the fitted normal models."""
    regressors = diag.normal_models_.regressors_
    return {
        **regression,
        "input_lags": [float(v) for v in diag.normal_models_.input_lags_],
        "relevance_vectors": {k: n_vectors(r) for k, r in regressors.items()},
        "noise_std": {
            k: float(r.beta_**-0.5) for k, r in regressors.items() if getattr(r, "beta_", None)
        },
    }


def _all_states_block(
    split: _Split,
    every: list[str],
    extra_states: bool,
    feats_train_all: np.ndarray,
    feats_test: np.ndarray,
    seed: int,
    timing: dict[str, float],
    say: Callable[[str], None],
) -> dict[str, Any]:
    """Beyond the paper: pairwise separability and groups of every state evaluated and, when
    there are more states than the paper's, both trees on all of them."""
    say(f"pairwise separability of {len(every)} states on their training features")
    t0 = time.perf_counter()
    sep_states, error = pairwise_separability(feats_train_all, split.y_train, states=every)
    groups = find_groups(sep_states, error)
    timing["separability"] = time.perf_counter() - t0
    block: dict[str, Any] = {
        "states": sep_states,
        "pairwise_error": error,
        "threshold": SEPARABILITY_THRESHOLD,
        "n_neighbors": SEPARABILITY_NEIGHBOURS,
        "groups": groups,
        "paper_groups": [list(g) for g in PAPER_GROUPS],
    }
    if extra_states:
        say(f"RVM and SVM trees on all {len(every)} states")
        for method, prefix in (("rvm", "RVM"), ("svm", "SVM")):
            clf, _, p, fit_s, pred_s = fit_tree(
                lambda kind=method: tree_classifier(kind, seed),
                feats_train_all,
                split.y_train,
                feats_test,
            )
            m = _method_result(clf, split.y_test, p, fit_s, pred_s, prefix)
            m.update(group_metrics(split.y_test, p, [str(c) for c in clf.classes_], groups))
            block[method] = m
    return block


def _evaluate_dataset(
    ds: xr.Dataset,
    *,
    states: Sequence[str],
    n_train: int,
    seed: int,
    all_states: bool,
    progress: Callable[[str], None] | None,
    diagnoser: Any,
    input_lags: Sequence[float],
) -> tuple[dict[str, Any], dict[str, Any]]:
    say = progress or (lambda _msg: None)
    states = [str(s) for s in states]
    if "fn" not in states:
        raise ValueError("the paper protocol needs the fault-free state 'fn' among the states")
    present = list(dict.fromkeys(np.asarray(ds["state"].values).astype(str)))
    every = [s for s in ALL_STATES if s in present] if all_states else states
    extra_states = all_states and len(every) > len(states)
    split = _split(ds, states, every, n_train)
    timing: dict[str, float] = {}
    if diagnoser is None:
        diagnoser, regression = _default_diagnoser(
            split.normal, seed=seed, input_lags=input_lags, timing=timing, say=say
        )
    elif len(input_lags):
        raise ValueError("give input_lags to the diagnoser itself when passing a diagnoser")
    else:
        regression = {}
    say(f"fitting the RVM pipeline (normal models on {split.normal.sizes['run']} fault-free runs)")
    diag = diagnoser.fit(split.normal, split.train.isel(run=np.flatnonzero(split.in_paper_train)))
    timing.update({f"rvm_fit_{k}": float(v) for k, v in diag.fit_seconds_.items()})

    say(f"residuals and features of {split.test.sizes['run']} test runs")
    res_test, feats_test, feats_train_all = _features(diag, split, extra_states, timing)
    X_te, y_te = feats_test[split.in_paper_test], split.y_test[split.in_paper_test]
    y_tr = np.asarray(diag.training_labels_).astype(str)
    results = _paper_methods(diag, X_te, y_te, seed, say)
    results["split"] = {
        "n_train_per_state": int(n_train),
        "train_runs": {s: int((y_tr == s).sum()) for s in states},
        "test_runs": {s: int((y_te == s).sum()) for s in states},
        "normal_model_runs": int(split.normal.sizes["run"]),
        "normal_model_samples": int(diag.normal_models_.n_train_samples_),
    }
    results["normal_models"] = _normal_models_record(diag, regression)
    results["strength"] = _strength_ranges(ds)
    results["features"] = list(diag.feature_names_)
    artifacts: dict[str, Any] = {
        "features": X_te,
        "labels": y_te,
        "rvm_predict": lambda F: diag.classes_[np.argmax(diag.predict_features(F), axis=1)],
        "residuals": _residual_examples(res_test, split.y_test, ("fn", "f1", "f2", "f15")),
        "train_features": feats_train_all,
        "train_labels": split.y_train,
        "diagnoser": diag,
        "test_runs": split.test.isel(run=np.flatnonzero(split.in_paper_test)),
    }
    if all_states:
        results["all_states"] = _all_states_block(
            split, every, extra_states, feats_train_all, feats_test, seed, timing, say
        )
    results["timing"] = timing
    return results, artifacts

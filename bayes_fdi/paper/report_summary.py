"""The opening of the reproduction's report: a plain-language summary, a glossary, fault codes.

`summary_section` says in a few sentences, from the results alone, what was run and what came
out (identification ratios against the paper's, the paired comparison, the states read as
others most often, how many misread runs fall inside the groups no classifier can split, the
dynamic normal models); `glossary_section` defines every index
the report prints; `fault_codes_section` names every state code the rest of the report uses
(found in its text, so none is left out).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

import numpy as np

from bayes_fdi.diagnosis.seva import describe_state
from bayes_fdi.paper.report_tables import PAPER_ACCURACY
from bayes_fdi.reporting import format_percent

__all__ = ["GLOSSARY", "fault_codes_section", "glossary_section", "summary_section"]

#: A state code as the report writes it: a fault (f1 .. f19) or the fault-free state (fn).
_STATE_CODE = re.compile(r"\b(fn|f\d{1,2})\b")

#: The indices and words of the report, in plain words.
GLOSSARY: dict[str, str] = {
    "identification ratio": "the share of test runs whose state the classifier names right "
    "(the paper's accuracy); per state, the share of that state's test runs named right",
    "log loss": "the mean over test runs of -ln(probability given to the true state); 0 is "
    "perfect, lower is better",
    "Brier score": "the mean over runs of the squared distance between the probability vector "
    "and the one-hot truth (0 best, 2 worst)",
    "ECE": "top-label expected calibration error: how far the confidence of the named state is "
    "from its observed frequency of being right (15 equal-width bins; 0 is calibrated)",
    "McNemar p": "the exact test of two classifiers on the same test runs, counting the runs "
    "only one of them names right; a large p means no evidence that one is better",
    "RVM / SVM tree": "the paper's k-means designed binary tree of classifiers, each node a "
    "relevance vector machine (probabilistic) or a support vector machine (Platt-scaled)",
    "relevance / support vectors": "the training points an RVM / SVM node keeps; fewer means "
    "a sparser, faster model",
    "separable states, groups": "states the two mean-residual features can tell apart; a group "
    "is a set of states whose training features overlap so much that no classifier can split "
    "them (pairwise k-nearest-neighbour error above a threshold)",
    "pairwise k-NN error": "how often a k-nearest-neighbour rule trained on the training "
    "features of just two states misreads them, balanced (0 = always told apart, about "
    "0.5 = chance)",
    "group level, P(true group)": "accuracy counting a run as right when the state named is in "
    "its true state's group; the mean probability the classifier puts on that group",
    "noise floor": "the ECE a perfectly calibrated model would show with these bins and this "
    "many runs; an ECE below it cannot be resolved",
    "recalibration": "a map of the probabilities (e.g. temperature scaling) fitted on held-out "
    "folds of the test runs to lower the log loss",
    "coverage": "the share of fault-free samples inside the normal models' central predictive "
    "interval (95 % when calibrated)",
    "fault strength": "the size of a fault, 0 (none) to 1 (largest), as the simulator sets it",
    "normal models": "the RVM regressions of the stem position X and the flow F of the "
    "fault-free actuator; their residuals are the features; dynamic ones also see the "
    "command lagged by a few seconds",
}


def summary_section(results: Mapping[str, Any]) -> list[str]:
    """ "In short": the headline figures of each dataset, from ``results``."""
    lines = ["## In short", ""]
    if results.get("small"):
        runs = max(int(np.asarray(d["rvm"]["confusion"]["matrix"]).sum()) for d in _values(results))
        lines += [
            "Small campaigns (a quick check, not the paper's sizes): one test run is "
            f"{format_percent(1 / runs)} of a ratio or more.",
            "",
        ]
    for name, d in results["datasets"].items():
        lines.append(f"- **{name}**: " + " ".join(_dataset_sentences(name, d)))
    lines += [
        "",
        "The sections below give every table of the paper, what limits the ratios (the states "
        "whose mean residuals overlap), the calibration of the probabilities and the "
        "dynamic normal models beyond the paper.",
        "",
    ]
    return lines


def _dataset_sentences(name: str, d: Mapping[str, Any]) -> list[str]:
    """The sentences of one dataset's bullet: ratios, paired test, what limits them, the
    dynamic normal models."""
    paper = PAPER_ACCURACY.get(name, {})
    rvm, svm = d["rvm"], d["svm"]
    runs = int(np.asarray(rvm["confusion"]["matrix"]).sum())
    sentences = [
        f"of {runs} test runs, the RVM tree names the state of {format_percent(rvm['accuracy'])} "
        f"right{_against(paper.get('rvm'))}, the SVM tree {format_percent(svm['accuracy'])}"
        f"{_against(paper.get('svm'))}."
    ]
    pair = d.get("paired")
    if pair:
        differ = pair["a_only"] + pair["b_only"]
        same = "The two name the same runs right"
        sentences.append(
            (f"The two differ on {differ} of the same runs" if differ else same)
            + f" (McNemar p = {pair['p_value']:.2g})."
        )
    sentences.append(_limit_sentence(rvm, d.get("all_states")))
    dynamic = d.get("dynamic")
    if dynamic:
        sentences.append(
            "With dynamic normal models (the command lagged) the RVM tree names "
            f"{format_percent(dynamic['rvm']['accuracy'])}, the SVM tree "
            f"{format_percent(dynamic['svm']['accuracy'])}."
        )
    return sentences


def _values(results: Mapping[str, Any]) -> list[Mapping[str, Any]]:
    return list(results["datasets"].values())


def _against(paper: float | None) -> str:
    return f" (the paper: {format_percent(paper)})" if paper is not None else ""


def _limit_sentence(method: Mapping[str, Any], all_states: Mapping[str, Any] | None) -> str:
    """What limits the RVM's ratio, as measured: its most frequent confusion, and how many of
    its misread runs went to a state in the same group (states no classifier can split)."""
    worst = _most_confused(method)
    if not worst:
        return "The RVM tree names every test run right."
    groups = [g for g in (all_states or {}).get("groups", []) if len(g) > 1]
    if all_states is None or not groups:
        return f"The RVM's most frequent confusion: {worst}."
    group_of = {s: i for i, g in enumerate(groups) for s in g}
    classes = method["confusion"]["classes"]
    matrix = np.asarray(method["confusion"]["matrix"], dtype=int)
    wrong = inside = 0
    for i, true in enumerate(classes):
        for j, named in enumerate(classes):
            if i != j:
                wrong += int(matrix[i, j])
                same = true in group_of and group_of[true] == group_of.get(named)
                inside += int(matrix[i, j]) if same else 0
    return (
        f"What limits it: {inside} of the RVM's {wrong} misread runs went to a state of their "
        "own group, states whose mean residuals overlap so that no classifier can split them "
        f"(over all {len(all_states['states'])} states: "
        + ", ".join("|".join(g) for g in groups)
        + f"); its most frequent confusion: {worst}."
    )


def _most_confused(method: Mapping[str, Any]) -> str:
    """The largest off-diagonal count of the confusion, in words ("f17 read as f2 in 30 of
    170 runs"); empty when there is none."""
    classes = method["confusion"]["classes"]
    matrix = np.asarray(method["confusion"]["matrix"], dtype=float)
    off = matrix.copy()
    np.fill_diagonal(off, 0.0)
    if not off.size or off.max() <= 0:
        return ""
    i, j = np.unravel_index(int(np.argmax(off)), off.shape)
    return f"{classes[i]} read as {classes[j]} in {int(off[i, j])} of {int(matrix[i].sum())} runs"


def glossary_section() -> list[str]:
    """The glossary of the report's indices."""
    return ["## Glossary", "", *(f"- **{k}**: {v}" for k, v in GLOSSARY.items()), ""]


def fault_codes_section(text: str) -> list[str]:
    """Every state code ``text`` (the rest of the report) uses, with what it means."""
    codes = set(_STATE_CODE.findall(text))
    order = sorted(codes, key=lambda c: (c != "fn", int(c[1:]) if c[1:].isdigit() else 99, c))
    named = [f"- {'fn fault-free' if c == 'fn' else describe_state(c)}" for c in order]
    return ["## State codes", "", *named, ""]

"""The opening of the reproduction's report: a plain-language summary, a glossary, fault codes.

`summary_section` says in a few sentences, from the results alone, what was run and what came
out (identification ratios against the paper's, the paired comparison, the states read as
others most often, the groups no classifier can split); `glossary_section` defines every index
the report prints; `fault_codes_section` names every state code the report uses.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from bayes_fdi.diagnosis.seva import describe_state
from bayes_fdi.paper.report_tables import PAPER_ACCURACY
from bayes_fdi.reporting import format_percent

__all__ = ["GLOSSARY", "fault_codes_section", "glossary_section", "summary_section"]

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
    "relevance / support vectors": "the training points an RVM / SVM node keeps; fewer means "
    "a sparser, faster model",
    "separable states, groups": "states the two mean-residual features can tell apart; a group "
    "is a set of states whose training features overlap so much that no classifier can split "
    "them (pairwise k-nearest-neighbour error above a threshold)",
    "normal models": "the RVM regressions of the stem position X and the flow F of the "
    "fault-free actuator; their residuals are the features",
}


def summary_section(results: Mapping[str, Any]) -> list[str]:
    """ "In short": the headline figures of each dataset, from ``results``."""
    lines = ["## In short", ""]
    for name, d in results["datasets"].items():
        rvm, svm = d["rvm"]["accuracy"], d["svm"]["accuracy"]
        paper = PAPER_ACCURACY.get(name, {}).get("rvm")
        against = f" (the paper: {format_percent(paper)})" if paper is not None else ""
        sentence = (
            f"- **{name}**: the RVM tree names the state of {format_percent(rvm)} of the test "
            f"runs{against}, the SVM tree {format_percent(svm)}."
        )
        pair = d.get("paired")
        if pair:
            sentence += (
                f" On the same runs the two differ on {pair['a_only'] + pair['b_only']} runs "
                f"(McNemar p = {pair['p_value']:.2g})."
            )
        worst = _most_confused(d["rvm"])
        if worst:
            sentence += f" The RVM's most frequent confusion: {worst}."
        groups = [g for g in (d.get("all_states") or {}).get("groups", []) if len(g) > 1]
        if groups:
            sentence += (
                " Over all 20 states, the features cannot split "
                + ", ".join("|".join(g) for g in groups)
                + "."
            )
        lines.append(sentence)
    lines += [
        "",
        "The sections below give every table of the paper, what limits the ratios (the states "
        "whose mean residuals overlap), the calibration of the probabilities and the "
        "dynamic normal models beyond the paper.",
        "",
    ]
    return lines


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


def fault_codes_section(results: Mapping[str, Any]) -> list[str]:
    """Every state code the report uses, with what it means."""
    codes: set[str] = set()
    for d in results["datasets"].values():
        codes |= set(d["rvm"]["confusion"]["classes"])
        codes |= set((d.get("all_states") or {}).get("states", []))
    order = sorted(codes, key=lambda c: (c != "fn", int(c[1:]) if c[1:].isdigit() else 99, c))
    named = [f"- {'fn fault-free' if c == 'fn' else describe_state(c)}" for c in order]
    return ["## State codes", "", *named, ""]

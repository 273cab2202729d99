"""The Markdown report of a reproduction (`render_report`), and the public names of its parts.

Every function here is pure (no fitting, no simulation): it takes plain results — the
dictionaries :func:`bayes_fdi.paper.reproduce.reproduce` builds — and renders them. The
parts live in `bayes_fdi.paper.report_tables` (tables laid out like the paper's),
`bayes_fdi.paper.report_figures` (residual and feature figures),
`bayes_fdi.paper.report_sections` (calibration headlines, dynamic normal models),
`bayes_fdi.paper.report_summary` (the summary, glossary and state codes that open it) and
`bayes_fdi.reporting` (Markdown tables, ``results.json``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from bayes_fdi.paper.report_sections import (
    calibration_table,
    display_path,
    dynamic_section,
    normal_models_text,
    why_below,
)
from bayes_fdi.paper.report_summary import (
    fault_codes_section,
    glossary_section,
    summary_section,
)
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
from bayes_fdi.reporting import format_number, format_percent, markdown_table

__all__ = ["render_report"]


def render_report(results: Mapping[str, Any]) -> str:
    """The Markdown report of a :func:`bayes_fdi.paper.reproduce.reproduce` run.

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
    opening = [*_header(results), *summary_section(results), *glossary_section()]
    md = [*_overall_section(datasets), *_calibration_section(datasets), *dynamic_section(results)]
    for name, d in datasets.items():
        md += _dataset_section(name, d, figures.get(name, {}))
    codes = fault_codes_section("\n".join([*opening, *md]))
    return "\n".join([*opening, *codes, *md]).rstrip() + "\n"


def _header(results: Mapping[str, Any]) -> list[str]:
    """Title, version, seed, total time and the protocol."""
    return [
        "# Reproduction of Feng & Wang: SEVA actuator fault diagnosis with RVMs",
        "",
        f"bayes_fdi {results.get('bayes_fdi_version', '?')}, seed {results.get('seed')}"
        + (
            ", **small campaigns** (quick check, not the paper's sizes)"
            if results.get("small")
            else ""
        )
        + f", {format_number(results.get('seconds'), '.0f')} s in total.",
        "",
        "Protocol (the paper's Section 5): per state, the first "
        f"{results.get('n_train_per_state', 20)} runs fit the normal models (fault-free runs) "
        "and train the classifiers; every other run is a test run. Features: the mean residuals "
        "`mean_r1`, `mean_r2` of each run. RVM = k-means designed tree of RVM classifiers; "
        "each node standardises its own training features and uses a Gaussian kernel with "
        "sigma = 2. SVM = the same tree with SVMs (same scaling and kernel, C = 1, Platt-scaled "
        "probabilities) on the same features.",
        "",
    ]


def _overall_section(datasets: Mapping[str, Any]) -> list[str]:
    """Overall identification ratios against the paper's, vectors per node, the scores used."""
    md = [
        "## Overall identification ratio",
        "",
        comparison_table({k: {m: v[m] for m in ("rvm", "svm")} for k, v in datasets.items()}),
    ]
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
            md.append(
                f"- {name}: RVM {format_percent(rvm)} {verdict} the paper's "
                f"{format_percent(paper)}; "
                f"RVM {'>=' if rvm >= svm else '<'} SVM ({format_percent(svm)})." + paired
            )
        rv = [n["vectors"] for n in d["rvm"]["nodes"] if n["vectors"] is not None]
        sv = [n["vectors"] for n in d["svm"]["nodes"] if n["vectors"] is not None]
        if rv and sv:
            md.append(
                f"- {name}: relevance vectors per node {min(rv)}–{max(rv)} "
                f"(total {sum(rv)}), support vectors per node {min(sv)}–{max(sv)} "
                f"(total {sum(sv)})."
            )
    md += [
        "",
        "Log loss (natural log) and Brier score (mean over runs of the squared distance between "
        "the probability vector and the one-hot truth, 0 best, 2 worst) score the full class "
        "distribution; ECE is the top-label expected calibration error (15 equal-width bins). "
        "Fit and predict times are for the classifier trees on the features (the normal models "
        "are shared; their time is in the per-dataset timing below).",
        "",
    ]
    return md


def _calibration_section(datasets: Mapping[str, Any]) -> list[str]:
    """Headline calibration figures of the RVM pipelines (none when no dataset has them)."""
    cal = calibration_table(datasets)
    if not cal:
        return []
    methods = {
        str(d["calibration"]["recalibration"].get("method"))
        for d in datasets.values()
        if d.get("calibration")
    }
    return [
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


def _dataset_section(name: str, d: Mapping[str, Any], figs: Mapping[str, str]) -> list[str]:
    """One dataset: campaign, strengths, residuals, both methods, states below the paper's
    ratio, the all-states analysis and the timing."""
    md = [f"## {name}", "", *_campaign_text(name, d), *_strengths_table(d)]
    if "residuals" in figs:
        md += [
            "### Residuals (as the paper's Figures 12-19)",
            "",
            f"![residuals]({figs['residuals']})",
            "",
        ]
    for method, prefix, vname, table in (("rvm", "RVM", "RV", "2/6"), ("svm", "SVM", "SV", "4/8")):
        md += _method_section(name, method, d[method], prefix, vname, table)
    target = PAPER_ACCURACY.get(name, {}).get("rvm")
    if target is not None:
        why = why_below(name, d["rvm"], d.get("all_states"), target)
        md += ["### States identified below the paper's overall ratio (RVM)", ""]
        md += why if why else ["None: every state reaches it."]
        md += [""]
    if "features" in figs:
        md += [f"![features]({figs['features']})", ""]
    block = d.get("all_states")
    if block:
        md += _all_states_section(block, figs)
    timing = d.get("timing", {})
    if timing:
        md += [
            "Timing (s): " + ", ".join(f"{k} {format_number(v, '.2f')}" for k, v in timing.items()),
            "",
        ]
    return md


def _campaign_text(name: str, d: Mapping[str, Any]) -> list[str]:
    """Where the dataset came from and the size of its normal models."""
    info = d.get("campaign", {})
    split = d.get("split", {})
    return [
        f"Campaign `{display_path(info.get('campaign_file') or name)}` "
        f"(sha256 {str(info.get('campaign_sha256', ''))[:16]}…), "
        + (
            "loaded from the cache"
            if info.get("cached")
            else f"simulated in {format_number(info.get('simulate_seconds'), '.0f')} s"
        )
        + f". Normal models: {split.get('normal_model_runs', '?')} fault-free runs, "
        f"{split.get('normal_model_samples', '?')} samples"
        + normal_models_text(d.get("normal_models", {}))
        + ".",
        "",
    ]


def _strengths_table(d: Mapping[str, Any]) -> list[str]:
    """The fault strengths and profiles of each state's runs."""
    md = ["### Fault strengths used", ""]
    rows = [
        [s, v["runs"], f"{v['min']:.3g}", f"{v['max']:.3g}", ", ".join(v["profiles"])]
        for s, v in d.get("strength", {}).items()
    ]
    if rows:
        md += [markdown_table(["State", "Runs", "Strength min", "Strength max", "Profiles"], rows)]
    return md


def _method_section(
    name: str, method: str, m: Mapping[str, Any], prefix: str, vname: str, table: str
) -> list[str]:
    """One method's confusion on the test runs, its scores and its tree (as the paper's
    Tables ``table``)."""
    return [
        f"### {prefix}: identification results of the test runs (as Tables {table})",
        "",
        confusion_table(m["confusion"]["matrix"], m["confusion"]["classes"]),
        f"Log loss {format_number(m['log_loss'])}, Brier {format_number(m['brier'])}, "
        f"ECE {format_number(m['ece'])}; "
        f"fit {format_number(m['fit_seconds'], '.2f')} s, "
        f"predict {format_number(m['predict_seconds'], '.3f')} s.",
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


def _all_states_section(block: Mapping[str, Any], figs: Mapping[str, str]) -> list[str]:
    """Beyond the paper: the groups of confusable states and both trees on all states."""
    md = [
        "### Beyond the paper: all states",
        "",
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
            f"state's group {format_number(m['group_mass'], '.3f')}; "
            f"log loss {format_number(m['log_loss'])}, "
            f"ECE {format_number(m['ece'])}.",
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
    return md

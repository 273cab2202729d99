"""Text blocks of the reproduction report: calibration headlines, the dynamic-model comparison.

:func:`calibration_table` (the headline calibration figures of each RVM pipeline) and
:func:`dynamic_section` (the paper's static normal models against the dynamic ones), with the
small formatters the report shares.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from bayes_fdi.paper.report_tables import confusion_table
from bayes_fdi.reporting import format_number, format_percent, markdown_table

__all__ = [
    "calibration_table",
    "display_path",
    "dynamic_section",
    "normal_models_text",
    "why_below",
]


def why_below(
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


def display_path(path: str | os.PathLike) -> str:
    """``path`` relative to the working folder when inside it (reports do not leak home paths)."""
    p = Path(path)
    try:
        return p.resolve().relative_to(Path.cwd().resolve()).as_posix()
    except (ValueError, OSError):
        return p.name if p.is_absolute() else p.as_posix()


def _ece_text(e: Mapping[str, Any]) -> str:
    return (
        f"{format_number(e.get('value'), '.3f')} [{format_number(e.get('ci_low'), '.3f')}, "
        f"{format_number(e.get('ci_high'), '.3f')}] "
        f"(floor {format_number(e.get('noise_floor'), '.3f')})"
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
    (:func:`bayes_fdi.paper.reproduce.calibration_headlines`); datasets without one are
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
                f"{format_number(c['before']['log_loss'])} → "
                f"{format_number(c['after']['log_loss'])}",
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
        f"{k}: {rv[k]} RVs, std {format_number(noise.get(k), '.4f')}" for k in ("X", "F") if k in rv
    )


def dynamic_section(results: Mapping[str, Any]) -> list[str]:
    """Report lines comparing the paper's static normal models with the dynamic ones.

    Uses each dataset's ``dynamic`` entry (see :func:`bayes_fdi.paper.reproduce.reproduce`);
    empty when there is none.
    """
    datasets = {k: v for k, v in results["datasets"].items() if v.get("dynamic")}
    if not datasets:
        return []
    lags = ", ".join(f"{float(v):g}" for v in results.get("dynamic_lags", []))
    return [
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
        _static_dynamic_table(datasets, lags),
        "",
        "The 20-state columns use each row's own groups (they change with the features): "
        "accuracy on the states that are separable, and accuracy up to the group.",
        "",
        _groups_by_models_table(datasets),
        *_dynamic_details(datasets),
    ]


def _static_dynamic_table(datasets: Mapping[str, Mapping[str, Any]], lags: str) -> str:
    """One row per dataset and normal models (static, dynamic): sizes, accuracies, ECE."""
    rows = []
    for name, d in datasets.items():
        for label, r in (("static (paper)", d), (f"dynamic ({lags} s)", d["dynamic"])):
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
                    format_number(cal.get("after", {}).get("ece", {}).get("value"), ".3f"),
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
    return markdown_table(header, rows)


def _groups_by_models_table(datasets: Mapping[str, Mapping[str, Any]]) -> str:
    """The groups of confusable states with the static and with the dynamic normal models."""
    rows = []
    for name, d in datasets.items():
        for label, r in (("static", d), ("dynamic", d["dynamic"])):
            block = r.get("all_states", {})
            groups = [g for g in block.get("groups", []) if len(g) > 1]
            rows.append([name, label, ", ".join("/".join(g) for g in groups) or "none"])
    return markdown_table(["Dataset", "Normal models", "Groups no classifier can split"], rows)


def _dynamic_details(datasets: Mapping[str, Mapping[str, Any]]) -> list[str]:
    """Each dynamic pipeline's confusion on the paper states and its intervals' coverage."""
    md: list[str] = []
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


def normal_models_text(nm: Mapping[str, Any]) -> str:
    """``"; RBF width ...; g for X: n relevance vectors, noise std ..."``: the normal models of
    a dataset's results (its ``normal_models`` entry) as a clause of a sentence; empty when
    there are none."""
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

"""The Markdown text of a calibration report, from the content of its ``calibration.json``."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from bayes_fdi.calibration.recalibrator_selection import RECALIBRATOR_LABELS
from bayes_fdi.reporting import format_number

__all__ = ["format_ece", "render_markdown"]


def format_ece(e: dict[str, Any]) -> str:
    """``plug-in (bias-corrected [basic CI])``, or just the plug-in without bootstrap."""
    if e["ci_low"] is None or not np.isfinite(e["ci_low"]):
        return f"{e['value']:.4f}"
    debiased = format_number(e["debiased"])
    return f"{e['value']:.4f} ({debiased} [{e['ci_low']:.4f}, {e['ci_high']:.4f}])"


def render_markdown(r: dict[str, Any], node_note: str) -> str:
    """The Markdown text of a calibration report from the content of its ``calibration.json``.

    ``node_note`` replaces the per-node table when there is none (why it was skipped).
    """
    lines = [
        f"# {r['title']}",
        "",
        f"Test runs: {r['n_test_runs']}"
        + (f", diagnosed in {r['n_samples']} windows" if r.get("windowed") else "")
        + f" ({r['n_excluded_unknown_state']} excluded from the "
        f"classification metrics because their state is not among the diagnoser's classes"
        + (f": {', '.join(r['excluded_states'])}" if r["excluded_states"] else "")
        + f"). Classes: {', '.join(r['classes'])}.",
        "",
        *_whole_tree_section(r),
        *_nodes_section(r, node_note),
        *_normal_models_section(r),
    ]
    lines.append("")
    return "\n".join(lines)


def _column_names(r: dict[str, Any]) -> tuple[list[str], dict[str, str]]:
    """The report's columns (before, each recalibrator, after) and their headings."""
    cols = ["before", *r["recalibration"]["methods"], "after"]
    names = {"before": "before", "after": "after (selected)", **RECALIBRATOR_LABELS}
    return cols, names


def _fit_lines(rc: dict[str, Any]) -> list[str]:
    """One line per recalibration fit: runs, the recalibrator selected and why, parameters."""
    lines = []
    for i, f in enumerate(rc["fits"]):
        cvs = ", ".join(f"{RECALIBRATOR_LABELS[m]} {v:.4f}" for m, v in f["cv_log_loss"].items())
        extra = []
        if "temperature" in f:
            extra.append(f"T = {f['temperature']['temperature']:.3f}")
        for m in ("vector", "dirichlet"):
            if m in f:
                d = f[m]
                lam = f"λ = {d['reg_lambda']:.3g}, " if m == "dirichlet" else ""
                fb = f", fell back: {d['fallback']}" if d["fallback"] else ""
                extra.append(f"{RECALIBRATOR_LABELS[m]} {lam}μ = {d['reg_mu']:.3g}{fb}")
        lines.append(
            f"- fit {i + 1}: {f['n_fit']} fitting runs, {f['scored']} scored; "
            f"selected **{RECALIBRATOR_LABELS[f['selected']]}** ({f['why']}"
            + (f": {cvs}" if cvs else "")
            + "); "
            + "; ".join(extra)
            + "."
        )
    return lines


def _binning_lines(r: dict[str, Any]) -> list[str]:
    """Table of the top-label ECE of every column under other binnings, with noise floors."""
    cols, names = _column_names(r)
    lines = [
        "| binning | " + " | ".join(names[c] for c in cols) + " | noise floor (before / after) |",
        "|---" * (len(cols) + 2) + "|",
    ]
    for b in r["ece_binning"]:
        kind = "equal width" if b["strategy"] == "uniform" else "equal mass"
        lines.append(
            f"| {b['n_bins']} bins, {kind} | "
            + " | ".join(format_ece(b[c]) for c in cols)
            + f" | {b['before']['noise_floor']:.4f} / {b['after']['noise_floor']:.4f} |"
        )
    return lines


def _whole_tree_section(r: dict[str, Any]) -> list[str]:
    """The whole tree's calibration before and after each recalibrator."""
    wt = r["whole_tree"]
    rc = r["recalibration"]
    cols, names = _column_names(r)

    def row(label: str, get: Callable[[dict[str, Any]], str]) -> str:
        return f"| {label} | " + " | ".join(get(wt[c]) for c in cols) + " |"

    return [
        "## Whole tree",
        "",
        f"Recalibration: {rc['how']}. Compared: one temperature; vector scaling (one power and "
        "one offset per class); Dirichlet calibration (a full linear map of the "
        "log-probabilities, off-diagonal and intercept penalty chosen by cross-validation). "
        "Vector and Dirichlet scaling can change the diagnosed class (compare the accuracy). "
        "The **after** column is, in every fit, the recalibrator of lowest cross-validated log "
        "loss on that fit's own fitting runs; the scored runs never enter the choice.",
        "",
        *_fit_lines(rc),
        "",
        "ECE cells: plug-in estimate (bias-corrected estimate [95 % basic-bootstrap interval "
        "of the population ECE]). The plug-in ECE is biased upwards, so it may lie above the "
        "interval; the bias-corrected value subtracts the bootstrap estimate of that bias. "
        "The noise floor is the ECE a perfectly calibrated model would show on this many "
        "runs: plug-in values near it are indistinguishable from sampling noise. "
        "Brier score is the multi-class one (sum over classes of squared errors, range [0, 2]).",
        "",
        "| metric | " + " | ".join(names[c] for c in cols) + " |",
        "|---" * (len(cols) + 1) + "|",
        row("accuracy", lambda s: f"{s['accuracy']:.4f}"),
        row("top-label ECE (equal width)", lambda s: format_ece(s["ece"])),
        row("top-label ECE (equal mass)", lambda s: format_ece(s["ece_quantile"])),
        row("classwise ECE", lambda s: format_ece(s["ece_classwise"])),
        row("noise floor of top-label ECE", lambda s: f"{s['ece']['noise_floor']:.4f}"),
        row("MCE (top-label)", lambda s: f"{s['ece']['mce']:.4f}"),
        row("log loss", lambda s: f"{s['log_loss']:.4f}"),
        row("Brier", lambda s: f"{s['brier']:.4f}"),
        "",
        "Top-label ECE for other binnings (fewer bins lower the noise floor but hide the "
        "shape of the reliability curve):",
        "",
        *_binning_lines(r),
        "",
        "![reliability](figures/reliability_whole_tree.png)",
        "",
    ]


def _nodes_section(r: dict[str, Any], node_note: str) -> list[str]:
    """Each tree node's binary calibration (or why there is none)."""
    lines = ["## Tree nodes", ""]
    if not r["nodes"]:
        lines.append(node_note or "No nodes.")
        return lines

    def f(v: float | None) -> str:
        return "–" if v is None else f"{v:.4f}"

    lines += [
        "Each node's binary calibration on the test runs of its classes "
        "(outcome: the run's class is on the right).",
        "",
        "| node | left | right | n | accuracy | ECE | MCE | log loss | Brier |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for n in r["nodes"]:
        lines.append(
            f"| {n['index']} | {' '.join(n['left'])} | {' '.join(n['right'])} | {n['n']} | "
            f"{f(n['accuracy'])} | {f(n['ece'])} | {f(n['mce'])} | {f(n['log_loss'])} | "
            f"{f(n['brier'])} |"
        )
    return lines


def _normal_models_section(r: dict[str, Any]) -> list[str]:
    """Coverage, widths, CRPS and PIT of the normal models on the fault-free test runs."""
    lines = ["", "## Normal models (fault-free test runs)", ""]
    if not r["normal_models"]:
        lines.append("No fault-free test runs: normal-model calibration not assessed.")
        return lines
    lines += [
        f"{r['n_fault_free_runs']} fault-free runs. Central predictive intervals "
        "mean ± z·std; CRPS in normalised units (lower is better).",
        "",
        "| output | level | coverage | mean width |",
        "|---|---|---|---|",
    ]
    for name, d in r["normal_models"].items():
        for lv, c in d["coverage"].items():
            lines.append(f"| {name} | {lv} | {c['coverage']:.4f} | {c['mean_width']:.4g} |")
    lines += [
        "",
        "| output | n samples | excluded (non-finite) | CRPS | RMSE | mean std |",
        "|---|---|---|---|---|---|",
    ]
    for name, d in r["normal_models"].items():
        lines.append(
            f"| {name} | {d['n']} | {d['n_excluded']} | {d['crps']:.4g} | {d['rmse']:.4g} | "
            f"{d['mean_std']:.4g} |"
        )
    lines += ["", "![PIT](figures/pit_normal_models.png)"]
    return lines

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
    wt = r["whole_tree"]
    rc = r["recalibration"]
    cols = ["before", *rc["methods"], "after"]
    names = {"before": "before", "after": "after (selected)", **RECALIBRATOR_LABELS}
    head = "| metric | " + " | ".join(names[c] for c in cols) + " |"
    rule = "|---" * (len(cols) + 1) + "|"

    def row(label: str, get: Callable[[dict[str, Any]], str]) -> str:
        return f"| {label} | " + " | ".join(get(wt[c]) for c in cols) + " |"

    fit_lines = []
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
        fit_lines.append(
            f"- fit {i + 1}: {f['n_fit']} fitting runs, {f['scored']} scored; "
            f"selected **{RECALIBRATOR_LABELS[f['selected']]}** ({f['why']}"
            + (f": {cvs}" if cvs else "")
            + "); "
            + "; ".join(extra)
            + "."
        )
    bin_lines = [
        "| binning | " + " | ".join(names[c] for c in cols) + " | noise floor (before / after) |",
        "|---" * (len(cols) + 2) + "|",
    ]
    for b in r["ece_binning"]:
        kind = "equal width" if b["strategy"] == "uniform" else "equal mass"
        bin_lines.append(
            f"| {b['n_bins']} bins, {kind} | "
            + " | ".join(format_ece(b[c]) for c in cols)
            + f" | {b['before']['noise_floor']:.4f} / {b['after']['noise_floor']:.4f} |"
        )
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
        "## Whole tree",
        "",
        f"Recalibration: {rc['how']}. Compared: one temperature; vector scaling (one power and "
        "one offset per class); Dirichlet calibration (a full linear map of the "
        "log-probabilities, off-diagonal and intercept penalty chosen by cross-validation). "
        "Vector and Dirichlet scaling can change the diagnosed class (compare the accuracy). "
        "The **after** column is, in every fit, the recalibrator of lowest cross-validated log "
        "loss on that fit's own fitting runs; the scored runs never enter the choice.",
        "",
        *fit_lines,
        "",
        "ECE cells: plug-in estimate (bias-corrected estimate [95 % basic-bootstrap interval "
        "of the population ECE]). The plug-in ECE is biased upwards, so it may lie above the "
        "interval; the bias-corrected value subtracts the bootstrap estimate of that bias. "
        "The noise floor is the ECE a perfectly calibrated model would show on this many "
        "runs: plug-in values near it are indistinguishable from sampling noise. "
        "Brier score is the multi-class one (sum over classes of squared errors, range [0, 2]).",
        "",
        head,
        rule,
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
        *bin_lines,
        "",
        "![reliability](figures/reliability_whole_tree.png)",
        "",
        "## Tree nodes",
        "",
    ]
    if r["nodes"]:
        lines += [
            "Each node's binary calibration on the test runs of its classes "
            "(outcome: the run's class is on the right).",
            "",
            "| node | left | right | n | accuracy | ECE | MCE | log loss | Brier |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for n in r["nodes"]:

            def f(v):
                return "–" if v is None else f"{v:.4f}"

            lines.append(
                f"| {n['index']} | {' '.join(n['left'])} | {' '.join(n['right'])} | {n['n']} | "
                f"{f(n['accuracy'])} | {f(n['ece'])} | {f(n['mce'])} | {f(n['log_loss'])} | "
                f"{f(n['brier'])} |"
            )
    else:
        lines.append(node_note or "No nodes.")
    lines += ["", "## Normal models (fault-free test runs)", ""]
    if r["normal_models"]:
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
    else:
        lines.append("No fault-free test runs: normal-model calibration not assessed.")
    lines.append("")
    return "\n".join(lines)

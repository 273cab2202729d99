"""The commissioning report in words: what the data identified, what the model can see and name.

`render_report` turns the report `commission` keeps (``diagnoser.commissioning_``) into Markdown:
a plain-language summary first, then the healthy data's operating range, the digital twin (its
fit on held-out data against the nominal model, what the data identify), the isolability
groups, and what to expect per fault and size. `write_report` writes it with the report as JSON.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from bayes_fdi.atomic import write_text
from bayes_fdi.diagnosis.seva import describe_state
from bayes_fdi.reporting import format_number, format_percent, markdown_table, write_json
from bayes_fdi.twin.laplace import RELIABLE_PARETO_K

__all__ = ["render_report", "write_report"]

#: The undetectable rule's share of training transplants in a report that does not record it
#: (written before ``commission`` took its ``detect_rate``): the diagnoser's default, half.
OLD_DETECT_RATE = 0.5


def _summary(report: Mapping[str, Any]) -> list[str]:
    expected = report["expected"]
    big = max((r["size"] for r in expected), default=None)
    seen = sorted({r["fault"] for r in expected if r["size"] == big and r["detected_share"] > 0})
    named = sorted({r["fault"] for r in expected if r["size"] == big and r["named_share"] >= 0.5})
    twin = report["twin"].get("heldout")
    lines = [
        "## In short",
        "",
        f"- Commissioned on {report['healthy']['seconds']} s of healthy data (seed "
        f"{report['seed']}) in {report['seconds']['total']:.0f} s.",
    ]
    if twin:
        lines.append(
            f"- The digital twin predicts held-out healthy data with "
            f"{format_percent(twin['coverage']['X'], 1)} (X) and "
            f"{format_percent(twin['coverage']['F'], 1)} (F) of samples inside its 95 % "
            f"interval; RMS error X {format_percent(twin['rms']['X'], 2)}, F "
            f"{format_percent(twin['rms']['F'], 2)} of full scale (nominal model: "
            f"{format_percent(twin['rms_nominal']['X'], 2)}, "
            f"{format_percent(twin['rms_nominal']['F'], 2)})."
        )
    if big is not None:
        lines += [
            f"- At size {big:g}, {len(seen)} of {len(report['library']['faults'])} faults are "
            f"detected on held-out transplants, {len(named)} named by their group in most of "
            f"their faulty seconds.",
        ]
    if report["undetectable"]:
        rates = report.get("detection_rates", {})
        runs = report["library"]["runs_per_fault"]
        named = [
            f"{f} ({round(rates[f] * runs)} of {runs})" if f in rates else f
            for f in report["undetectable"]
        ]
        share = _detect_share(report.get("detect_rate", OLD_DETECT_RATE))
        lines.append(
            f"- Detected in fewer than {share} of their training transplants (strengths 0.1-1, "
            "half of them incipient), so not classified: " + ", ".join(named) + "."
        )
    return [*lines, ""]


def _detect_share(rate: float) -> str:
    """The undetectable rule's share of transplants: "half", or a percentage ("25%")."""
    return "half" if float(rate) == 0.5 else format_percent(float(rate), 0)


def _laplace_warning(pareto_k: float) -> list[str]:
    """What a failed importance check means for the twin's posterior (nothing when it passed)."""
    if not pareto_k > RELIABLE_PARETO_K:  # a NaN k (no check) says nothing either
        return []
    return [
        f"**The check failed here (k = {pareto_k:.2f} > {RELIABLE_PARETO_K}):** the Gaussian "
        "misses part of the posterior's shape, so read the posterior standard deviations and "
        "sd ratios below as indicative only. The mode, the held-out check and the fault "
        "library drawn from this Gaussian are what commissioning used.",
        "",
    ]


def _twin_section(twin: Mapping[str, Any]) -> list[str]:
    rows = [
        [
            f"`{p['name']}`",
            format_number(p["prior_mean"], ".4g"),
            format_number(p["posterior_mean"], ".4g"),
            format_number(p["posterior_sd"], ".3g"),
            format_number(p["ratio"], ".2f"),
        ]
        for p in twin["parameters"]
    ]
    out = [
        "## The digital twin",
        "",
        "Posterior of the parameters the healthy data can inform (Laplace approximation at the "
        "mode, checked by Pareto-smoothed importance sampling: shape "
        f"k = {twin['pareto_k']:.2f}; up to {RELIABLE_PARETO_K} the approximation is reliable). "
        "The sd ratio is "
        "the posterior's standard deviation over the prior's: small means identified.",
        "",
        *_laplace_warning(twin["pareto_k"]),
        markdown_table(
            ["parameter", "prior mean", "posterior mean", "posterior sd", "sd ratio"], rows
        ),
    ]
    if twin["strong_correlations"]:
        pairs = ", ".join(
            f"{c['a']}/{c['b']} {c['correlation']:+.2f}" for c in twin["strong_correlations"]
        )
        out += [f"Strongly correlated (|r| >= 0.8; identified together only): {pairs}.", ""]
    return out


def _expected_section(report: Mapping[str, Any]) -> list[str]:
    rows = [
        [
            describe_state(r["fault"]),
            f"{r['size']:g}",
            format_percent(r["detected_share"], 0),
            format_number(r["median_detection_seconds"], ".0f"),
            format_percent(r["named_share"], 0),
            format_percent(r["unknown_share"], 0),
            format_percent(r["confident_wrong_share"], 1),
        ]
        for r in report["expected"]
    ]
    header = [
        "fault",
        "size",
        "detected",
        "median detection (s)",
        "named by its group",
        "unknown",
        "confident and wrong",
    ]
    return [
        "## What to expect",
        "",
        "Measured on transplants held out of every fitting step (abrupt, onset at 30 % of each "
        "run), on this valve's healthy data. The shares are of the seconds after the onset.",
        "",
        markdown_table(header, rows),
    ]


#: A cross-fitted std factor above this says that the healthy data's held-out stretches were
#: predicted much worse than the rest: about 1.1-1.7 on simulated plants commissioned on data
#: that cover their operating range (one hour, or three where one did not), 3.4-8.2 where one
#: stretch held the only visit to some operating point.
STD_FACTOR_WARNING = 3.0


def _normal_models_lines(report: Mapping[str, Any]) -> list[str]:
    """How the normal models were fitted, their predictive standard deviations and, where the
    cross-fit found them much worse on held-out stretches, a warning (reports written before
    the deviations were recorded: the first sentence only)."""
    models = report.get("normal_models", {})
    text, std, factor = models.get("text"), models.get("median_std"), models.get("std_factor")
    lines = [f"The normal models of X and F were {text}."] if text else []
    if std and factor:
        lines.append(
            f"Their predictive standard deviations are {std['X']:.4f} (X) and {std['F']:.4f} "
            "(F) of full scale (median over the healthy data): the posteriors' own, widened "
            f"{factor['X']:.2f} and {factor['F']:.2f} times so that stretches of the healthy "
            "data held out of the fit fall inside their intervals (cross-fit)."
        )
        wide = [c for c in ("X", "F") if factor[c] > STD_FACTOR_WARNING]
        if wide:
            which = " and ".join(f"{c} ({factor[c]:.1f} times)" for c in wide)
            lines += [
                "",
                f"**Wide intervals.** Held out of the fit, stretches of the healthy data were "
                f"predicted much worse than the models' posteriors allow for {which}: part of "
                "the data visits operating points that the rest does not. The wide intervals "
                "this gives hide faults that move a reading by less than about one standard "
                "deviation. Commission on more healthy data that covers the valve's usual range "
                "(on two simulated plants, three hours instead of one brought these factors "
                "from 3.4-8.2 to 1.4-1.7).",
            ]
    return [*lines, ""] if lines else []  # the table before them ends with its own newline


def _envelope_lines(envelope: Mapping[str, Any] | None) -> list[str]:
    """The input envelope, in words (nothing for a report written before it was recorded)."""
    if not envelope:
        return []
    levels = ", ".join(
        f"{c} {format_number(lo, '.3f')}-{format_number(hi, '.3f')}"
        for c, (lo, hi) in envelope["levels"].items()
    )
    rates = ", ".join(f"{c} {format_number(r, '.3g')}" for c, r in envelope["rates"].items())
    rates = f", and a mean absolute one-second change of at most {rates}" if rates else ""
    return [  # the table before it ends with its own newline
        f"The input envelope: {levels} (the healthy data's range, widened only by the sensors' "
        f"noise){rates}. Outside it the "
        "normal models extrapolate: a quiet second there is DAZZLED, and an alarm raised as the "
        "command leaves it is a model mismatch, not a fault. Commission again on data that "
        "cover a new operating range.",
        "",
    ]


def render_report(report: Mapping[str, Any]) -> str:
    """The Markdown commissioning report."""
    healthy = report["healthy"]
    range_rows = [
        [
            c,
            format_number(healthy[c]["p01"], ".3f"),
            format_number(healthy[c]["p50"], ".3f"),
            format_number(healthy[c]["p99"], ".3f"),
        ]
        for c in ("CV", "P1", "P2", "T1", "X", "F")
    ]
    groups = [describe_state("|".join(g)) for g in report["groups"]]
    lines = [
        "# Commissioning report",
        "",
        *_summary(report),
        "## The healthy data",
        "",
        "Where the commissioned model was fitted, hence where it can be trusted (full-scale "
        "units; 1st, 50th and 99th percentiles):",
        "",
        markdown_table(["channel", "1 %", "50 %", "99 %"], range_rows),
        *_envelope_lines(report.get("envelope")),
        *_normal_models_lines(report),
        *_twin_section(report["twin"]),
        "## Isolability groups",
        "",
        "Faults whose signatures the sensors cannot tell apart at this operating point are named "
        "together"
        + (
            " (one of them named as the other in at least "
            f"{format_percent(report['group_threshold'], 0)} of its detected seconds on "
            "held-out transplants):"
            if report.get("group_rule") == "naming" and "group_threshold" in report
            else ":"
        ),
        "",
        *[f"- {g}" for g in groups],
        "",
        *_classifier_lines(report),
        *_calibration_lines(report),
        *_expected_section(report),
    ]
    return "\n".join(lines) + "\n"


def _calibration_lines(report: Mapping[str, Any]) -> list[str]:
    """The group probabilities' calibration temperature (reports written before it was
    recorded: nothing)."""
    cal = report.get("calibration")
    if not cal or cal.get("temperature") is None:
        return []
    low, high = cal["bounds"]
    text = (
        f"The group probabilities are calibrated on held-out transplants with temperature "
        f"{format_number(cal['temperature'], '.3g')} (bounds {format_number(low, 'g')} to "
        f"{format_number(high, 'g')}; above 1 softens them)."
    )
    if cal.get("at_bound") and cal["temperature"] <= low * (1 + 1e-3):  # the scaler's tolerance
        text += (
            " The fit stopped at its lower bound: the held-out transplants asked for sharper "
            "probabilities, which are not given, since those transplants share the background "
            "of the data the classifier learnt."
        )
    return [text, ""]


def _classifier_lines(report: Mapping[str, Any]) -> list[str]:
    """Which classifier names the groups (reports written before the choice: the tree)."""
    if report.get("isolation_classifier", "tree") == "forest":
        return [
            "The faults are named by a random forest of the isolation signatures (its "
            "probability of a fault: the fault's share of the training signatures in the leaf "
            "the signature reaches, averaged over its trees; a group's, the sum over its "
            "faults, calibrated as below). It names the library's faults right more often "
            "than the k-means tree of relevance vector classifiers.",
            "",
        ]
    return [
        "The faults are named by the k-means tree of relevance vector classifiers (the "
        "probabilities multiply along its paths).",
        "",
    ]


def write_report(report: Mapping[str, Any], stem: str | os.PathLike) -> tuple[Path, Path]:
    """Write ``STEM.md`` and ``STEM.json`` (atomically); returns both paths."""
    stem = Path(stem)
    markdown = write_text(stem.with_suffix(".md"), render_report(report))
    return markdown, write_json(report, stem.with_suffix(".json"))

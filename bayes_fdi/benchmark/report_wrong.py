"""How the benchmark report words the isolation's probabilities: their calibration and its
confident wrong seconds.

`calibration_lines` is the report's calibration section (the top-label ECE with its interval,
and over the seconds not answered "mismatch" where some were); `calibration_target_rows` the
targets table's rows for them (the ECE at most `MAX_ECE`; confident wrong groups in at most
`MAX_CONFIDENT_WRONG_NOMINAL` of the faulty seconds on nominal inputs and
`MAX_CONFIDENT_WRONG_SHIFT` under an excitation shift, `confident_wrong_bound`).

A *confident wrong* second is a faulty second answered with a group other than the fault's at a
probability above 0.9 (`bayes_fdi.benchmark.collection.confident_wrong`). `published_wrong`
adds the group probabilities' own count where it differs (the seconds answered "unknown" or
"mismatch" included); `wrong_by_scenario` says in which scenarios they lie and which groups they
named, from the per-run counts of ``benchmark.json``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from bayes_fdi.benchmark.report_detection import scenario_name
from bayes_fdi.reporting import format_number

__all__ = ["MAX_CONFIDENT_WRONG_NOMINAL", "MAX_CONFIDENT_WRONG_SHIFT", "MAX_ECE",
           "WRONG_SCENARIOS_SHOWN", "calibration_lines", "calibration_target_rows",
           "confident_wrong_bound", "published_wrong", "wrong_by_scenario"]  # fmt: skip

#: The group-level ECE target of the per-second probabilities, nominal and under shift.
MAX_ECE = 0.05
#: Confident (p > 0.9) wrong groups allowed, as a share of the faulty seconds: nominal inputs.
MAX_CONFIDENT_WRONG_NOMINAL = 0.001
#: The same under an excitation shift (a family of `bayes_fdi.benchmark.shift`).
MAX_CONFIDENT_WRONG_SHIFT = 0.02


def confident_wrong_bound(results: Mapping[str, Any]) -> float:
    """The confident-wrong target of a benchmark's results: `MAX_CONFIDENT_WRONG_SHIFT` for
    one run under an excitation family (its settings name one), else
    `MAX_CONFIDENT_WRONG_NOMINAL`."""
    shifted = (results.get("settings") or {}).get("excitation") is not None
    return MAX_CONFIDENT_WRONG_SHIFT if shifted else MAX_CONFIDENT_WRONG_NOMINAL


def calibration_target_rows(results: Mapping[str, Any]) -> list[list[str]]:
    """The targets table's rows (target, measured, met) for the group probabilities: the ECE
    (where the benchmark calibrated any second; the bootstrap interval where there is one) and
    the confident wrong share against `confident_wrong_bound`."""
    rows = []
    cal = results.get("calibration") or {}
    if cal.get("ece") is not None:
        interval = ""
        if cal.get("n_bootstrap"):
            interval = (
                f" [{format_number(cal.get('ci_low'), '.3f')}, "
                f"{format_number(cal.get('ci_high'), '.3f')}]"
            )
        met = cal["ece"] <= MAX_ECE
        rows.append(
            [
                f"group-level ECE of the per-second probabilities <= {MAX_ECE}",
                f"{cal['ece']:.3f}{interval}",
                "yes" if met else "**no**",
            ]
        )
    cw = results["confident_wrong"]
    bound = confident_wrong_bound(results)
    where = " (under shift)" if bound == MAX_CONFIDENT_WRONG_SHIFT else " (nominal)"
    rows.append(
        [
            f"confident (p > 0.9) wrong group in <= {100 * bound:g} % of the faulty seconds{where}",
            f"{100 * cw['share']:.2f} % ({cw['seconds']} of {cw['faulty_seconds']} s)"
            + published_wrong(cw),
            "yes" if cw["share"] <= bound else "**no**",
        ]
    )
    return rows


def _num(v: Any, fmt: str = ".3f") -> str:
    return format_number(v, fmt)


def published_wrong(cw: Mapping[str, Any]) -> str:
    """What the group probabilities alone say, where it differs from the answers' count: the
    seconds answered "unknown" or "mismatch" whose most probable group is confident and wrong
    (`bayes_fdi.benchmark.collection.confident_wrong`); results without that count say nothing."""
    published = cw.get("probabilities_seconds")
    if published is None or published == cw["seconds"]:
        return ""
    return (
        f"; counting the seconds answered unknown or mismatch by their most probable group, "
        f"{100 * cw['probabilities_share']:.2f} %"
    )


#: Scenarios named in the sentence on where the confident wrong seconds lie.
WRONG_SCENARIOS_SHOWN = 3


def wrong_by_scenario(rows: Sequence[Mapping[str, Any]]) -> str:
    """Where the confident wrong seconds lie: the scenarios with the most of them (over the
    seeds), each with its share of them and the wrong groups named; empty without any (or for
    results without the per-run counts)."""
    seconds: dict[str, int] = {}
    named: dict[str, dict[str, int]] = {}
    for row in rows:
        if not row.get("confident_wrong_seconds"):
            continue
        name = scenario_name(row)
        seconds[name] = seconds.get(name, 0) + row["confident_wrong_seconds"]
        for group, n in row.get("confident_wrong_named", {}).items():
            named.setdefault(name, {})[group] = named.get(name, {}).get(group, 0) + n
    total = sum(seconds.values())
    if not total:
        return ""
    top = sorted(seconds, key=lambda k: (-seconds[k], k))[:WRONG_SCENARIOS_SHOWN]
    parts = []
    for name in top:
        groups = sorted(named.get(name, {}).items(), key=lambda kv: (-kv[1], kv[0]))
        share = seconds[name] / total
        parts.append(
            f"{name} {f'{100 * share:.0f} %' if share >= 0.01 else 'under 1 %'} (named "
            + ", ".join(f"{g} {n} s" for g, n in groups)
            + ")"
        )
    return f" Where they lie, most first: {'; '.join(parts)}."


def _answered_clause(a: Mapping[str, Any] | None) -> str:
    """The calibration over the seconds not answered "mismatch", where some were."""
    if a is None:
        return ""
    return (
        f'; over the {a["n_seconds"]} seconds not answered "mismatch": ECE {_num(a["ece"])} '
        f"[{_num(a['ci_low'])}, {_num(a['ci_high'])}], accuracy {_num(a['accuracy'])} at "
        f"{_num(a['mean_confidence'])}"
    )


def calibration_lines(results: Mapping[str, Any]) -> list[str]:
    """The report's section on the calibration of the per-second group probabilities (with
    the confident wrong seconds and the reliability diagram)."""
    cal = results["calibration"]
    cw = results["confident_wrong"]
    lines = ["## Calibration of the per-second isolation probabilities (group level)", ""]
    if not cal.get("n_seconds"):
        return [*lines, f"No sample: {cal.get('note', '')}.", ""]
    return [
        *lines,
        f"Top-label ECE of the group probabilities over {cal['n_seconds']} detected faulty "
        f"seconds of {cal['n_runs']} runs (at most 600 evenly spaced seconds per run): "
        f"**{_num(cal['ece'])}**, 95 % interval [{_num(cal['ci_low'])}, {_num(cal['ci_high'])}] "
        f"(basic bootstrap over runs, {cal['n_bootstrap']} resamples: the seconds of a run are "
        f"not independent); noise floor {_num(cal['noise_floor'])}, MCE {_num(cal['mce'])}; "
        f"accuracy {_num(cal['accuracy'])} at mean confidence {_num(cal['mean_confidence'])}"
        f"{_answered_clause(cal.get('answered'))}. Confident (p > 0.9) wrong group: "
        f"{100 * cw['share']:.2f} % of all faulty seconds"
        f"{published_wrong(cw)}.{wrong_by_scenario(results['scenarios'])}",
        "",
        "![reliability diagram](reliability.png)",
        "",
    ]

"""What DD did, for ``benchmark.md``: each fault's first detection, whether DD stayed on, and
the false detections the diagnoser declares faults.

PICalc times a detection to the *last* rising edge of DD (a detection counts once it is
permanent), so one dropped second late in a fault moves ``t_dt`` far from the moment the fault
was first seen. Beside it the benchmark records, run by run, the time to the first detection
(``t_dt_first``) and whether DD stayed on from then to the end of the zone (``dd_permanent``;
`bayes_fdi.scoring.picalc.first_detection`). `first_detection_summary` gathers them per
scenario, `permanence_target` is the report's target row on them and `first_detection_section`
its table.

A false detection of a diagnoser that answers "mismatch" (model mismatch: its normal models
do not fit the valve) is not one it declares a fault: ``declared_r_fd`` (recorded per run by
`bayes_fdi.benchmark.collection.RunCollector`) counts only the others, and
`declared_r_fd_median` / `declared_clause` report it beside PICalc's r_fd, which counts both;
`fault_free_target` is the target row of the simulated fault-free hours.

A run whose alarm was already on at the last second before the fault (``alarm_at_onset``, where
an excitation the normal models do not know keeps DD on) has ``t_dt = 0`` without having
detected anything: `judged_at_onset` marks its detection undetermined, so that the targets
tables count a fault as detected only where DD was off when it began (`ONSET_RULE`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from bayes_fdi.reporting import markdown_table
from bayes_fdi.scoring.picalc import UNDETERMINED

__all__ = ["DECLARED", "ONSET_RULE", "PERMANENT_SHARE", "alarm_at_onset",
           "declared_clause", "declared_r_fd_median", "fault_free_target",
           "first_detection_section",
           "first_detection_summary", "judged_at_onset", "permanence_target",
           "scenario_name"]  # fmt: skip

#: Share of the detected runs of the visible big abrupt faults whose DD must stay on after the
#: first detection.
PERMANENT_SHARE = 0.95


#: What ``declared_r_fd`` counts, in the reports' words.
DECLARED = 'counting only the alarms the diagnoser declares faults (its answer not "mismatch")'


def declared_r_fd_median(results: Mapping[str, Any] | Sequence[Mapping[str, Any]]) -> float | None:
    """Median over the runs (``results["scenarios"]``, or a sequence of run rows) of
    ``declared_r_fd`` (the share of the fault-free part with DD on and the diagnoser's answer
    other than "mismatch"), or None in results without it."""
    rows = results["scenarios"] if isinstance(results, Mapping) else results
    values = [r["declared_r_fd"] for r in rows if "declared_r_fd" in r]
    return float(np.median(values)) if values else None


def declared_clause(results: Mapping[str, Any]) -> str:
    """``"; DECLARED, <median>"`` for the false-alarm lines, or ``""`` without the figure."""
    declared = declared_r_fd_median(results)
    return "" if declared is None else f"; {DECLARED}, {declared:.4f}"


def fault_free_target(ff: Mapping[str, Any]) -> tuple[str, str, bool]:
    """The fault-free hours' target (target, measured, met): at most one alarm in 8 hours and DD
    on at most 1 % of the time (an alarm left on is one rising edge; its time share counts)."""
    on = ff.get("r_fd")
    return (
        f"<= 1 alarm in 8 fault-free hours, DD on <= 1 % ({ff['hours']:g} h simulated)",
        f"{ff['alarms']} alarm(s) = {ff['alarms_per_8h']:.2f} per 8 h"
        + ("" if on is None else f", DD on {100 * on:.2f} %"),
        ff["alarms_per_8h"] <= 1.0 and (on is None or on <= 0.01),
    )


#: How the targets tables count a detection, in their words.
ONSET_RULE = "a run counts as detected only if DD was off at the last second before the fault"


def alarm_at_onset(time: Any, dd: Any, *, t_from: float) -> float:
    """1.0 when DD is high at the last second before the fault (``t_from - 1``), else 0.0
    (also when the stream has no such second; NaN in ``dd`` counts as low)."""
    t = np.asarray(time, dtype=np.float64)
    high = np.asarray(dd, dtype=np.float64) == 1.0
    if t.shape != high.shape:
        raise ValueError(f"time {t.shape} and dd {high.shape} differ in shape")
    return float(high[t == float(t_from) - 1.0].any())


def judged_at_onset(results: Mapping[str, Any]) -> dict[str, Any]:
    """``results`` with the detection of every run whose alarm was on at the fault's start
    (``alarm_at_onset`` 1) undetermined: its ``t_dt``, ``t_dt_first`` and ``dd_permanent``
    set to :data:`~bayes_fdi.scoring.picalc.UNDETERMINED` (the other indices kept; the rows
    are copies, ``results`` is not changed). Rows without ``alarm_at_onset`` (results of an
    earlier version) are kept as they are."""
    rows = []
    for row in results["scenarios"]:
        if row.get("alarm_at_onset") == 1.0:
            row = {**row, "indices": {**row["indices"], "t_dt": UNDETERMINED}}
            if "first_detection" in row:
                row["first_detection"] = {"t_dt_first": UNDETERMINED,
                                          "dd_permanent": UNDETERMINED}  # fmt: skip
        rows.append(row)
    return {**results, "scenarios": rows}


def scenario_name(row: Mapping[str, Any]) -> str:
    """The scenario of a ``benchmark.json`` row, e.g. ``"f18 abrupt big"``, ``"f2 incipient"``."""
    return " ".join(p for p in (row["fault"], row["mode"], row.get("size")) if p)


def first_detection_summary(results: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """Per scenario: ``n`` runs, ``detected`` (DD on in the faulty part), ``kept`` (of those,
    DD on from the first detection to the end), and the median, min and max of ``t_dt_first``
    over the detected runs (None when none). Rows without ``first_detection`` (results of an
    earlier version) are left out."""
    runs: dict[str, list[Mapping[str, float]]] = {}
    for row in results["scenarios"]:
        if "first_detection" in row:
            runs.setdefault(scenario_name(row), []).append(row["first_detection"])
    out = {}
    for name, firsts in runs.items():
        t = np.array([f["t_dt_first"] for f in firsts], dtype=np.float64)
        found = t != UNDETERMINED
        kept = sum(f["dd_permanent"] == 1.0 for f in firsts)
        out[name] = {
            "n": len(firsts),
            "detected": int(found.sum()),
            "kept": int(kept),
            "median": float(np.median(t[found])) if found.any() else None,
            "min": float(t[found].min()) if found.any() else None,
            "max": float(t[found].max()) if found.any() else None,
        }
    return out


def permanence_target(results: Mapping[str, Any], names: Sequence[str]) -> list[str] | None:
    """The target row (target, measured, met) "DD kept on after its first detection in >= 95 %
    of the detected runs" over the scenarios ``names``; None without first detections."""
    summary = first_detection_summary(results)
    entries = [summary[n] for n in names if n in summary]
    if not entries:
        return None
    detected = sum(e["detected"] for e in entries)
    kept = sum(e["kept"] for e in entries)
    share = kept / detected if detected else 0.0
    met = detected > 0 and share >= PERMANENT_SHARE
    return [
        f"DD kept on after its first detection in >= {100 * PERMANENT_SHARE:.0f} % of the "
        "detected runs of those big abrupt faults",
        f"{kept} of {detected} runs ({100 * share:.1f} %)",
        "yes" if met else "**no**",
    ]


def _times(median: float | None, low: float | None, high: float | None) -> str:
    if median is None:
        return "–"
    return f"{median:.0f}" + (f" [{low:.0f}, {high:.0f}]" if low != high else "")


def first_detection_section(
    results: Mapping[str, Any], summary: Mapping[str, Mapping[str, Any]]
) -> list[str]:
    """The report's lines on the first detection: per scenario detected in some run, ``t_dt``
    (last rising edge, from ``summary``: `bayes_fdi.benchmark.report.summarise`) beside
    ``t_dt_first`` and the runs whose DD stayed on."""
    firsts = first_detection_summary(results)
    rows = []
    for name, e in firsts.items():
        if not e["detected"]:
            continue
        last = summary.get(name, {}).get("t_dt", {})
        rows.append(
            [
                name,
                _times(last.get("median"), last.get("min"), last.get("max")),
                _times(e["median"], e["min"], e["max"]),
                f"{e['kept']} of {e['detected']}",
            ]
        )
    if not rows:
        return []
    return [
        "## First detection and permanence",
        "",
        "t_dt (PICalc) runs to the last rising edge of DD; t_dt_first to the first second of "
        "the faulty part with DD on (median [min, max] over the runs that detect). They differ "
        "where DD dropped after the first detection; *kept on*: runs whose DD stayed on from "
        "the first detection to the end of the zone, of the runs that detect.",
        "",
        markdown_table(["scenario", "t_dt [s]", "t_dt_first [s]", "kept on"], rows),
    ]

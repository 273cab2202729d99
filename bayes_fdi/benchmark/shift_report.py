"""The summary report of the shift benchmark (``bayes-fdi benchmark --shift``): pure rendering.

:func:`write_shift_report` takes the results of every shift family (each the dictionary of
`bayes_fdi.benchmark.harness.run_benchmark`, whose full report lies in ``out/NAME/``) and
writes ``out/benchmark.json`` and ``out/benchmark.md``: the families, an overall table of the
key figures per family (fault-free false detections and alarms, big abrupt faults detected and
how fast, group isolation, calibration, confident wrong groups), each target met under every
family or not, and one section per family with its targets table (the nominal report's,
`bayes_fdi.benchmark.report.target_rows`). Like those tables, the figures count a fault as
detected only in runs whose alarm was off when it began
(`bayes_fdi.benchmark.report_detection.judged_at_onset`): under a shift the alarm may be on
through the fault-free part, and its ``t_dt = 0`` then detects nothing.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bayes_fdi.atomic import write_text
from bayes_fdi.benchmark.report import summarise, target_rows
from bayes_fdi.benchmark.report_detection import (
    ONSET_RULE,
    declared_r_fd_median,
    judged_at_onset,
)
from bayes_fdi.reporting import format_number, markdown_table, to_jsonable

__all__ = ["family_figures", "render_shift_report", "write_shift_report"]


def _median(values: Sequence[float | None]) -> float | None:
    ok = [v for v in values if v is not None]
    return float(np.median(ok)) if ok else None


def family_figures(results: Mapping[str, Any]) -> dict[str, Any]:
    """The key figures of one family's benchmark results.

    ``r_fd_median``: median r_fd over every run's fault-free part; ``r_fd_declared_median``:
    the same counting only the alarms the diagnoser declares faults (its answer not
    "mismatch"; None in results without it); ``alarmed_before``: the
    share of runs whose alarm was on through the whole fault-free part (r_fd = 1: a detection
    at t_dt = 0 then says nothing about the fault); ``alarms``, ``alarms_per_8h``,
    ``dd_share``: the fault-free hours (alarms counted as rising edges, and the share of
    seconds with the alarm on); ``big_detected``: big abrupt
    scenarios detected in at least half the seeds (of ``big``; a run counts as detected only
    if its alarm was off at the fault's start, `judged_at_onset`); ``t_dt_median``,
    ``t_dt_worst``: median and largest of those scenarios' median t_dt (s); ``r_ti_median``,
    ``r_ti_ok``: their median r_ti and how many reach 0.9; ``ece`` (with ``ece_low``,
    ``ece_high``; ``ece_answered`` over the seconds not answered "mismatch", None where none
    was), ``confident_wrong``: the calibration of the group probabilities;
    ``innovation_rms_X``, ``innovation_rms_F``: the whitened innovations' RMS on the scenarios'
    fault-free parts, how well the normal models fit the family's inputs (None in results
    without it).
    """
    summary = summarise(judged_at_onset(results))
    big = [n for n in summary if n.endswith("abrupt big")]
    detected = [n for n in big if 2 * summary[n]["t_dt"]["determined"] >= summary[n]["n"] > 0]
    t_dt = [summary[n]["t_dt"]["median"] for n in detected]
    r_ti = [summary[n]["r_ti"]["median"] for n in detected]
    ff, cal = results["fault_free"], results["calibration"]
    r_fd = np.array([r["indices"]["r_fd"] for r in results["scenarios"]], dtype=np.float64)
    return {
        "r_fd_median": float(np.median(r_fd)),
        "r_fd_declared_median": declared_r_fd_median(results),
        "alarmed_before": float(np.mean(r_fd >= 1.0)),
        "alarms": int(ff["alarms"]),
        "alarms_per_8h": float(ff["alarms_per_8h"]),
        "hours": float(ff["hours"]),
        "dd_share": float(ff["r_fd"]),
        "big": len(big),
        "big_detected": len(detected),
        "t_dt_median": _median(t_dt),
        "t_dt_worst": max((v for v in t_dt if v is not None), default=None),
        "r_ti_median": _median(r_ti),
        "r_ti_ok": sum(1 for v in r_ti if v is not None and v >= 0.9),
        "ece": cal.get("ece"),
        "ece_low": cal.get("ci_low"),
        "ece_high": cal.get("ci_high"),
        "ece_answered": (cal.get("answered") or {}).get("ece"),
        "confident_wrong": float(results["confident_wrong"]["share"]),
        **{f"innovation_rms_{c}": (results.get("innovation_rms") or {}).get(c) for c in "XF"},
    }


def _overall_table(families: Sequence[Mapping[str, Any]]) -> str:
    header = ["family", "median r_fd (fault-free parts)", "runs alarmed before the fault",
              "alarms per 8 h; alarm on (fault-free hours)", "big abrupt detected",
              "t_dt median / worst (s)", "r_ti median (>= 0.9)",
              "ECE [95 % interval]", "confident wrong", "innovations' RMS X / F",
              "targets met"]  # fmt: skip
    rows = []
    for f in families:
        g = f["figures"]
        met = [row for row in f["targets"] if row[2] != "–"]
        rows.append([
            f"[{f['name']}]({f['report']})",
            f"{g['r_fd_median']:.4f}"
            + (
                ""
                if g.get("r_fd_declared_median") is None
                else f" (declared faults {g['r_fd_declared_median']:.4f})"
            ),
            f"{100 * g['alarmed_before']:.0f} %",
            f"{g['alarms_per_8h']:.2f} ({g['alarms']} in {g['hours']:g} h); "
            f"{100 * g['dd_share']:.1f} % of the time",
            f"{g['big_detected']} of {g['big']}",
            f"{format_number(g['t_dt_median'], '.0f')} / {format_number(g['t_dt_worst'], '.0f')}",
            f"{format_number(g['r_ti_median'], '.3f')} ({g['r_ti_ok']} of {g['big_detected']})",
            f"{format_number(g['ece'], '.3f')} [{format_number(g['ece_low'], '.3f')}, "
            f"{format_number(g['ece_high'], '.3f')}]"
            + (
                ""
                if g.get("ece_answered") is None
                else f' ({format_number(g["ece_answered"], ".3f")} not answered "mismatch")'
            ),
            f"{100 * g['confident_wrong']:.2f} %",
            f"{format_number(g.get('innovation_rms_X'), '.2f')} / "
            f"{format_number(g.get('innovation_rms_F'), '.2f')}",
            f"{sum(row[2] == 'yes' for row in met)} of {len(met)}",
        ])  # fmt: skip
    return markdown_table(header, rows)


def _alarmed_note(families: Sequence[Mapping[str, Any]]) -> list[str]:
    """A warning where runs had the alarm on before their fault: their detections mean
    nothing."""
    named = [f"{f['name']} ({100 * f['figures']['alarmed_before']:.0f} %)" for f in families
             if f["figures"]["alarmed_before"] > 0]  # fmt: skip
    if not named:
        return []
    return [
        "**The alarm was already on through the whole fault-free part** of runs under "
        + ", ".join(named)
        + ": in those runs a detection (t_dt = 0 at the fault's start) says nothing about the "
        "fault (the tables count it as not detected), and the alarm counts of the fault-free "
        "hours are low because the alarm rarely goes off; read the share of time with the "
        "alarm on.",
        "",
    ]


def _every_family(families: Sequence[Mapping[str, Any]]) -> list[list[str]]:
    """Per target (in the first family's order): met under every family, or where not."""
    order: dict[str, list[str]] = {}
    for f in families:
        for target, _, met in f["targets"]:
            if met != "–":
                order.setdefault(target, []).append(f["name"] if met != "yes" else "")
    rows = []
    for target, misses in order.items():
        missed = [m for m in misses if m]
        rows.append([target, "yes" if not missed else "**no**: " + ", ".join(missed)])
    return rows


def render_shift_report(results: Mapping[str, Any]) -> str:
    """The Markdown summary of a shift benchmark run."""
    s, families = results["settings"], results["families"]
    lines = ["# DAMADICS benchmark (Step I) under excitation shift", ""]
    if not s.get("full_benchmark"):
        lines += [
            "> **Not the benchmark's numbers**: a reduced run (fewer scenarios or horizons cut "
            "short); use `bayes-fdi benchmark --shift --out DIR` for the full one.",
            "",
        ]
    lines += [
        f"The {s['n_scenarios']} scenarios x {s['n_seeds']} noise seeds ({s['seeds'][0]} .. "
        f"{s['seeds'][-1]}) and {s['hours']:g} fault-free hour(s), scored as the nominal "
        f"benchmark, under each of {len(families)} excitation families that no training "
        "campaign uses (the inputs CV, P1, P2, T1 are the family's instead of DGen's sines; "
        f"the operating points stay within the training ranges). Wall time "
        f"{results['timing']['wall_s']:.0f} s"
        + (f"; training took {s['fit_wall_s']:.0f} s wall." if "fit_wall_s" in s else "."),
        "",
        "## Families",
        "",
        markdown_table(
            ["family", "generator", "inputs", "file"],
            [[f["name"], f["family"], f["description"], f"sim/{f['file']}"] for f in families],
        ),
        "## Overall",
        "",
        "Per family; the full report of each (indices per scenario, fault effects under its "
        "inputs, calibration, false alarms) is linked. In this table and the targets tables "
        f"{ONSET_RULE}: under a shift the alarm may be on before the fault, and its t_dt = 0 "
        "then detects nothing.",
        "",
        _overall_table(families),
        *_alarmed_note(families),
        "Each target of the nominal benchmark, judged under every family:",
        "",
        markdown_table(["target", "met under every family"], _every_family(families)),
    ]
    for f in families:
        lines += [
            f"## {f['name']}",
            "",
            f"{f['description']} Full report: [{f['report']}]({f['report']}).",
            "",
            markdown_table(["target", "measured", "met"], f["targets"]),
        ]
    return "\n".join(lines) + "\n"


def write_shift_report(
    families: Sequence[Any],
    per_family: Mapping[str, Mapping[str, Any]],
    out: str | os.PathLike,
    *,
    wall_s: float,
    settings: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Write ``out/benchmark.json`` and ``out/benchmark.md``; return what the JSON holds.

    Parameters
    ----------
    families
        The shift families run (`bayes_fdi.benchmark.shift.ShiftFamily`), in order.
    per_family
        Each family's results (`~bayes_fdi.benchmark.harness.run_benchmark`), by name.
    wall_s
        Wall time of the whole run.
    settings
        Provenance: the CLI's settings.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    entries = []
    for family in families:
        results = per_family[family.name]
        entries.append({
            "name": family.name,
            "family": family.family,
            "description": family.description,
            "file": Path(family.path).name,
            "excitation": family.excitation,
            "report": f"{family.name}/benchmark.md",
            "figures": family_figures(results),
            "targets": target_rows(results),
            "timing": results["timing"],
        })  # fmt: skip
    first = per_family[families[0].name]["settings"]
    keep = ("n_seeds", "seeds", "hours", "n_scenarios", "full_benchmark")
    result = {
        "families": entries,
        "settings": {**{k: first[k] for k in keep}, **dict(settings or {})},
        "timing": {"wall_s": float(wall_s)},
    }
    write_text(out / "benchmark.json", json.dumps(to_jsonable(result), indent=1) + "\n")
    write_text(out / "benchmark.md", render_shift_report(result))
    return result

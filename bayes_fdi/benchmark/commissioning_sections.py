"""The sections of the commissioning benchmark's report: the real hour and the perturbed plants.

Pure rendering for `bayes_fdi.benchmark.commissioning_report`: each section's text and tables
(twin checks, clean runs, PICalc indices per case, the faults below the noise and why visible
faults were missed, the group-level confusion, the plants and their figures).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from bayes_fdi.benchmark.collection import NOT_DETECTED
from bayes_fdi.benchmark.commissioning_summary import (
    MODELS,
    big_abrupt_by_plant,
    confident_wrong_share,
    group_confusion,
    per_case,
)
from bayes_fdi.benchmark.report import DETECTABLE_DEFLECTION
from bayes_fdi.diagnosis.seva import describe_state
from bayes_fdi.reporting import format_number, markdown_table
from bayes_fdi.scoring.picalc import PICALC_KEYS

__all__ = ["index_cell", "median_or_none", "percent", "plants_section", "real_hour_section"]

_FORMATS = {k: ".0f" if k in ("t_dt", "t_it") else ".3f" for k in PICALC_KEYS}
_SIZE_ORDER = {"small": 0, "medium": 1, "big": 2}


def index_cell(stat: Mapping[str, Any], key: str, n: int) -> str:
    s = stat[key]
    if s["median"] is None:
        return "–"
    fmt = _FORMATS[key]
    text = format(s["median"], fmt)
    if s["min"] != s["max"]:
        text += f" [{format(s['min'], fmt)}, {format(s['max'], fmt)}]"
    if s["determined"] < n:
        text += f" ({s['determined']}/{n})"
    return text


def percent(value: float | None) -> str:
    return "–" if value is None else f"{100 * value:.1f} %"


def median_or_none(values: Sequence[float]) -> float | None:
    return float(np.median(values)) if len(values) else None


def _groups_lines(groups: Mapping[str, Any]) -> list[str]:
    lines = [f"- `{label}`: {describe_state(label)}" for label in groups["groups"]]
    dgn0 = groups["undetectable"]
    lines.append(
        "- DGN0 (not detectable on this valve): "
        + (", ".join(describe_state(f) for f in dgn0) if dgn0 else "none")
    )
    return lines


def _twin_table(checks: Sequence[tuple[str, Mapping[str, Any]]]) -> str:
    rows = [
        [
            name,
            *(f"{100 * c['coverage'][ch]:.1f} %" for ch in ("X", "F")),
            *(f"{c['rms'][ch]:.4f} / {c['rms_nominal'][ch]:.4f}" for ch in ("X", "F")),
            c["n_samples"],
        ]
        for name, c in checks
    ]
    header = [
        "data",
        "coverage X",
        "coverage F",
        "RMS X twin / nominal",
        "RMS F twin / nominal",
        "seconds",
    ]
    return markdown_table(header, rows)


def _clean_table(named: Sequence[tuple[str, Mapping[str, Any]]]) -> str:
    rows = [
        [
            name,
            c["seconds"],
            c["alarms"],
            percent(c["clear_share"]),
            f"{c['r_fd']:.4f}",
            ", ".join(f"{k} {v}" for k, v in c["status_counts"].items()),
        ]
        for name, c in named
    ]
    return markdown_table(["model", "seconds", "alarms", "CLEAR", "DD high", "statuses"], rows)


def _real_index_table(real: Mapping[str, Any]) -> str:
    key = lambda r: (r["fault"], r["size"])  # noqa: E731
    stats = {m: per_case((r for r in real["cases"] if r["model"] == m), key) for m in MODELS}
    order = sorted(
        stats["commissioned"], key=lambda k: (real["faults"].index(k[0]), _SIZE_ORDER[k[1]])
    )
    rows = []
    for k in order:
        s, d = stats["commissioned"][k], stats["default"][k]
        rows.append(
            [
                f"{k[0]} {k[1]}",
                *(index_cell(s, i, s["n"]) for i in PICALC_KEYS),
                format_number(s["deflection"], ".1f"),
                percent(s["confident_wrong"]),
                index_cell(d, "t_dt", d["n"]),
                index_cell(d, "r_ti", d["n"]),
            ]
        )
    header = ["case", *PICALC_KEYS, "deflection", "conf. wrong", "default t_dt", "default r_ti"]
    return markdown_table(header, rows)


def _below_noise(stats: Mapping[Any, Mapping[str, Any]], name) -> list[str]:
    below = [(k, s) for k, s in stats.items() if (s["deflection"] or 0) < DETECTABLE_DEFLECTION]
    if not below:
        return ["- none."]
    return [
        f"- {name(k)}: deflection {format_number(s['deflection'], '.1f')}, detected in "
        f"{s['t_dt']['determined']} of {s['n']}"
        for k, s in below
    ]


def _median_effect(rows: Sequence[Mapping[str, Any]], field: str, channel: str) -> str:
    values = [r["effect"][field][channel] for r in rows if field in r.get("effect", {})]
    return format_number(median_or_none(values), "+.2f")


def _why_table(rows: Sequence[Mapping[str, Any]], key, name) -> str:
    """The visible big abrupt cases that miss a target (never detected for good every time,
    median t_dt over 10 s, or median r_ti under 0.8), with what their effect looks like."""
    groups: dict[Any, list[Mapping[str, Any]]] = {}
    for r in rows:
        groups.setdefault(key(r), []).append(r)
    out = []
    for k, s in per_case(rows, key).items():
        if (s["deflection"] or 0) < DETECTABLE_DEFLECTION:
            continue
        missed = s["t_dt"]["determined"] < s["n"]
        slow = (s["t_dt"]["median"] or 0) > 10 or (s["r_ti"]["median"] or 0) < 0.8
        if not (missed or slow):
            continue
        mine = groups[k]
        states: dict[str, int] = {}
        for r in mine:
            for state, n in r["states"].items():
                states[state] = states.get(state, 0) + n
        top = max(states, key=states.get) if states else "–"
        out.append(
            [
                name(k),
                format_number(s["deflection"], ".0f"),
                *(_median_effect(mine, "residual_shift", c) for c in ("X", "F")),
                *(_median_effect(mine, "late_shift", c) for c in ("r_X", "r_F")),
                index_cell(s, "r_td", s["n"]),
                index_cell(s, "t_dt", s["n"]),
                index_cell(s, "r_ti", s["n"]),
                f"{top} ({100 * states.get(top, 0) / max(sum(states.values()), 1):.0f} %)",
            ]
        )
    if not out:
        return "None: every visible big abrupt fault meets the targets.\n"
    header = ["case", "deflection", "residual shift X", "residual shift F", "innovation shift X",
              "innovation shift F", "r_td", "t_dt", "r_ti", "most named"]  # fmt: skip
    return markdown_table(header, out)


_WHY = (
    "**Why visible faults were missed** (big abrupt faults above the noise that miss a target; "
    "medians over the runs of the mean shift of the normal models' standardised residual and of "
    "the detector's whitened innovation, in noise units, over the second half of the faulty "
    "part: a large residual shift with a small innovation shift is a persistent fault the "
    "whitening hides after its onset):"
)


def _confusion_table(rows: Sequence[Mapping[str, Any]]) -> str:
    confusion = group_confusion(rows)
    columns = sorted({s for row in confusion.values() for s in row} - {NOT_DETECTED})
    columns.append(NOT_DETECTED)
    table = [
        [truth, *(f"{100 * row[c]:.0f}" if row.get(c) else "" for c in columns)]
        for truth, row in confusion.items()
    ]
    return markdown_table(["true group \\ named (% of faulty s)", *columns], table)


def real_hour_section(real: Mapping[str, Any]) -> list[str]:
    com = real["commissioning"]
    z = real["zones"]
    big = [r for r in real["cases"] if r["model"] == "commissioned" and r["size"] == "big"]
    return [
        "## The real hour",
        "",
        f"Commissioned on the first 1800 s of the real Lublin hour in "
        f"{com['seconds']['total']:.0f} s (twin {com['seconds']['twin']:.0f} s, fault library "
        f"{com['seconds']['library']:.0f} s, diagnoser {com['seconds']['diagnoser']:.0f} s). "
        f"Every fault transplanted onto the second half at 0.25 / 0.5 / 0.75, abrupt, "
        f"{z['t_from']:.0f} s into it, with {real['draws']} draw(s) of the twin's parameters "
        f"(seeds {real['parameter_seeds'][0]}..{real['parameter_seeds'][-1]}, apart from "
        "commissioning's); the noise is the real data's. PICalc zones in the half's time: "
        f"t_on = {z['t_on']:.0f} s (the commissioned model needs no set-up zone), t_from = "
        f"{z['t_from']:.0f} s, t_hor = {z['t_hor']:.0f} s. The whitening multiplies a "
        "persistent shift of the standardised residual by "
        + ", ".join(f"{v:.2f} ({c})" for c, v in com["whitening_gain"].items())
        + ". The groups this valve's data allow:",
        "",
        *_groups_lines(real["groups"]["commissioned"]),
        "",
        "**The twin** on the second half (95 % posterior predictive intervals):",
        "",
        _twin_table([("real hour, second half", real["twin_check"])]),
        "**The clean second half:**",
        "",
        _clean_table([(m, real["clean"][m]) for m in MODELS]),
        "**Indices per case** (commissioned model; median over the draws, [min, max], (k/N) "
        "when only k of N draws determine it; group level; the default model's t_dt and r_ti "
        "beside):",
        "",
        _real_index_table(real),
        f"**Below the noise** (big abrupt, median deflection < {DETECTABLE_DEFLECTION:g}; "
        f"innovation noise on the clean half: r_X {real['noise']['r_X']:.2f}, r_F "
        f"{real['noise']['r_F']:.2f}):",
        "",
        *_below_noise(per_case(big, lambda r: r["fault"]), str),
        "",
        _WHY,
        "",
        _why_table(big, lambda r: r["fault"], str),
        "**Group-level confusion, big faults** (commissioned model, all draws):",
        "",
        _confusion_table(big),
    ]


def _plant_table(plants: Sequence[Mapping[str, Any]]) -> str:
    rows = []
    for p in plants:
        d, c = p["plant"], p["commissioning"]
        groups = p["groups"].get("commissioned")
        rows.append(
            [
                d["index"],
                f"{d['p1_MPa']:.2f}",
                f"{d['dp_MPa']:.2f}",
                f"{d['t1_C']:.0f}",
                f"{d['opening']:.2f}",
                c["refused"] if "refused" in c else f"{c['wall_s'] / 60:.1f} min",
                len(groups["groups"]) if groups else "–",
                ", ".join(groups["undetectable"]) if groups else "–",
                ", ".join(f"{v:.2f}" for v in c["whitening_gain"].values())
                if "whitening_gain" in c
                else "–",
            ]
        )
    header = [
        "plant",
        "P1 [MPa]",
        "ΔP [MPa]",
        "T1 [°C]",
        "opening",
        "commissioning",
        "groups",
        "DGN0",
        "whitening X, F",
    ]
    return markdown_table(header, rows)


def _factor_table(plants: Sequence[Mapping[str, Any]]) -> str:
    names = list(plants[0]["plant"]["factors"])
    rows = [[n, *(f"{p['plant']['factors'][n]:.2f}" for p in plants)] for n in names]
    return markdown_table(["parameter", *(f"plant {p['plant']['index']}" for p in plants)], rows)


def _per_plant_table(plants: Sequence[Mapping[str, Any]]) -> str:
    rows = []
    for p in plants:
        for m in MODELS:
            cases = [r for r in p["cases"] if r["model"] == m]
            if not cases:
                continue
            big = big_abrupt_by_plant(cases).get(p["plant"]["index"])
            clean = p["clean"][m]
            rows.append(
                [
                    p["plant"]["index"],
                    m,
                    f"{median_or_none([r['indices']['r_fd'] for r in cases]):.4f}",
                    f"{len(big['detected'])} of {big['scenarios']}" if big else "–",
                    f"{len(big['isolated'])} of {len(big['detected'])}" if big else "–",
                    percent(confident_wrong_share(cases)["share"]),
                    f"{clean['alarms']} / {percent(clean['clear_share'])}",
                ]
            )
    header = [
        "plant",
        "model",
        "median r_fd",
        "big abrupt detected",
        "r_ti >= 0.9",
        "conf. wrong",
        "held-out healthy: alarms / CLEAR",
    ]
    return markdown_table(header, rows)


def _scenario_table(plants: Sequence[Mapping[str, Any]]) -> str:
    cases = [r for p in plants for r in p["cases"]]
    stats = {
        m: per_case((r for r in cases if r["model"] == m), lambda r: r["scenario"]) for m in MODELS
    }
    rows = []
    for name, s in stats["commissioned"].items():
        d = stats["default"][name]
        rows.append(
            [
                name,
                *(index_cell(s, k, s["n"]) for k in PICALC_KEYS),
                format_number(s["deflection"], ".1f"),
                index_cell(d, "t_dt", d["n"]),
                index_cell(d, "r_fd", d["n"]),
                index_cell(d, "r_ti", d["n"]),
            ]
        )
    header = [
        "scenario",
        *PICALC_KEYS,
        "deflection",
        "default t_dt",
        "default r_fd",
        "default r_ti",
    ]
    return markdown_table(header, rows)


def plants_section(results: Mapping[str, Any]) -> list[str]:
    plants = results["plants"]
    s = results["settings"]
    com = [p for p in plants if "refused" not in p["commissioning"]]
    big = [
        r
        for p in com
        for r in p["cases"]
        if r["model"] == "commissioned" and r["mode"] == "abrupt" and r["size"] == "big"
    ]
    lines = [
        "## Perturbed plants",
        "",
        f"{len(plants)} simulated plant(s): every physical parameter of the valve, servomotor "
        "and positioner multiplied by a factor in [0.7, 0.8] or [1.2, 1.3] (seeded, never used "
        "in training), each in a PI level loop sized for its valve, at its own operating point "
        f"(not DGen's sines); commissioned on 1 h of its healthy data. Then {s['n_scenarios']} "
        f"Step-I scenarios x {s['n_seeds']} seed(s), each under a level-loop input of its own, "
        "scored with PICalc as the DAMADICS benchmark does (t_on = 300 s, t_from = 900 s)"
        + (f"; horizons cut at {s['horizon']:.0f} s" if s.get("horizon") else "")
        + ". The loop is open at the fault: the controller's CV does not react to it.",
        "",
        _plant_table(plants),
        "Factors against nominal:",
        "",
        _factor_table(plants),
    ]
    if com:
        lines += [
            "**The twin** on a held-out healthy half hour of each plant:",
            "",
            _twin_table([(f"plant {p['plant']['index']}", p["twin_check"]) for p in com]),
        ]
    lines += [
        "**Per plant** (both models on the same runs):",
        "",
        _per_plant_table(plants),
        "**Indices per scenario** (commissioned model; median over plants and seeds, [min, "
        "max], (k/N) when only k of N runs determine it; the default model beside):",
        "",
        _scenario_table(plants) if com else "No plant was commissioned.\n",
        f"**Below the noise** (big abrupt, median deflection < {DETECTABLE_DEFLECTION:g} on "
        "the commissioned model's residuals):",
        "",
        *_below_noise(per_case(big, _plant_fault), _plant_fault_name),
        "",
        _WHY,
        "",
        _why_table(big, _plant_fault, _plant_fault_name),
    ]
    return lines


def _plant_fault(row: Mapping[str, Any]) -> tuple[int, str]:
    return (row["plant"], row["fault"])


def _plant_fault_name(key: tuple[int, str]) -> str:
    return f"{key[1]} on plant {key[0]}"

"""The Markdown report and ``benchmark.json`` of ``bayes-fdi benchmark`` (pure rendering).

:func:`write_report` takes the results dictionary of
:func:`bayes_fdi.benchmark.harness.run_benchmark` and writes ``benchmark.json`` and
``benchmark.md`` atomically: a summary and a glossary (`bayes_fdi.benchmark.report_summary`),
the faults named, the product's targets against what was measured, the median and spread over
seeds of every PICalc index per scenario, what each fault does to the measured
signals against the noise (and so which faults no method can detect from CV, P1, P2, T1, X, F),
the group-level calibration of the per-second isolation probabilities, the false alarms on
simulated fault-free hours and on the real Lublin hour, and the published DAMADICS results side by
side (`bayes_fdi.benchmark.published.PUBLISHED`, listed with their citations on the DAMADICS
page of the documentation, ``docs/damadics.md``). The targets table counts a fault as detected
only in runs whose alarm was off when it began
(`bayes_fdi.benchmark.report_detection.judged_at_onset`).
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bayes_fdi.actuator import FAULT_TABLE, NOISE_STD
from bayes_fdi.atomic import write_text
from bayes_fdi.benchmark.published import PUBLISHED
from bayes_fdi.benchmark.report_detection import (
    DECLARED,
    ONSET_RULE,
    declared_clause,
    declared_r_fd_median,
    fault_free_target,
    first_detection_section,
    judged_at_onset,
    permanence_target,
)
from bayes_fdi.benchmark.report_summary import GLOSSARY, in_short_section
from bayes_fdi.benchmark.report_wrong import calibration_lines, calibration_target_rows
from bayes_fdi.diagnosis.seva import describe_state
from bayes_fdi.reporting import format_number, markdown_table, to_jsonable
from bayes_fdi.scoring.picalc import PICALC_KEYS

__all__ = ["DETECTABLE_DEFLECTION", "PUBLISHED", "render_report",
           "summarise", "target_rows", "write_report"]  # fmt: skip

#: Matched-filter separation (in noise standard deviations) below which no method can detect a
#: fault: an ideal detector that knows the exact noise-free signals with and without the fault
#: compares N(0, 1) with N(d, 1); keeping one false alarm in 8 h of 1-s decisions
#: (alpha = 1 / 28 800, z = 3.97) and detecting with 84 % probability needs d >= 3.97 + 1.
DETECTABLE_DEFLECTION = 5.0


def write_report(results: Mapping[str, Any], out: str | os.PathLike) -> tuple[Path, Path]:
    """Write ``benchmark.json`` and ``benchmark.md`` into ``out``; return their paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    js = write_text(out / "benchmark.json", json.dumps(to_jsonable(results), indent=1) + "\n")
    md = write_text(out / "benchmark.md", render_report(results))
    return js, md


# ----------------------------------------------------------------------------------------------
# summaries
# ----------------------------------------------------------------------------------------------
#: A fault code as the report writes it (f1 .. f19).
_FAULT_CODE = re.compile(r"\b(f\d{1,2})\b")


def _name(row: Mapping[str, Any]) -> str:
    return " ".join(p for p in (row["fault"], row["mode"], row.get("size")) if p)


def summarise(results: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """Per scenario: for each index the median, min and max over the seeds where it is
    determinable (not -1) and how many seeds that is."""
    rows: dict[str, list[Mapping[str, float]]] = {}
    for row in results["scenarios"]:
        rows.setdefault(_name(row), []).append(row["indices"])
    out: dict[str, dict[str, Any]] = {}
    for name, runs in rows.items():
        entry: dict[str, Any] = {"n": len(runs)}
        for key in PICALC_KEYS:
            v = np.array([r[key] for r in runs], dtype=np.float64)
            ok = v[v != -1.0]
            entry[key] = {
                "median": float(np.median(ok)) if ok.size else None,
                "min": float(ok.min()) if ok.size else None,
                "max": float(ok.max()) if ok.size else None,
                "determined": int(ok.size),
            }
        out[name] = entry
    return out


def _cell(stat: Mapping[str, Any], fmt: str, n: int) -> str:
    if stat["median"] is None:
        return "–"
    text = format(stat["median"], fmt)
    if stat["min"] != stat["max"]:
        text += f" [{format(stat['min'], fmt)}, {format(stat['max'], fmt)}]"
    if stat["determined"] < n:
        text += f" ({stat['determined']}/{n})"
    return text


_FORMATS = {
    "t_dt": ".0f",
    "t_it": ".0f",
    "r_fd": ".3f",
    "r_td": ".3f",
    "r_fi": ".3f",
    "r_ti": ".3f",
    "r_mi": ".3f",
    "fs_d": ".3f",
    "fs_i": ".3f",
    "dacc": ".2f",
}


def _index_table(results: Mapping[str, Any], summary: Mapping[str, Mapping[str, Any]]) -> str:
    figures = results.get("figures", {})
    header = ["scenario", *PICALC_KEYS, "timeline"]
    rows = []
    for name, entry in summary.items():
        n = entry["n"]
        cells = [_cell(entry[k], _FORMATS[k], n) for k in PICALC_KEYS]
        link = f"[png]({figures[name]})" if name in figures else ""
        rows.append([name, *cells, link])
    return markdown_table(header, rows)


def _effect_of(results: Mapping[str, Any]) -> dict[str, Mapping[str, Any]]:
    return {e["scenario"]: e for e in results.get("effects", [])}


def _big_abrupt(summary: Mapping[str, Any]) -> list[str]:
    return [n for n in summary if n.endswith("abrupt big")]


def _detected_all(entry: Mapping[str, Any]) -> bool:
    return entry["t_dt"]["determined"] == entry["n"]


def _median_r_fd(results: Mapping[str, Any]) -> float:
    return float(np.median([r["indices"]["r_fd"] for r in results["scenarios"]]))


def target_rows(results: Mapping[str, Any]) -> list[list[str]]:
    """The targets table: rows (target, measured, met: "yes", "**no**" or "–" not judged);
    detections judged by `ONSET_RULE` (`judged_at_onset`)."""
    rows: list[list[str]] = []
    results = judged_at_onset(results)
    summary = summarise(results)

    def add(target: str, measured: str, met: bool | None) -> None:
        rows.append([target, measured, "–" if met is None else ("yes" if met else "**no**")])

    med = _median_r_fd(results)
    add("median r_fd <= 0.01 (scenarios' fault-free parts)", f"{med:.4f}", med <= 0.01)
    if (declared := declared_r_fd_median(results)) is not None:
        add(f"(not a target) the same, {DECLARED}", f"{declared:.4f}", None)
    add(*fault_free_target(results["fault_free"]))
    real = results.get("real_hour")
    if real:
        add(
            "real hour (2nd half): no alarm",
            f"{real['alarms']} in {real['seconds']} s",
            real["alarms"] == 0,
        )
        add(
            "real hour: >= 95 % of seconds CLEAR",
            f"{100 * real['clear_share']:.1f} %",
            real["clear_share"] >= 0.95,
        )
    effects = _effect_of(results)
    big = _big_abrupt(summary)
    visible = [
        n for n in big if n in effects and max(effects[n]["rms"]["X"], effects[n]["rms"]["F"]) > 1.0
    ]
    missed = [n for n in visible if not _detected_all(summary[n])]
    add(
        "every big abrupt fault with an effect on X or F above the noise (RMS > 1 σ) detected "
        f"in every seed ({ONSET_RULE})",
        f"{len(visible) - len(missed)} of {len(visible)}"
        + (f"; missed in some seed: {', '.join(missed)}" if missed else ""),
        not missed,
    )
    t_dt = [
        summary[n]["t_dt"]["median"] for n in visible if summary[n]["t_dt"]["median"] is not None
    ]
    if t_dt:
        worst = max(t_dt)
        add(
            "median t_dt <= 10 s for those big abrupt faults",
            f"largest scenario median {worst:.0f} s",
            worst <= 10,
        )
    rows += [row for row in [permanence_target(results, visible)] if row]
    detected = [n for n in big if summary[n]["t_dt"]["determined"] * 2 >= summary[n]["n"] > 0]
    add(
        f">= 10 of the {len(big)} big abrupt scenarios detected (in >= half the seeds)",
        str(len(detected)),
        len(detected) >= 10 if len(big) == 14 else None,
    )
    r_ti = {n: summary[n]["r_ti"]["median"] for n in detected}
    low = [n for n, v in r_ti.items() if v is None or v < 0.9]
    add(
        "r_ti >= 0.9 (group level) for the detected big abrupt faults",
        f"{len(r_ti) - len(low)} of {len(r_ti)}" + (f"; below: {', '.join(low)}" if low else ""),
        not low if r_ti else None,
    )
    rows += calibration_target_rows(results)
    timing = results["timing"]
    rate = timing.get("run_samples_per_cpu_s")
    if rate:
        add(
            "`run` replays >= 20 000 samples/s on one core",
            f"{rate:,.0f} samples per CPU s",
            rate >= 20_000,
        )
    settings = results["settings"]
    if "fit_wall_s" in settings:
        total = settings["fit_wall_s"] + timing["wall_s"]
        full = settings.get("full_benchmark") and settings["n_seeds"] == 10
        add(
            "whole benchmark with 10 seeds <= 15 min (2-core machine)",
            f"{total / 60:.1f} min wall (fit {settings['fit_wall_s']:.0f} s)",
            total <= 900 if full else None,
        )
    return rows


def _effects_table(results: Mapping[str, Any], summary: Mapping[str, Any]) -> str:
    header = [
        "scenario",
        "RMS X",
        "RMS F",
        "RMS P1",
        "RMS P2",
        "RMS T1",
        "max X",
        "max F",
        "deflection",
        "oracle time [s]",
        "t_dt median [s]",
    ]
    rows = []
    for e in results.get("effects", []):
        name = e["scenario"]
        t_dt = summary.get(name, {}).get("t_dt", {}).get("median")
        oracle = e["oracle_time"]
        rows.append(
            [
                name,
                *(f"{e['rms'][c]:.2f}" for c in ("X", "F", "P1", "P2", "T1")),
                f"{e['max']['X']:.2f}",
                f"{e['max']['F']:.2f}",
                f"{e['deflection']:.1f}",
                "never" if oracle is None else f"{oracle:.0f}",
                "–" if t_dt is None else f"{t_dt:.0f}",
            ]
        )
    return markdown_table(header, rows)


def _undetectable_text(results: Mapping[str, Any]) -> list[str]:
    effects = results.get("effects", [])
    blind = [e for e in effects if e["deflection"] < DETECTABLE_DEFLECTION]
    lines = [
        f"Faults that no method can detect from CV, P1, P2, T1, X, F (deflection < "
        f"{DETECTABLE_DEFLECTION:g}):",
        "",
    ]
    if not blind:
        lines.append(
            "- none: every fault moves the measured signals far enough for an ideal detector."
        )
    for e in blind:
        fault = e["scenario"].split()[0]
        info = FAULT_TABLE[fault]
        why = (
            "no effect at all on X, F, P1, P2, T1 (bit-identical noise-free signals)"
            if e["deflection"] == 0.0
            else f"largest effect {max(e['max'].values()):.2f} σ in one second, matched-filter "
            f"deflection {e['deflection']:.2f} over the whole faulty part"
        )
        lines.append(f"- **{e['scenario']}** ({info.description}; enters as {info.entry}): {why}.")
    model = results.get("model_std") or {}
    if model.get("X") and model.get("F"):
        hidden = [
            e
            for e in effects
            if e["deflection"] >= DETECTABLE_DEFLECTION
            and all(e["max"][c] * NOISE_STD < model[c] for c in ("X", "F"))
            and max(e["max"][c] for c in ("P1", "P2", "T1")) < 1.0
        ]
        lines += [
            "",
            "Detectable in principle, but every second's effect on X and F stays below the "
            "normal models' predictive std (and P1, P2, T1 are untouched), so a method that must "
            "predict X and F from CV, P1, P2, T1 sees it only by accumulating evidence:",
            "",
        ]
        lines += [
            f"- **{e['scenario']}** ({FAULT_TABLE[e['scenario'].split()[0]].description}): largest "
            f"effect {e['max']['X'] * NOISE_STD / model['X']:.2f} (X) and "
            f"{e['max']['F'] * NOISE_STD / model['F']:.2f} (F) predictive std, deflection "
            f"{e['deflection']:.1f}."
            for e in hidden
        ] or ["- none."]
    return lines


def _published_table(summary: Mapping[str, Any]) -> str:
    def ours(name: str, keys: Sequence[str]) -> str:
        entry = summary.get(name)
        if entry is None:
            return "not run"
        return ", ".join(f"{k} {_cell(entry[k], _FORMATS[k], entry['n'])}" for k in keys)

    ours_by_method = [
        "group-level online diagnosis, not whole-run accuracy: see the tables above",
        "; ".join(
            f"{f}: " + ours(f"{f} abrupt big", ("t_dt", "r_fd", "r_td", "t_it", "r_fi", "r_ti"))
            for f in ("f16", "f17", "f18")
        ),
        "big abrupt not detected in every seed: "
        + (
            ", ".join(n.split()[0] for n in _big_abrupt(summary) if not _detected_all(summary[n]))
            or "none"
        ),
        "f17 incipient: " + ours("f17 incipient", ("fs_d", "fs_i")),
        "median t_dt over big abrupt: " + _median_over(summary, _big_abrupt(summary), "t_dt"),
    ]
    rows = [[m, s, d, f, o] for (m, s, d, f), o in zip(PUBLISHED, ours_by_method, strict=True)]
    return markdown_table(
        ["method", "source", "data", "published figures", "this run (simulated)"], rows
    )


def _median_over(summary: Mapping[str, Any], names: Sequence[str], key: str) -> str:
    values = [summary[n][key]["median"] for n in names if summary[n][key]["median"] is not None]
    return f"{np.median(values):.0f} s" if values else "–"


def _groups_table(results: Mapping[str, Any]) -> str:
    groups = results.get("groups") or {}
    undetectable = results.get("undetectable") or []
    rows = [["DGN0", ", ".join(["OK", *undetectable]), f"{1 / (len(undetectable) + 1):.3f}"]]
    rows += [
        [f"DGN{i}", ", ".join(m), f"{1 / len(m):.3f}"]
        for i, m in enumerate(groups.values(), start=1)
    ]
    dacc_tm = float(np.mean([float(r[2]) for r in rows]))
    return markdown_table(["diagnosis", "faults", "dacc_t"], rows) + f"\ndacc_tm = {dacc_tm:.3f}\n"


def _num(v: Any, fmt: str = ".3f") -> str:
    return format_number(v, fmt)


def render_report(results: Mapping[str, Any]) -> str:
    """The Markdown report of a benchmark run."""
    summary = summarise(results)
    targets = target_rows(results)
    blind = [
        e["scenario"] for e in results.get("effects", []) if e["deflection"] < DETECTABLE_DEFLECTION
    ]
    s, timing = results["settings"], results["timing"]
    lines = ["# DAMADICS benchmark (Step I) of the online diagnoser", ""]
    if s.get("excitation"):  # a shift family's run (bayes_fdi.benchmark.shift)
        lines += [f"> Inputs: shift family **{s['excitation']['name']}**, not DGen's sines: "
                  f"{s['excitation']['description']}", ""]  # fmt: skip
    if not s.get("full_benchmark"):
        lines += [
            "> **Not the benchmark's numbers**: a reduced run (fewer scenarios or horizons "
            "cut short); use `bayes-fdi benchmark --out DIR` for the full one.",
            "",
        ]
    lines += [
        f"{s['n_scenarios']} scenarios x {s['n_seeds']} noise seeds ({s['seeds'][0]} .. "
        f"{s['seeds'][-1]}); fault-free budget {s['hours']:g} h (seed "
        f"{results['fault_free']['seed']}). Wall time {timing['wall_s']:.0f} s: simulation "
        f"{timing['simulation_cpu_s']:.0f} CPU s, diagnosis {timing['run_cpu_s']:.0f} CPU s for "
        f"{timing['run_samples']:,} samples"
        + (f"; training took {s['fit_wall_s']:.0f} s wall." if "fit_wall_s" in s else ".")
        + (
            f" The diagnoser reads a detection as a fault only after {s['fit_proof_seconds']} s "
            "without detection before its change point (its fit proof); an earlier one is a "
            "model mismatch."
            if s.get("fit_proof_seconds")
            else ""
        ),
        "",
        *in_short_section(targets, summary, blind),
        "## Glossary",
        "",
        *(f"- **{name}**: {meaning}" for name, meaning in GLOSSARY),
        "",
        "## Targets",
        "",
        markdown_table(["target", "measured", "met"], targets),
        "## Indices per scenario",
        "",
        "Median over the seeds where the index is determinable, [min, max] when they differ, "
        "(k/N) when only k of the N seeds determine it; – = never determinable (PICalc's -1). "
        "Times in s from t_from = 900 s to the last rising edge (detection must be permanent); "
        "isolation at the group level (PID = the true fault's group is indicated).",
        "",
        _index_table(results, summary),
        *first_detection_section(results, summary),
        "## What each fault does to the measurements, against the noise",
        "",
        f"Noise-free simulations with and without the fault, over the faulty part: RMS and "
        f"largest difference in units of the sensor noise σ = {NOISE_STD:.5f} (normalised full "
        "scale). *Deflection*: the separation an ideal detector knowing both noise-free signals "
        "would see (sqrt of the summed squared effect on X, F, P1, P2, T1 in σ units), an upper "
        "bound for any method; *oracle time*: when it first reaches "
        f"{DETECTABLE_DEFLECTION:g}. The normal models' own median predictive std on the "
        f"fault-free parts is {_num(results['model_std']['X'], '.4f')} (X) and "
        f"{_num(results['model_std']['F'], '.4f')} (F): effects below that are hard to see "
        "for a method that must predict X and F from CV, P1, P2, T1."
        + _innovation_text(results.get("innovation_rms")),
        "",
        _effects_table(results, summary),
        *_undetectable_text(results),
        "",
    ]
    lines += calibration_lines(results)
    ff, real = results["fault_free"], results.get("real_hour")
    lines += [
        "## False alarms",
        "",
        f"- Simulated fault-free: {ff['hours']:g} h after a 300-s warm-up: {ff['alarms']} "
        f"alarm(s) ({ff['alarms_per_8h']:.2f} per 8 h), DD high {100 * ff['r_fd']:.3f} % of the "
        f"time, CLEAR {100 * ff['clear_share']:.1f} %.",
        f"- Fault-free parts of the scenarios: median r_fd {_median_r_fd(results):.4f}"
        f"{declared_clause(results)}.",
    ]
    if real:
        lines.append(
            f"- Real Lublin hour, second half ({real['seconds']} s; normal models and detector "
            f"fitted on the first half): {real['alarms']} alarm(s), CLEAR "
            f"{100 * real['clear_share']:.1f} %, statuses {real['status_counts']}."
        )
    lines += [
        "",
        "## Elementary diagnoses (form S1-MF)",
        "",
        _groups_table(results),
        "## Published DAMADICS results side by side",
        "",
        "The published figures are on other data (real Lublin segments, other fault sets or "
        "whole-run accuracy); they are listed for context, not as a like-for-like ranking.",
        "",
        _published_table(summary),
    ]
    return "\n".join(_with_fault_codes(lines)) + "\n"


def _with_fault_codes(lines: list[str]) -> list[str]:
    """``lines`` with a "Fault codes" section before the targets naming every fault code the
    report mentions (scenarios, elementary diagnoses, published results)."""
    used = set(_FAULT_CODE.findall("\n".join(lines)))
    at = lines.index("## Targets")
    named = [f"- {describe_state(f)}" for f in FAULT_TABLE if f in used]
    return [*lines[:at], "## Fault codes", "", *named, "", *lines[at:]]


def _innovation_text(rms: Mapping[str, Any] | None) -> str:
    """How well the normal models fit the scenarios' inputs: the whitened innovations' RMS on
    the fault-free parts (results without it say nothing)."""
    if not rms or rms.get("X") is None or rms.get("F") is None:
        return ""
    return (
        f" Their whitened innovations have an RMS of {_num(rms['X'], '.2f')} (X) and "
        f"{_num(rms['F'], '.2f')} (F) there (median over the runs); the whitening was fitted "
        "on out-of-fold residuals of the training data, so an RMS well above 1 says that the "
        "normal models fit these inputs worse than their training data."
    )

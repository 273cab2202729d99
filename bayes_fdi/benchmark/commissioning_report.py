"""The Markdown report and ``benchmark.json`` of the commissioning benchmark (pure rendering).

`write_commissioning_report` takes the results of
`bayes_fdi.benchmark.commissioning.run_commissioning_benchmark` and writes ``benchmark.json``
and ``benchmark.md`` atomically: a plain-language summary, the targets against the
measurements with the default model's figures beside, a glossary of the indices, the real hour
(twin check, clean half, PICalc indices per transplanted case, the faults below the noise, the
group-level confusion), the perturbed plants (what they are, their indices per plant and per
scenario), the fault codes with their names, and how the run was made.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from bayes_fdi.atomic import write_text
from bayes_fdi.benchmark.commissioning_sections import (
    median_or_none,
    percent,
    plants_section,
    real_hour_section,
)
from bayes_fdi.benchmark.commissioning_summary import (
    MODELS,
    big_abrupt_by_plant,
    confident_wrong_share,
    per_case,
)
from bayes_fdi.benchmark.report import DETECTABLE_DEFLECTION
from bayes_fdi.benchmark.report_detection import declared_r_fd_median
from bayes_fdi.benchmark.report_summary import DECISION_TERMS
from bayes_fdi.diagnosis.seva import describe_state
from bayes_fdi.reporting import markdown_table, to_jsonable
from bayes_fdi.scoring.picalc import INDEX_MEANINGS

__all__ = ["GLOSSARY", "render_commissioning_report", "write_commissioning_report"]

#: The indices and terms of the report, in plain words.
GLOSSARY: tuple[tuple[str, str], ...] = (
    *INDEX_MEANINGS,
    ("group", "faults the sensors cannot tell apart on this valve, named together (f4|f11)"),
    ("DGN0", "faults the commissioned diagnoser declares it cannot detect on this valve"),
    (
        "deflection",
        "how far a fault moves the diagnoser's whitened residuals, in noise "
        f"standard deviations summed over the faulty part; below {DETECTABLE_DEFLECTION:g} no "
        "detector built on these normal models can find it",
    ),
    *DECISION_TERMS,
    (
        "mismatch",
        "a detection whose change began outside the normal models' envelope (commission it)",
    ),
    ("unknown", "a detection unlike every fault the diagnoser knows"),
)


def write_commissioning_report(
    results: Mapping[str, Any], out: str | os.PathLike
) -> tuple[Path, Path]:
    """Write ``benchmark.json`` and ``benchmark.md`` into ``out``; return their paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    js = write_text(out / "benchmark.json", json.dumps(to_jsonable(results), indent=1) + "\n")
    md = write_text(out / "benchmark.md", render_commissioning_report(results))
    return js, md


# ---------------------------------------------------------------------------------- summary
def _visible_big(rows, key) -> tuple[dict, list]:
    """Per case of big abrupt commissioned rows: the statistics, and the cases whose effect
    stands out of the noise."""
    big = per_case(rows, key)
    return big, [k for k, s in big.items() if (s["deflection"] or 0) >= DETECTABLE_DEFLECTION]


def _detection_sentence(big: Mapping[Any, Any], visible: Sequence[Any], where: str) -> str:
    found = [k for k in visible if big[k]["t_dt"]["determined"] == big[k]["n"]]
    t_dt = [big[k]["t_dt"]["median"] for k in found]
    r_ti = [big[k]["r_ti"]["median"] or 0.0 for k in visible]
    text = (
        f"{len(visible)} of {len(big)} big abrupt faults {where} move the diagnoser's residuals "
        f"beyond their noise; {len(found)} of these were detected for good every time"
    )
    if t_dt:
        text += f", after {median_or_none(t_dt):.0f} s (median)"
    if r_ti:
        text += f", and their group was named {percent(median_or_none(r_ti))} of the faulty time"
    return text


def _summary_real(real: Mapping[str, Any]) -> list[str]:
    c, d = real["clean"]["commissioned"], real["clean"]["default"]
    rows = [r for r in real["cases"] if r["model"] == "commissioned"]
    big, visible = _visible_big([r for r in rows if r["size"] == "big"], lambda r: r["fault"])
    wrong = confident_wrong_share(rows)
    seconds = real["commissioning"]["seconds"]["total"]
    return [
        f"- **The real valve** (the Lublin hour): commissioned on its first half hour in "
        f"{seconds:.0f} s, the diagnoser raised {c['alarms']} alarm(s) in the following half "
        f"hour and said CLEAR {percent(c['clear_share'])} of the time. The default model, "
        f"trained on the nominal simulator, raised {d['alarms']} (CLEAR "
        f"{percent(d['clear_share'])}).",
        "- **Faults transplanted onto that real half hour**: "
        + _detection_sentence(big, visible, "(of the library)")
        + f". A confident wrong answer came in {percent(wrong['share'])} of all faulty "
        "seconds (all sizes).",
    ]


def _model_sentence(model: str, rows: Sequence[Mapping[str, Any]]) -> str:
    big = big_abrupt_by_plant(rows)
    r_fd = median_or_none([r["indices"]["r_fd"] for r in rows])
    det = [len(e["detected"]) for e in big.values()]
    declared = declared_r_fd_median(rows)
    faults = "" if declared is None else f"; declared faults, not mismatch: {percent(declared)}"
    text = (
        f"the {model} model had the alarm on {percent(r_fd)} of the fault-free time (median"
        f"{faults}), "
        f"detected {min(det, default=0)}-{max(det, default=0)} of the "
        f"{max((e['scenarios'] for e in big.values()), default=0)} big abrupt faults per plant "
        f"and was confidently wrong {percent(confident_wrong_share(rows)['share'])} of the "
        "faulty seconds"
    )
    if r_fd is not None and r_fd > 0.5:
        text += " (a standing alarm: its detections say nothing about the faults)"
    return text


def _summary_plants(plants: Sequence[Mapping[str, Any]]) -> list[str]:
    cases = [r for p in plants for r in p["cases"]]
    walls = [p["commissioning"]["wall_s"] for p in plants if "wall_s" in p["commissioning"]]
    refused = [p["plant"]["index"] for p in plants if "refused" in p["commissioning"]]
    text = (
        f"- **{len(plants)} simulated valve(s) 20-30 % off the nominal one**, each in its own "
        "level loop, commissioned on one healthy hour"
        + (f" ({min(walls) / 60:.1f}-{max(walls) / 60:.1f} min each)" if walls else "")
        + (f"; commissioning refused plant(s) {refused}" if refused else "")
        + ": "
        + "; ".join(
            _model_sentence(m, [r for r in cases if r["model"] == m])
            for m in MODELS
            if any(r["model"] == m for r in cases)
        )
        + "."
    )
    lines = [text]
    rows = [r for r in cases if r["model"] == "commissioned" and r["size"] == "big"]
    if rows:
        big, visible = _visible_big(rows, lambda r: (r["plant"], r["fault"]))
        gains = [
            p["commissioning"]["whitening_gain"] for p in plants if "wall_s" in p["commissioning"]
        ]
        factors = ", ".join(
            f"{min(g[c] for g in gains):.2f}-{max(g[c] for g in gains):.2f} ({c})"
            for c in ("X", "F")
        )
        lines.append(
            "- **On the plants**, "
            + _detection_sentence(big, visible, "(plant by plant)")
            + ". The detector watches the residuals after an AR whitening, which multiplies a "
            f"persistent shift of a standardised residual by {factors} on these plants: where "
            "that factor is small, a fault that shifts the residual for good shows at its "
            "onset, then fades from the detector's view (see *Why visible faults were "
            "missed*)."
        )
    return lines


def _summary(results: Mapping[str, Any]) -> list[str]:
    lines = ["## In short", ""]
    if results.get("real_hour"):
        lines += _summary_real(results["real_hour"])
    if results.get("plants"):
        lines += _summary_plants(results["plants"])
    met = [r for r in results["targets"] if r[2] == "yes"]
    missed = [r[0] for r in results["targets"] if r[2] == "**no**"]
    lines += [
        f"- **Targets**: {len(met)} met, {len(missed)} missed"
        + (": " + "; ".join(missed) if missed else "")
        + " (table below).",
        "",
    ]
    return lines


def _fault_codes(results: Mapping[str, Any]) -> list[str]:
    real = results.get("real_hour")
    faults = (
        real["faults"]
        if real
        else sorted({r["fault"] for p in results["plants"] for r in p["cases"]})
    )
    return ["## Fault codes", "", *(f"- {describe_state(f)}" for f in faults), ""]


def _provenance(results: Mapping[str, Any]) -> list[str]:
    s, t, load = results["settings"], results["timing"], results.get("load", {})
    return [
        "## How this run was made",
        "",
        f"- {s['n_plants']} plant(s) x {s['n_scenarios']} scenario(s) x {s['n_seeds']} seed(s); "
        f"{s['draws']} twin draw(s) per transplanted case; small version: "
        f"{bool(s.get('small'))}.",
        f"- Wall time {t['wall_s'] / 60:.1f} min, {t['cpu_s'] / 60:.1f} CPU min in this process"
        + (
            f"; default model fitted in {s['default_fit_wall_s']:.0f} s"
            if "default_fit_wall_s" in s
            else ""
        )
        + (
            f"; load average {load['start']:.1f} at the start, {load['end']:.1f} at the end, "
            f"{load['cpus']} CPUs"
            if load.get("start") is not None
            else ""
        )
        + ".",
        "",
    ]


def render_commissioning_report(results: Mapping[str, Any]) -> str:
    """The Markdown report of a commissioning benchmark run."""
    s = results["settings"]
    lines = ["# Commissioning benchmark", ""]
    if s.get("small") or not s.get("full_scenarios") or s["n_plants"] < 5:
        lines += [
            "> **A reduced run** (fewer plants, seeds or scenarios, or horizons cut): "
            "use `bayes-fdi benchmark --commissioning --out DIR` for the full one.",
            "",
        ]
    lines += _summary(results)
    lines += [
        "## Targets",
        "",
        markdown_table(
            ["target", "measured (commissioned)", "met", "default model beside"], results["targets"]
        ),
        "## Glossary",
        "",
        *(f"- **{term}**: {meaning}" for term, meaning in GLOSSARY),
        "",
    ]
    if results.get("real_hour"):
        lines += real_hour_section(results["real_hour"])
    if results.get("plants"):
        lines += plants_section(results)
    lines += _fault_codes(results) + _provenance(results)
    return "\n".join(lines) + "\n"

"""The numbers of the commissioning benchmark's report: index statistics, confusion, targets.

Pure functions of the results dictionary of
`bayes_fdi.benchmark.commissioning.run_commissioning_benchmark` (no diagnoser, no simulation):
`index_stats` (median and range of every PICalc index over cases), `real_hour_table` and
`plant_tables` (per case), `group_confusion` (how the faulty seconds of each true group were
named), `targets` (the product's targets against the measurements, with the default model's
figures beside).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from bayes_fdi.benchmark.report import DETECTABLE_DEFLECTION
from bayes_fdi.benchmark.report_wrong import published_wrong
from bayes_fdi.scoring.picalc import PICALC_KEYS, UNDETERMINED

__all__ = [
    "MODELS",
    "big_abrupt_by_plant",
    "confident_wrong_share",
    "group_confusion",
    "index_stats",
    "per_case",
    "targets",
]

#: The diagnosers compared: the commissioned one and the default (nominal) one beside it.
MODELS = ("commissioned", "default")
#: Confidence-wrong and detection targets of the product.
MAX_CONFIDENT_WRONG, MAX_T_DT, MIN_R_TI_VISIBLE, MIN_R_TI_PLANTS = 0.02, 10.0, 0.8, 0.9
MIN_BIG_DETECTED, MAX_R_FD, MIN_CLEAR = 10, 0.01, 0.95
COVERAGE, ONE_HOUR_SECONDS = (0.90, 0.98), 300.0


def index_stats(rows: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """For each PICalc index over ``rows``: median, min and max where it is determined (not -1)
    and on how many rows; ``n`` rows; the median effect deflection when the rows carry one."""
    out: dict[str, Any] = {"n": len(rows)}
    for key in PICALC_KEYS:
        v = np.array([r["indices"][key] for r in rows], dtype=np.float64)
        ok = v[v != UNDETERMINED]
        out[key] = {
            "median": float(np.median(ok)) if ok.size else None,
            "min": float(ok.min()) if ok.size else None,
            "max": float(ok.max()) if ok.size else None,
            "determined": int(ok.size),
        }
    effects = [r["effect"]["deflection"] for r in rows if r.get("effect")]
    out["deflection"] = float(np.median(effects)) if effects else None
    out["confident_wrong"] = sum(r["confident_wrong_seconds"] for r in rows) / max(
        sum(r["faulty_seconds"] for r in rows), 1
    )
    return out


def per_case(
    rows: Iterable[Mapping[str, Any]], key: Callable[[Mapping[str, Any]], Any]
) -> dict[Any, dict[str, Any]]:
    """`index_stats` of the rows grouped by ``key(row)`` (in order of first appearance)."""
    groups: dict[Any, list[Mapping[str, Any]]] = {}
    for r in rows:
        groups.setdefault(key(r), []).append(r)
    return {k: index_stats(v) for k, v in groups.items()}


def confident_wrong_share(rows: Iterable[Mapping[str, Any]]) -> dict[str, float]:
    """Faulty seconds answered with a confident wrong group, of all faulty seconds of ``rows``
    (``seconds``, ``faulty_seconds``, ``share``), and those whose most probable group was
    confident and wrong, the seconds answered "unknown" included (``probabilities_seconds``,
    ``probabilities_share``; see `bayes_fdi.benchmark.collection.confident_wrong`)."""
    rows = list(rows)
    wrong = sum(r["confident_wrong_seconds"] for r in rows)
    published = sum(r["confident_wrong_probabilities_seconds"] for r in rows)
    total = sum(r["faulty_seconds"] for r in rows)
    return {
        "seconds": int(wrong),
        "faulty_seconds": int(total),
        "share": wrong / max(total, 1),
        "probabilities_seconds": int(published),
        "probabilities_share": published / max(total, 1),
    }


def _wrong_text(wrong: Mapping[str, Any]) -> str:
    """A `confident_wrong_share` as a percentage, with the group probabilities' own count
    where it differs (`~bayes_fdi.benchmark.report_wrong.published_wrong`)."""
    return f"{wrong['share']:.2%}{published_wrong(wrong)}"


def group_confusion(rows: Iterable[Mapping[str, Any]]) -> dict[str, dict[str, float]]:
    """Per true group (``DGN0``: declared undetectable; ``unknown to the model``), the share of
    its faulty seconds named by each state, and not detected."""
    counts: dict[str, dict[str, int]] = {}
    for r in rows:
        truth = r["true_group"] or "unknown to the model"
        row = counts.setdefault(truth, {})
        for state, n in r["states"].items():
            row[state] = row.get(state, 0) + int(n)
    return {
        truth: {s: n / max(sum(row.values()), 1) for s, n in sorted(row.items())}
        for truth, row in counts.items()
    }


def _detected_everywhere(stats: Mapping[str, Any]) -> bool:
    return stats["t_dt"]["determined"] == stats["n"]


def _visible(cases: Mapping[Any, Mapping[str, Any]]) -> list[Any]:
    """The cases whose median effect deflection reaches `DETECTABLE_DEFLECTION`."""
    return [k for k, s in cases.items() if (s["deflection"] or 0.0) >= DETECTABLE_DEFLECTION]


def big_abrupt_by_plant(rows: Iterable[Mapping[str, Any]]) -> dict[int, dict[str, Any]]:
    """Per plant: the big abrupt scenarios detected in at least half the seeds, and those of
    them whose median group-level r_ti reaches 0.9."""
    cases = per_case(
        (r for r in rows if r["mode"] == "abrupt" and r["size"] == "big"),
        lambda r: (r["plant"], r["scenario"]),
    )
    out: dict[int, dict[str, Any]] = {}
    for (plant, name), s in cases.items():
        entry = out.setdefault(plant, {"scenarios": 0, "detected": [], "isolated": []})
        entry["scenarios"] += 1
        if 2 * s["t_dt"]["determined"] >= s["n"] > 0:
            entry["detected"].append(name)
            if (s["r_ti"]["median"] or 0.0) >= MIN_R_TI_PLANTS:
                entry["isolated"].append(name)
    return out


def _visible_faults_rows(
    cases: Mapping[Any, Mapping[str, Any]], name: Callable[[Any], str]
) -> tuple[str, bool | None, list[str]]:
    """Measured text and verdict of 'visible big abrupt faults all detected, fast, isolated'."""
    visible = _visible(cases)
    if not visible:
        return "no big abrupt fault stands out of the noise", None, []
    missed = [name(k) for k in visible if not _detected_everywhere(cases[k])]
    slow = [name(k) for k in visible if (cases[k]["t_dt"]["median"] or 0.0) > MAX_T_DT]
    low = [name(k) for k in visible if (cases[k]["r_ti"]["median"] or 0.0) < MIN_R_TI_VISIBLE]
    t_dt = [cases[k]["t_dt"]["median"] for k in visible if cases[k]["t_dt"]["median"] is not None]
    r_ti = [cases[k]["r_ti"]["median"] or 0.0 for k in visible]
    text = (
        f"{len(visible) - len(missed)} of {len(visible)} detected in every draw or seed"
        + (f" (missed: {', '.join(missed)})" if missed else "")
        + (f"; t_dt median {np.median(t_dt):.0f} s, largest {max(t_dt):.0f} s" if t_dt else "")
        + (f" ({', '.join(slow)} over {MAX_T_DT:g} s)" if slow else "")
        + f"; r_ti median {np.median(r_ti):.2f}"
        + (f", below {MIN_R_TI_VISIBLE:g}: {', '.join(low)}" if low else "")
    )
    return text, not (missed or slow or low), [name(k) for k in visible]


def _row(target: str, measured: str, met: bool | None, beside: str = "") -> list[str]:
    return [target, measured, "–" if met is None else ("yes" if met else "**no**"), beside]


def _real_hour_targets(real: Mapping[str, Any]) -> list[list[str]]:
    rows = []
    clean = real["clean"]
    c, d = clean["commissioned"], clean.get("default")
    rows.append(
        _row(
            "real hour, clean second half: 0 alarms",
            f"{c['alarms']} in {c['seconds']} s",
            c["alarms"] == 0,
            f"{d['alarms']} alarm(s)" if d else "",
        )
    )
    rows.append(
        _row(
            f"real hour, clean second half: >= {MIN_CLEAR:.0%} CLEAR",
            f"{c['clear_share']:.1%}",
            c["clear_share"] >= MIN_CLEAR,
            f"{d['clear_share']:.1%}" if d else "",
        )
    )
    big = {
        m: per_case(
            (r for r in real["cases"] if r["model"] == m and r["size"] == "big"),
            lambda r: r["fault"],
        )
        for m in MODELS
    }
    text, met, _ = _visible_faults_rows(big["commissioned"], str)
    rows.append(
        _row(
            "real hour, transplanted big abrupt faults above the noise: all detected, "
            f"median t_dt <= {MAX_T_DT:g} s, group r_ti >= {MIN_R_TI_VISIBLE:g}",
            text,
            met,
        )
    )
    wrong = {m: confident_wrong_share(r for r in real["cases"] if r["model"] == m) for m in MODELS}
    rows.append(
        _row(
            f"real hour: confident (p > 0.9) wrong group in <= {MAX_CONFIDENT_WRONG:.0%} of the "
            "faulty seconds (all sizes)",
            _wrong_text(wrong["commissioned"]),
            wrong["commissioned"]["share"] <= MAX_CONFIDENT_WRONG,
            _wrong_text(wrong["default"]),
        )
    )
    return rows


def _plant_targets(plants: Sequence[Mapping[str, Any]]) -> list[list[str]]:
    rows = []
    cases = [r for p in plants for r in p["cases"]]
    r_fd = {m: [r["indices"]["r_fd"] for r in cases if r["model"] == m] for m in MODELS}
    med = {m: float(np.median(v)) if v else None for m, v in r_fd.items()}
    rows.append(
        _row(
            f"perturbed plants: median r_fd <= {MAX_R_FD:g}",
            "–" if med["commissioned"] is None else f"{med['commissioned']:.4f}",
            None if med["commissioned"] is None else med["commissioned"] <= MAX_R_FD,
            "–" if med["default"] is None else f"{med['default']:.4f}",
        )
    )
    big = {m: big_abrupt_by_plant(r for r in cases if r["model"] == m) for m in MODELS}

    def counts(m: str, what: str) -> str:
        return ", ".join(f"{len(e[what])}" for _, e in sorted(big[m].items())) or "–"

    com = big["commissioned"]
    full = all(e["scenarios"] == 14 for e in com.values()) and bool(com)
    rows.append(
        _row(
            f"perturbed plants: >= {MIN_BIG_DETECTED} of 14 big abrupt detected (each plant; in "
            ">= half the seeds)",
            f"per plant: {counts('commissioned', 'detected')}",
            all(len(e["detected"]) >= MIN_BIG_DETECTED for e in com.values()) if full else None,
            f"per plant: {counts('default', 'detected')}",
        )
    )
    rows.append(
        _row(
            f"perturbed plants: group r_ti >= {MIN_R_TI_PLANTS:g} on those (each plant)",
            "per plant: "
            + ", ".join(
                f"{len(e['isolated'])} of {len(e['detected'])}" for _, e in sorted(com.items())
            ),
            all(len(e["isolated"]) == len(e["detected"]) for e in com.values()) if com else None,
            "per plant: "
            + ", ".join(
                f"{len(e['isolated'])} of {len(e['detected'])}"
                for _, e in sorted(big["default"].items())
            ),
        )
    )
    by_case = per_case(
        (
            r
            for r in cases
            if r["model"] == "commissioned" and r["mode"] == "abrupt" and r["size"] == "big"
        ),
        lambda r: (r["plant"], r["fault"]),
    )
    text, met, _ = _visible_faults_rows(by_case, lambda k: f"{k[1]} (plant {k[0]})")
    rows.append(
        _row(
            "perturbed plants, big abrupt faults above the noise: all detected, median t_dt <= "
            f"{MAX_T_DT:g} s, group r_ti >= {MIN_R_TI_VISIBLE:g}",
            text,
            met,
        )
    )
    wrong = {m: confident_wrong_share(r for r in cases if r["model"] == m) for m in MODELS}
    rows.append(
        _row(
            f"perturbed plants: confident wrong group in <= {MAX_CONFIDENT_WRONG:.0%} of the "
            "faulty seconds",
            _wrong_text(wrong["commissioned"]),
            wrong["commissioned"]["share"] <= MAX_CONFIDENT_WRONG if cases else None,
            _wrong_text(wrong["default"]),
        )
    )
    return rows


def _twin_targets(results: Mapping[str, Any]) -> list[list[str]]:
    checks = []
    if results.get("real_hour"):
        checks.append(("real hour", results["real_hour"]["twin_check"]))
    checks += [
        (f"plant {p['plant']['index']}", p["twin_check"])
        for p in results.get("plants", [])
        if p.get("twin_check")
    ]
    if not checks:
        return []
    lo, hi = COVERAGE
    cov = [f"{name}: X {c['coverage']['X']:.1%}, F {c['coverage']['F']:.1%}" for name, c in checks]
    cov_ok = all(lo <= c["coverage"][ch] <= hi for _, c in checks for ch in ("X", "F"))
    rms = [
        f"{name}: X {c['rms']['X']:.4f} / {c['rms_nominal']['X']:.4f}, "
        f"F {c['rms']['F']:.4f} / {c['rms_nominal']['F']:.4f}"
        for name, c in checks
    ]
    rms_ok = all(c["rms"][ch] <= c["rms_nominal"][ch] for _, c in checks for ch in ("X", "F"))
    return [
        _row(
            f"twin: 95 % predictive coverage {lo:.0%}-{hi:.0%} on held-out healthy data",
            "; ".join(cov),
            cov_ok,
        ),
        _row("twin: RMS at or below the nominal model's (twin / nominal)", "; ".join(rms), rms_ok),
    ]


def _time_targets(results: Mapping[str, Any]) -> list[list[str]]:
    walls = [
        p["commissioning"]["wall_s"]
        for p in results.get("plants", [])
        if "wall_s" in p["commissioning"]
    ]
    load = results.get("load", {})
    rows = []
    if walls:
        during = ""
        if load.get("start") is not None:
            during = (
                f" (load average {load['start']:.1f} at the start, {load['end']:.1f} at the end)"
            )
        measured = "per plant: " + ", ".join(f"{w / 60:.1f}" for w in walls) + " min wall"
        rows.append(
            _row(
                f"commissioning on 1 h of data <= {ONE_HOUR_SECONDS / 60:.0f} min (2-core machine)",
                measured + during,
                max(walls) <= ONE_HOUR_SECONDS,
            )
        )
    rows.append(_row("commissioning on 24 h of data <= 15 min", "not measured by this run", None))
    return rows


def targets(results: Mapping[str, Any]) -> list[list[str]]:
    """Rows ``[target, measured (commissioned), met, default model beside]``."""
    rows = []
    if results.get("real_hour"):
        rows += _real_hour_targets(results["real_hour"])
    if results.get("plants"):
        rows += _plant_targets(results["plants"])
    return rows + _twin_targets(results) + _time_targets(results)

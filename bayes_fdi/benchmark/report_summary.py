"""The opening of ``benchmark.md``: a plain-language summary and the glossary of its terms.

`in_short_section` says in a few lines, from the results alone, how many targets were met, what
was measured for those missed, how many scenarios were detected and isolated, and which faults
leave the measurements untouched. `GLOSSARY` defines every index and abbreviation
``benchmark.md`` prints: the PICalc indices (one definition,
:data:`bayes_fdi.scoring.picalc.INDEX_MEANINGS`) with the first detection beside them
(:data:`~bayes_fdi.scoring.picalc.FIRST_DETECTION_MEANINGS`), the DAMADICS terms, and the
decision terms (:data:`DECISION_TERMS`) the commissioning benchmark's report shares.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from bayes_fdi.scoring.picalc import FIRST_DETECTION_MEANINGS, INDEX_MEANINGS

__all__ = ["DECISION_TERMS", "GLOSSARY", "in_short_section"]

#: Terms of the online diagnoser's decisions, used by both benchmark reports.
DECISION_TERMS: tuple[tuple[str, str], ...] = (
    ("confident wrong", "a second whose most probable group is above 0.9 and is not the fault's"),
    ("CLEAR", "the SEVA status of a second with no fault detected"),
)

#: The indices and abbreviations of ``benchmark.md``, in plain words.
GLOSSARY: tuple[tuple[str, str], ...] = (
    *INDEX_MEANINGS,
    *FIRST_DETECTION_MEANINGS,
    (
        "DD, PID, CID",
        "the benchmark's decision signals, one per second: DD the detection decision (alarm "
        "on), PID the primary isolation decision (the fault's group is named), CID the "
        "complementary isolation decision (how many other groups are named)",
    ),
    (
        "t_on, t_from, t_hor",
        "the scoring zone's start, the fault's start and the zone's end, in seconds; the "
        "fault-free part is [t_on, t_from), the faulty part [t_from, t_hor)",
    ),
    ("–", "an index that cannot be determined, e.g. never detected (PICalc's -1)"),
    (
        "big / medium / small, abrupt / incipient",
        "the scenarios' fault strengths; the fault appears at once or grows linearly",
    ),
    (
        "group, DGN",
        "an elementary diagnosis: faults the sensors cannot tell apart, named together; DGN0 is "
        "the OK state with the faults the diagnoser declares it cannot detect",
    ),
    (
        "dacc_t, dacc_tm",
        "theoretical diagnosis accuracy of one elementary diagnosis (1 / its number of faults) "
        "and its mean over all of them",
    ),
    (
        "σ, RMS, deflection, oracle time",
        "the sensor noise std; a fault's root-mean-square effect on a signal in σ; the "
        "separation an ideal detector knowing both noise-free signals would see; when it first "
        "reaches the detectable level",
    ),
    (
        "ECE, MCE",
        "top-label expected / maximum calibration error: the mean / largest gap between the "
        "confidence in the named group and how often it is right",
    ),
    *DECISION_TERMS,
)


def in_short_section(
    targets: Sequence[Sequence[str]],
    summary: Mapping[str, Mapping[str, Any]],
    blind: Sequence[str],
) -> list[str]:
    """ "In short": the targets met, the measurements of those missed, the scenarios detected
    and isolated, and the faults no method can detect.

    Parameters
    ----------
    targets
        The rows (target, measured, met) of the report's target table; met is ``"yes"``,
        ``"**no**"`` or ``"–"`` (not judged).
    summary
        Per scenario, each index's median, min, max over the seeds and how many seeds
        determine it, and the number of seeds ``n`` (``bayes_fdi.benchmark.report.summarise``).
    blind
        The scenarios whose effect on the measurements is below what any method can detect.
    """
    judged = [row for row in targets if row[2] != "–"]
    missed = [row for row in judged if row[2] != "yes"]
    lines = ["## In short", "", f"- {len(judged) - len(missed)} of {len(judged)} targets met."]
    if missed:
        lines.append("- Not met: " + "; ".join(f"{t} (measured: {m})" for t, m, _ in missed) + ".")

    def in_half(key: str) -> list[str]:
        return [n for n, e in summary.items() if 2 * e[key]["determined"] >= e["n"] > 0]

    lines.append(
        f"- Of the {len(summary)} scenarios, {len(in_half('t_dt'))} are detected and "
        f"{len(in_half('t_it'))} isolated (the fault's group named for good) in at least half "
        "the seeds."
    )
    if blind:
        lines.append(
            "- No method can detect " + ", ".join(blind) + " from the measurements: the "
            "fault's effect on them is below what even an ideal detector can find (see what "
            "each fault does to the measurements)."
        )
    return [*lines, ""]

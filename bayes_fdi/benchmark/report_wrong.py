"""How the benchmark report words its confident wrong seconds.

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

__all__ = ["WRONG_SCENARIOS_SHOWN", "published_wrong", "wrong_by_scenario"]


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

"""The real fault events of a Lublin day file, scored with the benchmark's indices (PICalc).

A day file of the DAMADICS benchmark's Lublin data lists the real fault events of its actuators
(`bayes_fdi.datasets.LUBLIN_FAULT_EVENTS`); ``bayes-fdi diagnose`` scores the stream of such a day
at each event (`score_lublin_events`) and writes ``events.csv``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

__all__ = [
    "EVENT_LEAD_SECONDS",
    "event_summary",
    "fault_events",
    "score_lublin_events",
    "write_events",
]

#: Fault-free seconds before a real fault event scored (the Step I benchmark uses 600 s).
EVENT_LEAD_SECONDS = 600


def fault_events(attrs: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The fault events a recording's attributes list (``fault_events``, JSON); [] if none."""
    text = attrs.get("fault_events")
    if not text:
        return []
    try:
        events = json.loads(text)
    except (TypeError, ValueError):
        return []
    return [e for e in events if isinstance(e, dict) and {"fault", "start", "end"} <= set(e)]


def score_lublin_events(
    stream: xr.Dataset, events: Sequence[Mapping[str, Any]]
) -> list[dict[str, Any]]:
    """The benchmark's indices of each real fault event in a day's stream (one run).

    Each event is scored by :func:`~bayes_fdi.scoring.picalc.picalc` over the
    zone ``[t_on, t_hor)``: ``t_from`` = the event's start, ``t_hor`` = one second after its end
    (Step III's zones are user-entered; the fault ends there), ``t_on`` = ``EVENT_LEAD_SECONDS``
    before the start, later if the recording or the previous event (of any fault) ends later.
    An event the stream does not cover is listed with ``covered = False`` and no indices.
    """
    from bayes_fdi.scoring.decision_signals import decision_signals
    from bayes_fdi.scoring.picalc import PICALC_KEYS, picalc

    t = np.asarray(stream["time"].values, dtype=np.float64)
    ordered = sorted(events, key=lambda e: (float(e["start"]), float(e["end"])))
    out = []
    for k, event in enumerate(ordered):
        start, end = float(event["start"]), float(event["end"])
        previous_end = max((float(e["end"]) for e in ordered[:k]), default=-np.inf)
        t_on = max(start - EVENT_LEAD_SECONDS, t[0], previous_end + 1)
        t_hor = end + 1
        row: dict[str, Any] = {
            "fault": event["fault"], "start": start, "end": end, "actuator": event.get("actuator"),
            "date": event.get("date"), "note": event.get("note", ""), "t_on": t_on,
            "covered": bool(t[0] <= t_on < start < t_hor <= t[-1] + 1),
        }  # fmt: skip
        if row["covered"]:
            signals = decision_signals(stream, str(event["fault"]))
            indices = picalc(t, signals.dd, signals.pid, signals.cid, t_on=t_on, t_from=start,
                             t_hor=t_hor, indicated=signals.indicated,
                             group_sizes=signals.group_sizes)  # fmt: skip
            row.update(indices)
            inside = (t >= start) & (t < t_hor)
            named = np.asarray(stream["state"].values).astype(str)[inside & signals.dd]
            values, n = np.unique(named, return_counts=True)
            row["isolated_as"] = str(values[np.argmax(n)]) if n.size else ""
        else:
            row.update(dict.fromkeys(PICALC_KEYS, np.nan))
            row["isolated_as"] = ""
        out.append(row)
    return out


def write_events(rows: Sequence[Mapping[str, Any]], path: Path) -> None:
    """``events.csv``: one row per scored event (written atomically)."""
    import pandas as pd

    from bayes_fdi.atomic import atomic_path

    with atomic_path(path) as tmp:
        pd.DataFrame(list(rows)).to_csv(tmp, index=False, float_format="%.6g", lineterminator="\n")


def event_summary(stream: xr.Dataset, events, scored) -> dict[str, Any]:
    """False-alarm share outside the events and how many events were detected."""
    t = np.asarray(stream["time"].values, dtype=np.float64)
    dd = np.asarray(stream["DD"].values, dtype=bool)
    faulty = np.zeros(t.size, dtype=bool)
    for e in events:
        faulty |= (t >= float(e["start"])) & (t <= float(e["end"]))
    covered = [r for r in scored if r["covered"]]
    return {
        "events": len(scored),
        "covered": len(covered),
        "detected": sum(1 for r in covered if r["t_dt"] >= 0),
        "isolated": sum(1 for r in covered if r["t_it"] >= 0),
        "dd_share_outside_events": float(dd[~faulty].mean()) if (~faulty).any() else np.nan,
    }

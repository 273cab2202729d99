"""What a commissioned diagnoser can be expected to do, measured on held-out transplants.

`expected_performance` transplants every fault of the library at fixed sizes (abrupt, a fixed
onset) onto the valve's healthy data with parameter and noise draws that no fitting step used,
runs the commissioned diagnoser over them and reports, per fault and size: whether it was
detected after the onset and how fast, the share of its faulty seconds named by the fault's
isolability group, the share named confidently wrong, and the share called unknown.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr

__all__ = ["CONFIDENT", "expected_performance", "score_transplants"]

#: A group probability above this is a confident answer.
CONFIDENT = 0.9


def _group_of(fault: str, groups: Sequence[Sequence[str]]) -> int | None:
    return next((j for j, g in enumerate(groups) if fault in g), None)


def score_transplants(stream: xr.Dataset, runs: xr.Dataset, groups: Sequence[Sequence[str]]):
    """One row per run of a diagnosed transplant library (``runs`` with coordinates ``state``,
    ``strength``, ``onset``): detection, its delay, and how the faulty seconds were named."""
    labels = ["|".join(g) for g in groups]
    rows = []
    t = np.asarray(stream["time"].values, dtype=np.float64)
    for r in range(runs.sizes["run"]):
        one = stream.isel(run=r)
        fault = str(runs["state"].values[r])
        onset = float(runs["onset"].values[r])
        faulty = t >= onset
        dd = np.asarray(one["DD"].values, dtype=bool)
        rise = np.flatnonzero(dd & ~np.concatenate([[False], dd[:-1]]) & faulty)
        state = np.asarray(one["state"].values).astype(str)
        prob = np.asarray(one["probability"].values, dtype=np.float64)
        true = _group_of(fault, groups)
        named_right = np.isin(state, [labels[true]]) if true is not None else np.zeros_like(dd)
        wrong = dd & ~np.isin(state, ["unknown", "mismatch", "fn"]) & ~named_right
        n_faulty = max(int(faulty.sum()), 1)
        rows.append(
            {
                "fault": fault,
                "strength": float(runs["strength"].values[r]),
                "detected": bool(rise.size),
                "detection_seconds": float(t[rise[0]] - onset) if rise.size else None,
                "named_share": float((named_right & faulty).sum() / n_faulty),
                "unknown_share": float(((state == "unknown") & faulty).sum() / n_faulty),
                "confident_wrong_share": float(
                    (wrong & faulty & (np.nan_to_num(prob) > CONFIDENT)).sum() / n_faulty
                ),
            }
        )
    return rows


def expected_performance(
    diagnoser: Any,
    healthy: xr.Dataset,
    twin: Any,
    *,
    faults: Sequence[str],
    sizes: Sequence[float] = (0.25, 0.5, 0.75),
    runs_per_size: int = 2,
    duration: int = 600,
    onset: float = 0.3,
    seed: int = 0,
) -> list[dict[str, Any]]:
    """Per fault and size, the mean of `score_transplants` over ``runs_per_size`` abrupt
    transplants (onset at ``onset`` of ``duration``; seeds ``seed``, ``seed + 1``, ...)."""
    from bayes_fdi.twin import transplant_library

    summary = []
    for size in sizes:
        parts = [
            transplant_library(
                healthy,
                twin,
                faults=faults,
                runs_per_fault=1,
                duration=duration,
                strength=(size, size),
                onset=(onset, onset),
                seed=seed + k,
            )
            for k in range(runs_per_size)
        ]
        runs = xr.concat(parts, dim="run").assign_coords(run=np.arange(len(faults) * runs_per_size))
        stream = diagnoser.run(runs[["CV", "P1", "P2", "T1", "X", "F"]])
        rows = score_transplants(stream, runs, diagnoser.groups_)
        for fault in faults:
            mine = [r for r in rows if r["fault"] == fault]
            delays = [r["detection_seconds"] for r in mine if r["detected"]]
            summary.append(
                {
                    "fault": fault,
                    "size": float(size),
                    "runs": len(mine),
                    "detected_share": float(np.mean([r["detected"] for r in mine])),
                    "median_detection_seconds": float(np.median(delays)) if delays else None,
                    "named_share": float(np.mean([r["named_share"] for r in mine])),
                    "unknown_share": float(np.mean([r["unknown_share"] for r in mine])),
                    "confident_wrong_share": float(
                        np.mean([r["confident_wrong_share"] for r in mine])
                    ),
                }
            )
    return summary

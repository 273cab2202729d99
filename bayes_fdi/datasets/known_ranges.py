"""A recording against the ranges a model was fitted on.

`channel_ranges` summarises where a model's training data lie (per channel, normalised: the
1st percentile, the median and the 99th percentile); fitted diagnosers keep it in their model
files. `check_known_ranges` compares a recording with it before diagnosing: a channel whose
median lies far outside what the model knows, but inside it had its raw values been declared in
another unit of the same quantity (F in kg/s declared as t/h, pressures in MPa declared as bar),
is refused with a message naming that unit; a channel far outside in every unit is returned so
that the caller can say so (the diagnoser then answers "mismatch"). `units_of` reads the units a
read recording was declared in, which fitted diagnosers keep beside the ranges.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import numpy as np

from bayes_fdi.datasets.format import CHANNELS
from bayes_fdi.datasets.units import (
    QUANTITIES,
    UNIT_ALIASES,
    UNITS,
    normalise,
    parse_units,
    to_physical,
)

__all__ = ["FAR_OUTSIDE", "channel_ranges", "check_known_ranges", "units_of"]

#: How far outside a model's training range a recording's median must lie to be "far": beyond
#: either end of the 1st-to-99th-percentile range by the larger of a quarter of its span and
#: this share of full scale. A unit that puts the median back within that margin "fits".
FAR_OUTSIDE = 0.05


def channel_ranges(runs: Any) -> dict[str, list[float]]:
    """Per channel of ``runs`` (normalised): ``[1st percentile, median, 99th percentile]`` of
    the finite samples (NaN for a channel without any)."""
    out = {}
    for channel in CHANNELS:
        if channel not in runs:
            continue
        v = np.asarray(runs[channel].values, dtype=np.float64).ravel()
        v = v[np.isfinite(v)]
        out[channel] = (
            [float(q) for q in np.quantile(v, [0.01, 0.5, 0.99])] if v.size else [np.nan] * 3
        )
    return out


def units_of(runs: Any) -> dict[str, str] | None:
    """The units the recordings of ``runs`` were declared in (channel -> unit, as the readers
    record them in the ``units`` attribute), or None where unknown (simulated data, a file
    whose ``units`` attribute is free text, recordings declared in different units)."""
    text = getattr(runs, "attrs", {}).get("units")
    try:
        units = json.loads(text) if isinstance(text, str) else None
    except json.JSONDecodeError:
        return None
    if not isinstance(units, dict) or set(units) != set(CHANNELS):
        return None
    return {c: str(units[c]) for c in CHANNELS}


def _far(median: float, known: list[float]) -> bool:
    low, _, high = known
    margin = max(0.25 * (high - low), FAR_OUTSIDE)
    return bool(median < low - margin or median > high + margin)


def check_known_ranges(
    ds: Any,
    ranges: Mapping[str, list[float]],
    units: str | Mapping[str, str] = "normalised",
    source: str = "recording",
) -> list[str]:
    """Compare a recording (normalised from ``units``) with a model's training ``ranges``.

    Raises
    ------
    ValueError
        Naming every channel whose median lies far outside the model's range (see
        `FAR_OUTSIDE`) but inside it had the raw values been in another known unit, and that
        unit.

    Returns
    -------
    list of str
        One note per channel far outside the model's range in every unit.
    """
    declared = parse_units(units)
    fixable, notes = [], []
    for channel, known in ranges.items():
        if channel not in ds or not np.all(np.isfinite(known)):
            continue
        v = np.asarray(ds[channel].values, dtype=np.float64).ravel()
        v = v[np.isfinite(v)]
        if not v.size:
            continue
        median = float(np.median(v))
        if not _far(median, known):
            continue
        unit = UNIT_ALIASES.get(declared[channel], declared[channel])
        raw = float(to_physical(median, channel, unit))
        fits = [
            u
            for u in UNITS[QUANTITIES[channel]]
            if u != unit and not _far(float(normalise(raw, channel, u)), known)
        ]
        where = (
            f"{channel}: median {raw:.4g} {unit!r} is {median:.3g} of full scale, far from "
            f"the model's {known[0]:.3g} to {known[2]:.3g} (1st to 99th percentile)"
        )
        if fits:
            fixable.append(f"{where}; in {fits[0]!r} it would lie inside")
        else:
            notes.append(f"{source}: {where}; in no known unit would it lie inside")
    if fixable:
        raise ValueError(
            f"{source}: values far outside what the model was fitted on, as if declared in the "
            "wrong unit: " + "; ".join(fixable) + ". Declare the units the recording was made "
            "in (--units), or check that this model belongs to this valve (--no-unit-check: "
            "diagnose the values as they are)"
        )
    return notes

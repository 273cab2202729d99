"""Units of the recording channels: DABLib's normalisation and the physical units it undoes.

``normalised = (value + offset) * factor`` per channel quantity (DABLib: P / 4 MPa, T1 / 200 degC,
F / 40 t/h, CV and X / 100 %); :func:`parse_units` reads ``"normalised"``, ``"physical"``, a
mapping or the command line's ``"CV=%,X=%,..."`` form; :func:`normalise` and :func:`to_physical`
convert. :func:`check_plausible_units` refuses values that are implausible, by orders of
magnitude, in their declared units (a physical recording read as normalised, pressures in bar
declared as kPa) and names the units that would fit. Used by the recording readers
(`bayes_fdi.datasets.readers`) and the plots.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from bayes_fdi.datasets.format import CHANNELS

__all__ = [
    "DABLIB_RANGES",
    "PHYSICAL_UNITS",
    "PLAUSIBLE_RANGES",
    "QUANTITIES",
    "UNITS",
    "UNIT_ALIASES",
    "check_plausible_units",
    "likely_units",
    "normalise",
    "parse_units",
    "to_physical",
    "units_attribute",
]

#: DABLib's ranges (the normalisation of simulated data and of Lublin Actuator 3) for plots:
#: physical value = normalised value x factor, in the unit given.
DABLIB_RANGES: dict[str, tuple[float, str]] = {
    "CV": (100.0, "%"),
    "P1": (4.0, "MPa"),
    "P2": (4.0, "MPa"),
    "T1": (200.0, "°C"),
    "X": (100.0, "%"),
    "F": (40.0, "t/h"),
}
#: The physical units of ``units="physical"``.
PHYSICAL_UNITS: dict[str, str] = {
    "CV": "%",
    "P1": "kPa",
    "P2": "kPa",
    "T1": "degC",
    "X": "%",
    "F": "t/h",
}
#: The quantity of each channel (its unit family in `UNITS`).
QUANTITIES: dict[str, str] = {"CV": "fraction", "X": "fraction", "P1": "pressure", "P2": "pressure",
             "T1": "temperature", "F": "flow"}  # fmt: skip
#: Known units per quantity: unit -> (offset, factor) with ``normalised = (value + offset) *
#: factor`` (DABLib: P / 4 MPa, T1 / 200 degC, F / 40 t/h, CV and X / 100 %).
UNITS: dict[str, dict[str, tuple[float, float]]] = {
    "fraction": {"1": (0.0, 1.0), "%": (0.0, 0.01)},
    "pressure": {"1": (0.0, 1.0), "Pa": (0.0, 1 / 4e6), "kPa": (0.0, 1 / 4000.0),
                 "MPa": (0.0, 0.25), "bar": (0.0, 1 / 40.0)},
    "temperature": {"1": (0.0, 1.0), "degC": (0.0, 1 / 200.0), "K": (-273.15, 1 / 200.0)},
    "flow": {"1": (0.0, 1.0), "t/h": (0.0, 1 / 40.0), "kg/s": (0.0, 3.6 / 40.0)},
}  # fmt: skip
#: Other spellings of the units (netCDF ``units`` attributes, the command line).
UNIT_ALIASES: dict[str, str] = {
    "normalised": "1", "normalized": "1", "": "1", "-": "1", "percent": "%",
    "°C": "degC", "C": "degC", "degree_Celsius": "degC", "celsius": "degC",
}  # fmt: skip
#: Plausible normalised values per quantity: the 1st and the 99th percentile of a channel must
#: lie in ``[low, high]`` (fractions within -100 % .. 200 % of travel, pressures up to 12 MPa,
#: temperatures -100 .. 400 degC, flows up to 120 t/h). Wide on purpose: only values wrong by
#: orders of magnitude are refused (a fault such as DAMADICS' evaporation f7 reaches 1.5 in T1).
PLAUSIBLE_RANGES: dict[str, tuple[float, float]] = {
    "fraction": (-1.0, 2.0),
    "pressure": (-1.0, 3.0),
    "temperature": (-0.5, 2.0),
    "flow": (-1.0, 3.0),
}
#: The smallest plausible median of the inlet pressure P1 (normalised: 80 kPa) where it is not
#: zero: pressures in bar declared as kPa read 100 times too small. (P2 has no floor: a valve may
#: discharge at atmospheric pressure; it is judged with P1 when declared in the same unit.)
P1_FLOOR = 0.02


def parse_units(units: str | Mapping[str, str]) -> dict[str, str]:
    """The unit of every channel from ``"normalised"``, ``"physical"`` or a full mapping.

    A string ``"CV=%,X=%,P1=kPa,..."`` (the command line's form) is accepted as a mapping.
    """
    if isinstance(units, str):
        key = units.strip()
        if key in ("normalised", "normalized"):
            return dict.fromkeys(CHANNELS, "1")
        if key == "physical":
            return dict(PHYSICAL_UNITS)
        if "=" not in key:
            raise ValueError(
                f"units must be 'normalised', 'physical' or CHANNEL=UNIT pairs, got {units!r}"
            )
        pairs = [p.split("=", 1) for p in key.split(",") if p.strip()]
        units = {name.strip(): unit.strip() for name, unit in pairs}
    unknown = sorted(set(units) - set(CHANNELS))
    if unknown:
        raise ValueError(f"units given for unknown channel(s) {unknown}; channels are {CHANNELS}")
    missing = [c for c in CHANNELS if c not in units]
    if missing:
        raise ValueError(f"units: no unit given for channel(s) {missing} (give all six)")
    out = {}
    for name in CHANNELS:
        unit = UNIT_ALIASES.get(str(units[name]), str(units[name]))
        known = UNITS[QUANTITIES[name]]
        if unit not in known:
            raise ValueError(
                f"unit {units[name]!r} of {name} is not known; use one of {sorted(known)} "
                "('1' = normalised)"
            )
        out[name] = unit
    return out


def normalise(values: Any, channel: str, unit: str) -> Any:
    """``values`` of ``channel`` in ``unit`` divided by DABLib's range (see the module doc)."""
    offset, factor = UNITS[QUANTITIES[channel]][UNIT_ALIASES.get(unit, unit)]
    return (values + offset) * factor if offset else values * factor


def to_physical(values: Any, channel: str, unit: str | None = None) -> Any:
    """Normalised ``values`` of ``channel`` back in ``unit`` (default :data:`PHYSICAL_UNITS`)."""
    unit = PHYSICAL_UNITS[channel] if unit is None else unit
    offset, factor = UNITS[QUANTITIES[channel]][UNIT_ALIASES.get(unit, unit)]
    return values / factor - offset


def units_attribute(units: Mapping[str, str]) -> str:
    """The ``units`` attribute of a read recording: JSON channel -> unit, in channel order."""
    return json.dumps({name: units[name] for name in CHANNELS})


def _statistics(values: np.ndarray) -> tuple[float, float, float] | None:
    """1st and 99th percentile and median magnitude of the finite values; None if none."""
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return None
    low, high = np.quantile(finite, [0.01, 0.99])
    return float(low), float(high), float(np.median(np.abs(finite)))


def _plausible(channel: str, stats: tuple[float, float, float]) -> bool:
    low, high = PLAUSIBLE_RANGES[QUANTITIES[channel]]
    floor_ok = channel != "P1" or stats[2] == 0.0 or stats[2] >= P1_FLOOR
    return low <= stats[0] and stats[1] <= high and floor_ok


def _in_unit(stats: tuple[float, float, float], channel: str, declared: str, unit: str):
    """The normalised statistics had the raw values been in ``unit`` instead of ``declared``."""
    low, high = (float(normalise(to_physical(v, channel, declared), channel, unit))
                 for v in stats[:2])  # fmt: skip
    # the median magnitude serves P1's floor only: pressures have no offset, a plain rescaling
    scale = UNITS[QUANTITIES[channel]][unit][1] / UNITS[QUANTITIES[channel]][declared][1]
    return low, high, stats[2] * scale


def likely_units(ds: Any, units: str | Mapping[str, str]) -> dict[str, list[str]]:
    """Per channel, the known units in which its values are plausible, the likeliest first.

    Parameters
    ----------
    ds
        A dataset in the project's format whose channels were normalised from ``units``.
    units
        The declared units (as for :func:`parse_units`).

    Returns
    -------
    dict
        Channel -> units (known spellings of :data:`UNITS`) in which the channel's values lie
        in :data:`PLAUSIBLE_RANGES`: the declared unit first where it fits, then the unit of
        :data:`PHYSICAL_UNITS`, then by how close the top magnitude comes to DABLib's full
        scale (1 normalised); empty where no known unit fits; a channel whose values are all
        missing gets its declared unit. P2 declared in the same unit as an implausible P1
        follows P1's likeliest unit.
    """
    declared = parse_units(units)
    out: dict[str, list[str]] = {}
    for channel in CHANNELS:
        if channel not in ds.data_vars:
            continue
        stats = _statistics(np.asarray(ds[channel].values, dtype=np.float64).ravel())
        # the statistics in normalised units map back to raw values in the declared unit
        if stats is None:
            out[channel] = [declared[channel]]
            continue
        fits = []
        for unit in UNITS[QUANTITIES[channel]]:
            candidate = _in_unit(stats, channel, declared[channel], unit)
            if _plausible(channel, candidate):
                top = max(abs(candidate[0]), abs(candidate[1]))
                # the declared unit first where it fits, then the physical unit of
                # units="physical" (the usual convention), then by closeness of the top to
                # DABLib's nominal full scale of 1
                closeness = abs(math.log10(top)) if top > 0 else 0.0
                rank = (unit != declared[channel], unit != PHYSICAL_UNITS[channel], closeness)
                fits.append((*rank, unit))
        out[channel] = [unit for *_, unit in sorted(fits)]
    _pressures_together(out, declared)
    return out


def _pressures_together(likely: dict[str, list[str]], declared: Mapping[str, str]) -> None:
    """P2 declared in P1's unit follows P1 where P1 is implausible and P2 fits P1's likely unit."""
    p1, p2 = likely.get("P1"), likely.get("P2")
    if not p1 or not p2 or declared["P1"] != declared["P2"] or declared["P1"] in p1:
        return
    if p1[0] in p2:
        likely["P2"] = [p1[0]] + [u for u in p2 if u != p1[0]]
        if declared["P2"] in likely["P2"] and declared["P2"] != p1[0]:
            likely["P2"].remove(declared["P2"])


def check_plausible_units(
    ds: Any, units: str | Mapping[str, str], source: str = "recording"
) -> dict[str, str]:
    """The declared units if every channel's values are plausible in them; else a ``ValueError``.

    A channel is implausible where its 1st or 99th percentile, normalised from the declared
    unit, falls outside :data:`PLAUSIBLE_RANGES` (or P1's median is below :data:`P1_FLOOR`):
    X = 61 read as normalised is 61 times the full stroke; 35 bar declared as kPa is 0.9 % of
    DABLib's 4 MPa. The error names every such channel, its values and the units in which they
    would be plausible (:func:`likely_units`), and the ``units`` to declare. Factors of a few
    (kg/s for t/h, K for degC) are not caught: only orders of magnitude are.

    Parameters
    ----------
    ds
        The recording, normalised from ``units`` (a dataset in the project's format).
    units
        The declared units.
    source
        The file, for the message.

    Returns
    -------
    dict
        The declared units, channel -> unit.
    """
    declared = parse_units(units)
    likely = likely_units(ds, declared)
    wrong = [c for c in likely if declared[c] not in likely[c]]
    if not wrong:
        return declared
    parts = []
    for channel in wrong:
        low, high, _ = _statistics(np.asarray(ds[channel].values, dtype=np.float64).ravel())
        raw = [float(to_physical(v, channel, declared[channel])) for v in (low, high)]
        fit = likely[channel]
        known = ", ".join(repr(u) for u in UNITS[QUANTITIES[channel]])
        parts.append(
            f"{channel} from {raw[0]:.4g} to {raw[1]:.4g} (1st to 99th percentile) in "
            f"{declared[channel]!r} is {low:.3g} to {high:.3g} x DABLib's range: "
            + (f"likely {fit[0]!r}" if fit else f"no known unit fits (known: {known})")
        )
    unfit = [c for c in wrong if not likely[c]]
    if unfit:
        hint = f"Convert {', '.join(unfit)} to a known unit and declare the units"
    else:
        suggestion = {c: likely[c][0] if c in wrong else declared[c] for c in CHANNELS}
        pairs = ",".join(f"{c}={suggestion[c]}" for c in CHANNELS)
        if suggestion == PHYSICAL_UNITS:
            pairs = "physical"
        hint = f"Declare the units, e.g. units={pairs!r} (command line: --units {pairs})"
    raise ValueError(
        f"{source}: values implausible in their declared units ('1' = normalised): "
        + "; ".join(parts)
        + f". {hint}, or pass check_units=False (command line: --no-unit-check) to read the "
        "values as they are"
    )

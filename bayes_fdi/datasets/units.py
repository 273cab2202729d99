"""Units of the recording channels: DABLib's normalisation and the physical units it undoes.

``normalised = (value + offset) * factor`` per channel quantity (DABLib: P / 4 MPa, T1 / 200 degC,
F / 40 t/h, CV and X / 100 %); :func:`parse_units` reads ``"normalised"``, ``"physical"``, a
mapping or the command line's ``"CV=%,X=%,..."`` form; :func:`normalise` and :func:`to_physical`
convert. Used by the recording readers (`bayes_fdi.datasets.readers`) and the plots.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

from bayes_fdi.datasets.format import CHANNELS

__all__ = ["DABLIB_RANGES", "PHYSICAL_UNITS", "UNITS", "normalise", "parse_units", "to_physical"]

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
_QUANTITY = {"CV": "fraction", "X": "fraction", "P1": "pressure", "P2": "pressure",
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
_ALIASES = {"normalised": "1", "normalized": "1", "": "1", "-": "1", "percent": "%",
            "°C": "degC", "C": "degC", "degree_Celsius": "degC", "celsius": "degC"}  # fmt: skip


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
        unit = _ALIASES.get(str(units[name]), str(units[name]))
        known = UNITS[_QUANTITY[name]]
        if unit not in known:
            raise ValueError(
                f"unit {units[name]!r} of {name} is not known; use one of {sorted(known)} "
                "('1' = normalised)"
            )
        out[name] = unit
    return out


def normalise(values: Any, channel: str, unit: str) -> Any:
    """``values`` of ``channel`` in ``unit`` divided by DABLib's range (see the module doc)."""
    offset, factor = UNITS[_QUANTITY[channel]][_ALIASES.get(unit, unit)]
    return (values + offset) * factor if offset else values * factor


def to_physical(values: Any, channel: str, unit: str | None = None) -> Any:
    """Normalised ``values`` of ``channel`` back in ``unit`` (default :data:`PHYSICAL_UNITS`)."""
    unit = PHYSICAL_UNITS[channel] if unit is None else unit
    offset, factor = UNITS[_QUANTITY[channel]][_ALIASES.get(unit, unit)]
    return values / factor - offset


def _units_attr(units: Mapping[str, str]) -> str:
    return json.dumps({name: units[name] for name in CHANNELS})

"""What a diagnosed state means, in words: fault codes with their names, groups, statuses.

A diagnoser names a state by a code: a DAMADICS fault (``"f18"``), an isolability group of
faults the sensors cannot split (``"f4|f11"``), a fault of one measurement alone (``"bias_X"``,
``"drift_F"``), or one of the answers that are not a fault (``"fn"``, ``"unknown"``,
``"mismatch"``). `describe_state` gives the words an engineer reads in reports, CSV files and
figures ("f18 fully or partly opened bypass valve"); `STATUS_MEANINGS` does the same for the SEVA
statuses.
"""

from __future__ import annotations

from bayes_fdi.actuator import FAULT_TABLE

__all__ = ["NOT_FAULTS", "STATUS_MEANINGS", "describe_state"]

#: The states that name no fault, and what they mean.
NOT_FAULTS: dict[str, str] = {
    "fn": "no fault detected",
    "unknown": "unknown fault: detected, but unlike every fault the model knows",
    "mismatch": "model mismatch: the normal models do not fit this valve; commission it",
}
#: The SEVA statuses and what each tells the user.
STATUS_MEANINGS: dict[str, str] = {
    "CLEAR": "no fault detected; the measurements and their validated values can be trusted",
    "BLURRED": "a fault is detected and isolated with confidence; use the validated values",
    "DAZZLED": "something is wrong that the diagnoser cannot name with confidence",
    "BLIND": "a measurement is missing: nothing can be said this second",
}
_MEASUREMENT_KINDS = {"bias": "bias", "drift": "drift"}
_MEASURED = {"X": "stem position", "F": "flow", "P1": "inlet pressure", "P2": "outlet pressure",
             "T1": "temperature"}  # fmt: skip


def _fault(code: str) -> str:
    if code in FAULT_TABLE:
        return f"{code} {FAULT_TABLE[code].description}"
    kind, _, channel = code.partition("_")
    if kind in _MEASUREMENT_KINDS and channel in _MEASURED:
        return f"{code} {_MEASUREMENT_KINDS[kind]} of the {_MEASURED[channel]} reading alone"
    return code


def describe_state(state: str, *, detection_only: bool = False) -> str:
    """The code of a diagnosed state with its meaning, e.g. ``"f18 fully or partly opened
    bypass valve"``, ``"f4|f11: f4 increase of valve or bushing friction, or f11 servomotor
    spring fault"``.

    ``detection_only``: the model has no fault library, so an ``"unknown"`` detection is a
    fault it cannot name rather than an unfamiliar one.
    """
    state = str(state)
    if state == "unknown" and detection_only:
        return "unknown: fault detected; this model is detection only and cannot name faults"
    if state in NOT_FAULTS:
        return f"{state}: {NOT_FAULTS[state]}"
    members = state.split("|")
    if len(members) == 1:
        return _fault(state)
    return f"{state}: " + ", or ".join(_fault(m) for m in members)

"""The 19 DAMADICS faults: the :class:`Fault` record, the fault table and the FGen time law."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

__all__ = [
    "FAULT_NAMES",
    "FAULT_TABLE",
    "SIGNED_FAULTS",
    "Fault",
    "FaultInfo",
    "fault_value",
]


class FaultInfo(NamedTuple):
    """One row of the fault table: what the fault is and where it enters the model."""

    name: str
    description: str
    entry: str
    signed: bool


FAULT_TABLE: dict[str, FaultInfo] = {
    info.name: info
    for info in (
        FaultInfo("f1", "valve clogging", "stem upper bound Hb*(1-f)", False),
        FaultInfo(
            "f2",
            "valve plug or seat sedimentation",
            "Hb*(1-0.2f); valve position X+0.2f; Kvr*(1-0.2f)",
            False,
        ),
        FaultInfo("f3", "valve plug or seat erosion", "Hb*(1+0.1f); X-0.1f; Kvr*(1+0.1f)", False),
        FaultInfo(
            "f4", "increase of valve or bushing friction", "backlash width X0*(0.01+f)", True
        ),
        FaultInfo("f5", "external leakage", "valve flow F*(1-0.05f)", False),
        FaultInfo("f6", "internal leakage (valve tightness)", "Kvr + 0.1f", False),
        FaultInfo(
            "f7",
            "medium evaporation or critical flow",
            "T1 + 200 + 100f (vapour pressure above P1, choked flow); shown in T1'",
            False,
        ),
        FaultInfo("f8", "twisted servomotor stem", "backlash width *(1+0.5f(1-X))", False),
        FaultInfo(
            "f9", "servomotor housing or terminal tightness", "air leak 2e-7*f*sqrt(Ps)", False
        ),
        FaultInfo(
            "f10", "servomotor diaphragm perforation", "air leak; diaphragm area Ae*(1-f)", False
        ),
        FaultInfo("f11", "servomotor spring fault", "spring constant k*(1-f)", False),
        FaultInfo("f12", "electro-pneumatic transducer fault", "E/P output *(1-f)", True),
        FaultInfo(
            "f13",
            "stem displacement sensor fault",
            "measured stem position x*(1+1.25f) (positioner loop and X')",
            True,
        ),
        FaultInfo(
            "f14",
            "positioner pressure sensor fault",
            "chamber pressure reading Ps*(1-f) only (no effect on X', F')",
            True,
        ),
        FaultInfo(
            "f15", "positioner feedback fault", "backlash of width f*X0 in the PV path", False
        ),
        FaultInfo(
            "f16", "positioner supply pressure drop", "supply Pz*(1-f); 0 below 120 kPa", False
        ),
        FaultInfo(
            "f17",
            "unexpected pressure change across the valve",
            "f<0: P1*(1-|f|); f>0: P2*(1-f); shown in P1'/P2'",
            True,
        ),
        FaultInfo("f18", "fully or partly opened bypass valve", "bypass Kv = 19.75*f", False),
        FaultInfo("f19", "flow rate sensor fault", "measured F'*(1-f)", True),
    )
}

FAULT_NAMES: tuple[str, ...] = tuple(FAULT_TABLE)
#: Faults whose strength may be negative (the benchmark's fault vector allows [-1, 1]).
SIGNED_FAULTS: frozenset[str] = frozenset(n for n, i in FAULT_TABLE.items() if i.signed)
PROFILES: tuple[str, ...] = ("abrupt", "incipient")


def _number(value, field: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise ValueError(f"Fault.{field} must be a real number, got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise ValueError(f"Fault.{field} must be finite, got {value!r}")
    return out


class Fault(NamedTuple):
    """One fault of the DAMADICS actuator, switched on at ``onset``.

    Attributes
    ----------
    name
        ``"f1"`` .. ``"f19"`` (see :data:`FAULT_TABLE`).
    strength
        Full fault strength (the benchmark's fault-vector entry). In ``[0, 1]``, or in
        ``[-1, 1]`` for the faults the benchmark allows negative (f4, f12, f13, f14, f17, f19).
        A strength of 0 reproduces the nominal model bit for bit.
    onset
        Time (s, in the run's time frame, >= 0) at which the fault starts.
    profile
        ``"abrupt"`` (full strength from ``onset``) or ``"incipient"`` (linear ramp from 0 at
        ``onset`` to full strength at ``onset + ramp``, then constant: DABLib's FGen law).
    ramp
        Ramp duration in s (> 0 for ``"incipient"``, must be 0 for ``"abrupt"``).

    Examples
    --------
    >>> Fault("f1", 0.75, onset=100.0)
    Fault(name='f1', strength=0.75, onset=100.0, profile='abrupt', ramp=0.0)
    >>> Fault("f17", -0.5, onset=0.0, profile="incipient", ramp=60.0).value_at(30.0)
    -0.25
    """

    name: str
    strength: float
    onset: float = 0.0
    profile: str = "abrupt"
    ramp: float = 0.0

    def validated(self) -> Fault:
        """Return a checked copy (floats as float); raise ``ValueError`` naming the bad field."""
        if self.name not in FAULT_TABLE:
            raise ValueError(f"Fault.name must be one of f1..f19, got {self.name!r}")
        strength = _number(self.strength, "strength")
        low = -1.0 if self.name in SIGNED_FAULTS else 0.0
        if not low <= strength <= 1.0:
            allowed = "[-1, 1]" if low < 0 else "[0, 1]"
            raise ValueError(
                f"Fault.strength of {self.name} must lie in {allowed}, got {strength!r}"
            )
        onset = _number(self.onset, "onset")
        if onset < 0:
            raise ValueError(f"Fault.onset must be >= 0 s, got {onset!r}")
        if self.profile not in PROFILES:
            raise ValueError(f"Fault.profile must be 'abrupt' or 'incipient', got {self.profile!r}")
        ramp = _number(self.ramp, "ramp")
        if self.profile == "incipient" and ramp <= 0:
            raise ValueError(f"Fault.ramp must be > 0 s for an incipient fault, got {ramp!r}")
        if self.profile == "abrupt" and ramp != 0:
            raise ValueError(f"Fault.ramp must be 0 for an abrupt fault, got {ramp!r}")
        return Fault(self.name, strength, onset, self.profile, ramp)

    def value_at(self, t):
        """Fault-vector value at time(s) ``t`` (s): the FGen law, vectorised over ``t``."""
        f = self.validated()
        return fault_value(t, f.strength, f.onset, f.ramp)


def fault_value(t, strength: float, onset: float, ramp: float):
    """FGen law: 0 before ``onset``, then ``strength`` (``ramp == 0``) or a linear ramp.

    ``f(t) = strength * min(1, max(0, (t - onset) / ramp))`` for ``t >= onset``; 0 before.
    """
    t = np.asarray(t, dtype=np.float64)
    if ramp > 0:
        frac = np.clip((t - onset) / ramp, 0.0, 1.0)
    else:
        frac = (t >= onset).astype(np.float64)
    out = np.where(t >= onset, strength * frac, 0.0)
    return float(out) if out.ndim == 0 else out

"""The actuator's parameters: an immutable record with DABLib's nominal values, units and bounds.

:class:`ActuatorParameters` holds what may differ from one valve to the next: the valve's flow
coefficient and characteristic, the servomotor (spring, preload, diaphragm area, damping,
friction), the positioner (gain, set-point lag, air capacity, supply pressure) and the
calibration (offset and gain) of the five measured channels. Its defaults are the nominal values
of DABLib v1.22; the nominal record reproduces the simulator's historical output bit for bit.
:data:`PARAMETER_INFO` gives each field's unit, physical bounds and meaning. The fixed geometry
(stroke, lever, E/P polygon, controller sampling) stays in `bayes_fdi.actuator.model`.

The compiled kernels read a record as a float64 vector (:meth:`ActuatorParameters.as_vector`,
whose layout the index constants ``IDX_*`` name), with a few derived constants appended so that
the nominal vector gives exactly the numbers the model's module constants gave.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

__all__ = [
    "F_RANGE",
    "NOMINAL",
    "PARAMETER_INFO",
    "P_RANGE",
    "T_RANGE",
    "ActuatorParameters",
    "ParameterInfo",
    "parameter_matrix",
]

#: Full scales of the measured channels: P1', P2' [Pa], T1' [°C], F' [t/h].
P_RANGE, T_RANGE, F_RANGE = 4e6, 200.0, 40.0

#: Largest damping / mass [1/s]: RK4 at 2.5 ms is stable for c/m < 2.78/0.0025 = 1114 1/s.
MAX_DAMPING_RATE = 1000.0

#: atmospheric pressure [Pa], gas constant [J/(kg K)] and temperature [K] of the chamber's air
#: (the initial air mass is that of the dead volume at atmospheric pressure)
_PATM, _R_AIR, _T_AIR = 101325.0, 287.0, 293.0


class ParameterInfo(NamedTuple):
    """Unit, physical bounds and meaning of one field of :class:`ActuatorParameters`."""

    unit: str
    low: float
    high: float
    description: str
    group: str


class ActuatorParameters(NamedTuple):
    """Parameters of one DAMADICS actuator (SI units; sensors in normalised full scale).

    Defaults are DABLib v1.22's nominal values (boiler feed-water valve of Lublin, Actuator 3).
    A measured channel reads ``gain * true / range + offset`` (``range``: 4 MPa for P1, P2,
    200 °C for T1, 40 t/h for F, the stroke for X). The recorded P1', P2', T1' drive the model
    through the inverse, ``true = (reading - offset) / gain * range``; the X' transmitter's
    calibration acts on X' only (the positioner reads the stem through its own lever).
    :data:`PARAMETER_INFO` lists units and bounds; :meth:`validated` checks them.

    Examples
    --------
    >>> from bayes_fdi.actuator import ActuatorParameters
    >>> p = ActuatorParameters(kv=110.0, x_offset=0.01).validated()
    >>> p.kv, p.spring
    (110.0, 60892.0)
    """

    kv: float = 120.0
    characteristic: float = 5.0
    kv_bypass: float = 19.75
    plug_diameter: float = 0.05
    diaphragm_area: float = 0.029
    mass: float = 2.0
    spring: float = 60892.0
    preload: float = 0.009525
    damping: float = 1500.0
    backlash: float = 0.01
    chamber_volume: float = 0.0055
    positioner_gain: float = 100.0
    setpoint_lag: float = 0.30
    inflow_coefficient: float = 2.5e-6
    supply_pressure: float = 600e3
    x_offset: float = 0.0
    x_gain: float = 1.0
    f_offset: float = 0.0
    f_gain: float = 1.0
    p1_offset: float = 0.0
    p1_gain: float = 1.0
    p2_offset: float = 0.0
    p2_gain: float = 1.0
    t1_offset: float = 0.0
    t1_gain: float = 1.0

    def validated(self) -> ActuatorParameters:
        """Return a checked copy (plain floats); raise ``ValueError`` naming a bad field."""
        values = []
        for name, value in zip(self._fields, self, strict=True):
            if isinstance(value, bool) or not isinstance(
                value, int | float | np.integer | np.floating
            ):
                raise ValueError(f"ActuatorParameters.{name} must be a real number, got {value!r}")
            value = float(value)
            info = PARAMETER_INFO[name]
            if not math.isfinite(value) or not info.low <= value <= info.high:
                raise ValueError(
                    f"ActuatorParameters.{name} = {value!r} {info.unit} lies outside its "
                    f"physical bounds [{info.low:g}, {info.high:g}] ({info.description})"
                )
            values.append(value)
        out = ActuatorParameters(*values)
        if out.damping / out.mass > MAX_DAMPING_RATE:
            raise ValueError(
                f"ActuatorParameters: damping / mass = {out.damping / out.mass:.4g} 1/s exceeds "
                f"{MAX_DAMPING_RATE:g} 1/s: the stem's time constant m/c must be at least 1 ms "
                "for the simulator's 2.5 ms RK4 steps to be stable"
            )
        return out

    def as_vector(self) -> np.ndarray:
        """The float64 vector the compiled kernels read (fields, then derived constants)."""
        p = self.validated()
        derived = (
            math.pi * p.plug_diameter**2 / 4.0,  # plug area [m^2]
            _PATM * p.chamber_volume / (_R_AIR * _T_AIR),  # initial air mass [kg]
            math.exp(-p.characteristic * 0.975),  # Kv ratio where the characteristic turns linear
        )
        return np.array([*p, *derived], dtype=np.float64)


#: Units, physical bounds and meaning of every field of :class:`ActuatorParameters`.
PARAMETER_INFO: dict[str, ParameterInfo] = {
    "kv": ParameterInfo("m^3/h", 10.0, 1000.0, "valve flow coefficient, fully open", "valve"),
    "characteristic": ParameterInfo(
        "1", 1.0, 10.0, "equal-percentage exponent n: Kv/Kv_max = exp(-n X)", "valve"
    ),
    "kv_bypass": ParameterInfo("m^3/h", 1.0, 200.0, "bypass flow coefficient, open", "valve"),
    "plug_diameter": ParameterInfo("m", 0.005, 0.5, "plug diameter (plug force)", "valve"),
    "diaphragm_area": ParameterInfo("m^2", 0.005, 0.2, "effective diaphragm area", "servomotor"),
    "mass": ParameterInfo("kg", 0.1, 100.0, "moving mass of stem and plug", "servomotor"),
    "spring": ParameterInfo("N/m", 5e3, 5e5, "spring and diaphragm stiffness", "servomotor"),
    "preload": ParameterInfo("m", 0.0, 0.0381, "spring preload compression", "servomotor"),
    "damping": ParameterInfo("N s/m", 50.0, 5e4, "viscous damping", "servomotor"),
    "backlash": ParameterInfo(
        "1", 0.0, 0.2, "friction as a backlash width, fraction of stroke", "servomotor"
    ),
    "chamber_volume": ParameterInfo("m^3", 5e-4, 0.05, "chamber dead volume", "servomotor"),
    "positioner_gain": ParameterInfo("1", 5.0, 2000.0, "positioner P gain", "positioner"),
    "setpoint_lag": ParameterInfo(
        "s", 0.01, 10.0, "each of the two set-point filter lags", "positioner"
    ),
    "inflow_coefficient": ParameterInfo(
        "kg/(s Pa^0.5)", 1e-8, 1e-4, "chamber air inflow coefficient (E/P relay)", "positioner"
    ),
    "supply_pressure": ParameterInfo(
        "Pa", 1.5e5, 1.2e6, "positioner air supply pressure (gauge)", "positioner"
    ),
    "x_offset": ParameterInfo("1", -0.25, 0.25, "X' transmitter offset", "sensors"),
    "x_gain": ParameterInfo("1", 0.5, 1.5, "X' transmitter gain", "sensors"),
    "f_offset": ParameterInfo("1", -0.25, 0.25, "F' transmitter offset", "sensors"),
    "f_gain": ParameterInfo("1", 0.5, 1.5, "F' transmitter gain", "sensors"),
    "p1_offset": ParameterInfo("1", -0.25, 0.25, "P1' transmitter offset", "sensors"),
    "p1_gain": ParameterInfo("1", 0.5, 1.5, "P1' transmitter gain", "sensors"),
    "p2_offset": ParameterInfo("1", -0.25, 0.25, "P2' transmitter offset", "sensors"),
    "p2_gain": ParameterInfo("1", 0.5, 1.5, "P2' transmitter gain", "sensors"),
    "t1_offset": ParameterInfo("1", -0.25, 0.25, "T1' transmitter offset", "sensors"),
    "t1_gain": ParameterInfo("1", 0.5, 1.5, "T1' transmitter gain", "sensors"),
}

#: The nominal parameters (DABLib v1.22).
NOMINAL = ActuatorParameters()

# positions in the kernels' vector (fields in order, then the derived constants)
(
    IDX_KV, IDX_CHARACTERISTIC, IDX_KV_BYPASS, IDX_PLUG_DIAMETER, IDX_AREA, IDX_MASS,
    IDX_SPRING, IDX_PRELOAD, IDX_DAMPING, IDX_BACKLASH, IDX_VOLUME, IDX_KP, IDX_TAU,
    IDX_K_IN, IDX_SUPPLY, IDX_X_OFFSET, IDX_X_GAIN, IDX_F_OFFSET, IDX_F_GAIN, IDX_P1_OFFSET,
    IDX_P1_GAIN, IDX_P2_OFFSET, IDX_P2_GAIN, IDX_T1_OFFSET, IDX_T1_GAIN,
    IDX_PLUG_AREA, IDX_M_INIT, IDX_KVR_KNEE,
) = range(28)  # fmt: skip
VECTOR_SIZE = 28


def parameter_matrix(
    parameters: ActuatorParameters | Sequence[ActuatorParameters] | None, n_runs: int, who: str
) -> np.ndarray:
    """The kernels' ``(n_runs, VECTOR_SIZE)`` matrix: one record for all runs, or one per run.

    ``None`` means :data:`NOMINAL`. Raises ``ValueError`` naming the problem (wrong type, wrong
    count, a field outside its bounds).
    """
    if parameters is None:
        parameters = NOMINAL
    if isinstance(parameters, ActuatorParameters):
        try:
            row = parameters.as_vector()
        except ValueError as exc:
            raise ValueError(f"{who}: {exc}") from None
        return np.ascontiguousarray(np.broadcast_to(row, (n_runs, VECTOR_SIZE)))
    if isinstance(parameters, str | bytes) or not isinstance(parameters, Sequence):
        raise ValueError(
            f"{who}: parameters must be None, an ActuatorParameters or a sequence of them (one "
            f"per run), got {type(parameters).__name__}"
        )
    if len(parameters) != n_runs:
        raise ValueError(f"{who}: got {len(parameters)} parameter records for {n_runs} runs")
    out = np.empty((n_runs, VECTOR_SIZE))
    for r, p in enumerate(parameters):
        if not isinstance(p, ActuatorParameters):
            raise ValueError(f"{who}: parameters[{r}] must be an ActuatorParameters, got {p!r}")
        try:
            out[r] = p.as_vector()
        except ValueError as exc:
            raise ValueError(f"{who}: run {r}: {exc}") from None
    return out

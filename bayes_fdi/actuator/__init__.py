"""The DAMADICS (DABLib v1.22) actuator model and its 19 faults.

>>> from bayes_fdi.actuator import Fault, benchmark_inputs, simulate
>>> runs = simulate(benchmark_inputs(n_runs=3, duration=120, vary=True),
...                 [None, Fault("f1", 0.75, onset=30.0), Fault("f18", 0.5, onset=30.0)])

See ``docs/actuator.md`` for the model, its integrators and validation, and the fault table.
"""

from bayes_fdi.actuator.faults import FAULT_NAMES, FAULT_TABLE, SIGNED_FAULTS, Fault, FaultInfo
from bayes_fdi.actuator.inputs import benchmark_inputs
from bayes_fdi.actuator.model import PARAMETERS
from bayes_fdi.actuator.parameters import (
    NOMINAL,
    PARAMETER_INFO,
    ActuatorParameters,
    ParameterInfo,
)
from bayes_fdi.actuator.simulate import NOISE_STD, inject_faults, simulate, simulate_replicas
from bayes_fdi.actuator.valve import flow_rate, vapour_pressure, water_density

__all__ = [
    "FAULT_NAMES",
    "FAULT_TABLE",
    "NOISE_STD",
    "NOMINAL",
    "PARAMETERS",
    "PARAMETER_INFO",
    "SIGNED_FAULTS",
    "ActuatorParameters",
    "Fault",
    "FaultInfo",
    "ParameterInfo",
    "benchmark_inputs",
    "flow_rate",
    "inject_faults",
    "simulate",
    "simulate_replicas",
    "vapour_pressure",
    "water_density",
]

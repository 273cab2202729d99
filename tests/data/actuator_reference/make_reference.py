"""Outputs of the actuator simulator at its nominal parameters, kept to check refactors bit for bit.

``reference_outputs()`` simulates a fixed set of cases (reference and fast integrator, linear
and zero-order hold, a fault-free run, all 19 faults abrupt and incipient, noise on, the real
hour's inputs, fault injection into the real hour, replicas) and returns every array by name.
``actuator_reference.npz`` holds what the simulator gave before it took a parameter record
(written once by running this file from the repository root:
``python tests/data/actuator_reference/make_reference.py``); ``tests/test_actuator_parameters.py``
recomputes the cases and requires the same bytes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bayes_fdi.actuator import Fault, benchmark_inputs, inject_faults, simulate, simulate_replicas
from bayes_fdi.datasets import load_lublin_example

HERE = Path(__file__).parent
FILE = HERE / "actuator_reference.npz"
MEASURED = ("X", "F", "P1", "P2", "T1")
STATES = ("X_true", "F_true", "Ps", "CVI")

#: a fault-free run and a mix of abrupt and incipient faults, onsets inside the run
MIXED = [
    None,
    Fault("f1", 0.6, onset=60.0),
    Fault("f17", -0.5, onset=50.0, profile="incipient", ramp=100.0),
    Fault("f13", 0.4, onset=80.0),
    Fault("f16", 0.7, onset=40.0, profile="incipient", ramp=120.0),
    Fault("f7", 0.5, onset=100.0),
]
#: the other faults (with MIXED: all 19)
OTHERS = [
    Fault("f2", 0.8, onset=30.0, profile="incipient", ramp=90.0),
    Fault("f3", 0.9, onset=30.0),
    Fault("f4", 0.3, onset=70.0),
    Fault("f5", 0.7, onset=20.0),
    Fault("f6", 0.5, onset=60.0, profile="incipient", ramp=60.0),
    Fault("f8", 0.9, onset=10.0),
    Fault("f9", 1.0, onset=40.0),
    Fault("f10", 0.5, onset=90.0),
    Fault("f11", 0.6, onset=50.0, profile="incipient", ramp=80.0),
    Fault("f12", -0.6, onset=70.0),
    Fault("f14", -0.5, onset=30.0),
    Fault("f15", 0.3, onset=60.0),
    Fault("f18", 0.5, onset=40.0, profile="incipient", ramp=50.0),
    Fault("f19", -0.75, onset=80.0),
]


def _add(out: dict[str, np.ndarray], prefix: str, ds, states=None) -> None:
    for name in MEASURED:
        out[f"{prefix}/{name}"] = ds[name].transpose("run", "time").values
    if states is not None:
        for name in STATES:
            out[f"{prefix}/{name}"] = states[name].transpose("run", "time").values


def reference_outputs() -> dict[str, np.ndarray]:
    """Every case's output arrays by ``case/channel`` name."""
    out: dict[str, np.ndarray] = {}
    mixed_inputs = benchmark_inputs(n_runs=len(MIXED), duration=200, seed=11, vary=True)
    for integrator in ("fast", "reference"):
        ds, st = simulate(mixed_inputs, MIXED, seed=5, integrator=integrator, return_states=True)
        _add(out, f"mixed-{integrator}", ds, st)
    other_inputs = benchmark_inputs(n_runs=len(OTHERS), duration=160, seed=12, vary=True)
    ds, st = simulate(other_inputs, OTHERS, seed=6, return_states=True)
    _add(out, "others-fast", ds, st)
    ds = simulate(other_inputs, OTHERS, seed=6, integrator="reference", noise=False)
    _add(out, "others-reference", ds)
    zero = benchmark_inputs(n_runs=2, duration=120, seed=13, vary=True)
    ds = simulate(zero, [None, Fault("f10", 0.4, onset=30.0)], seed=7, hold="zero")
    _add(out, "zero-hold", ds)
    ds = simulate(zero, None, seed=8, warmup=0, noise=False)
    _add(out, "no-warmup", ds)
    hour = load_lublin_example().isel(time=slice(1000, 1300))
    for integrator in ("fast", "reference"):
        ds, st = simulate(hour, None, seed=9, integrator=integrator, return_states=True)
        _add(out, f"lublin-{integrator}", ds, st)
    two = hour.isel(run=[0, 0]).assign_coords(run=[0, 1])
    injected = inject_faults(
        two,
        [Fault("f18", 0.5, onset=50.0, profile="incipient", ramp=100.0), Fault("f19", -0.5, 80.0)],
    )
    _add(out, "lublin-injected", injected)
    for k, ds in enumerate(simulate_replicas(zero, [None, Fault("f6", 0.3, 20.0)], seeds=[1, 2])):
        _add(out, f"replica-{k}", ds)
    return out


if __name__ == "__main__":
    arrays = reference_outputs()
    np.savez_compressed(FILE, **arrays)
    print(f"wrote {FILE} ({FILE.stat().st_size / 1e3:.0f} kB, {len(arrays)} arrays)")

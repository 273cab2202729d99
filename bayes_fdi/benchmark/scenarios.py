"""The 44 Step-I scenarios of the DAMADICS benchmark and its fault-free false-alarm hours.

The scenarios follow the benchmark's own definition (the DABLib v1.22 manual, Bartyś & Syfert,
Warsaw University of Technology, 2002, Tables 28-29, and the mask of DABLib's PICalc block),
summarised with their citations on the DAMADICS page of the documentation
(``docs/damadics.md``, "The 44 Step-I scenarios"):

- the actuator stands alone, driven by DGen's sines without variation
  (:func:`bayes_fdi.actuator.benchmark_inputs`);
- the fault starts at ``t_from = 900`` s; the benchmark zone is ``[t_on, t_hor)`` with
  ``t_on = 300`` s and ``t_hor = t_from + t_fd + 600`` s;
- abrupt faults (``t_fd = 0``, ``t_hor = 1500`` s) are small / medium / big (strength 0.25 /
  0.5 / 0.75) for f1, f7, f8, f10, f12, f13, f14, f16, f18, f19 and big only for f2, f11, f15,
  f17 (34 scenarios);
- incipient faults ramp linearly from 0 at ``t_from`` to 1.0 at ``t_from + t_fd``: over
  ``t_fd = 84 000`` s (``t_hor = 85 500`` s) for f2, f3, f5, f6, f9, f11, f18; over 3 600 s
  (5 100 s) for f4, f17; over 900 s (2 400 s) for f13 (10 scenarios);
- the direction of the fault vector is -1 for f12, f14, f19 and +1 otherwise.

Seeds
-----
Every run is simulated up to its ``t_hor`` only, with the noise seed ``BENCHMARK_SEED + k`` for
the ``k``-th noise seed (``k = 0 .. n - 1``) and the scenario's position in :data:`SCENARIOS`
as the run id, so each (scenario, seed) has its own noise stream
(``numpy.random.default_rng([10_000 + k, position])``, see :func:`bayes_fdi.actuator.simulate`).
The fault-free hours of the false-alarm budget use the seed :data:`FAULT_FREE_SEED`. Both lie
outside the seeds below 1000 that the online diagnoser's training campaigns use. As the inputs
do not vary and the measurement noise is added to the outputs only, the model runs once per
scenario and each seed only draws its noise (:func:`bayes_fdi.actuator.simulate_replicas`).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any, NamedTuple

import numpy as np
import xarray as xr

from bayes_fdi.actuator import Fault, benchmark_inputs, simulate_replicas
from bayes_fdi.datasets import CHANNELS

__all__ = [
    "BENCHMARK_SEED",
    "FAULT_FREE_SEED",
    "SCENARIOS",
    "SIZES",
    "TRUTH_COORDS",
    "T_FROM",
    "T_ON",
    "T_OV",
    "BenchmarkScenario",
    "benchmark_seeds",
    "fault_free_hours",
    "iter_scenarios",
    "scenario_inputs",
    "simulate_scenario",
    "strip_truth",
]

#: Start of the benchmark zone (s): [0, T_ON) is the set-up zone.
T_ON = 300.0
#: Start of every fault (s).
T_FROM = 900.0
#: Observation time after the end of the fault's development (s): t_hor = t_from + t_fd + t_ov.
T_OV = 600.0
#: Normalised strengths of the abrupt scenarios.
SIZES: dict[str, float] = {"small": 0.25, "medium": 0.5, "big": 0.75}
#: Noise seed of the first benchmark seed; seed k is BENCHMARK_SEED + k.
BENCHMARK_SEED = 10_000
#: Noise seed of the simulated fault-free hours.
FAULT_FREE_SEED = 20_000
#: Largest number of benchmark seeds (keeps them below FAULT_FREE_SEED).
MAX_SEEDS = FAULT_FREE_SEED - BENCHMARK_SEED
#: Coordinates of simulated runs that hold the truth (`strip_truth` removes them).
TRUTH_COORDS = ("state", "strength", "onset", "profile", "ramp")

_NEGATIVE = frozenset({"f12", "f14", "f19"})
_ABRUPT_SMB = ("f1", "f7", "f8", "f10", "f12", "f13", "f14", "f16", "f18", "f19")
_ABRUPT_BIG = ("f2", "f11", "f15", "f17")
_INCIPIENT = {
    84_000.0: ("f2", "f3", "f5", "f6", "f9", "f11", "f18"),  # one day, as the benchmark codes it
    3_600.0: ("f4", "f17"),
    900.0: ("f13",),
}


class BenchmarkScenario(NamedTuple):
    """One Step-I scenario: which fault, how it develops, and its time zones (s).

    ``strength`` is the magnitude of the fault vector at full development (0.25 / 0.5 / 0.75
    abrupt, 1.0 incipient) and ``direction`` its sign (-1 for f12, f14, f19).
    """

    fault: str
    mode: str
    size: str | None
    strength: float
    direction: int
    t_fd: float
    t_on: float = T_ON
    t_from: float = T_FROM
    t_hor: float = 0.0

    @property
    def name(self) -> str:
        """Short label, e.g. ``"f1 abrupt small"`` or ``"f2 incipient"``."""
        return " ".join(p for p in (self.fault, self.mode, self.size) if p)

    @property
    def slug(self) -> str:
        """File-name form of :attr:`name`, e.g. ``"f1-abrupt-small"``."""
        return self.name.replace(" ", "-")

    def fault_spec(self) -> Fault:
        """The :class:`~bayes_fdi.actuator.Fault` that DABLib's FGen applies (signed)."""
        profile = "abrupt" if self.mode == "abrupt" else "incipient"
        return Fault(self.fault, self.direction * self.strength, self.t_from, profile, self.t_fd)

    def strength_at(self, time) -> np.ndarray:
        """The fault strength (magnitude, the benchmark's ``fs``) at the given times (s)."""
        return np.abs(np.asarray(self.fault_spec().value_at(time), dtype=np.float64))

    def run_attrs(self, position: int, seeds: Sequence[int]) -> dict[str, Any]:
        """The attributes of a dataset of this scenario's runs (run id ``position``, noise
        ``seeds``): its name, zone times, position and seeds."""
        return {
            "scenario": self.name,
            "t_on": self.t_on,
            "t_from": self.t_from,
            "t_fd": self.t_fd,
            "t_hor": self.t_hor,
            "scenario_position": int(position),
            "seeds": ",".join(str(int(s)) for s in seeds),
        }

    def truncated(self, t_hor: float) -> BenchmarkScenario:
        """The same scenario observed only up to ``min(t_hor, self.t_hor)`` (quick runs)."""
        if not t_hor > self.t_from:
            raise ValueError(f"truncated: t_hor must exceed t_from = {self.t_from:g} s")
        return self._replace(t_hor=float(min(t_hor, self.t_hor)))


def _scenario(fault: str, mode: str, size: str | None, strength: float, t_fd: float):
    direction = -1 if fault in _NEGATIVE else 1
    return BenchmarkScenario(
        fault, mode, size, strength, direction, t_fd, t_hor=T_FROM + t_fd + T_OV
    )


def _table() -> tuple[BenchmarkScenario, ...]:
    rows = [_scenario(f, "abrupt", s, v, 0.0) for f in _ABRUPT_SMB for s, v in SIZES.items()]
    rows += [_scenario(f, "abrupt", "big", SIZES["big"], 0.0) for f in _ABRUPT_BIG]
    rows += [
        _scenario(f, "incipient", None, 1.0, t_fd) for t_fd, fs in _INCIPIENT.items() for f in fs
    ]
    return tuple(rows)


#: The 44 Step-I scenarios, abrupt S/M/B first, then abrupt big only, then incipient.
SCENARIOS: tuple[BenchmarkScenario, ...] = _table()
_POSITION: dict[str, int] = {s.name: i for i, s in enumerate(SCENARIOS)}


def benchmark_seeds(n_seeds: int) -> tuple[int, ...]:
    """The noise seeds of ``n_seeds`` benchmark seeds: ``BENCHMARK_SEED + k``."""
    if isinstance(n_seeds, bool) or not isinstance(n_seeds, int | np.integer):
        raise ValueError(f"benchmark_seeds: n_seeds must be an integer, got {n_seeds!r}")
    if not 1 <= n_seeds <= MAX_SEEDS:
        raise ValueError(f"benchmark_seeds: n_seeds must lie in [1, {MAX_SEEDS}], got {n_seeds}")
    return tuple(BENCHMARK_SEED + k for k in range(int(n_seeds)))


def scenario_inputs(scenario: BenchmarkScenario) -> xr.Dataset:
    """The one run of inputs (CV, P1, P2, T1: DGen's sines without variation) a scenario is
    simulated under, up to its ``t_hor``."""
    duration = round(scenario.t_hor)
    return benchmark_inputs(n_runs=1, duration=duration, vary=False, campaign="damadics-step1")


def strip_truth(ds: xr.Dataset) -> xr.Dataset:
    """The six channels of simulated runs only: the diagnoser must not see the labels."""
    return ds[list(CHANNELS)].drop_vars([c for c in TRUTH_COORDS if c in ds.coords])


def simulate_scenario(
    scenario: BenchmarkScenario,
    seeds: Sequence[int],
    *,
    position: int | None = None,
) -> xr.Dataset:
    """Simulate one scenario up to its ``t_hor`` with each noise seed.

    Parameters
    ----------
    scenario
        One of :data:`SCENARIOS` (possibly :meth:`~BenchmarkScenario.truncated`).
    seeds
        Noise seeds, e.g. :func:`benchmark_seeds`.
    position
        Run id of the noise stream; default: the scenario's position in :data:`SCENARIOS`
        (a scenario not in the table needs one).

    Returns
    -------
    xarray.Dataset
        One run per seed (``run`` = the seed), ``time`` = 0 .. t_hor - 1 s, the channels in the
        project's format and the fault coordinates (the strength stream PICalc reads is
        :meth:`BenchmarkScenario.strength_at` of the time coordinate).
    """
    if position is None:
        if scenario.name not in _POSITION:
            raise ValueError("simulate_scenario: the scenario is not in SCENARIOS; give position")
        position = _POSITION[scenario.name]
    seeds = [int(s) for s in seeds]
    inputs = scenario_inputs(scenario).assign_coords(run=[int(position)])
    runs = simulate_replicas(inputs, [scenario.fault_spec()], seeds=seeds)
    ds = xr.concat(runs, dim="run", combine_attrs="drop_conflicts")
    ds = ds.assign_coords(run=np.asarray(seeds, dtype=np.int64))
    ds.attrs.update(scenario.run_attrs(position, seeds))
    return ds


def iter_scenarios(
    scenarios: Sequence[BenchmarkScenario], seeds: Sequence[int], *, batch: int = 10
) -> Iterator[tuple[BenchmarkScenario, xr.Dataset]]:
    """Yield ``(scenario, runs)`` with at most ``batch`` seeds per dataset (bounded memory)."""
    for scenario in scenarios:
        for start in range(0, len(seeds), batch):
            yield scenario, simulate_scenario(scenario, seeds[start : start + batch])


def fault_free_hours(hours: float = 8.0, *, warmup: float = T_ON, seed: int = FAULT_FREE_SEED):
    """One continuous fault-free run of ``warmup + hours`` with the benchmark's inputs.

    The first ``warmup`` seconds play the role of the benchmark's set-up zone (the detector
    settles there) and are not counted in the false-alarm budget.

    Returns
    -------
    xarray.Dataset
        One run (``run`` = the seed), attrs ``warmup`` and ``hours``.
    """
    if not hours > 0:
        raise ValueError(f"fault_free_hours: hours must be > 0, got {hours!r}")
    duration = round(warmup + 3600.0 * hours)
    inputs = benchmark_inputs(n_runs=1, duration=duration, vary=False, campaign="fault-free")
    (ds,) = simulate_replicas(inputs, None, seeds=[int(seed)])
    ds = ds.assign_coords(run=[int(seed)])
    ds.attrs.update(warmup=float(warmup), hours=float(hours))
    return ds

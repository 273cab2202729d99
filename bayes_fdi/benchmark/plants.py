"""Perturbed plants: simulated valves unlike the nominal one, each in its own level loop.

The commissioning benchmark (`bayes_fdi.benchmark.commissioning`) asks whether commissioning
learns a valve that differs from the nominal DAMADICS actuator. `draw_plant` draws one such
plant, seeded and never used in any training:

- its parameters: each physical parameter of the valve, servomotor and positioner
  (`PERTURBED_FIELDS`: the fields of `bayes_fdi.actuator.PARAMETER_INFO` in those groups)
  multiplied by a factor uniform in ``[0.7, 0.8]`` or ``[1.2, 1.3]`` (the side drawn with
  equal odds), i.e. 20-30 % away from nominal; the transmitters' calibration stays nominal.
  A record outside the physical bounds (`ActuatorParameters.validated`, e.g. a damping too
  large for the mass) is drawn again;
- its operating point, sized for the valve: the stem opening its level loop balances at
  (`OPENING`) and the outflow demand (`DEMAND`) are drawn, and the pressure drop follows from
  the valve's flow law (it must lie in `PRESSURE_DROP`, and the closed valve must pass at most
  `CLOSED_SHARE` of the demand, or the draw is made again); inlet pressure and temperature are
  drawn once from `bayes_fdi.actuator.excitation.DEFAULT_OPERATING`. Pressures and temperature
  drift around these levels run by run;
- its level loop: the tank, the PI controller's tuning and the level sensor's noise drawn
  once from `bayes_fdi.actuator.excitation.DEFAULT_LOOP` (set-points and the demand's drift
  vary run by run); the loop's flow law has the plant's Kv and characteristic, so the
  controller holds the level with this valve's opening;
- a check of the result: if the healthy hour holds CV, X or F at a range end (0 or 1 of full
  scale: a transmitter over range, a valve pinned shut or open) in more than
  `MAX_AT_RANGE_END` of the seconds, the operating point and loop are drawn again
  (``operating_redraws`` counts every new draw).

Its runs are driven by `bayes_fdi.actuator.excitation.level_loop_inputs` (closed-loop CV, not
DGen's sines) and simulated with `bayes_fdi.actuator.simulate` with the plant's parameters and
DABLib's measurement noise. The loop is open at the fault: the controller's CV is computed
with the nominal flow law and does not react to a fault (see the excitation module).

Seeds (all at or above 30 000: apart from the training campaigns below 1000, the DAMADICS
benchmark's noise seeds 10 000 + k and its fault-free hours 20 000): plant ``i`` draws from
``default_rng([PLANT_SEED, i])``; its healthy hour uses input and noise seed
``HEALTHY_SEED + i``, its held-out healthy half hour ``HELDOUT_SEED + i``, and the run of a
scenario at position ``p`` of `bayes_fdi.benchmark.scenarios.SCENARIOS` with the plant's
``k``-th benchmark seed ``scenario_seed(i, k, p) = SCENARIO_SEED + 1000 i + 100 k + p``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import xarray as xr

from bayes_fdi.actuator import NOMINAL, PARAMETER_INFO, ActuatorParameters, simulate
from bayes_fdi.actuator.excitation import (
    DEFAULT_LOOP,
    DEFAULT_OPERATING,
    LevelLoop,
    OperatingRange,
    level_loop_inputs,
)
from bayes_fdi.benchmark.scenarios import BenchmarkScenario

__all__ = [
    "FACTOR_BANDS",
    "HEALTHY_SEED",
    "HELDOUT_SEED",
    "MAX_PLANTS",
    "MAX_PLANT_SEEDS",
    "PERTURBED_FIELDS",
    "PLANT_SEED",
    "SCENARIO_SEED",
    "PerturbedPlant",
    "draw_plant",
    "healthy_run",
    "scenario_run",
    "scenario_seed",
]

PLANT_SEED = 30_000
HEALTHY_SEED = 40_000
HELDOUT_SEED = 45_000
SCENARIO_SEED = 50_000
#: Plants and benchmark seeds per plant the seed layout keeps apart.
MAX_PLANTS, MAX_PLANT_SEEDS = 50, 10
#: The fields perturbed: the physical parameters of the valve, servomotor and positioner.
PERTURBED_FIELDS: tuple[str, ...] = tuple(
    name
    for name, info in PARAMETER_INFO.items()
    if info.group in ("valve", "servomotor", "positioner")
)
#: A factor is drawn uniformly in one of these bands (which one with equal odds).
FACTOR_BANDS: tuple[tuple[float, float], tuple[float, float]] = ((0.7, 0.8), (1.2, 1.3))
#: Draws of a plant's parameters before giving up, and of its operating point for each.
MAX_REDRAWS, OPERATING_TRIES = 100, 50
#: A plant runs at a balance opening drawn here (fraction of closing; the real Lublin hour
#: ranges over 0.49-0.78) ...
OPENING = (0.35, 0.8)
#: ... with an outflow demand drawn here (share of the nominal valve's full-open flow at the
#: nominal pressure drop): flows of about 15-50 % of the F' transmitter's range at balance (the
#: real hour: about 30 %), with room for the loop's swings; ...
DEMAND = (0.02, 0.06)
#: ... and the pressure drop that balances them, which must lie here [Pa] ...
PRESSURE_DROP = (0.1e6, 1.2e6)
#: ... while the closed valve (X = 1 in the loop's flow law) passes at most this share of the
#: balance flow, so that the loop can throttle.
CLOSED_SHARE = 1.0 / 3.0
#: A reading within this of 0 or 1 (full scale) is at its range end.
RANGE_END = 0.005
#: Largest share of the healthy hour's seconds with CV, X or F at a range end.
MAX_AT_RANGE_END = 0.01


class PerturbedPlant(NamedTuple):
    """One simulated plant (see the module docstring)."""

    index: int
    parameters: ActuatorParameters
    factors: dict[str, float]  #: field -> factor against nominal
    operating: OperatingRange  #: its operating point (levels fixed, drifts as the default)
    loop: LevelLoop  #: its level loop (tuning and demand fixed)
    redraws: int  #: parameter records drawn again (out of bounds, or the plant not sized)
    operating_redraws: int  #: operating points drawn again (the plant not sized)
    opening: float  #: the stem opening the level loop balances at (fraction of closing)

    def describe(self) -> dict:
        """What ``benchmark.json`` lists of the plant."""
        return {
            "index": int(self.index),
            "factors": {k: float(v) for k, v in self.factors.items()},
            "parameters": {k: float(v) for k, v in self.parameters._asdict().items()},
            "p1_MPa": self.operating.p1[0] / 1e6,
            "dp_MPa": self.operating.dp[0] / 1e6,
            "t1_C": self.operating.t1[0],
            "loop": {
                k: float(v[0] if isinstance(v, tuple) else v)
                for k, v in self.loop._asdict().items()
            },
            "redraws": int(self.redraws),
            "operating_redraws": int(self.operating_redraws),
            "opening": float(self.opening),
        }


def _fixed(rng: np.random.Generator, band: tuple[float, float]) -> tuple[float, float]:
    value = float(rng.uniform(*band))
    return (value, value)


def _check_index(value, name: str, limit: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if not 0 <= value < limit:
        raise ValueError(f"{name} must lie in [0, {limit}), got {value}")
    return int(value)


def draw_plant(index: int) -> PerturbedPlant:
    """Plant ``index`` (0 .. `MAX_PLANTS` - 1): parameters, operating point and level loop.

    A parameter record outside the physical bounds, or one for which `OPERATING_TRIES` draws
    find no operating point that sizes the plant, is drawn again (``redraws``).
    """
    index = _check_index(index, "plant index", MAX_PLANTS)
    rng = np.random.default_rng([PLANT_SEED, index])
    operating_draws = 0
    for redraws in range(MAX_REDRAWS):
        factors = {
            name: float(rng.uniform(*FACTOR_BANDS[int(rng.integers(0, 2))]))
            for name in PERTURBED_FIELDS
        }
        record = NOMINAL._replace(**{k: getattr(NOMINAL, k) * f for k, f in factors.items()})
        try:
            parameters = record.validated()
        except ValueError:
            continue
        for _ in range(OPERATING_TRIES):
            drawn = _operation(rng, parameters)
            operating_draws += 1
            if drawn is None:
                continue
            operating, loop, opening = drawn
            plant = PerturbedPlant(
                index, parameters, factors, operating, loop, redraws, operating_draws - 1, opening
            )
            if _in_range(healthy_run(plant)):
                return plant
    raise RuntimeError(f"plant {index}: no plant could be sized in {MAX_REDRAWS} draws")


def _operation(rng: np.random.Generator, parameters: ActuatorParameters):
    """A plant's operating point and level loop, and the opening the loop balances at; None
    when the draw cannot size the plant (see the module docstring)."""
    n, kv_ratio = parameters.characteristic, parameters.kv / NOMINAL.kv
    opening, demand = float(rng.uniform(*OPENING)), float(rng.uniform(*DEMAND))
    # the loop's flow law, demand = kv_ratio sqrt(dp / dp_nominal) exp(-n X), solved for dp
    dp = DEFAULT_LOOP.dp_nominal * (demand / (kv_ratio * np.exp(-n * opening))) ** 2
    operating = DEFAULT_OPERATING._replace(
        p1=_fixed(rng, DEFAULT_OPERATING.p1), dp=(dp, dp), t1=_fixed(rng, DEFAULT_OPERATING.t1)
    )
    loop = DEFAULT_LOOP._replace(
        **{
            name: _fixed(rng, getattr(DEFAULT_LOOP, name))
            for name in ("area_seconds", "kp", "ti", "level_noise")
        },
        demand=(demand, demand),
        characteristic=n,
        kv_ratio=kv_ratio,
    )
    sized = PRESSURE_DROP[0] <= dp <= PRESSURE_DROP[1] and dp < operating.p1[0] - 0.2e6
    throttles = np.exp(-n * (1.0 - opening)) <= CLOSED_SHARE
    return (operating, loop, opening) if sized and throttles else None


def _in_range(run: xr.Dataset) -> bool:
    """Whether CV, X and F stay off their range ends in all but `MAX_AT_RANGE_END` of the
    seconds."""
    ends = [
        (run[c].values <= RANGE_END) | (run[c].values >= 1.0 - RANGE_END) for c in ("CV", "X", "F")
    ]
    return float(np.mean(np.any(ends, axis=0))) < MAX_AT_RANGE_END


def scenario_seed(plant: int, k: int, position: int) -> int:
    """Input and noise seed of scenario ``position`` with plant ``plant``'s ``k``-th seed."""
    plant = _check_index(plant, "plant index", MAX_PLANTS)
    k = _check_index(k, "plant seed", MAX_PLANT_SEEDS)
    position = _check_index(position, "scenario position", 100)
    return SCENARIO_SEED + 1000 * plant + 100 * k + position


def _run(plant: PerturbedPlant, duration: int, seed: int, fault, run_id: int) -> xr.Dataset:
    inputs = level_loop_inputs(
        1, int(duration), seed=int(seed), loop=plant.loop, operating=plant.operating
    )
    inputs = inputs.drop_vars("level").assign_coords(run=[int(run_id)])
    return simulate(inputs, [fault], seed=int(seed), parameters=plant.parameters)


def healthy_run(plant: PerturbedPlant, duration: int = 3600, *, heldout: bool = False):
    """The plant's healthy recording (one run): its commissioning data, or (``heldout``) a
    second recording that commissioning never sees."""
    seed = (HELDOUT_SEED if heldout else HEALTHY_SEED) + plant.index
    return _run(plant, duration, seed, None, 0)


def scenario_run(
    plant: PerturbedPlant, scenario: BenchmarkScenario, k: int, position: int, *, faulty=True
) -> xr.Dataset:
    """Scenario ``scenario`` (at ``position`` of the table) on the plant with its ``k``-th seed,
    simulated up to ``t_hor`` under a level-loop input of its own; ``faulty=False`` gives the
    same run without the fault (same inputs, same noise)."""
    seed = scenario_seed(plant.index, k, position)
    fault = scenario.fault_spec() if faulty else None
    return _run(plant, round(scenario.t_hor), seed, fault, position)

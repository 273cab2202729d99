"""The real Lublin hour in the commissioning benchmark: commissioned on one half, tested on the
other, clean and with every fault transplanted.

`real_hour_benchmark` commissions a diagnoser (`bayes_fdi.commissioning.commission`) on the
first half of the shipped real hour (`bayes_fdi.datasets.load_lublin_example`, 1800 s) and
then, on the second half, which commissioning never saw:

- checks the digital twin's posterior predictive on it (coverage, RMS against the nominal
  model);
- runs the commissioned diagnoser (and the default one, beside it) on it as it is: alarms and
  CLEAR seconds;
- transplants each fault of the library (`bayes_fdi.commissioning.LIBRARY_FAULTS`) onto it at
  the benchmark's small / medium / big strengths (0.25 / 0.5 / 0.75; direction -1 for f12, f14,
  f19 as the benchmark codes them, +1 otherwise), abrupt, 300 s into the half
  (`bayes_fdi.twin.transplant`), with actuator parameters drawn from the twin's posterior with
  seeds ``TRANSPLANT_SEED + k`` for draw ``k``, apart from the seeds ``10 seed + 1 .. 4`` that
  commissioning draws its libraries and checks from; the measurement noise is the real one of
  the second half;
- scores every case with PICalc (`bayes_fdi.benchmark.cases.score_case`) in the zones
  ``t_on = 0`` (the commissioned model needs no set-up zone), ``t_from = 300``,
  ``t_hor = 1800`` s of the half, and measures each transplant's effect on the commissioned
  diagnoser's whitened innovations against their noise on the clean half
  (`bayes_fdi.benchmark.cases.innovation_effect`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.actuator import Fault
from bayes_fdi.benchmark.cases import (
    clean_summary,
    groups_of,
    innovation_effect,
    innovation_noise,
    score_case,
    zeroed,
)
from bayes_fdi.benchmark.scenarios import SIZES
from bayes_fdi.commissioning import LIBRARY_FAULTS, commission
from bayes_fdi.datasets import CHANNELS, MEASUREMENT_FAULTS
from bayes_fdi.progress import busy

__all__ = [
    "DIRECTIONS",
    "REAL_HOUR_ZONES",
    "TRANSPLANT_SEED",
    "commissioning_summary",
    "real_hour_benchmark",
    "whitening_gain",
]

#: The zones of a transplanted case in the second half's time (s): t_on, t_from, t_hor.
REAL_HOUR_ZONES = (0.0, 300.0, 1800.0)
#: Posterior draw k of the twin's parameters for the transplants uses seed TRANSPLANT_SEED + k.
TRANSPLANT_SEED = 10_000
#: Sign of each fault's strength (the benchmark's directions; the measurement faults +1).
DIRECTIONS: dict[str, int] = {"f12": -1, "f14": -1, "f19": -1}


def _halves(hour: xr.Dataset) -> tuple[xr.Dataset, xr.Dataset]:
    half = hour.sizes["time"] // 2
    return hour.isel(time=slice(0, half)), hour.isel(time=slice(half, None))


def _fault(name: str, size: float, onset: float):
    from bayes_fdi.twin import MeasurementFault

    kind = MeasurementFault if name in MEASUREMENT_FAULTS else Fault
    return kind(name, DIRECTIONS.get(name, 1) * float(size), float(onset))


def _replicated(run: xr.Dataset, n: int) -> xr.Dataset:
    """``n`` copies of one run's six channels (runs 0 .. n - 1)."""
    one = run[list(CHANNELS)].reset_coords(drop=True)
    if "run" in one.dims:
        one = one.isel(run=0, drop=True)
    return xr.concat([one] * n, dim="run").assign_coords(run=np.arange(n))


def _transplanted(
    second: xr.Dataset, twin: Any, faults: Sequence[str], size: float, draw: int
) -> xr.Dataset:
    from bayes_fdi.twin import transplant

    parameters = twin.sample_parameters(1, seed=TRANSPLANT_SEED + draw)[0]
    onset = REAL_HOUR_ZONES[1]
    return transplant(
        _replicated(second, len(faults)), [_fault(f, size, onset) for f in faults], parameters
    )


def _cases(
    models: Mapping[str, Any],
    runs: xr.Dataset,
    faults: Sequence[str],
    size_name: str,
    draw: int,
    clean: xr.Dataset,
    clean_data: xr.Dataset,
    noise: Mapping[str, float],
) -> list[dict[str, Any]]:
    """Every model's score of every transplanted run (and the commissioned one's effect)."""
    t_on, t_from, t_hor = REAL_HOUR_ZONES
    rows = []
    for model, diagnoser in models.items():
        stream = diagnoser.run(runs[list(CHANNELS)])
        for r, fault in enumerate(faults):
            one = zeroed(stream.isel(run=r))
            t = np.asarray(one["time"].values)
            strength = np.where(t >= t_from, SIZES[size_name], 0.0)
            row = {
                "fault": fault,
                "size": size_name,
                "strength": DIRECTIONS.get(fault, 1) * SIZES[size_name],
                "draw": int(draw),
                "parameter_seed": TRANSPLANT_SEED + int(draw),
                "model": model,
                **score_case(one, fault, t_on=t_on, t_from=t_from, t_hor=t_hor, strength=strength),
            }
            if model == "commissioned":
                row["effect"] = innovation_effect(
                    one,
                    clean,
                    t_from=t_from,
                    noise=noise,
                    faulty_data=runs.isel(run=r),
                    healthy_data=clean_data,
                )
            rows.append(row)
    return rows


def commissioning_summary(result: Any) -> dict[str, Any]:
    """What the benchmark keeps of a commissioning (`bayes_fdi.commissioning.Commissioning`)."""
    report = result.report
    twin = report["twin"]
    return {
        "seconds": report["seconds"],
        "groups": report["groups"],
        "undetectable": report["undetectable"],
        "threshold": report["detection"]["threshold"],
        "twin": {
            "pareto_k": twin["pareto_k"],
            "heldout": twin.get("heldout"),
            "parameters": twin["parameters"],
        },
        "healthy": report["healthy"],
        "whitening_gain": whitening_gain(result.diagnoser),
    }


def whitening_gain(diagnoser: Any) -> dict[str, float]:
    """Per residual, what the diagnoser's AR whitening makes of a persistent shift of the
    standardised residual: the innovations shift by ``(1 - sum(a)) / sigma_e`` times it, for
    the whitener's AR coefficients ``a`` and innovation standard deviation ``sigma_e`` (the
    innovations are in units of their own noise). Near 0, a fault that shifts the residual for
    good shows in the innovations at its onset only."""
    out = {}
    for channel, w in diagnoser.whiteners_.items():
        out[str(channel)] = float((1.0 - np.sum(w.coef_)) / w.innovation_std_[w.order_])
    return out


def real_hour_benchmark(
    default: Any,
    *,
    draws: int = 3,
    faults: Sequence[str] = LIBRARY_FAULTS,
    commission_options: Mapping[str, Any] | None = None,
    seed: int = 0,
    progress: bool = True,
) -> dict[str, Any]:
    """The real-hour part of the commissioning benchmark (see the module docstring).

    Parameters
    ----------
    default
        The default (nominal, DAMADICS-trained) online diagnoser, run beside the commissioned
        one on the same data.
    draws
        Posterior parameter draws of the twin per fault and size (seeds
        ``TRANSPLANT_SEED + k``).
    faults
        The faults transplanted.
    commission_options
        Extra arguments of `bayes_fdi.commissioning.commission` (e.g. lighter normal models).
    seed
        Commissioning's seed.
    progress
        Progress on stderr.

    Returns
    -------
    dict
        ``commissioning``, ``twin_check``, ``clean`` (per model), ``noise`` (the commissioned
        innovations' standard deviations on the clean half), ``zones`` and ``cases`` (one row
        per fault, size, draw and model).
    """
    from bayes_fdi.datasets import load_lublin_example

    if isinstance(draws, bool) or not isinstance(draws, int) or not 1 <= draws <= 1000:
        raise ValueError(f"draws must be an integer in [1, 1000], got {draws!r}")
    first, second = _halves(load_lublin_example())
    with busy("real hour: commissioning on the first half", enabled=progress):
        result = commission(first, seed=seed, progress=False, **dict(commission_options or {}))
    check = result.twin.check(second, seed=seed)
    models = {"commissioned": result.diagnoser, "default": default}
    clean_streams = {
        m: zeroed(d.run(second[list(CHANNELS)]).isel(run=0)) for m, d in models.items()
    }
    noise = innovation_noise(clean_streams["commissioned"])
    cases = []
    with busy("real hour: transplanted faults", enabled=progress):
        for draw in range(draws):
            for size_name, size in SIZES.items():
                runs = _transplanted(second, result.twin, faults, size, draw)
                clean = clean_streams["commissioned"]
                cases += _cases(models, runs, faults, size_name, draw, clean, second, noise)
    t_on, t_from, t_hor = REAL_HOUR_ZONES
    return {
        "commissioning": commissioning_summary(result),
        "twin_check": check._asdict(),
        "clean": {m: clean_summary(s) for m, s in clean_streams.items()},
        "noise": noise,
        "zones": {"t_on": t_on, "t_from": t_from, "t_hor": t_hor},
        "draws": int(draws),
        "parameter_seeds": [TRANSPLANT_SEED + k for k in range(draws)],
        "faults": list(faults),
        "groups": {m: groups_of(d) for m, d in models.items()},
        "cases": cases,
    }

"""Commissioning a valve: its own normal models, digital twin, fault library and isolation.

`commission` learns the valve a diagnoser sits on from the plant's healthy data:

1. checks the data (`bayes_fdi.commissioning.healthy`);
2. fits the Bayesian digital twin (`bayes_fdi.twin.ActuatorTwin`) on the first part of the
   data and checks its posterior predictive on the rest (coverage, RMS against the nominal
   model);
3. transplants every fault of the library (the 19 DAMADICS faults and the bias or drift of one
   reading) onto the healthy data, with parameters drawn from the twin's posterior: one
   library trains the isolation, one finds the isolability groups, one calibrates the group
   probabilities (disjoint parameter and noise draws: seeds ``10 seed + 1, 2, 3``; 12 runs
   per fault, both signs of a signed fault in each profile) with a temperature that may
   soften them, never sharpen them (`TEMPERATURE_BOUNDS`);
4. fits the online diagnoser (`bayes_fdi.diagnosis.OnlineDiagnoser`) with the valve's own normal
   models (the command through the valve's own lag and speed limits among their inputs,
   `NORMAL_MODEL_OPTIONS`), detector threshold and input envelope on all the healthy data, and
   the isolation on those libraries (`bayes_fdi.commissioning.isolation`: groups from the
   one-way confusion of the held-out library's detected seconds); its detector is the
   two-speed CUSUM (`bayes_fdi.diagnosis.detection.TwoSpeedCUSUM`, `DETECTOR_K_SLOW`): a
   plant's residuals are often so autocorrelated that their whitening leaves of a lasting
   fault only a small lasting shift of the innovations, which the slow branch accumulates;
5. measures what to expect on held-out transplants (`expected_performance`, seed
   ``10 seed + 4``) and writes it, with the twin's fit and what the data identify, into the
   diagnoser's ``commissioning_`` record, which its model file keeps.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import Any, NamedTuple

import numpy as np
import xarray as xr

from bayes_fdi.commissioning.expectations import expected_performance
from bayes_fdi.commissioning.healthy import check_healthy, operating_range
from bayes_fdi.commissioning.isolation import GROUP_RULE, fit_commissioned_isolation
from bayes_fdi.progress import busy

__all__ = [
    "DETECTOR_K_SLOW",
    "DETECT_RATE",
    "INPUT_MARGIN",
    "ISOLATION_CLASSIFIERS",
    "LIBRARY_FAULTS",
    "NORMAL_MODEL_OPTIONS",
    "TEMPERATURE_BOUNDS",
    "Commissioning",
    "commission",
]

#: The faults transplanted by default: the DAMADICS faults, then a bias or drift of one reading.
LIBRARY_FAULTS: tuple[str, ...] = (
    *(f"f{i}" for i in range(1, 20)),
    "bias_X",
    "bias_F",
    "bias_P1",
    "bias_P2",
)
#: Reference value of the detector's slow branch (innovation standard deviations): it is tuned
#: for a lasting shift of twice this, what the whitening leaves of a residual shift of one to
#: five standard deviations on the strongly autocorrelated residuals of a plant.
DETECTOR_K_SLOW = 0.1
#: The default normal models' physics: the command through the valve's own lag, with the
#: stem's speed limits, both fitted on the healthy data (`DynamicNormalModels` ``physics_inputs``,
#: ``lag_speed_limits``). Chosen on a transplant library that no fit uses: on the real hour's
#: first half it named more held-out seconds' groups right for each of three commissioning
#: seeds (see the Commissioning page of the documentation).
NORMAL_MODEL_OPTIONS: Mapping[str, Any] = MappingProxyType(
    {"physics_inputs": ("command_lag",), "lag_speed_limits": True}
)
#: Widening of the input envelope beyond the healthy data's range, as a share of its span (at
#: least `~bayes_fdi.diagnosis.online.envelope.INPUT_MARGIN_FLOOR`): none. Fitted on one
#: recording, the normal models extrapolate as soon as the inputs leave it: on two perturbed
#: plants that no benchmark scores, the RMS of the standardised residuals grew from 0.24 (X)
#: and 0.17 (F) inside the range to 0.48 and 0.62 at 2-5 % of its span beyond it, 0.75 and
#: 0.99 at 5-10 % (``benchmarks/commissioned_envelope.py``; see the Commissioning page).
INPUT_MARGIN = 0.0
#: A library fault detected in fewer of its training transplants than this share is declared
#: undetectable (not classified; a detection of it is reported without a name), as in the
#: simulator-trained diagnoser. A quarter, which classifies the faults that only their large
#: sizes make detectable, was tried: it isolated more on the two selection plants and less on
#: the benchmark's five (see the Commissioning page of the documentation).
DETECT_RATE = 0.5
#: The isolation classifiers `commission` offers: ``"tree"`` (default), the k-means tree of
#: RVCs whose probabilities multiply along its paths; ``"forest"``, a random forest
#: (`~bayes_fdi.diagnosis.isolation.ForestClassifier`), which names more faults' groups right
#: on the perturbed plants, with as few confident wrong answers (see the Commissioning page).
ISOLATION_CLASSIFIERS: tuple[str, ...] = ("tree", "forest")
#: Bounds of the temperature that calibrates the group probabilities
#: (`~bayes_fdi.calibration.TemperatureScaler`): at least 1, so the calibration softens the
#: classifier's probabilities or leaves them, never sharpens them. Its transplants share the
#: background of the library the classifier learnt (the same healthy data), where a random
#: forest's trees agree less than they deserve; the sharpening fitted there (temperatures
#: 0.47-0.59 on two perturbed plants outside the benchmark, two commissioning seeds) made the
#: forest name new data's faults confidently wrong (see the Commissioning page).
TEMPERATURE_BOUNDS: tuple[float, float] = (1.0, 50.0)
#: Share of the healthy data the twin is fitted on; the rest checks its predictive.
TWIN_FIT_SHARE = 0.8


class Commissioning(NamedTuple):
    """What `commission` returns."""

    diagnoser: Any  #: the fitted `OnlineDiagnoser` (its ``commissioning_`` holds the report)
    twin: Any  #: the fitted `ActuatorTwin`
    report: dict  #: the commissioning report (also ``diagnoser.commissioning_``)


def _split_for_twin(runs: xr.Dataset) -> tuple[xr.Dataset, xr.Dataset | None]:
    """The first `TWIN_FIT_SHARE` of the time axis, and the rest (None when under 300 s)."""
    n = runs.sizes["time"]
    cut = round(TWIN_FIT_SHARE * n)
    rest = runs.isel(time=slice(cut, None))
    return runs.isel(time=slice(0, cut)), (rest if n - cut >= 300 else None)


def _envelope_report(envelope: Any) -> dict[str, Any]:
    """The input envelope: per input its ``[low, high]``, and the largest mean absolute
    one-second change of CV and P1 (full scale per second)."""
    from bayes_fdi.diagnosis.online.envelope import ENVELOPE_CHANNELS, RATE_CHANNELS

    low, high, rate = envelope.low_, envelope.high_, envelope.rate_high_
    return {
        "levels": {c: [float(low[i]), float(high[i])] for i, c in enumerate(ENVELOPE_CHANNELS)},
        "rates": {c: float(rate[i]) for i, c in enumerate(RATE_CHANNELS) if math.isfinite(rate[i])},
    }


def _twin_report(twin: Any, check: Any) -> dict[str, Any]:
    from bayes_fdi.twin import identification

    table, names, corr = identification(twin.inference_data_)
    strong = [
        {"a": names[i], "b": names[j], "correlation": float(corr[i, j])}
        for i in range(len(names))
        for j in range(i + 1, len(names))
        if abs(corr[i, j]) >= 0.8
    ]
    out: dict[str, Any] = {
        "parameters": [row._asdict() for row in table],
        "strong_correlations": strong,
        "pareto_k": float(twin.pareto_k_),
        "fit_seconds": float(twin.fit_seconds_),
    }
    if check is not None:
        out["heldout"] = check._asdict()
    return out


def _normal_models_report(models: Any, runs: Any) -> dict[str, Any]:
    """The normal models' training samples (and the learning curve that chose them), and their
    predictive standard deviations on the healthy data: the median, and the cross-fitted factor
    that made them honest on held-out stretches (``std_factor``)."""
    size = getattr(models, "training_size_", None)
    if size is None:  # normal models of another kind
        return {}
    predicted = models.predict(runs)
    return {
        "rows": int(size.rows),
        "available": size.available,
        "curve": [point._asdict() for point in size.curve],
        "text": size.describe(),
        "median_std": {
            c: float(np.nanmedian(predicted[f"{c}_hat_std"].values)) for c in ("X", "F")
        },
        "std_factor": {c: float(v) for c, v in getattr(models, "std_scale_all_", {}).items()},
    }


def _calibration_report(diagnoser: Any, bounds: tuple[float, float]) -> dict[str, Any]:
    """The group probabilities' calibration: its temperature (None without one: a single
    group, or no classified fault), bounds and whether the fit stopped at a bound."""
    isolator = getattr(diagnoser, "isolator_", None)
    scaler = None if isolator is None else isolator.calibrator_
    return {
        "temperature": None if scaler is None else float(scaler.temperature_),
        "bounds": [float(b) for b in bounds],
        "at_bound": None if scaler is None else bool(scaler.at_bound_),
    }


def commission(
    healthy: xr.Dataset | Sequence[xr.Dataset],
    *,
    faults: Sequence[str] = LIBRARY_FAULTS,
    runs_per_fault: int = 12,
    duration: int = 600,
    sizes: Sequence[float] = (0.25, 0.5, 0.75),
    evaluation_runs: int = 2,
    normal_models: Any = None,
    normal_samples: int | str = 2000,
    twin: Any = None,
    isolation: str = "tree",
    temperature_bounds: tuple[float, float] = TEMPERATURE_BOUNDS,
    detect_rate: float = DETECT_RATE,
    seed: int = 0,
    progress: bool = True,
) -> Commissioning:
    """Commission a valve on its healthy data (see the module docstring).

    Parameters
    ----------
    healthy
        Fault-free recordings of the valve (channels CV, P1, P2, T1, X, F normalised; NaN
        gaps allowed), a dataset or a list of them.
    faults
        The fault library (`LIBRARY_FAULTS`).
    runs_per_fault, duration
        Transplanted runs per fault in each library, and their length (s; at most the
        length of the healthy data).
    sizes, evaluation_runs
        Fault sizes of the held-out check, and runs per fault and size.
    normal_models
        Unfitted normal models (default: `DynamicNormalModels` with `NORMAL_MODEL_OPTIONS`,
        fitted on ``normal_samples``).
    normal_samples
        Samples the default normal models are fitted on (a seeded subset), or ``"auto"``:
        chosen by a learning curve on held-out minutes (up to 4000; costlier, see
        `~bayes_fdi.diagnosis.normal_models.training_size`). The report says which.
    twin
        Unfitted digital twin, cloned before fitting (default:
        ``ActuatorTwin(random_state=seed)``; e.g. fewer fitted parameters for a quick check).
    isolation
        The isolation classifier, one of `ISOLATION_CLASSIFIERS`: ``"tree"``, the k-means
        tree of RVCs, or ``"forest"``, a random forest of 300 trees.
    temperature_bounds
        Bounds ``(low, high)`` of the group probabilities' calibration temperature
        (`TEMPERATURE_BOUNDS`; ``(0.02, 50)`` lets it sharpen them too).
    detect_rate
        A fault detected in fewer than this share of its transplants in the training library
        is declared undetectable (`DETECT_RATE`).
    seed
        Seed of everything drawn (the twin's draws, the libraries, the folds).
    progress
        Progress on stderr.

    Returns
    -------
    Commissioning
    """
    from sklearn.base import clone

    from bayes_fdi.calibration import TemperatureScaler, check_temperature_bounds
    from bayes_fdi.diagnosis import OnlineDiagnoser
    from bayes_fdi.diagnosis.detection import TwoSpeedCUSUM
    from bayes_fdi.diagnosis.isolation import ForestClassifier
    from bayes_fdi.diagnosis.normal_models import DynamicNormalModels
    from bayes_fdi.diagnosis.online.checks import check_settings
    from bayes_fdi.diagnosis.online.training import stack_runs
    from bayes_fdi.twin import ActuatorTwin, transplant_library

    if isolation not in ISOLATION_CLASSIFIERS:
        raise ValueError(
            f"isolation must be one of {', '.join(ISOLATION_CLASSIFIERS)}, got {isolation!r}"
        )
    low, high = check_temperature_bounds(temperature_bounds, name="temperature_bounds")
    if normal_models is None:
        normal_models = DynamicNormalModels(
            max_train_samples=normal_samples, random_state=seed, **NORMAL_MODEL_OPTIONS
        )
    diagnoser = OnlineDiagnoser(
        normal_models,
        detector=TwoSpeedCUSUM(k_slow=DETECTOR_K_SLOW),
        calibrator=TemperatureScaler(bounds=(low, high)),
        isolation_classifier=ForestClassifier(random_state=seed) if isolation == "forest" else None,
        group_rule=GROUP_RULE,
        detect_rate=detect_rate,
        input_margin=INPUT_MARGIN,
        random_state=seed,
    )
    check_settings(diagnoser.get_params())  # refused before anything is fitted
    t_start = time.perf_counter()
    runs = check_healthy(stack_runs(healthy))
    duration = int(min(duration, runs.sizes["time"] - 60))
    seconds: dict[str, float] = {}
    fit_part, check_part = _split_for_twin(runs)
    t0 = time.perf_counter()
    with busy("commissioning: fitting the digital twin", enabled=progress):
        twin = (ActuatorTwin(random_state=seed) if twin is None else clone(twin)).fit(fit_part)
        check = twin.check(check_part, seed=seed) if check_part is not None else None
    seconds["twin"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    with busy("commissioning: transplanting the fault library", enabled=progress):
        libraries = [
            transplant_library(
                runs,
                twin,
                faults=faults,
                runs_per_fault=runs_per_fault,
                duration=duration,
                seed=10 * seed + k,
            )
            for k in (1, 2, 3)
        ]
    seconds["library"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    with busy("commissioning: fitting the normal models, detector and isolation", enabled=progress):
        diagnoser.fit(runs)
        fit_commissioned_isolation(diagnoser, *libraries)
    seconds["diagnoser"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    with busy("commissioning: checking it on held-out transplants", enabled=progress):
        expected = expected_performance(
            diagnoser,
            runs,
            twin,
            faults=faults,
            sizes=sizes,
            runs_per_size=evaluation_runs,
            duration=duration,
            seed=10 * seed + 4,
        )
    seconds["expectations"] = time.perf_counter() - t0
    seconds["total"] = time.perf_counter() - t_start
    report = {
        "healthy": operating_range(runs),
        "envelope": _envelope_report(diagnoser.envelope_),
        "twin": _twin_report(twin, check),
        "library": {
            "faults": list(faults),
            "runs_per_fault": int(runs_per_fault),
            "duration": int(duration),
            "seeds": [10 * seed + k for k in (1, 2, 3)],
        },
        "normal_models": _normal_models_report(diagnoser.normal_models_, runs),
        "detection": {
            "detector": type(diagnoser.detector_).__name__,
            "k": float(diagnoser.detector_.k),
            "k_slow": float(diagnoser.detector_.k_slow),
            "threshold": float(diagnoser.threshold_),
            "false_alarm_hours": float(diagnoser.false_alarm_hours),
        },
        "groups": [list(g) for g in diagnoser.groups_],
        "isolation_classifier": isolation,
        "calibration": _calibration_report(diagnoser, (low, high)),
        "group_rule": GROUP_RULE,
        "group_threshold": float(diagnoser.group_threshold),
        "undetectable": list(diagnoser.undetectable_),
        "detect_rate": float(diagnoser.detect_rate),
        "detection_rates": {k: float(v) for k, v in diagnoser.detection_rates_.items()},
        "expected": expected,
        "seconds": seconds,
        "seed": int(seed),
    }
    diagnoser.commissioning_ = report
    return Commissioning(diagnoser, twin, report)

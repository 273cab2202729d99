"""The steps of `NormalModels.fit` before its final fits: the samples, then the kernel widths.

`training_samples` reads the fault-free runs into model inputs and outputs and leaves out the
samples with a NaN (with a warning giving their number). `choose_widths` gives a regressor whose
width is ``"auto"`` one from `NormalModels`' width search (``width_search``): the summed
evidence over a grid (``"evidence-grid"``, the default), the RVR's own search on a subsample
(``"evidence"``) or the paper's GA on held-out runs (``"ga"``); the searches themselves are in
`bayes_fdi.diagnosis.normal_models.width_search`.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
import xarray as xr
from sklearn.base import clone

from bayes_fdi.datasets import OUTPUT_CHANNELS
from bayes_fdi.diagnosis.normal_models.inputs import model_inputs
from bayes_fdi.diagnosis.normal_models.width_search import (
    GAResult,
    evidence_grid_search,
    genetic_width_search,
)

__all__ = [
    "TrainingSamples",
    "WidthChoice",
    "check_width_grid",
    "choose_widths",
    "training_samples",
    "with_width",
]


class TrainingSamples(NamedTuple):
    """The fault-free samples of `training_samples`, flattened run by run."""

    U: np.ndarray  #: model inputs, ``(n_samples, n_inputs)``
    targets: dict[str, np.ndarray]  #: output name -> ``(n_samples,)``
    finite: np.ndarray  #: samples with every input and output finite
    run_of: np.ndarray  #: the run of every sample
    n_negative_pressure_drop: int  #: samples with ``P1 < P2`` (signed root used)
    n_dropped: int  #: samples left out for a NaN


def training_samples(normal_runs: xr.Dataset, input_lags: tuple[float, ...]) -> TrainingSamples:
    """Model inputs and outputs of every sample of ``normal_runs``; at least two finite ones.

    Warns (a `UserWarning`) with the number of samples left out because an input or output is
    NaN.
    """
    U, n_neg = model_inputs(normal_runs, input_lags=input_lags)
    n_runs, n_times = normal_runs.sizes["run"], normal_runs.sizes["time"]
    targets = {
        name: np.asarray(normal_runs[name].transpose("run", "time").values).ravel()
        for name in OUTPUT_CHANNELS
    }
    finite = np.isfinite(U).all(axis=1)
    for y in targets.values():
        finite &= np.isfinite(y)
    n_dropped = int((~finite).sum())
    if n_dropped:
        warnings.warn(
            f"{n_dropped} fault-free sample(s) with NaN inputs/outputs are not used to fit "
            "the normal models",
            UserWarning,
            stacklevel=3,  # the frame NormalModels.fit's own warnings point at
        )
    if np.flatnonzero(finite).size < 2:
        raise ValueError("fewer than 2 finite fault-free samples to fit the normal models")
    run_of = np.repeat(np.arange(n_runs), n_times)
    return TrainingSamples(U, targets, finite, run_of, n_neg, n_dropped)


class WidthChoice(NamedTuple):
    """What `choose_widths` found (the attributes `NormalModels` keeps of it)."""

    widths: dict[str, float]  #: output -> width; an output without one keeps the regressor's
    ga_results: dict[str, GAResult]  #: ``"ga"``: output -> the GA's result
    log_evidence: dict[float, float]  #: ``"evidence-grid"``: width -> summed log evidence
    log_evidence_by_output: dict[str, dict[float, float]]  #: ``"evidence-grid"``, per output
    seconds: dict[str, float]  #: wall-clock seconds of the search, under its name


def with_width(base: Any, width_param: str, width: float) -> Any:
    """An unfitted clone of ``base`` with its kernel-width parameter set to ``width``."""
    return clone(base).set_params(**{width_param: width})


def check_width_grid(width_grid: Any) -> tuple[float, ...]:
    """The validated ``width_grid`` (non-empty, positive finite, distinct) as floats."""
    msg = "width_grid must be a non-empty sequence of distinct positive finite widths"
    try:
        grid = tuple(width_grid)
    except TypeError:
        raise ValueError(f"{msg}, got {width_grid!r}") from None
    if not grid:
        raise ValueError(f"{msg}, got an empty grid")
    for w in grid:
        if isinstance(w, bool) or not isinstance(w, int | float | np.integer | np.floating):
            raise ValueError(f"{msg}, got {w!r} in {width_grid!r}")
        if not (math.isfinite(float(w)) and float(w) > 0):
            raise ValueError(f"{msg}, got {w!r} in {width_grid!r}")
    if len({float(w) for w in grid}) != len(grid):
        raise ValueError(f"{msg}, got repeated widths in {width_grid!r}")
    return tuple(float(w) for w in grid)


def choose_widths(
    base: Any,
    U: np.ndarray,
    targets: Mapping[str, np.ndarray],
    idx: np.ndarray,
    run_of: np.ndarray,
    rng: np.random.Generator,
    *,
    method: str | None,
    width_param: str,
    grid: Sequence[float],
    evidence_max_samples: int,
    ga_bounds: tuple[float, float],
    ga_population: int,
    ga_generations: int,
    ga_validation_fraction: float,
    ga_max_samples: int,
    random_state: int | None,
) -> WidthChoice:
    """Run the width search ``method`` of `NormalModels` on the fault-free samples.

    Parameters
    ----------
    base
        The unfitted regressor; ``"evidence-grid"`` and ``"evidence"`` search only when its
        ``width_param`` is ``"auto"``, ``"ga"`` always.
    U, targets
        Model inputs ``(n_samples, n_inputs)`` and the outputs (name -> ``(n_samples,)``).
    idx
        The finite samples (the only ones searched on).
    run_of
        The run of every sample (the GA holds whole runs out).
    rng
        The fit's random stream (subsamples, the GA's validation runs); it advances.
    method, width_param, grid, evidence_max_samples, ga_bounds, ga_population, ga_generations,
    ga_validation_fraction, ga_max_samples, random_state
        `NormalModels`' parameters of the same names (``method`` is ``width_search``).

    Returns
    -------
    WidthChoice
        Empty widths when no search ran (``None``, or a width other than ``"auto"``).
    """
    choice = WidthChoice({}, {}, {}, {}, {})
    auto_width = base.get_params().get(width_param, None) == "auto"
    if method == "ga":
        if width_param not in base.get_params():
            raise ValueError(f"{type(base).__name__} has no parameter {width_param!r} for the GA")
        n_runs = int(run_of.max()) + 1 if run_of.size else 0
        if n_runs < 2:
            raise ValueError("the genetic width search needs at least 2 fault-free runs")
        n_val = max(1, round(ga_validation_fraction * n_runs))
        n_val = min(n_val, n_runs - 1)
        val_runs = rng.choice(n_runs, size=n_val, replace=False)
        is_val = np.isin(run_of[idx], val_runs)
        tr, va = idx[~is_val], idx[is_val]
        if tr.size > ga_max_samples:
            tr = rng.choice(tr, size=int(ga_max_samples), replace=False)
        if va.size > ga_max_samples:
            va = rng.choice(va, size=int(ga_max_samples), replace=False)
        t0 = time.perf_counter()
        for name, y in targets.items():
            res = genetic_width_search(
                lambda width: with_width(base, width_param, width),
                U[tr],
                y[tr],
                U[va],
                y[va],
                bounds=ga_bounds,
                population=ga_population,
                generations=ga_generations,
                random_state=random_state,
            )
            choice.ga_results[name] = res
            choice.widths[name] = res.width
        choice.seconds["ga"] = time.perf_counter() - t0
    elif method == "evidence-grid" and auto_width:
        t0 = time.perf_counter()
        res = evidence_grid_search(
            lambda width: with_width(base, width_param, width),
            U[idx],
            {name: y[idx] for name, y in targets.items()},
            grid,
            max_samples=evidence_max_samples,
            rng=rng,
        )
        choice.widths.update(dict.fromkeys(targets, res.width))
        choice.log_evidence.update(res.log_evidence)
        choice.log_evidence_by_output.update(res.log_evidence_by_output)
        choice.seconds["evidence-grid"] = time.perf_counter() - t0
    elif method == "evidence" and auto_width and idx.size > evidence_max_samples:
        sub = np.sort(rng.choice(idx, size=evidence_max_samples, replace=False))
        t0 = time.perf_counter()
        for name, y in targets.items():
            searched = clone(base).fit(U[sub], y[sub])
            choice.widths[name] = float(searched.width_)
        choice.seconds["evidence"] = time.perf_counter() - t0
    return choice

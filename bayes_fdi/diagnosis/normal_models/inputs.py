"""Normal-model inputs: ``(CV, sqrt(P1 - P2), T1)`` and, optionally, delayed commands.

Pressure drop: where ``P1 < P2`` (reverse flow under fault f17, or bad data), the square root
is replaced by the signed root ``sign(D) * sqrt(|D|)`` with ``D = P1 - P2``; such samples are
kept (never dropped) and counted, with a `NegativePressureDropWarning`.

Dynamic inputs (beyond the paper): ``input_lags=(L1, L2, ...)`` appends the delayed commands
``CV(t - L1), CV(t - L2), ...`` (lags in seconds of the ``time`` coordinate) to the three inputs,
so the models can follow the actuator's lag behind its command. Before a run's first sample the
command is taken as held at its first value (no sample is dropped). The default ``()`` gives the
paper's static models.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.datasets import INPUT_CHANNELS, validate_dataset

__all__ = ["MODEL_INPUTS", "NegativePressureDropWarning", "input_names", "model_inputs"]

#: Names of the three regression inputs (columns of `model_inputs`).
MODEL_INPUTS: tuple[str, ...] = ("CV", "sqrt_dP", "T1")


class NegativePressureDropWarning(UserWarning):
    """Some samples have ``P1 < P2``; the signed root ``sign(D) sqrt(|D|)`` was used."""


def check_lags(input_lags: Any) -> tuple[float, ...]:
    """Validate ``input_lags`` (seconds): a sequence of distinct finite positive numbers."""
    if isinstance(input_lags, (str, bytes)) or not hasattr(input_lags, "__iter__"):
        raise ValueError(
            f"input_lags must be a sequence of lags in seconds, e.g. (1, 2); got {input_lags!r}"
        )
    lags = []
    for lag in input_lags:
        if isinstance(lag, (bool, np.bool_)) or not isinstance(lag, (int, float, np.number)):
            raise ValueError(f"input_lags must hold numbers (seconds); got {lag!r}")
        value = float(lag)
        if not math.isfinite(value) or value <= 0:
            raise ValueError(f"input_lags must be positive and finite (seconds); got {lag!r}")
        lags.append(value)
    if len(set(lags)) != len(lags):
        raise ValueError(f"input_lags has duplicate lags: {tuple(input_lags)!r}")
    return tuple(lags)


def _lag_name(lag: float) -> str:
    return f"CV_lag{lag:g}s"


def input_names(input_lags: Any = ()) -> tuple[str, ...]:
    """Names of the columns of ``model_inputs(ds, input_lags=input_lags)``.

    ``("CV", "sqrt_dP", "T1")`` followed by ``"CV_lag{L}s"`` for each lag ``L`` (in the order
    given), e.g. ``input_names((1, 2.5))`` is
    ``("CV", "sqrt_dP", "T1", "CV_lag1s", "CV_lag2.5s")``.
    """
    return MODEL_INPUTS + tuple(_lag_name(lag) for lag in check_lags(input_lags))


def _lag_steps(ds: xr.Dataset, lags: tuple[float, ...]) -> list[int]:
    """Each lag as a whole number of sampling steps of ``ds["time"]`` (ValueError otherwise)."""
    if "time" not in ds.coords:
        raise ValueError("input_lags need a 'time' coordinate (seconds) to define the lag")
    t = np.asarray(ds["time"].values)
    if np.issubdtype(t.dtype, np.datetime64) or np.issubdtype(t.dtype, np.timedelta64):
        t = (t - t[0]) / np.timedelta64(1, "s")
    if not np.issubdtype(t.dtype, np.number):
        raise ValueError(f"the 'time' coordinate must be numeric seconds, got dtype {t.dtype}")
    t = t.astype(np.float64)
    if t.size < 2:
        raise ValueError(
            f"input_lags need at least 2 time samples to define the sampling step, got {t.size}"
        )
    dt = np.diff(t)
    step = float(dt[0])
    if not (math.isfinite(step) and step > 0):
        raise ValueError(f"the 'time' coordinate must increase, got a first step of {step}")
    if not np.allclose(dt, step, rtol=1e-6, atol=0.0):
        raise ValueError(
            "input_lags need a uniform time grid; the 'time' steps range from "
            f"{dt.min():g} to {dt.max():g} s"
        )
    steps = []
    for lag in lags:
        ratio = lag / step
        k = round(ratio)
        if k < 1 or abs(ratio - k) > 1e-6 * max(1.0, ratio):
            raise ValueError(
                f"input lag {lag:g} s is not a whole multiple of the sampling step {step:g} s"
            )
        steps.append(int(k))
    return steps


def _held_shift(cv: np.ndarray, k: int) -> np.ndarray:
    """``cv`` (run, time) delayed by ``k`` samples, held at each run's first value before it."""
    out = np.empty_like(cv)
    k = min(k, cv.shape[1])
    out[:, :k] = cv[:, :1]
    out[:, k:] = cv[:, : cv.shape[1] - k]
    return out


def model_inputs(
    ds: xr.Dataset, *, warn: bool = True, input_lags: Any = ()
) -> tuple[np.ndarray, int]:
    """Regression inputs ``(CV, sign(D) sqrt(|D|), T1)`` with ``D = P1 - P2``, one row a sample.

    Parameters
    ----------
    ds
        Dataset in the project's format with channels ``CV``, ``P1``, ``P2``, ``T1``.
    warn
        Emit a `NegativePressureDropWarning` when some samples have ``P1 < P2``.
    input_lags
        Lags ``L`` in seconds (positive, distinct, each a whole multiple of the sampling step of
        the uniform ``time`` coordinate); one column ``CV(t - L)`` is appended per lag, in the
        order given (names: `input_names`). Before a run's first sample the command is taken
        as held at its first value, so ``CV(t - L) = CV(t_0)`` for ``t - L < t_0``: no sample
        is dropped. A NaN command stays NaN in the lagged columns (``L`` later). Default
        ``()``: the paper's three static inputs.

    Returns
    -------
    inputs : numpy.ndarray
        ``(n_runs * n_times, 3 + len(input_lags))``, runs stacked in order (row
        ``r * n_times + t``). NaN inputs stay NaN.
    n_negative : int
        Number of samples with ``P1 < P2`` (signed root used; samples kept).
    """
    lags = check_lags(input_lags)
    validate_dataset(ds, require=INPUT_CHANNELS, allow_nan=True)
    steps = _lag_steps(ds, lags) if lags else []

    def grid(name: str) -> np.ndarray:
        return np.asarray(ds[name].transpose("run", "time").values, dtype=np.float64)

    def flat(name: str) -> np.ndarray:
        return grid(name).ravel()

    dp = flat("P1") - flat("P2")
    n_negative = int(np.sum(dp < 0))
    if n_negative and warn:
        warnings.warn(
            f"{n_negative} of {dp.size} samples have P1 < P2; using the signed root "
            "sign(P1-P2)*sqrt(|P1-P2|) for them (samples kept)",
            NegativePressureDropWarning,
            stacklevel=2,
        )
    root = np.sign(dp) * np.sqrt(np.abs(dp))
    columns = [flat("CV"), root, flat("T1")]
    if steps:
        cv = grid("CV")
        columns += [_held_shift(cv, k).ravel() for k in steps]
    return np.column_stack(columns), n_negative

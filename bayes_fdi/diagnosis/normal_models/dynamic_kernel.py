"""The inputs and the compiled per-second predictor of the dynamic normal models: its parameters,
its state and its kernel.

`~bayes_fdi.diagnosis.normal_models.dynamic.DynamicNormalModels` predicts X and F second by
second through `predict_seconds`, a compiled loop over the samples of one run that keeps the
last ``D`` values of CV and of the signed root ``s`` of the pressure drop
(`NormalModelsState`) and takes the fitted values as one named tuple (`NormalModelsParams`:
the input standardisation, the two `~bayes_fdi.diagnosis.normal_models.compiled.LeanRVR`
regressions and the std factors per bin of the command speed or of the input novelty). Whole
recordings and single seconds go through the same loop (`predict_runs` runs it over many runs
at once), so they give the same numbers. `dynamic_inputs` is a vectorised reference
of the inputs the loop builds, and the fit's. With physics inputs
(`bayes_fdi.diagnosis.normal_models.physics_inputs`) the loop also carries the command's lag
(one more input of the position model) and evaluates the valve law at the predicted position (one
more input of the flow model).

Written by hand: no library compiles this per-sample chain of two RVM predictions.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
import xarray as xr
from numba import njit

from bayes_fdi.diagnosis.normal_models.compiled import LeanRVR, rvr_predict
from bayes_fdi.diagnosis.normal_models.input_novelty import nearest_distance, novelty_columns
from bayes_fdi.diagnosis.normal_models.physics_inputs import lag_rates, lag_step, valve_law_at
from bayes_fdi.diagnosis.normal_models.residuals import SENSOR_RANGE

__all__ = [
    "PREDICTION_COLUMNS",
    "NormalModelsParams",
    "NormalModelsState",
    "dynamic_inputs",
    "identity_std_factors",
    "kernel_params",
    "predict_runs",
    "predict_seconds",
    "signed_root",
]

#: Columns of `predict_seconds`' output; the last is what bins the std factors: the command
#: speed, or the input novelty (`~.input_novelty`) where ``novelty_reference`` is given.
PREDICTION_COLUMNS = ("X_hat", "X_hat_std", "F_hat", "F_hat_std", "command_speed")


def signed_root(p1: Any, p2: Any) -> np.ndarray:
    """``sign(P1 - P2) sqrt(|P1 - P2|)`` (the paper's ``sqrt(P1 - P2)``, kept for P1 < P2)."""
    d = np.asarray(p1, dtype=np.float64) - np.asarray(p2, dtype=np.float64)
    return np.sign(d) * np.sqrt(np.abs(d))


def _held_shift(a: np.ndarray, k: int) -> np.ndarray:
    out = np.empty_like(a)
    k = min(k, a.shape[1])
    out[:, :k] = a[:, :1]
    out[:, k:] = a[:, : a.shape[1] - k]
    return out


def dynamic_inputs(runs: xr.Dataset, n_differences: int) -> np.ndarray:
    """The unscaled inputs of the position model, ``(n_runs, n_times, 2 + 2 D)``.

    Columns ``CV, s, dCV_0 .. dCV_{D-1}, ds_0 .. ds_{D-1}`` (see
    `bayes_fdi.diagnosis.normal_models.dynamic`); before a run's first sample CV and ``s`` are
    held at their first values (increments 0); a NaN stays NaN in every increment that uses it.
    A vectorised reference of the compiled kernel's inputs.
    """
    cv = np.asarray(runs["CV"].transpose("run", "time").values, dtype=np.float64)
    s = signed_root(
        runs["P1"].transpose("run", "time").values, runs["P2"].transpose("run", "time").values
    )
    cols = [cv, s]
    for v in (cv, s):
        for k in range(n_differences):
            cols.append(_held_shift(v, k) - _held_shift(v, k + 1))
    return np.stack(cols, axis=-1)


class NormalModelsState(NamedTuple):
    """The state of the dynamic normal models' predictor (one run)."""

    #: ``(2, D)`` the last ``D`` values of CV (row 0) and ``s`` (row 1), newest first; with
    #: physics inputs ``(2, D + 1)``, the last column holding the command lag's output (row 0)
    history: np.ndarray
    #: ``(1,)`` int64: 1 once a sample has been seen (before it, the history is undefined)
    seen: np.ndarray


class NormalModelsParams(NamedTuple):
    """The fitted values `predict_seconds` takes."""

    input_mean: np.ndarray  #: ``(2 + 2 D,)`` standardisation of the position model's inputs
    input_scale: np.ndarray  #: ``(2 + 2 D,)``
    x_model: LeanRVR  #: the position model
    f_model: LeanRVR  #: the flow model, of ``(X_hat, s)``
    speed_edges: np.ndarray  #: inner edges of the command-speed bins
    x_std_scale: np.ndarray  #: std factor of X per speed bin
    f_std_scale: np.ndarray  #: std factor of F per speed bin
    x_std_scale_all: float  #: std factor of X where the speed is undefined
    f_std_scale_all: float  #: std factor of F there
    low: float  #: lower rail of the predictions
    high: float  #: upper rail of the predictions
    #: ``(4,)`` rates and speed limits of the command lag (`~.physics_inputs.lag_rates`), or
    #: ``(0,)``: none
    command_lag: np.ndarray = np.empty(0)
    #: the valve law's constants (`~.physics_inputs.nominal_valve_law`), or ``(0,)``: none
    valve_law: np.ndarray = np.empty(0)
    #: True: the position model learnt X minus the lagged command, which is added back
    lag_as_mean: bool = False
    #: True: the flow model learnt F minus the valve law's clipped flow, which is added back
    law_as_mean: bool = False
    #: ``(m, len(novelty_columns))`` standardised training inputs whose nearest distance bins
    #: the std factors (`~.input_novelty`), or ``(0, 0)``: the command speed bins them
    novelty_reference: np.ndarray = np.empty((0, 0))
    #: the columns of the standardised inputs that the novelty measures
    novelty_columns: np.ndarray = np.empty(0, dtype=np.int64)

    @classmethod
    def upgrade_model_file(cls, data: dict, format_version: int) -> dict:
        """Files of format <= 8 have no physics inputs; of format <= 10, a command lag without
        speed limits and a position model that learnt X itself; of format <= 11, a flow model
        that learnt F itself and std factors binned by the command speed."""
        data.setdefault("command_lag", np.empty(0))
        data.setdefault("valve_law", np.empty(0))
        data.setdefault("lag_as_mean", False)
        data.setdefault("law_as_mean", False)
        data.setdefault("novelty_reference", np.empty((0, 0)))
        data.setdefault("novelty_columns", np.empty(0, dtype=np.int64))
        lag = np.asarray(data["command_lag"], dtype=np.float64)
        if lag.size == 2:  # format <= 10: a lag without speed limits
            data["command_lag"] = np.concatenate([lag, [np.inf, np.inf]])
        return data


def identity_std_factors(n_bins: int) -> tuple[np.ndarray, dict, dict]:
    """Std factors 1 (no bin edges, ``{"X": ones, "F": ones}`` per bin, 1 over every bin): the
    cross-fit's, and the fitted models' until the cross-fit gives theirs."""
    return np.empty(0), {c: np.ones(n_bins) for c in ("X", "F")}, {"X": 1.0, "F": 1.0}


def kernel_params(models: Any, mx: Any, mf: Any, *, calibrated: bool = True) -> NormalModelsParams:
    """The compiled predictor's parameters of fitted
    `~bayes_fdi.diagnosis.normal_models.dynamic.DynamicNormalModels` ``models`` for the
    regressions ``mx``, ``mf``: with the fitted std factors, or (``calibrated=False``) with
    factors 1 and no novelty reference (the cross-fit's)."""
    if calibrated:
        edges, scale, scale_all = models.std_scale_edges_, models.std_scale_, models.std_scale_all_
    else:
        edges, scale, scale_all = identity_std_factors(int(models.calibration_bins))
    lag = models.command_lag_
    return NormalModelsParams(
        input_mean=np.ascontiguousarray(models.input_mean_),
        input_scale=np.ascontiguousarray(models.input_scale_),
        x_model=LeanRVR.from_estimator(mx),
        f_model=LeanRVR.from_estimator(mf),
        speed_edges=np.ascontiguousarray(edges),
        x_std_scale=np.ascontiguousarray(scale["X"]),
        f_std_scale=np.ascontiguousarray(scale["F"]),
        x_std_scale_all=float(scale_all["X"]),
        f_std_scale_all=float(scale_all["F"]),
        low=SENSOR_RANGE[0],
        high=SENSOR_RANGE[1],
        command_lag=lag_rates(*lag) if lag else np.empty(0),
        valve_law=np.ascontiguousarray(models.valve_law_),
        lag_as_mean=bool(models.lag_as_mean),
        law_as_mean=bool(models.law_as_mean),
        novelty_reference=models.novelty_reference_ if calibrated else np.empty((0, 0)),
        novelty_columns=novelty_columns(models.std_bins, int(models.n_differences), bool(lag)),
    )


# one compiled loop over the seconds, clearer whole than cut into pieces
@njit(cache=True, error_model="numpy")
def predict_seconds(cv, p1, p2, t1, params, state, out):  # pragma: no cover - compiled
    """Predictions of one run's consecutive samples into ``out`` ``(n, 5)`` (columns
    `PREDICTION_COLUMNS`); ``state`` (a `NormalModelsState`) is updated in place. ``t1`` is
    read by the valve law only."""
    hist = state.history
    n_seen = state.seen
    lagged = params.command_lag.size > 0
    law = params.valve_law.size > 0
    n_d = hist.shape[1] - (1 if lagged else 0)
    n_u = 2 + 2 * n_d + (1 if lagged else 0)
    u = np.empty(n_u)
    v = np.empty(3 if law else 2)
    phi_x = np.empty(params.x_model.weights.size)
    phi_f = np.empty(params.f_model.weights.size)
    edges = params.speed_edges
    for t in range(cv.size):
        c = cv[t]
        dp = p1[t] - p2[t]
        s = math.sqrt(dp) if dp >= 0.0 else -math.sqrt(-dp)
        if n_seen[0] == 0:
            for k in range(n_d):
                hist[0, k] = c
                hist[1, k] = s
            if lagged:
                hist[0, n_d] = c
                hist[1, n_d] = 0.0
            n_seen[0] = 1
        # raw inputs: levels, then the increments of CV and of s
        u[0] = c
        u[1] = s
        prev_c = c
        prev_s = s
        for k in range(n_d):
            u[2 + k] = prev_c - hist[0, k]
            u[2 + n_d + k] = prev_s - hist[1, k]
            prev_c = hist[0, k]
            prev_s = hist[1, k]
        speed = abs(u[2]) if n_d > 0 else math.nan
        for k in range(n_d - 1, 0, -1):
            hist[0, k] = hist[0, k - 1]
            hist[1, k] = hist[1, k - 1]
        if n_d > 0:
            hist[0, 0] = c
            hist[1, 0] = s
        if lagged:  # the two-rate lag of the command; a NaN command leaves it where it was
            if np.isfinite(c):
                y = hist[0, n_d]
                hist[0, n_d] = c if not np.isfinite(y) else lag_step(y, c, params.command_lag)
            u[n_u - 1] = hist[0, n_d] if np.isfinite(c) else math.nan
        ok = True
        for j in range(u.size):
            if not np.isfinite(u[j]):
                ok = False
        if not ok:
            for j in range(5):
                out[t, j] = np.nan
            continue
        for j in range(u.size):
            u[j] = (u[j] - params.input_mean[j]) / params.input_scale[j]
        if params.novelty_reference.shape[0] > 0:  # the std bins follow the input novelty
            speed = nearest_distance(u, params.novelty_reference, params.novelty_columns)
        xm, xv = rvr_predict(u, params.x_model, phi_x)
        if lagged and params.lag_as_mean:  # the model learnt X minus the lagged command
            xm = xm + hist[0, n_d]
        xm = min(max(xm, params.low), params.high)
        v[0] = xm
        v[1] = s
        if law:
            v[2] = valve_law_at(xm, s, t1[t], p1[t], params.valve_law)
        fm, fv = rvr_predict(v, params.f_model, phi_f)
        if law and params.law_as_mean:  # the model learnt F minus the clipped valve law
            fm = fm + min(max(v[2], params.low), params.high)
        fm = min(max(fm, params.low), params.high)
        if np.isfinite(speed):
            b = 0
            while b < edges.size and speed >= edges[b]:
                b += 1
            xs = params.x_std_scale[b]
            fs = params.f_std_scale[b]
        else:
            xs = params.x_std_scale_all
            fs = params.f_std_scale_all
        out[t, 0] = xm
        out[t, 1] = math.sqrt(xv) * xs
        out[t, 2] = fm
        out[t, 3] = math.sqrt(fv) * fs
        out[t, 4] = speed


@njit(cache=True, error_model="numpy")
def predict_runs(cv, p1, p2, t1, params, state, out):  # pragma: no cover - compiled
    """`predict_seconds` of each run (row) of ``(runs, n)`` inputs into ``out``
    ``(runs, n, 5)``; ``state`` stacks the runs' `NormalModelsState` (leading run axis)."""
    for r in range(cv.shape[0]):
        run_state = NormalModelsState(state.history[r], state.seen[r])
        predict_seconds(cv[r], p1[r], p2[r], t1[r], params, run_state, out[r])

"""Physics-carrying inputs of the dynamic normal models (opt-in: ``physics_inputs``).

The dynamic normal models' default inputs (levels and one-second increments of the command and
of the pressure-drop root) describe the excitation's pattern; after a command step the stem's
travel takes seconds, and a model that learnt one excitation extrapolates. Two inputs carry what
the actuator does instead:

- **The command through the actuator's lag** (`lagged_command`): CV passed through a first-order
  lag whose time constant depends on the direction of travel (the chamber fills from the supply
  one way and vents the other, at different speeds), optionally with the stem's speed limited in
  each direction (the air flows in and out through restrictions, so after a large step the stem
  travels at a constant speed): per one-second sample
  ``y(t) = y(t-1) + clip(a (CV(t) - y(t-1)), -v_fall, v_rise)`` with
  ``a = 1 - exp(-1 s / tau)``, ``tau = tau_rise`` where ``CV(t) > y(t-1)`` and ``tau_fall``
  elsewhere, ``y`` held at the run's first command before it. The time constants (and, when
  asked for, the speed limits) are estimated from the fault-free training runs
  (`fit_command_lag`: on logarithmic grids, the values whose lagged command, with ``s``,
  explains X best by least squares; no limit where the runs never show one). The position
  model takes ``y`` as one more input, or learns ``X - y``
  (`~bayes_fdi.diagnosis.normal_models.dynamic.DynamicNormalModels` ``lag_as_mean``).
- **The valve law** (`valve_law_flow`): the flow of the nominal valve (DABLib's
  equal-percentage characteristic ``Kv exp(-c x)``, linear above 97.5 % closing, the water's
  density at T1 and P1; no choking, bypass closed) at the predicted position, in the F sensor's
  normalised units with the nominal sensor calibration (`valve_law_at`). The flow model takes
  it as a third input beside ``(X_hat, s)``: the law's shape and its temperature term come from
  the model rather than from the RBF's interpolation.

The per-sample functions are compiled (`lag_step`, `valve_law_at`): the normal models' compiled
kernel calls them every second, and the vectorised functions here call the same ones, so fit
and stream compute the same numbers. Written by hand: a two-rate lag and DABLib's valve law
are not in any library.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from bayes_fdi.actuator.parameters import F_RANGE, P_RANGE, T_RANGE, ActuatorParameters
from bayes_fdi.actuator.valve import compiled_water_density

__all__ = [
    "LAG_GRID",
    "PHYSICS_INPUTS",
    "SPEED_GRID",
    "check_physics_inputs",
    "fit_command_lag",
    "flow_model_inputs",
    "lag_rates",
    "lag_step",
    "lagged_command",
    "nominal_valve_law",
    "stream_channels",
    "valve_law_at",
    "valve_law_flow",
]

#: The physics inputs a model may take: the command through the actuator's lag (position model)
#: and the valve law's flow at the predicted position (flow model).
PHYSICS_INPUTS: tuple[str, ...] = ("command_lag", "valve_law")
#: Time constants (s) tried for each direction by `fit_command_lag`.
LAG_GRID: tuple[float, ...] = tuple(float(v) for v in np.round(np.geomspace(0.25, 32.0, 22), 3))
#: Stem speed limits (normalised travel per second) tried for each direction by
#: `fit_command_lag`, no limit first (kept unless a limit explains the position better).
SPEED_GRID: tuple[float, ...] = (
    math.inf,
    *(float(v) for v in np.geomspace(0.01, 0.5, 14).round(4)),
)


def check_physics_inputs(physics_inputs: Any) -> tuple[str, ...]:
    """``physics_inputs`` as a tuple of distinct names of `PHYSICS_INPUTS` (ValueError else)."""
    if isinstance(physics_inputs, str | bytes) or not isinstance(physics_inputs, tuple | list):
        raise ValueError(
            f"physics_inputs must be a tuple of names among {PHYSICS_INPUTS}, e.g. "
            f"('command_lag', 'valve_law'); got {physics_inputs!r}"
        )
    names = tuple(physics_inputs)
    unknown = [n for n in names if n not in PHYSICS_INPUTS]
    if unknown or len(set(names)) != len(names):
        raise ValueError(
            f"physics_inputs must hold distinct names among {PHYSICS_INPUTS}; got {names!r}"
        )
    return names


def lag_rates(
    tau_rise: float, tau_fall: float, v_rise: float = math.inf, v_fall: float = math.inf
) -> np.ndarray:
    """``[a_rise, a_fall, v_rise, v_fall]``, ``a = 1 - exp(-1 s / tau)``: the per-second rates
    and speed limits of `lag_step` (``inf``: no limit)."""
    for name, tau in (("tau_rise", tau_rise), ("tau_fall", tau_fall)):
        if not (math.isfinite(float(tau)) and float(tau) > 0):
            raise ValueError(f"{name} must be a positive number of seconds, got {tau!r}")
    for name, v in (("v_rise", v_rise), ("v_fall", v_fall)):
        if not float(v) > 0:
            raise ValueError(f"{name} must be a positive speed (or inf: no limit), got {v!r}")
    a = [-math.expm1(-1.0 / float(tau_rise)), -math.expm1(-1.0 / float(tau_fall))]
    return np.array([*a, float(v_rise), float(v_fall)])


@njit(cache=True, error_model="numpy")
def lag_step(y, c, rates):  # pragma: no cover - compiled
    """One second of the two-rate lag with speed limits: the new output from the last ``y`` and
    command ``c`` (``rates`` of `lag_rates`)."""
    a = rates[0] if c > y else rates[1]
    step = a * (c - y)
    if step > rates[2]:
        step = rates[2]
    elif step < -rates[3]:
        step = -rates[3]
    return y + step


@njit(cache=True, error_model="numpy")
def _lag_runs(cv, rates, out):  # pragma: no cover - compiled
    for r in range(cv.shape[0]):
        y = math.nan
        for t in range(cv.shape[1]):
            c = cv[r, t]
            if not np.isfinite(c):
                out[r, t] = math.nan  # a missing command: the lag holds its last output
                continue
            y = c if not np.isfinite(y) else lag_step(y, c, rates)
            out[r, t] = y


def lagged_command(
    cv: Any,
    tau_rise: float,
    tau_fall: float,
    v_rise: float = math.inf,
    v_fall: float = math.inf,
) -> np.ndarray:
    """The command through the two-rate lag with speed limits, ``(runs, n)`` (or ``(n,)``) like
    ``cv``.

    Before a run's first finite command the lag is held at it (its first output is that
    command); a NaN command gives NaN and leaves the lag where it was.
    """
    arr = np.asarray(cv, dtype=np.float64)
    grid = np.ascontiguousarray(np.atleast_2d(arr))
    out = np.empty_like(grid)
    _lag_runs(grid, lag_rates(tau_rise, tau_fall, v_rise, v_fall), out)
    return out.reshape(arr.shape)


def _position_sse(cv: np.ndarray, x: np.ndarray, s: np.ndarray, lag: tuple) -> float:
    """Residual sum of squares of ``X ~ b0 + b1 y + b2 s`` with ``y`` the command through
    ``lag`` (complete rows only)."""
    y = lagged_command(cv, *lag)
    ok = np.isfinite(y) & np.isfinite(x) & np.isfinite(s)
    if ok.sum() < 10:
        raise ValueError(f"only {int(ok.sum())} complete samples to fit the command lag")
    A = np.column_stack([np.ones(int(ok.sum())), y[ok], s[ok]])
    coef, *_ = np.linalg.lstsq(A, x[ok], rcond=None)
    return float(np.sum((x[ok] - A @ coef) ** 2))


def fit_command_lag(
    cv: Any,
    x: Any,
    s: Any,
    grid: tuple[float, ...] = LAG_GRID,
    limits: tuple[float, ...] = SPEED_GRID,
) -> tuple[float, float, float, float]:
    """``(tau_rise, tau_fall, v_rise, v_fall)`` whose lagged command best explains the position.

    The residual sum of squares of the least-squares fit ``X ~ b0 + b1 y + b2 s`` of the
    fault-free samples (``y`` the lagged command, ``s`` the pressure-drop root; rows with a NaN
    left out) is minimised in three passes: the pair of time constants on ``grid`` without
    speed limits, then the pair of speed limits on ``limits`` with those time constants, then
    (where a limit was kept) the time constants again with those limits. A value changes only
    where it lowers the sum (the first on a tie), so runs that never show a limit keep none
    (``inf``); ``limits=(inf,)`` fits the time constants alone.

    Parameters
    ----------
    cv, x, s
        ``(runs, n)`` command, position and pressure-drop root of fault-free runs.
    grid
        Time constants (s) tried for each direction.
    limits
        Speed limits (per second; ``inf``: none) tried for each direction.
    """
    cv, x, s = (np.asarray(a, dtype=np.float64) for a in (cv, x, s))
    if cv.shape != x.shape or cv.shape != s.shape or cv.ndim != 2:
        raise ValueError("cv, x and s must be (runs, n) arrays of one shape")
    best: tuple = ()
    best_sse = math.inf
    for tau_rise in grid:
        for tau_fall in grid:
            sse = _position_sse(cv, x, s, (tau_rise, tau_fall))
            if sse < best_sse:
                best, best_sse = (float(tau_rise), float(tau_fall), math.inf, math.inf), sse
    taus = best[:2]
    for v_rise in limits:
        for v_fall in limits:
            if math.isinf(v_rise) and math.isinf(v_fall):
                continue  # the first pass's own lag
            sse = _position_sse(cv, x, s, (*taus, v_rise, v_fall))
            if sse < best_sse:
                best, best_sse = (*taus, float(v_rise), float(v_fall)), sse
    fitted_limits = best[2:]
    if fitted_limits == (math.inf, math.inf):
        return best  # no limit kept: the third pass would repeat the first
    for tau_rise in grid:
        for tau_fall in grid:
            sse = _position_sse(cv, x, s, (tau_rise, tau_fall, *fitted_limits))
            if sse < best_sse:
                best, best_sse = (float(tau_rise), float(tau_fall), *fitted_limits), sse
    return best


def nominal_valve_law(parameters: ActuatorParameters | None = None) -> np.ndarray:
    """The constants `valve_law_at` takes: ``[Kv, c, Kvr at 97.5 %, P range, T range, F range]``
    of ``parameters`` (default: the nominal valve)."""
    p = (parameters or ActuatorParameters()).validated()
    knee = math.exp(-p.characteristic * 0.975)
    return np.array([p.kv, p.characteristic, knee, P_RANGE, T_RANGE, F_RANGE])


@njit(cache=True, error_model="numpy")
def valve_law_at(x, s, t1, p1, law):  # pragma: no cover - compiled
    """Normalised flow of the valve law at normalised position ``x``, pressure-drop root ``s``,
    temperature ``t1`` and inlet pressure ``p1`` (``law``: `nominal_valve_law`).

    Flow [t/h] ``= 100 Kv Kvr(x) sqrt(dP[MPa] / rho) rho / 1000`` with ``dP = s^2 P_range``
    (signed: ``s < 0`` gives a negative flow), ``Kvr = exp(-c x)`` up to ``x = 0.975`` and
    linear to 0 at ``x = 1``, ``rho`` the water's density at ``t1`` and ``p1``; divided by the
    F range.
    """
    xv = min(max(x, 0.0), 1.0)
    if xv <= 0.975:
        kvr = math.exp(-law[1] * xv)
    else:
        kvr = law[2] * (1.0 - xv) / 0.025
    rho = compiled_water_density(t1 * law[4], p1 * law[3])
    root_mpa = s * math.sqrt(law[3] * 1e-6)  # sign(dP) sqrt(|dP| [MPa])
    flow = 100.0 * law[0] * kvr * root_mpa / math.sqrt(rho) * rho / 1000.0
    return flow / law[5]


@njit(cache=True, error_model="numpy")
def _law_rows(x, s, t1, p1, law, out):  # pragma: no cover - compiled
    for i in range(x.shape[0]):
        out[i] = valve_law_at(x[i], s[i], t1[i], p1[i], law)


def valve_law_flow(x: Any, s: Any, t1: Any, p1: Any, law: Any = None) -> np.ndarray:
    """`valve_law_at` of each element (broadcast; ``law`` default: the nominal valve's)."""
    law = nominal_valve_law() if law is None else np.asarray(law, dtype=np.float64)
    arrays = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (x, s, t1, p1)))
    flat = [np.ascontiguousarray(a.ravel()) for a in arrays]
    out = np.empty(flat[0].size)
    _law_rows(*flat, law, out)
    return out.reshape(arrays[0].shape)


def flow_model_inputs(x_hat: Any, s: Any, t1: Any, p1: Any, law: np.ndarray) -> np.ndarray:
    """The flow model's input rows: ``(X_hat, s)``, and ``F_law`` at ``X_hat`` when ``law`` is
    not empty (the models' ``params_.valve_law``)."""
    if np.size(law) == 0:
        return np.column_stack([x_hat, s])
    return np.column_stack([x_hat, s, valve_law_flow(x_hat, s, t1, p1, law)])


def stream_channels(
    channels: Any, valve_law: bool, ndim: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``CV, P1, P2, T1`` of ``channels`` as contiguous float64 arrays of ``ndim`` dimensions
    and one shape, for the compiled predictor. T1 is needed with the valve law only (NaN
    otherwise); a ValueError names what is missing or mis-shaped."""
    names = ("CV", "P1", "P2", "T1") if valve_law else ("CV", "P1", "P2")
    missing = [c for c in names if c not in channels]
    if missing:
        why = " (the valve law of the physics inputs reads T1)" if "T1" in missing else ""
        raise ValueError(f"the normal models need channel(s) {', '.join(missing)}{why}")
    arrays = [np.ascontiguousarray(np.asarray(channels[c], dtype=np.float64)) for c in names]
    if not valve_law:
        arrays.append(np.full(arrays[0].shape, np.nan))
    shape = arrays[0].shape
    if len(shape) != ndim or any(a.shape != shape for a in arrays):
        what = "(n,) sequences of one length" if ndim == 1 else "(runs, n) arrays of one shape"
        raise ValueError(f"{', '.join(names)} must be {what}")
    return tuple(arrays)

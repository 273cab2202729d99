"""Isolation signatures: what the residuals have done since the detection, second by second.

Once the detector has raised DD, the online diagnoser summarises the residuals since that
moment over a window that grows every second until DD falls (`SignatureWindow`, running sums,
O(1) per second), into the features `ISOLATION_FEATURES`:

``mean_rX``, ``mean_rF``
    the paper's mean residuals ``r1 = X - X_hat``, ``r2 = F - F_hat`` (normalised units);
``std_rX``, ``std_rF``
    their spread (friction and positioner faults make the stem hunt rather than shift);
``slope_rX_X``
    the least-squares slope of ``r1`` on ``X_hat`` (a stem-sensor gain fault f13 scales with the
    position; clogging f1 bites only where the stem would close past its new limit);
``slope_rF_F``, ``slope_rF_s``
    the slopes of ``r2`` on ``F_hat`` (multiplicative flow faults: sensor f19, sedimentation f2)
    and on ``s = sqrt(P1 - P2)`` (additive leak flows: bypass f18, internal leakage f6);
``dP1``, ``dP2``, ``dT1``
    the shift of the measured inputs since before the detection (f17 scales P1 or P2, f7 makes
    T1 jump), against a slow average of the fault-free past that freezes at the detection.

Slopes are shrunk towards 0 while the regressor has hardly varied (a ridge of `SLOPE_RIDGE` on
its variance), so the first seconds give finite, small slopes. Like every online component the
window owns its state (`SignatureState`), with ``update`` for one second and ``run`` over a
chunk through the same compiled kernel. The classifier that reads the signatures is
`bayes_fdi.diagnosis.isolation.isolator.FaultIsolator`.

Written by hand: running window statistics that restart at each detection, compiled.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from bayes_fdi.diagnosis.component_state import (
    check_stacked_state,
    check_state,
    working_state,
    writable_copy,
)

__all__ = [
    "INPUT_REFERENCE_SECONDS",
    "ISOLATION_FEATURES",
    "SLOPE_RIDGE",
    "SignatureInputs",
    "SignatureState",
    "SignatureWindow",
]

#: Names of the isolation features, in column order.
ISOLATION_FEATURES: tuple[str, ...] = (
    "mean_rX", "mean_rF", "std_rX", "std_rF", "slope_rX_X", "slope_rF_F", "slope_rF_s",
    "dP1", "dP2", "dT1",
)  # fmt: skip
#: Ridge added to a regressor's variance (normalised units squared) in the slopes: a slope
#: over a window in which the regressor moved by much less than sqrt(SLOPE_RIDGE) = 0.03 is
#: shrunk towards 0.
SLOPE_RIDGE = 1e-3
#: Time constant (s) of the fault-free input average the input shifts are measured against.
INPUT_REFERENCE_SECONDS = 60.0
#: Running sums of the window: r_x, r_f, r_x^2, r_f^2, x_hat, x_hat^2, x_hat r_x, f_hat,
#: f_hat^2, f_hat r_f, s, s^2, s r_f, P1, P2, T1.
_N_SUMS = 16


class SignatureInputs(NamedTuple):
    """What the signature window reads each second (``(n,)`` arrays, or floats for ``update``)."""

    detected: Any  #: the detection decision DD
    r_x: Any  #: raw residual ``X - X_hat``
    r_f: Any  #: raw residual ``F - F_hat``
    x_hat: Any  #: predicted position
    f_hat: Any  #: predicted flow
    s: Any  #: signed root of the pressure drop
    p1: Any  #: measured P1
    p2: Any  #: measured P2
    t1: Any  #: measured T1


class SignatureState(NamedTuple):
    """The state of a `SignatureWindow`."""

    count: np.ndarray  #: ``(1,)`` complete seconds in the window
    sums: np.ndarray  #: ``(16,)`` running sums over the window
    reference: np.ndarray  #: ``(3,)`` average of P1, P2, T1 before the detection
    reference_set: np.ndarray  #: ``(1,)`` bool: the average has a first value
    detected: np.ndarray  #: ``(1,)`` bool: DD of the last second


# one compiled loop over the seconds, clearer whole than cut into pieces
@njit(cache=True, error_model="numpy")
def _signature_kernel(x, alpha, ridge, state, out, seconds):  # pragma: no cover - compiled
    """Running-sum isolation features of consecutive seconds and the window's complete seconds
    after each (``state`` updated in place)."""
    dd, rx, rf, xh, fh, s = x.detected, x.r_x, x.r_f, x.x_hat, x.f_hat, x.s
    p1, p2, t1 = x.p1, x.p2, x.t1
    sums = state.sums
    ref = state.reference
    for t in range(dd.size):
        on = dd[t]
        if on and not state.detected[0]:  # a new detection: open the window
            state.count[0] = 0.0
            for j in range(sums.size):
                sums[j] = 0.0
        state.detected[0] = on
        if not on:
            if np.isfinite(p1[t]) and np.isfinite(p2[t]) and np.isfinite(t1[t]):
                if not state.reference_set[0]:
                    ref[0] = p1[t]
                    ref[1] = p2[t]
                    ref[2] = t1[t]
                    state.reference_set[0] = True
                else:
                    ref[0] += alpha * (p1[t] - ref[0])
                    ref[1] += alpha * (p2[t] - ref[1])
                    ref[2] += alpha * (t1[t] - ref[2])
            for j in range(out.shape[1]):
                out[t, j] = np.nan
            seconds[t] = 0.0
            continue
        ok = (
            np.isfinite(rx[t])
            and np.isfinite(rf[t])
            and np.isfinite(xh[t])
            and np.isfinite(fh[t])
            and np.isfinite(s[t])
            and np.isfinite(p1[t])
            and np.isfinite(p2[t])
            and np.isfinite(t1[t])
        )
        if ok:
            state.count[0] += 1.0
            sums[0] += rx[t]
            sums[1] += rf[t]
            sums[2] += rx[t] * rx[t]
            sums[3] += rf[t] * rf[t]
            sums[4] += xh[t]
            sums[5] += xh[t] * xh[t]
            sums[6] += xh[t] * rx[t]
            sums[7] += fh[t]
            sums[8] += fh[t] * fh[t]
            sums[9] += fh[t] * rf[t]
            sums[10] += s[t]
            sums[11] += s[t] * s[t]
            sums[12] += s[t] * rf[t]
            sums[13] += p1[t]
            sums[14] += p2[t]
            sums[15] += t1[t]
        n = state.count[0]
        seconds[t] = n
        if n < 0.5 or not state.reference_set[0]:
            for j in range(out.shape[1]):
                out[t, j] = np.nan
            continue
        mx = sums[0] / n
        mf = sums[1] / n
        out[t, 0] = mx
        out[t, 1] = mf
        out[t, 2] = math.sqrt(max(sums[2] / n - mx * mx, 0.0))
        out[t, 3] = math.sqrt(max(sums[3] / n - mf * mf, 0.0))
        m = sums[4] / n
        out[t, 4] = (sums[6] / n - m * mx) / (max(sums[5] / n - m * m, 0.0) + ridge)
        m = sums[7] / n
        out[t, 5] = (sums[9] / n - m * mf) / (max(sums[8] / n - m * m, 0.0) + ridge)
        m = sums[10] / n
        out[t, 6] = (sums[12] / n - m * mf) / (max(sums[11] / n - m * m, 0.0) + ridge)
        out[t, 7] = sums[13] / n - ref[0]
        out[t, 8] = sums[14] / n - ref[1]
        out[t, 9] = sums[15] / n - ref[2]


@njit(cache=True, error_model="numpy")
def _signature_runs(x, alpha, ridge, state, out, seconds):  # pragma: no cover - compiled
    """`_signature_kernel` over each run (row) of the inputs; ``state`` stacks the runs'."""
    for r in range(x.detected.shape[0]):
        inputs = SignatureInputs(
            x.detected[r], x.r_x[r], x.r_f[r], x.x_hat[r], x.f_hat[r], x.s[r], x.p1[r], x.p2[r],
            x.t1[r],
        )  # fmt: skip
        run_state = SignatureState(
            state.count[r],
            state.sums[r],
            state.reference[r],
            state.reference_set[r],
            state.detected[r],
        )
        _signature_kernel(inputs, alpha, ridge, run_state, out[r], seconds[r])


class SignatureWindow:
    """The isolation features of the window since each detection (see the module docstring).

    The window opens at each rising edge of DD and grows while it stays on; seconds with a NaN
    are skipped. The input reference is an exponential average (time constant
    ``reference_seconds``) of P1, P2, T1 over the seconds without detection. The features are
    NaN while DD is off (and until the window holds a complete second and the reference a
    value).

    Parameters
    ----------
    reference_seconds
        Time constant of the input reference (default `INPUT_REFERENCE_SECONDS`).
    slope_ridge
        Ridge on the regressors' variances in the slopes (default `SLOPE_RIDGE`).
    """

    def __init__(
        self,
        reference_seconds: float = INPUT_REFERENCE_SECONDS,
        slope_ridge: float = SLOPE_RIDGE,
    ) -> None:
        self.reference_seconds = reference_seconds
        self.slope_ridge = slope_ridge

    def _check_params(self) -> None:
        if not self.reference_seconds > 0:
            raise ValueError(f"reference_seconds must be > 0, got {self.reference_seconds!r}")
        if not self.slope_ridge >= 0:
            raise ValueError(f"slope_ridge must be >= 0, got {self.slope_ridge!r}")

    def init_state(self) -> SignatureState:
        """A fresh state: no window open, no input reference yet."""
        return SignatureState(
            np.zeros(1),
            np.zeros(_N_SUMS),
            np.zeros(3),
            np.zeros(1, dtype=np.bool_),
            np.zeros(1, dtype=np.bool_),
        )

    def check_state(self, state: Any) -> None:
        """Raise a `ValueError` naming the field unless ``state`` is a state of this window."""
        check_state(state, self.init_state(), "signature state")

    def run(
        self,
        inputs: SignatureInputs,
        state: SignatureState | None = None,
        *,
        seconds: np.ndarray | None = None,
    ) -> tuple[np.ndarray, SignatureState]:
        """The features of consecutive seconds of one run.

        Parameters
        ----------
        inputs
            `SignatureInputs` of ``(n,)`` sequences.
        state
            The state after the preceding second (default: a fresh one); not changed.
        seconds
            Optional ``(n,)`` float64 array that receives, second by second, the complete
            seconds the window holds (its age in measured seconds; 0 while DD is off).

        Returns
        -------
        features : numpy.ndarray
            ``(n, 10)``, columns `ISOLATION_FEATURES`.
        state : SignatureState
            The state after the last second.
        """
        self._check_params()
        flags = np.ascontiguousarray(np.asarray(inputs.detected, dtype=np.bool_))
        values = [np.ascontiguousarray(np.asarray(a, dtype=np.float64)) for a in inputs[1:]]
        n = flags.size
        if flags.ndim != 1 or any(a.shape != (n,) for a in values):
            raise ValueError("SignatureWindow: every input must be a (n,) sequence")
        state = working_state(self, state)
        out = np.empty((n, len(ISOLATION_FEATURES)))
        held = _seconds_buffer(seconds, flags.shape)
        alpha = 1.0 / self.reference_seconds
        _signature_kernel(
            SignatureInputs(flags, *values), alpha, self.slope_ridge, state, out, held
        )
        return out, state

    def run_stacked(
        self,
        inputs: SignatureInputs,
        state: SignatureState,
        *,
        seconds: np.ndarray | None = None,
    ) -> tuple[np.ndarray, SignatureState]:
        """`run` of many runs at once: `SignatureInputs` of ``(runs, n)`` arrays, ``state``
        their states stacked along a leading run axis; returns ``(runs, n, 10)`` features and
        the stacked states after them (each run's equal to `run`'s); ``seconds``, if given, a
        ``(runs, n)`` float64 array, receives the windows' complete seconds."""
        self._check_params()
        flags = np.ascontiguousarray(np.asarray(inputs.detected, dtype=np.bool_))
        values = [np.ascontiguousarray(np.asarray(a, dtype=np.float64)) for a in inputs[1:]]
        if flags.ndim != 2 or any(a.shape != flags.shape for a in values):
            raise ValueError("SignatureWindow: every input must be a (runs, n) array")
        check_stacked_state(state, self.init_state(), flags.shape[0], "signature state")
        state = writable_copy(state)
        out = np.empty((*flags.shape, len(ISOLATION_FEATURES)))
        held = _seconds_buffer(seconds, flags.shape)
        alpha = 1.0 / self.reference_seconds
        _signature_runs(SignatureInputs(flags, *values), alpha, self.slope_ridge, state, out, held)
        return out, state

    def update(
        self, inputs: SignatureInputs, state: SignatureState | None = None
    ) -> tuple[np.ndarray, SignatureState]:
        """The features of one second (`run` on one sample): ``(10,)`` and the new state."""
        out, state = self.run(SignatureInputs(*([v] for v in inputs)), state)
        return out[0], state


def _seconds_buffer(seconds: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray:
    """The array the kernel writes the window's seconds into: ``seconds`` itself (checked:
    float64, C-contiguous, of ``shape``) or a scratch array."""
    if seconds is None:
        return np.empty(shape)
    if seconds.shape != shape or seconds.dtype != np.float64 or not seconds.flags.c_contiguous:
        raise ValueError(
            f"seconds must be a C-contiguous float64 array of shape {shape}, got "
            f"{seconds.dtype} {seconds.shape}"
        )
    return seconds

"""Sequential change detection on the whitened residuals of the normal models.

The online diagnoser detects a fault from the residuals of the normal models,
``z = (y - y_hat) / std``, standardised by their calibrated predictive standard deviation and
whitened (`bayes_fdi.diagnosis.detection.whitening.ARWhitener`) into about independent
unit-variance innovations ``e``, which feed a sequential test:

`CUSUM`
    Page's two-sided cumulative sum ``S+ = max(0, S+ + e - k)``, ``S- = max(0, S- - e - k)``,
    statistic ``max(S+, S-)``, capped at ``cap`` so that the evidence clears in bounded time
    once a fault is gone. A persistent bias below ``k`` (slow model drift on real data) does
    not accumulate.
`GLR`
    The generalised likelihood ratio for a change of unknown size in the mean of unit-variance
    Gaussian innovations within the last ``window`` samples,
    ``g = max_{1 <= L <= window} (sum of the last L innovations)^2 / (2 L)`` (two-sided by
    construction; the evidence clears ``window`` samples after the change is gone).

Each detector is one small class in the style of river's drift detectors and BlackJAX's
kernels: immutable parameters, a state it creates (``init_state``: `CUSUMState`, `GLRState`),
checks (``check_state``) and carries, ``update(e, state)`` for one sample (O(1) time and memory),
``run(e, state)`` over a sequence and ``run_stacked`` over the sequences of many runs at once,
all through the same compiled kernel, so ``run`` equals ``update`` sample by sample exactly.
They return the statistics (`DetectorOutput`) and the new state; the state passed in is never
changed. A NaN innovation (a gap) counts as an in-control one, an innovation of 0 (its expected
value without a fault): the statistic decays through a gap as on fault-free data, and is NaN there.

The detection decision DD with hysteresis is `bayes_fdi.diagnosis.detection.decision`; the
thresholds for a false-alarm budget are `bayes_fdi.diagnosis.detection.thresholds`, and each
detector knows its threshold on white Gaussian innovations (``gaussian_threshold``).

Written by hand: scipy and scikit-learn have no sequential change detectors, and river's
(not a dependency) have neither a vectorised path equal to ``update`` nor NaN gaps.
"""

from __future__ import annotations

import inspect
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from bayes_fdi.diagnosis.component_state import (
    check_state,
    one_sequence,
    stacked_sequences,
    working_state,
)
from bayes_fdi.diagnosis.detection.thresholds import calibrate_threshold, cusum_threshold

__all__ = [
    "CUSUM",
    "GLR",
    "SEQUENTIAL_TEST_METHODS",
    "WHITE_SAMPLES",
    "CUSUMState",
    "DetectorOutput",
    "GLRState",
    "sequential_test",
]

#: White Gaussian samples per channel behind the GLR's threshold on Gaussian innovations.
WHITE_SAMPLES = 200_000


class DetectorOutput(NamedTuple):
    """What a detector says of each innovation (arrays from ``run``, floats from ``update``)."""

    statistic: Any  #: the test statistic (NaN for a NaN innovation)
    since: Any  #: samples since the estimated change (-1 for a NaN innovation)


class CUSUMState(NamedTuple):
    """The state of a `CUSUM`."""

    sums: np.ndarray  #: ``(2,)`` the one-sided sums ``S+`` and ``S-``
    lengths: np.ndarray  #: ``(2,)`` samples since ``S+`` and ``S-`` last were 0 (float)


class GLRState(NamedTuple):
    """The state of a `GLR`."""

    buffer: np.ndarray  #: ``(window,)`` the last innovations, a ring
    stored: np.ndarray  #: ``(1,)`` int64: innovations in the ring (at most ``window``)
    slot: np.ndarray  #: ``(1,)`` int64: where the next innovation goes


@njit(cache=True, error_model="numpy")
def _cusum_kernel(e, k, cap, state, stat, since):  # pragma: no cover - compiled
    """Two-sided CUSUM (``state`` updated in place)."""
    sums = state.sums
    lengths = state.lengths
    for t in range(e.size):
        v = e[t]
        missing = not np.isfinite(v)
        if missing:  # an in-control second: innovation 0, its expectation without a fault
            v = 0.0
        sp = sums[0] + v - k
        sn = sums[1] - v - k
        if sp > 0.0:
            lengths[0] += 1.0
        else:
            sp = 0.0
            lengths[0] = 0.0
        if sn > 0.0:
            lengths[1] += 1.0
        else:
            sn = 0.0
            lengths[1] = 0.0
        if sp > cap:
            sp = cap
        if sn > cap:
            sn = cap
        sums[0] = sp
        sums[1] = sn
        if missing:
            stat[t] = np.nan
            since[t] = -1
        elif sp >= sn:
            stat[t] = sp
            since[t] = lengths[0]
        else:
            stat[t] = sn
            since[t] = lengths[1]


@njit(cache=True, error_model="numpy")
def _glr_kernel(e, state, stat, since):  # pragma: no cover - compiled
    """Windowed GLR for a mean change (``state`` updated in place)."""
    buf = state.buffer
    w = buf.size
    for t in range(e.size):
        v = e[t]
        missing = not np.isfinite(v)
        if missing:  # an in-control second: innovation 0, its expectation without a fault
            v = 0.0
        slot = state.slot[0]
        buf[slot] = v
        state.slot[0] = (slot + 1) % w
        if state.stored[0] < w:
            state.stored[0] += 1
        n = state.stored[0]
        total = 0.0
        best = 0.0
        best_len = 0
        for length in range(1, n + 1):
            total += buf[(slot - length + 1) % w]
            g = total * total / (2.0 * length)
            if g > best:
                best = g
                best_len = length
        if missing:
            stat[t] = np.nan
            since[t] = -1
        else:
            stat[t] = best
            since[t] = best_len


@njit(cache=True, error_model="numpy")
def _cusum_runs(e, k, cap, state, stat, since):  # pragma: no cover - compiled
    """`_cusum_kernel` over each run (row) of ``e``; ``state`` stacks the runs' states."""
    for r in range(e.shape[0]):
        run_state = CUSUMState(state.sums[r], state.lengths[r])
        _cusum_kernel(e[r], k, cap, run_state, stat[r], since[r])


@njit(cache=True, error_model="numpy")
def _glr_runs(e, state, stat, since):  # pragma: no cover - compiled
    """`_glr_kernel` over each run (row) of ``e``; ``state`` stacks the runs' states."""
    for r in range(e.shape[0]):
        run_state = GLRState(state.buffer[r], state.stored[r], state.slot[r])
        _glr_kernel(e[r], run_state, stat[r], since[r])


class _SequentialTest:
    """What `CUSUM` and `GLR` share: ``update``/``run`` over one compiled kernel."""

    threshold: float

    def init_state(self) -> Any:  # pragma: no cover - abstract
        """A fresh state (no evidence)."""
        raise NotImplementedError

    def _kernel(self, e: np.ndarray, state: Any, stat: np.ndarray, since: np.ndarray) -> None:
        raise NotImplementedError  # pragma: no cover - abstract

    def _kernel_stacked(
        self, e: np.ndarray, state: Any, stat: np.ndarray, since: np.ndarray
    ) -> None:
        raise NotImplementedError  # pragma: no cover - abstract

    def _check_params(self) -> None:
        if not (isinstance(self.threshold, int | float) and self.threshold > 0):
            raise ValueError(f"threshold must be a positive number, got {self.threshold!r}")

    def check_state(self, state: Any) -> None:
        """Raise a `ValueError` naming the field unless ``state`` is a state of this detector."""
        check_state(state, self.init_state(), "detector state")

    def run(self, e: Any, state: Any = None) -> tuple[DetectorOutput, Any]:
        """Statistics of consecutive innovations.

        Parameters
        ----------
        e
            ``(n,)`` innovations of one run (NaN: a gap).
        state
            The state after the preceding innovation (default: a fresh one); not changed.

        Returns
        -------
        output : DetectorOutput
            ``(n,)`` statistics and samples since the estimated change.
        state
            The state after the last innovation.
        """
        self._check_params()
        x = one_sequence(e)
        state = working_state(self, state)
        stat = np.empty_like(x)
        since = np.empty(x.size, dtype=np.float64)
        self._kernel(x, state, stat, since)
        return DetectorOutput(stat, since), state

    def run_stacked(self, e: Any, state: Any) -> tuple[DetectorOutput, Any]:
        """`run` of many runs at once: ``e`` ``(runs, n)``, ``state`` their states stacked
        along a leading run axis (`~bayes_fdi.diagnosis.component_state.stack_states`); returns
        ``(runs, n)`` outputs and the stacked states after them (each run's equal to `run`'s)."""
        self._check_params()
        x, state = stacked_sequences(e, state, self.init_state(), "detector state")
        stat = np.empty_like(x)
        since = np.empty(x.shape, dtype=np.float64)
        self._kernel_stacked(x, state, stat, since)
        return DetectorOutput(stat, since), state

    def update(self, e: float, state: Any = None) -> tuple[DetectorOutput, Any]:
        """The statistic after one more innovation (`run` on one sample): floats, new state."""
        out, state = self.run(np.array([e], dtype=np.float64), state)
        return DetectorOutput(float(out.statistic[0]), float(out.since[0])), state

    @classmethod
    def upgrade_model_file(cls, data: dict, format_version: int) -> dict:
        """A detector's saved attributes in today's layout: files of bayes_fdi 0.1.0 may hold
        the state of its own stream (``_state``, ``statistic``, ``drift_detected``), which
        detectors no longer keep."""
        return {k: v for k, v in data.items() if k not in ("_state", "statistic", "drift_detected")}


class CUSUM(_SequentialTest):
    """Page's two-sided CUSUM on unit-variance innovations, capped.

    ``S+ = min(cap, max(0, S+ + e - k))``, ``S- = min(cap, max(0, S- - e - k))``; the statistic
    is ``max(S+, S-)``. It detects a mean shift of size ``delta`` (in innovation standard
    deviations) in about ``threshold / (delta - k)`` samples; ``k`` is half the smallest shift
    it is tuned for, and a persistent offset below ``k`` never accumulates.

    Parameters
    ----------
    k
        Reference value (allowance), >= 0 (default 0.5).
    threshold
        Alarm level ``h`` (default 10).
    cap
        Largest value of ``S+`` and ``S-`` (default ``2 * threshold``): once a fault is gone
        the statistic returns to 0 within about ``cap / k`` samples.
    """

    def __init__(self, k: float = 0.5, threshold: float = 10.0, cap: float | None = None) -> None:
        self.k = k
        self.threshold = threshold
        self.cap = cap

    def _check_params(self) -> None:
        super()._check_params()
        if not (isinstance(self.k, int | float) and self.k >= 0):
            raise ValueError(f"k must be a number >= 0, got {self.k!r}")
        if self.cap is not None and not self.cap >= self.threshold:
            raise ValueError(f"cap must be >= threshold, got {self.cap!r}")

    @property
    def cap_(self) -> float:
        """The cap in use."""
        return float(2.0 * self.threshold if self.cap is None else self.cap)

    def init_state(self) -> CUSUMState:
        """A fresh state: both sums 0."""
        return CUSUMState(np.zeros(2), np.zeros(2))

    #: The compiled kernels over one run and over stacked runs, called with `_arguments`; a
    #: variant of the CUSUM (`~bayes_fdi.diagnosis.detection.two_speed.TwoSpeedCUSUM`,
    #: `~bayes_fdi.diagnosis.detection.variance_hold.VarianceHoldCUSUM`) sets its own.
    _run_kernel = staticmethod(_cusum_kernel)
    _runs_kernel = staticmethod(_cusum_runs)

    def _arguments(self) -> tuple[Any, ...]:
        return float(self.k), self.cap_

    def _kernel(self, e: np.ndarray, state: Any, stat: np.ndarray, since: np.ndarray) -> None:
        self._run_kernel(e, *self._arguments(), state, stat, since)

    def _kernel_stacked(
        self, e: np.ndarray, state: Any, stat: np.ndarray, since: np.ndarray
    ) -> None:
        self._runs_kernel(e, *self._arguments(), state, stat, since)

    def _params(self) -> dict[str, Any]:
        """The constructor's parameters (of this class) and their values."""
        names = inspect.signature(type(self).__init__).parameters
        return {name: getattr(self, name) for name in names if name != "self"}

    def __repr__(self) -> str:
        shown = {n: v for n, v in self._params().items() if not (n == "cap" and v is None)}
        return f"{type(self).__name__}({', '.join(f'{n}={v!r}' for n, v in shown.items())})"

    def with_threshold(self, threshold: float) -> CUSUM:
        """The same test (of this class, with these parameters) with another threshold; a
        default cap follows it."""
        return type(self)(**(self._params() | {"threshold": float(threshold)}))

    def gaussian_threshold(
        self,
        target_arl: float,
        *,
        n_channels: int = 2,
        clear: float = 0.0,
        random_state: int | None = None,
    ) -> float:
        """The threshold whose mean run length between false alarms on white N(0, 1)
        innovations of ``n_channels`` channels is ``target_arl``: Siegmund's approximation, the
        ``2 n_channels`` one-sided sums sharing the budget (``clear`` and ``random_state`` are
        not needed)."""
        return cusum_threshold(target_arl, float(self.k), n_sides=2 * int(n_channels))


class GLR(_SequentialTest):
    """Windowed generalised likelihood ratio for a mean change in N(0, 1) innovations.

    ``g = max_{1 <= L <= window} S_L^2 / (2 L)`` with ``S_L`` the sum of the last ``L``
    innovations: the log likelihood ratio of "the mean changed ``L`` samples ago to the value
    that fits best" against "no change", maximised over ``L``. Two-sided; ``O(window)`` per
    sample.

    Parameters
    ----------
    window
        Longest change age considered (samples, default 60).
    threshold
        Alarm level (default 10).
    """

    def __init__(self, window: int = 60, threshold: float = 10.0) -> None:
        self.window = window
        self.threshold = threshold

    def _check_params(self) -> None:
        super()._check_params()
        if isinstance(self.window, bool) or not isinstance(self.window, int) or self.window < 1:
            raise ValueError(f"window must be an integer >= 1, got {self.window!r}")

    def init_state(self) -> GLRState:
        """A fresh state: an empty ring of ``window`` innovations."""
        self._check_params()
        return GLRState(
            np.zeros(int(self.window)), np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64)
        )

    def _kernel(self, e: np.ndarray, state: Any, stat: np.ndarray, since: np.ndarray) -> None:
        _glr_kernel(e, state, stat, since)

    def _kernel_stacked(
        self, e: np.ndarray, state: Any, stat: np.ndarray, since: np.ndarray
    ) -> None:
        _glr_runs(e, state, stat, since)

    def with_threshold(self, threshold: float) -> GLR:
        """The same GLR with another threshold."""
        return GLR(window=self.window, threshold=float(threshold))

    def gaussian_threshold(
        self,
        target_arl: float,
        *,
        n_channels: int = 2,
        clear: float = 0.0,
        random_state: int | None = None,
    ) -> float:
        """The threshold that meets ``target_arl`` on white N(0, 1) innovations of
        ``n_channels`` channels, measured (`calibrate_threshold`, hysteresis off at ``clear``)
        on `WHITE_SAMPLES` simulated seconds drawn with seed ``[random_state, 3]``."""
        rng = np.random.default_rng(None if random_state is None else [random_state, 3])
        white = [rng.standard_normal((WHITE_SAMPLES, int(n_channels)))]
        grid = np.arange(2.0, 40.01, 1.0)
        return calibrate_threshold(self, white, target_arl, clear=clear, grid=grid)["threshold"]


#: What a sequential test needs to serve as the online diagnoser's detector.
SEQUENTIAL_TEST_METHODS = (
    "init_state",
    "check_state",
    "update",
    "run",
    "run_stacked",
    "with_threshold",
    "gaussian_threshold",
)


def sequential_test(detector: Any, *, cusum_k: float, glr_window: int) -> Any:
    """The unfitted test (threshold 1) that ``detector`` names: ``"cusum"`` (`CUSUM` with
    reference ``cusum_k``), ``"variance-hold"``
    (`~bayes_fdi.diagnosis.detection.variance_hold.VarianceHoldCUSUM` with reference
    ``cusum_k``: the CUSUM whose alarm holds while the innovations' variance stays high),
    ``"glr"`` (`GLR` over ``glr_window`` s), or an object with the methods of
    :data:`SEQUENTIAL_TEST_METHODS` (e.g. a new detector class)."""
    if isinstance(detector, str):
        if detector == "cusum":
            return CUSUM(k=float(cusum_k), threshold=1.0)
        if detector == "variance-hold":  # the module extends CUSUM: imported here, not above
            from bayes_fdi.diagnosis.detection.variance_hold import VarianceHoldCUSUM

            return VarianceHoldCUSUM(k=float(cusum_k), threshold=1.0)
        if detector == "glr":
            return GLR(window=int(glr_window), threshold=1.0)
    elif all(hasattr(detector, m) for m in SEQUENTIAL_TEST_METHODS):
        return detector.with_threshold(1.0)
    raise ValueError(
        f"detector must be 'cusum', 'variance-hold', 'glr' or a sequential test with the methods "
        f"{', '.join(SEQUENTIAL_TEST_METHODS)}; got {detector!r}"
    )

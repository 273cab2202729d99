"""A two-speed CUSUM: Page's CUSUM for abrupt faults and a slow CUSUM for lasting small shifts.

The whitening of the residuals (`bayes_fdi.diagnosis.detection.whitening`) turns a lasting
shift ``delta`` of a standardised residual into a spike at its onset and then a lasting shift
of the innovations of only ``g delta``, with ``g = (1 - sum(a)) / s`` for the AR coefficients
``a`` and the innovation standard deviation ``s``: on strongly autocorrelated residuals ``g``
is 0.04-0.2, and a fault that shifts the residual for good shows in the innovations as a shift
well below the CUSUM's reference value ``k = 0.5``, which never accumulates. The information
is still there (the shift in the innovations is what the matched filter of
`bayes_fdi.benchmark.cases.innovation_effect` sums), but only a test that accumulates small
shifts over hundreds of seconds reads it.

`TwoSpeedCUSUM` runs two two-sided CUSUMs on the same innovations: the fast one (reference
``k``, as `~bayes_fdi.diagnosis.detection.detectors.CUSUM`) and a slow one (reference
``k_slow``, e.g. 0.1: tuned for a lasting shift of 0.2 innovation standard deviations). Its
statistic is ``max(S_fast, scale * S_slow)``, so one threshold serves both: ``scale`` is the
ratio of their thresholds for the same false-alarm budget on white Gaussian innovations
(Siegmund's approximation at `REFERENCE_ARL`), so that at that budget each branch raises about
as many false alarms as the other. The online diagnoser calibrates the one threshold on the
fault-free innovations as for any detector. Each sum is capped (the fast one at ``cap``, the
slow one at ``cap / scale``): once a fault is gone the slow branch's evidence clears within
about ``cap / (scale k_slow)`` seconds, longer than the fast one's.

Written by hand, as the CUSUM it extends (no maintained library has these tests with a
vectorised path equal to ``update`` and NaN gaps).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from bayes_fdi.diagnosis.detection.detectors import CUSUM
from bayes_fdi.diagnosis.detection.thresholds import cusum_threshold

__all__ = ["REFERENCE_ARL", "TwoSpeedCUSUM", "TwoSpeedCUSUMState"]

#: The false-alarm budget (mean seconds between false alarms of one channel's two sides) at
#: which the two branches' Gaussian thresholds are matched: 8 hours.
REFERENCE_ARL = 8 * 3600.0


class TwoSpeedCUSUMState(NamedTuple):
    """The state of a `TwoSpeedCUSUM`."""

    sums: np.ndarray  #: ``(4,)`` ``S+`` and ``S-`` of the fast branch, then of the slow one
    lengths: np.ndarray  #: ``(4,)`` samples since each sum last was 0 (float)


@njit(cache=True, error_model="numpy")
def _two_speed_kernel(e, ks, caps, scale, band, state, stat, since):  # pragma: no cover
    """Fast and slow two-sided CUSUMs (references ``ks``, caps ``caps``; the slow sums count
    ``scale`` times beyond ``band``; ``state`` updated in place). Compiled."""
    sums = state.sums
    lengths = state.lengths
    for t in range(e.size):
        v = e[t]
        missing = not np.isfinite(v)
        if missing:  # an in-control second: innovation 0, its expectation without a fault
            v = 0.0
        for j in range(4):
            branch = j // 2
            sign = 1.0 if j % 2 == 0 else -1.0
            s = sums[j] + sign * v - ks[branch]
            if s > 0.0:
                lengths[j] += 1.0
            else:
                s = 0.0
                lengths[j] = 0.0
            sums[j] = min(s, caps[branch])
        best = 0.0
        best_len = 0.0
        for j in range(4):
            value = scale * max(sums[j] - band, 0.0) if j >= 2 else sums[j]
            if value > best:
                best = value
                best_len = lengths[j]
        if missing:
            stat[t] = np.nan
            since[t] = -1
        else:
            stat[t] = best
            since[t] = best_len


@njit(cache=True, error_model="numpy")
def _two_speed_runs(e, ks, caps, scale, band, state, stat, since):  # pragma: no cover
    """`_two_speed_kernel` over each run (row) of ``e``; ``state`` stacks the runs' states."""
    for r in range(e.shape[0]):
        run_state = TwoSpeedCUSUMState(state.sums[r], state.lengths[r])
        _two_speed_kernel(e[r], ks, caps, scale, band, run_state, stat[r], since[r])


class TwoSpeedCUSUM(CUSUM):
    """A fast and a slow two-sided CUSUM on unit-variance innovations, one threshold for both.

    ``S_fast`` is `~bayes_fdi.diagnosis.detection.detectors.CUSUM`'s statistic with reference
    ``k``; the slow sums ``S_slow`` are the same with reference ``k_slow``, counted beyond a
    band of ``1 / k_slow`` (`slow_band_`: twice their mean on white in-control innovations,
    so that the statistic is 0 most of the time without a fault and the detection decision
    can clear); the statistic is ``max(S_fast, scale * (S_slow - band)+)`` with ``scale`` =
    `slow_scale_`. The slow branch detects a lasting shift ``delta > k_slow`` in about
    ``(threshold / scale + band) / (delta - k_slow)`` samples.

    Parameters
    ----------
    k
        Reference value of the fast branch (default 0.5).
    k_slow
        Reference value of the slow branch, ``0 < k_slow < k`` (default 0.1).
    threshold
        Alarm level (default 10).
    cap
        Largest value of the fast sums (default ``2 * threshold``); the slow sums are capped
        at ``cap / scale + band``, so the statistic never exceeds ``cap``.
    """

    def __init__(
        self,
        k: float = 0.5,
        k_slow: float = 0.1,
        threshold: float = 10.0,
        cap: float | None = None,
    ) -> None:
        super().__init__(k=k, threshold=threshold, cap=cap)
        self.k_slow = k_slow

    def _check_params(self) -> None:
        super()._check_params()
        if not (isinstance(self.k_slow, int | float) and 0 < self.k_slow < self.k):
            raise ValueError(f"k_slow must be a number in (0, k = {self.k}), got {self.k_slow!r}")

    @property
    def slow_band_(self) -> float:
        """The band the slow sums must leave before they count: ``1 / k_slow``."""
        return 1.0 / float(self.k_slow)

    @property
    def slow_scale_(self) -> float:
        """The factor of the slow sums beyond their band: the ratio of the fast branch's
        threshold to the slow one's (less the band) on white Gaussian innovations at
        `REFERENCE_ARL` (Siegmund's approximation)."""
        self._check_params()
        fast = cusum_threshold(REFERENCE_ARL, float(self.k), n_sides=2)
        slow = cusum_threshold(REFERENCE_ARL, float(self.k_slow), n_sides=2)
        return fast / (slow - self.slow_band_)

    def init_state(self) -> TwoSpeedCUSUMState:
        """A fresh state: every sum 0."""
        return TwoSpeedCUSUMState(np.zeros(4), np.zeros(4))

    _run_kernel = staticmethod(_two_speed_kernel)
    _runs_kernel = staticmethod(_two_speed_runs)

    def _arguments(self) -> tuple[np.ndarray, np.ndarray, float, float]:
        scale, band = self.slow_scale_, self.slow_band_
        ks = np.array([float(self.k), float(self.k_slow)])
        return ks, np.array([self.cap_, self.cap_ / scale + band]), scale, band

    def gaussian_threshold(
        self,
        target_arl: float,
        *,
        n_channels: int = 2,
        clear: float = 0.0,
        random_state: int | None = None,
    ) -> float:
        """The threshold whose mean run length between false alarms on white N(0, 1)
        innovations of ``n_channels`` channels is at least ``target_arl``: the two branches'
        ``4 n_channels`` one-sided sums share the budget (Siegmund's approximation for each;
        ``clear`` and ``random_state`` are not needed)."""
        sides = 4 * int(n_channels)
        fast = cusum_threshold(target_arl, float(self.k), n_sides=sides)
        slow = cusum_threshold(target_arl, float(self.k_slow), n_sides=sides)
        return float(max(fast, self.slow_scale_ * (slow - self.slow_band_)))

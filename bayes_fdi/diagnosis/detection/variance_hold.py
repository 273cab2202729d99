"""A CUSUM whose alarm holds while the innovations' variance stays above its in-control level.

Page's CUSUM (`~bayes_fdi.diagnosis.detection.detectors.CUSUM`) reads a change of the
innovations' *mean*. Some faults change mainly their *variance*: a weaker spring (f11) or an
electro-pneumatic transducer fault (f12) changes how the stem answers the command, and the
residuals swing to either side of zero within each period of the excitation. The innovations'
mean then stays near 0 and the mean sums return to 0 within seconds of each swing, so the
detection decision clears in the middle of a fault that is still there, and raises again at the
next swing (PICalc times detection to the last rising edge).

`VarianceHoldCUSUM` adds to the two mean sums a one-sided CUSUM of the clipped squared
innovations, ``V = max(0, V + min(e^2, clip^2) - k_var)``, the likelihood-ratio test of a
variance increase from 1 to ``hold_sigma^2`` (reference
``k_var = 2 ln(hold_sigma) hold_sigma^2 / (hold_sigma^2 - 1)``, 1.46 for the default 1.5; the
clip bounds what one outlier adds). On in-control innovations ``V`` drifts down by about
``k_var - 1`` per sample and sits at 0 most of the time; while the variance is above about
``k_var`` it grows. ``V`` is capped as the mean sums are (at twice the threshold by default) and
counts in the statistic only up to half the threshold, ``max(S+, S-, min(V, threshold / 2))``:
it never raises a detection by itself (the
threshold is the mean CUSUM's), but the detection decision, which clears only once every
statistic is back at its clear level 0 (`~bayes_fdi.diagnosis.detection.decision`), keeps a
detection on while the innovations stay wider than in control. That is the *sustained in-control
evidence* the decision waits for: the mean sums at 0 and the variance back to its in-control
level. Its cost: after a false alarm the innovations must also calm down, so false alarms last
longer (never more of them: the hold lengthens and merges alarms, it adds none), and once the
variance is back ``V`` clears within about ``cap / (k_var - 1)`` samples (90 s at the default
model's threshold, about the decision's own hold). The cap is what carries a detection over the
calm stretches of a fault whose residuals widen at some phases of the excitation only: with ``V``
capped at half the threshold instead, f11 and f12 runs of the held-out families cleared
mid-fault as often as with the plain CUSUM.

Like every detector it owns its state (`VarianceHoldCUSUMState`), with ``update`` and ``run``
over the same compiled kernel; a NaN innovation (a gap) is an in-control one (innovation 0 for
the mean sums, its expected square 1 for ``V``).

Written by hand, as the CUSUM it extends (no maintained library has these tests with a
vectorised path equal to ``update`` and NaN gaps).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from bayes_fdi.diagnosis.detection.detectors import CUSUM

__all__ = ["VarianceHoldCUSUM", "VarianceHoldCUSUMState", "variance_reference"]


class VarianceHoldCUSUMState(NamedTuple):
    """The state of a `VarianceHoldCUSUM`."""

    sums: np.ndarray  #: ``(3,)`` the mean sums ``S+`` and ``S-``, then the variance sum ``V``
    lengths: np.ndarray  #: ``(3,)`` samples since each sum last was 0 (float)


def variance_reference(hold_sigma: float) -> float:
    """The reference value ``k_var`` of the variance sum: per sample, the log likelihood ratio
    of N(0, ``hold_sigma^2``) against N(0, 1) is ``(e^2 - k_var) (1 - 1 / hold_sigma^2) / 2``,
    so ``k_var = 2 ln(hold_sigma) hold_sigma^2 / (hold_sigma^2 - 1)`` (between 1 and
    ``hold_sigma^2``)."""
    s2 = float(hold_sigma) ** 2
    return 2.0 * math.log(float(hold_sigma)) * s2 / (s2 - 1.0)


@njit(cache=True, error_model="numpy")
def _hold_kernel(e, k, k_var, clip2, cap, hold, state, stat, since):  # pragma: no cover
    """Two-sided mean CUSUM and the variance sum (``state`` updated in place). Compiled."""
    sums = state.sums
    lengths = state.lengths
    for t in range(e.size):
        v = e[t]
        missing = not np.isfinite(v)
        if missing:  # an in-control second: innovation 0, its expected square 1
            v = 0.0
        square = 1.0 if missing else min(v * v, clip2)
        for j in range(3):
            if j == 0:
                s = sums[0] + v - k
            elif j == 1:
                s = sums[1] - v - k
            else:
                s = sums[2] + square - k_var
            if s > 0.0:
                lengths[j] += 1.0
            else:
                s = 0.0
                lengths[j] = 0.0
            sums[j] = min(s, cap)
        side = 0 if sums[0] >= sums[1] else 1  # the larger mean sum (a tie: S+)
        best, best_len = sums[side], lengths[side]
        held = min(sums[2], hold)  # the variance sum counts up to the hold level
        if held > best:
            best, best_len = held, lengths[2]
        stat[t] = np.nan if missing else best
        since[t] = -1.0 if missing else best_len


@njit(cache=True, error_model="numpy")
def _hold_runs(e, k, k_var, clip2, cap, hold, state, stat, since):  # pragma: no cover
    """`_hold_kernel` over each run (row) of ``e``; ``state`` stacks the runs' states."""
    for r in range(e.shape[0]):
        run_state = VarianceHoldCUSUMState(state.sums[r], state.lengths[r])
        _hold_kernel(e[r], k, k_var, clip2, cap, hold, run_state, stat[r], since[r])


class VarianceHoldCUSUM(CUSUM):
    """Page's two-sided CUSUM whose statistic stays above 0 while the innovations' variance
    stays above its in-control level (see the module's text).

    The statistic is ``max(S+, S-, min(V, threshold / 2))``: ``S+`` and ``S-`` as in `CUSUM`
    (reference ``k``), ``V`` the CUSUM of the squared innovations clipped at ``clip``,
    reference `k_var_`; all three capped at ``cap``, ``V`` counted up to `hold_level_` =
    ``threshold / 2``. The mean sums alone exceed the threshold (the Gaussian threshold is
    `CUSUM`'s); ``V`` holds a detection.

    Parameters
    ----------
    k
        Reference value of the mean sums (default 0.5).
    hold_sigma
        The innovations' standard deviation, relative to in control, that the variance sum is
        tuned to (> 1, default 1.5).
    clip
        Largest absolute innovation the variance sum counts (> 1, default 3).
    threshold
        Alarm level (default 10).
    cap
        Largest value of the three sums (default ``2 * threshold``).
    """

    def __init__(
        self,
        k: float = 0.5,
        hold_sigma: float = 1.5,
        clip: float = 3.0,
        threshold: float = 10.0,
        cap: float | None = None,
    ) -> None:
        super().__init__(k=k, threshold=threshold, cap=cap)
        self.hold_sigma = hold_sigma
        self.clip = clip

    def _check_params(self) -> None:
        super()._check_params()
        for name in ("hold_sigma", "clip"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not value > 1:
                raise ValueError(f"{name} must be a number above 1, got {value!r}")

    @property
    def k_var_(self) -> float:
        """The variance sum's reference value (`variance_reference` of ``hold_sigma``)."""
        self._check_params()
        return variance_reference(self.hold_sigma)

    @property
    def hold_level_(self) -> float:
        """The variance sum's largest share of the statistic: ``threshold / 2``."""
        return 0.5 * float(self.threshold)

    def init_state(self) -> VarianceHoldCUSUMState:
        """A fresh state: every sum 0."""
        return VarianceHoldCUSUMState(np.zeros(3), np.zeros(3))

    _run_kernel = staticmethod(_hold_kernel)
    _runs_kernel = staticmethod(_hold_runs)

    def _arguments(self) -> tuple[float, float, float, float, float]:
        clip = float(self.clip)
        return float(self.k), self.k_var_, clip * clip, self.cap_, self.hold_level_

    def mean_test(self) -> CUSUM:
        """The same test without the variance sum: `CUSUM` with the same reference, threshold
        and cap (the online diagnoser's fit takes its training signatures with it, as it does
        without the decision's hold)."""
        return CUSUM(k=self.k, threshold=self.threshold, cap=self.cap)

"""The stream's clock: the online diagnoser works at 1 Hz, one sample per second.

`check_time_axis` refuses a recording's time axis that is not a 1 Hz grid (another rate,
time going back, repeated or missing values), and `check_next_time` a sample of `update`
whose time does not follow the previous one by 1 s. Missing seconds are fed as samples of
NaN (they are BLIND), never skipped: a gap in time would otherwise be read as one second.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["STEP_TOLERANCE", "check_next_time", "check_time_axis"]

#: Seconds by which a step may differ from 1 s (clock rounding in the recorded times).
STEP_TOLERANCE = 1e-6

_RESAMPLE = (
    "bring the recording to 1 Hz first (bayes_fdi.datasets.read_recording(..., "
    "resample='mean'); command line: --resample mean); gaps are NaN samples, BLIND"
)


def check_time_axis(time: np.ndarray) -> None:
    """Refuse a time axis (s) that is not finite and increasing by 1 s per sample."""
    t = np.asarray(time, dtype=np.float64)
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise ValueError(
            f"time is not finite at index {bad[0]} ({t[bad[0]]!r}; {bad.size} such values): "
            "every sample needs its second"
        )
    if t.size < 2:
        return
    steps = np.diff(t)
    off = np.flatnonzero(np.abs(steps - 1.0) > STEP_TOLERANCE)
    if not off.size:
        return
    i = off[0]
    if steps[i] <= 0:
        what = "goes back" if steps[i] < 0 else "repeats"
        raise ValueError(
            f"time {what} at index {i + 1} ({t[i]:g} s then {t[i + 1]:g} s): the online "
            "diagnoser needs time increasing by 1 s per sample"
        )
    median = float(np.median(steps))
    raise ValueError(
        f"time advances by {steps[i]:g} s at index {i + 1} ({t[i]:g} s then {t[i + 1]:g} s; "
        f"median step {median:g} s): the online diagnoser needs one sample per second; " + _RESAMPLE
    )


def check_next_time(previous: float | None, time: float) -> None:
    """Refuse an `update` sample whose ``time`` is not finite or not ``previous`` + 1 s."""
    if not math.isfinite(time):
        raise ValueError(f"sample time is not finite ({time!r}): every sample needs its second")
    if previous is None or abs(time - previous - 1.0) <= STEP_TOLERANCE:
        return
    if time <= previous:
        what = "goes back" if time < previous else "repeats"
        raise ValueError(
            f"sample time {what} ({previous:g} s then {time:g} s): feed each second once, in order"
        )
    raise ValueError(
        f"sample time jumps from {previous:g} s to {time:g} s: feed the missing seconds as "
        "samples of NaN (they are BLIND), one sample per second"
    )

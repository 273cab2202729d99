"""The online diagnoser's clock: a recording's time must be a 1 Hz grid and each `update` sample
must follow the previous one by 1 s; anything else is refused with its index and values."""

from __future__ import annotations

import numpy as np
import pytest

from bayes_fdi.datasets import load_lublin_example
from bayes_fdi.diagnosis import OnlineDiagnoser
from bayes_fdi.diagnosis.online.clock import check_next_time, check_time_axis

CHANNELS = ("CV", "P1", "P2", "T1", "X", "F")


@pytest.fixture(scope="module")
def fitted():
    hour = load_lublin_example()
    model = OnlineDiagnoser(random_state=0).fit(hour.isel(time=slice(0, 900)))
    return model, hour.isel(time=slice(900, 1200))


@pytest.mark.parametrize(
    ("time", "message"),
    [
        (np.arange(10) * 2.0, r"advances by 2 s at index 1 \(0 s then 2 s; median step 2 s\)"),
        (np.arange(10.0)[::-1], r"goes back at index 1 \(9 s then 8 s\)"),
        (np.zeros(10), r"repeats at index 1 \(0 s then 0 s\)"),
        (np.r_[0.0, 1.0, np.nan, 3.0], r"not finite at index 2"),
        (np.r_[0.0, 1.0, 2.0, 10.0], r"advances by 8 s at index 3"),
    ],
)
def test_time_axes_that_are_not_a_1_hz_grid_are_refused(time, message):
    with pytest.raises(ValueError, match=message):
        check_time_axis(time)


def test_a_1_hz_grid_passes_from_any_start_and_within_clock_rounding():
    check_time_axis(36000.0 + np.arange(100))
    check_time_axis(np.arange(100) * (1 + 1e-9))  # 1e-7 s over the recording: rounding
    check_time_axis(np.array([5.0]))
    check_next_time(None, 123.0)
    check_next_time(123.0, 124.0)


def test_run_refuses_a_half_hertz_reversed_or_frozen_time_axis(fitted):
    model, part = fitted
    for time in (np.arange(300) * 2.0, np.arange(300.0)[::-1], np.zeros(300)):
        with pytest.raises(ValueError, match="time"):
            model.run(part.assign_coords(time=time))
    stream = model.run(part)  # the recording's own 1 Hz grid
    assert stream.sizes["time"] == 300


def test_update_refuses_time_going_back_repeated_jumping_or_nan(fitted):
    model, part = fitted
    sample = {c: float(part[c].values[0, 0]) for c in CHANNELS}
    model.reset()
    model.update({**sample, "time": 10.0})
    model.update({**sample, "time": 11.0})
    jump = "jumps from 11 s to 15 s: feed the missing seconds as samples of NaN"
    for t, message in ((11.0, "repeats"), (10.5, "goes back"), (float("nan"), "not finite"),
                       (15.0, jump)):  # fmt: skip
        with pytest.raises(ValueError, match=message):
            model.update({**sample, "time": t})
    model.update({**sample, "time": 12.0})  # a refused sample changes nothing
    gap = dict.fromkeys(CHANNELS, float("nan"))
    assert model.update({**gap, "time": 13.0}).status == "BLIND"  # a missing second, fed
    model.reset()
    assert model.update({**sample, "time": 0.0}).status in ("CLEAR", "DAZZLED")  # any start

"""The input envelope also judges a detection by the command during it (``command_check``).

The normal models' residuals grow as the command nears the end of its training range, so the
detector fires there while the input average before its estimated change point still lay
inside: such a detection is the model's, not the valve's. From a second of a detection, within
``change_lookback`` s of its estimated change point, whose CV lies outside the envelope, the
detection is held as begun outside it (a model mismatch) until DD falls; the other inputs,
which faults move (f17 drops P2, f7 heats T1), are judged before the change point only. Checked
against hand-made runs, old model files and a saved file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from bayes_fdi import model_files
from bayes_fdi.diagnosis import OnlineDiagnoser
from bayes_fdi.diagnosis.component_state import stack_states
from bayes_fdi.diagnosis.online import InputEnvelope
from bayes_fdi.diagnosis.online.envelope import ENVELOPE_CHANNELS

FORMAT3 = Path(__file__).parent / "data" / "model_files_format3"
LOW, HIGH = np.zeros(4), np.full(4, 0.4)


def _run(column: int):
    """40 s at 0.2; the input of ``column`` at 0.5 (outside) over seconds 15..24; DD on over
    seconds 10..29 and 33..36 (the input inside again by then)."""
    inputs = np.full((40, 4), 0.2)
    inputs[15:25, column] = 0.5
    dd = np.zeros(40, dtype=bool)
    dd[10:30] = True
    dd[33:37] = True
    return inputs, dd


def test_the_command_leaving_the_envelope_during_a_detection_makes_it_a_mismatch():
    inputs, dd = _run(0)
    envelope = InputEnvelope.from_bounds(LOW, HIGH, reference_seconds=5.0)
    assert envelope.command_check
    novel, _ = envelope.run(inputs, dd)
    want = np.zeros(40, dtype=bool)
    want[15:30] = True  # from the first second outside until DD falls, not before
    np.testing.assert_array_equal(novel, want)  # the next detection, inside: a fault again
    # without the check (model files saved before it): judged before the change point only
    off = InputEnvelope.from_bounds(LOW, HIGH, reference_seconds=5.0, command_check=False)
    assert not off.run(inputs, dd)[0].any()
    # the same, second by second and stacked with other runs
    state, seconds = None, []
    for t in range(40):
        flag, state = envelope.update(inputs[t], bool(dd[t]), state)
        seconds.append(flag)
    np.testing.assert_array_equal(seconds, want)
    runs = np.stack([inputs, _run(2)[0]])
    fresh = stack_states([envelope.init_state()] * 2)
    stacked = envelope.run_stacked(runs, np.stack([dd, dd]), fresh)[0]
    np.testing.assert_array_equal(stacked[0], want)
    assert not stacked[1].any()


def test_a_command_leaving_long_after_the_change_point_leaves_the_detection_as_judged():
    inputs, dd = _run(0)  # CV outside over seconds 15..24, DD on from second 10
    ages = np.zeros(40, dtype=np.int64)
    ages[10:30] = np.arange(1, 21)  # the change began at second 10: age 6 at second 15
    near = InputEnvelope.from_bounds(LOW, HIGH, reference_seconds=5.0, change_lookback=6)
    novel, _ = near.run(inputs, dd, change_age=ages)
    want = np.zeros(40, dtype=bool)
    want[15:30] = True  # 6 s after the change: within the lookback
    np.testing.assert_array_equal(novel, want)
    far = InputEnvelope.from_bounds(LOW, HIGH, reference_seconds=5.0, change_lookback=5)
    assert not far.run(inputs, dd, change_age=ages)[0].any()  # 6 s: later than the lookback


@pytest.mark.parametrize("column", [1, 2, 3])
def test_the_inputs_a_fault_moves_are_judged_before_the_change_point_only(column):
    inputs, dd = _run(column)  # P1, P2 or T1 outside during the detection, inside before it
    novel, _ = InputEnvelope.from_bounds(LOW, HIGH, reference_seconds=5.0).run(inputs, dd)
    assert not novel.any()


def test_old_files_load_without_the_check_and_new_ones_keep_it(tmp_path):
    old = OnlineDiagnoser.load(FORMAT3 / "online.npz")
    assert old.envelope_.command_check is False
    runs = xr.Dataset(
        {c: (("run", "time"), np.linspace(0.1, 0.6, 50)[None]) for c in ENVELOPE_CHANNELS},
        coords={"run": [0], "time": np.arange(50.0)},
    )
    fitted = InputEnvelope().fit(runs)
    path = tmp_path / "envelope.npz"
    model_files.save(fitted, path)
    back = model_files.load(path)
    assert back.command_check is True
    np.testing.assert_array_equal(back.high_, fitted.high_)
    with pytest.raises(ValueError, match="command_check"):
        InputEnvelope(command_check="yes").fit(runs)

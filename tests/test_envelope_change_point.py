"""The input envelope judges a detection by the inputs before the detector's estimated change
point.

A fault that itself moves an input (f17 drops P2) pulls the input average out of the envelope
in the seconds the detector needs to detect it; judged on the average before the detection,
its detection would read as a model mismatch. Checked against hand-computed averages, the
CUSUM's closed-form change age, and old model files keeping their old onset check.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bayes_fdi import model_files
from bayes_fdi.diagnosis import OnlineDiagnoser
from bayes_fdi.diagnosis.detection.detectors import CUSUM, GLR
from bayes_fdi.diagnosis.online import InputEnvelope
from bayes_fdi.diagnosis.online.change_point import change_ages
from bayes_fdi.diagnosis.online.envelope import CHANGE_LOOKBACK, EnvelopeState

FORMAT3 = Path(__file__).parent / "data" / "model_files_format3"

# An envelope of [0, 0.4] on every input, the average with a 5 s time constant (alpha 0.2).
LOW, HIGH = np.zeros(4), np.full(4, 0.4)


def _p2_drop_run():
    """30 s at 0.2; P2 (column 2) jumps to 0.9 from second 20; DD on from second 30, when the
    detector's change began at second 20 (age 11 at second 30: seconds 20..30)."""
    inputs = np.full((40, 4), 0.2)
    inputs[20:, 2] = 0.9
    dd = np.arange(40) >= 30
    ages = np.zeros(40, dtype=np.int64)
    ages[30:] = np.arange(11, 21)
    return inputs, dd, ages


def test_the_average_before_the_change_point_decides_not_the_one_before_the_detection():
    inputs, dd, ages = _p2_drop_run()
    # by hand: the average of P2 after second 29 is 0.2 + 0.7 (1 - 0.8^10) = 0.825, outside;
    # after second 19 (before the change) it is 0.2, inside
    assert 0.2 + 0.7 * (1 - 0.8**10) > 0.4
    old = InputEnvelope.from_bounds(LOW, HIGH, reference_seconds=5.0, change_lookback=0)
    novel_old, end_old = old.run(inputs, dd)
    np.testing.assert_array_equal(novel_old, dd)  # judged before the detection: mismatch
    assert end_old.average[2] == pytest.approx(0.2 + 0.7 * (1 - 0.8**10), rel=1e-12)
    new = InputEnvelope.from_bounds(LOW, HIGH, reference_seconds=5.0, change_lookback=30)
    novel, end = new.run(inputs, dd, change_age=ages)
    assert not novel.any()  # judged before the change point: inside, a fault
    np.testing.assert_array_equal(end.average, end_old.average)  # the average is the same
    # without change ages (a change at the detection second) the new envelope is the old one
    np.testing.assert_array_equal(new.run(inputs, dd)[0], novel_old)


def test_a_change_older_than_the_lookback_is_judged_on_the_oldest_average_kept():
    inputs, dd, ages = _p2_drop_run()
    # a ring of 5 s: at second 30 it holds the averages after seconds 25..29; the oldest, after
    # second 25, is 0.2 + 0.7 (1 - 0.8^6) = 0.63: outside the envelope
    assert 0.2 + 0.7 * (1 - 0.8**6) > 0.4
    short = InputEnvelope.from_bounds(LOW, HIGH, reference_seconds=5.0, change_lookback=5)
    np.testing.assert_array_equal(short.run(inputs, dd, change_age=ages)[0], dd)
    # a ring of 11 s reaches the average after second 19 (age 11: 10 s back from second 29)
    exact = InputEnvelope.from_bounds(LOW, HIGH, reference_seconds=5.0, change_lookback=11)
    assert not exact.run(inputs, dd, change_age=ages)[0].any()
    # a ring of 10 s: the oldest is after second 20, 0.2 + 0.7 * 0.2 = 0.34, still inside; a
    # ring of 9 s: after second 21, 0.2 + 0.7 (1 - 0.8^2) = 0.452, outside
    ten = InputEnvelope.from_bounds(LOW, HIGH, reference_seconds=5.0, change_lookback=10)
    assert not ten.run(inputs, dd, change_age=ages)[0].any()
    nine = InputEnvelope.from_bounds(LOW, HIGH, reference_seconds=5.0, change_lookback=9)
    np.testing.assert_array_equal(nine.run(inputs, dd, change_age=ages)[0], dd)


def test_a_plant_outside_the_envelope_before_any_change_stays_a_mismatch():
    inputs, dd, ages = _p2_drop_run()
    inputs[:, 3] = 0.5  # T1 outside the envelope from the first second
    envelope = InputEnvelope.from_bounds(LOW, HIGH, reference_seconds=5.0, change_lookback=30)
    np.testing.assert_array_equal(envelope.run(inputs, dd, change_age=ages)[0], dd)
    # a change older than the stream: judged on the oldest average (the first second's)
    far = np.where(dd, 1000, 0)
    np.testing.assert_array_equal(envelope.run(inputs, dd, change_age=far)[0], dd)
    # detected from the first second: judged on that second's inputs
    always = np.ones(40, dtype=bool)
    np.testing.assert_array_equal(envelope.run(inputs, always, change_age=far)[0], always)


def test_run_update_chunks_and_stacked_runs_agree_with_change_ages():
    inputs, dd, ages = _p2_drop_run()
    dd = dd.copy()
    dd[34:37] = False  # DD falls and rises again at 37 (age 18: the change at 20, frozen ring)
    envelope = InputEnvelope.from_bounds(LOW, HIGH, reference_seconds=5.0, change_lookback=12)
    whole, end = envelope.run(inputs, dd, change_age=ages)
    first, state = envelope.run(inputs[:25], dd[:25], change_age=ages[:25])
    second, end2 = envelope.run(inputs[25:], dd[25:], state, change_age=ages[25:])
    np.testing.assert_array_equal(np.concatenate([first, second]), whole)
    state, stepwise = envelope.init_state(), []
    for t in range(40):
        novel, state = envelope.update(inputs[t], bool(dd[t]), state, int(ages[t]))
        stepwise.append(novel)
    np.testing.assert_array_equal(stepwise, whole)
    for a, b, c in zip(end, end2, state, strict=True):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, c)
    from bayes_fdi.diagnosis.component_state import stack_states

    shifted = inputs.copy()
    shifted[:, 3] = 0.5
    stacked, _ = envelope.run_stacked(
        np.stack([inputs, shifted]), np.stack([dd, dd]),
        stack_states([envelope.init_state()] * 2), np.stack([ages, ages]),
    )  # fmt: skip
    np.testing.assert_array_equal(stacked[0], whole)
    np.testing.assert_array_equal(stacked[1], envelope.run(shifted, dd, change_age=ages)[0])
    assert stacked[1][dd].all()


def test_bad_change_ages_and_lookbacks_are_named():
    inputs, dd, ages = _p2_drop_run()
    envelope = InputEnvelope.from_bounds(LOW, HIGH)
    with pytest.raises(ValueError, match="change_age must have shape"):
        envelope.run(inputs, dd, change_age=ages[:5])
    with pytest.raises(ValueError, match="change_age must hold integers"):
        envelope.run(inputs, dd, change_age=ages.astype(float))
    for bad in (-1, 2.5, True):
        with pytest.raises(ValueError, match="change_lookback must be an int >= 0"):
            InputEnvelope.from_bounds(LOW, HIGH, change_lookback=bad).init_state()


def test_change_ages_take_the_excursion_of_the_statistic_above_the_threshold():
    # output 0: above clear (0) from second 1 on, above the threshold 10 at seconds 4 and 5;
    # output 1: at 0 at second 3, above the threshold at second 5 with a GLR-like since of 4
    stats = np.array([[0, 0], [2, 1], [1, 1], [3, 0], [11, 2], [12, 12.0]])
    since = np.array([[0, 0], [1, 1], [2, 2], [1, 0], [1, 1], [2, 4.0]])
    ages, end = change_ages(stats, since, 10.0, 0.0)
    # by hand: second 4, output 0 above since second 1: 4 seconds (1..4); second 5: output 0's
    # 5 seconds against output 1's max(2 seconds since 3, since 4) = 4: the older, 5
    np.testing.assert_array_equal(ages, [0, 0, 0, 0, 4, 5])
    np.testing.assert_array_equal(end, [5, 2])
    # in two chunks, carrying the excursions: the same
    a1, carry = change_ages(stats[:3], since[:3], 10.0, 0.0)
    a2, end2 = change_ages(stats[3:], since[3:], 10.0, 0.0, carry)
    np.testing.assert_array_equal(np.concatenate([a1, a2]), ages)
    np.testing.assert_array_equal(end2, end)
    # a gap (NaN) continues an excursion; a clear level of 1.5 ends output 0's at second 2
    gap = stats.copy()
    gap[3, 0] = np.nan
    np.testing.assert_array_equal(change_ages(gap, since, 10.0, 0.0)[0], [0, 0, 0, 0, 4, 5])
    np.testing.assert_array_equal(change_ages(stats, since, 10.0, 1.5)[0], [0, 0, 0, 0, 2, 4])
    # stacked runs: each run as alone
    both, _ = change_ages(np.stack([stats, gap]), np.stack([since, since]), 10.0, 0.0)
    np.testing.assert_array_equal(both[0], ages)
    with pytest.raises(ValueError, match="must be"):
        change_ages(stats, since[:2], 10.0, 0.0)
    with pytest.raises(ValueError, match="excursion must have shape"):
        change_ages(stats, since, 10.0, 0.0, np.zeros(3, np.int64))


@pytest.mark.parametrize("detector", [CUSUM(k=0.5), GLR(window=60)])
def test_the_detectors_change_age_points_at_a_step_in_the_mean(detector):
    """Innovations 0 up to second 49, 2 from second 50: the CUSUM's excursion starts at the
    step (its sum grows by 1.5 a second); the GLR's best window is the seconds since it."""
    e = np.zeros(120)
    e[50:] = 2.0
    out, _ = detector.run(e)
    ages, _ = change_ages(out.statistic[:, None], out.since[:, None], 10.0, 1e9)
    crossing = np.flatnonzero(out.statistic > 10.0)
    assert crossing.size and crossing[0] > 50
    for t in crossing[crossing < 110]:
        assert ages[t] == t - 49  # seconds 50 .. t
        assert t - ages[t] + 1 == 50


def test_a_cusum_whose_sums_take_turns_dates_the_change_to_its_first_excursion():
    """A fault seen through the whitening as one positive innovation, five negative ones, then
    a growing positive drift (what the default model's X innovations do under f17): the sum
    that crosses the threshold started at second 56, but the statistic never returned to 0
    since the step at 50, so the change is dated to 50."""
    e = np.zeros(90)
    e[50], e[51:56], e[56:] = 6.4, -2.0, 1.0 + 0.5 * np.arange(34)
    out, _ = CUSUM(k=0.5).run(e)
    t = int(np.flatnonzero(out.statistic > 10.0)[0])
    assert t > 56
    assert out.since[t] == t - 55  # the larger sum's own excursion, from 56
    assert (out.statistic[50 : t + 1] > 0).all()
    ages, _ = change_ages(out.statistic[:, None], out.since[:, None], 10.0, 0.0)
    assert ages[t] == t - 49


def test_files_saved_before_the_change_point_keep_their_onset_check():
    assert model_files.read_metadata(FORMAT3 / "online.npz")["format_version"] == 3
    model = OnlineDiagnoser.load(FORMAT3 / "online.npz")
    assert model.envelope_.change_lookback == 0
    assert model.stream_state().onset.history.shape == (1, 0, 4)
    assert InputEnvelope().change_lookback == CHANGE_LOOKBACK


def test_an_envelope_state_of_format_7_gains_an_empty_ring_with_or_without_runs():
    one = {"average": np.zeros(4), "previous": np.zeros(2), "rate": np.zeros(2)}
    got = EnvelopeState.upgrade_model_file(one, 7)
    assert got["history"].shape == (0, 4) and got["stored"].shape == (1,)
    stacked = {"average": np.zeros((3, 4)), "previous": np.zeros((3, 2)), "rate": np.zeros((3, 2))}
    got = EnvelopeState.upgrade_model_file(stacked, 7)
    assert got["history"].shape == (3, 0, 4) and got["slot"].shape == (3, 1)

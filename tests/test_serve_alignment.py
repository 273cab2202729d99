"""One valve's seconds in ``serve``: the aligner's rules with an explicit wall clock (deadlines,
duplicates, late samples, clock jumps, restarts), the runner against the batch ``run`` of the
same seconds, and the durable log's checkpoints (a runner rebuilt from the log continues the
stream bit for bit)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import xarray as xr
from serve_helpers import fit_tiny_model

from bayes_fdi.actuator import Fault, benchmark_inputs, simulate
from bayes_fdi.datasets import CHANNELS
from bayes_fdi.datasets.units import PHYSICAL_UNITS, to_physical
from bayes_fdi.deployment.serve.alignment import FinishedSecond, Gap, SecondAligner
from bayes_fdi.deployment.serve.durable_log import DurableLog, read_log
from bayes_fdi.deployment.serve.records import group_labels
from bayes_fdi.deployment.serve.valve_runner import ValveRunner
from bayes_fdi.diagnosis import OnlineDiagnoser

T0 = 1_800_000_000  # plant time of second 0


def _feed(aligner, second, wall, channels=CHANNELS, value=0.5):
    for c in channels:
        aligner.offer(c, value, T0 + second, wall)


def test_a_complete_second_is_finished_at_once_and_a_missing_one_at_its_deadline():
    a = SecondAligner(CHANNELS, max_delay=1.5)
    _feed(a, 0, 0.1)
    (first,) = a.due(0.1)
    assert first.second == T0 and first.complete and first.received == 0.1
    _feed(a, 1, 1.1, channels=CHANNELS[:5])  # F of second 1 never comes
    assert a.due(1.1) == [] and a.due(2.5) == []  # due at 0.1 + 1 + 1.5 = 2.6
    (late,) = a.due(2.6)
    assert not late.complete and math.isnan(late.values["F"]) and late.values["X"] == 0.5
    assert late.notes == ("missing F",)
    # a silent plant: one BLIND second per second of wall clock, by the same rule
    seconds = [s.second - T0 for s in a.due(5.6)]
    assert seconds == [2, 3, 4]


def test_speed_scales_the_deadlines():
    a = SecondAligner(CHANNELS, speed=10.0, max_delay=0.2, clock_tolerance=5.0)
    _feed(a, 0, 0.0)
    a.due(0.0)
    assert a.due(0.29) == []  # second 1 is due at 0.1 + 0.2
    assert [s.second - T0 for s in a.due(0.31)] == [1]


def test_duplicates_and_late_samples_are_reported_not_merged():
    a = SecondAligner(CHANNELS, max_delay=1.5)
    _feed(a, 0, 0.0)
    a.due(0.0)
    a.offer("X", 0.5, T0 + 1, 1.0)
    a.offer("X", 0.7, T0 + 1, 1.01)  # a second value for X of second 1: the first is kept
    _feed(a, 1, 1.02, channels=("CV", "P1", "P2", "T1", "F"))
    (s1,) = a.due(1.02)
    assert s1.values["X"] == 0.5 and "duplicate sample of X" in s1.notes[0]
    a.offer("F", 0.9, T0 + 1, 1.5)  # F of second 1 again, after it was finished
    _feed(a, 2, 2.0, channels=CHANNELS[:5])
    (s2,) = a.due(3.6)  # F of second 2 missing: finished by its deadline
    assert "duplicate sample of F" in s2.notes[0] and "not merged" in s2.notes[0]
    a.offer("F", 0.9, T0 + 2, 3.7)  # F of second 2 arrives after its second was published
    _feed(a, 3, 3.8)
    (s3,) = a.due(3.8)
    assert any("late sample of F" in n for n in s3.notes)
    assert a.counts["duplicate"] == 2 and a.counts["late"] == 1


def test_a_forward_clock_jump_becomes_a_gap_and_the_stream_goes_on():
    a = SecondAligner(CHANNELS, max_delay=1.5, clock_tolerance=5.0)
    for k in range(3):
        _feed(a, k, float(k))
        a.due(float(k))
    _feed(a, 103, 3.0)  # the plant clock jumps 100 s forward between two samples
    out = a.due(3.0)
    assert isinstance(out[0], Gap) and (out[0].first - T0, out[0].last - T0) == (3, 102)
    assert "jumped forward" in out[0].notes[-1]
    assert isinstance(out[1], FinishedSecond) and out[1].second == T0 + 103
    _feed(a, 104, 4.0)
    assert [s.second - T0 for s in a.due(4.0)] == [104]  # re-anchored: no further gap


def test_a_backward_clock_jump_is_rejected_until_the_plant_catches_up():
    a = SecondAligner(CHANNELS, max_delay=1.5, clock_tolerance=5.0)
    for k in range(50, 53):
        _feed(a, k, float(k))
        a.due(float(k))
    _feed(a, 20, 53.0)  # 33 s back
    (blind,) = a.due(54.6)
    assert not blind.complete and "33 s behind" in blind.notes[0]
    assert a.counts["rejected"] == 6 and a.counts["clock_jump"] == 1


def test_a_restart_fills_the_seconds_it_was_down():
    a = SecondAligner(CHANNELS, resume_after=T0 + 9)
    _feed(a, 14, 100.0)
    gap, first = a.due(100.0)
    assert (gap.first - T0, gap.last - T0) == (10, 13) and first.second == T0 + 14
    b = SecondAligner(CHANNELS, resume_after=T0 + 9)
    _feed(b, 9, 100.0)  # already in the log
    assert b.due(100.0) == [] and b.counts["rejected"] == 1


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return fit_tiny_model(tmp_path_factory.mktemp("model") / "tiny.npz")


@pytest.fixture(scope="module")
def recording():
    rec = simulate(benchmark_inputs(1, 240, seed=7, vary=True), [Fault("f1", 0.7, 120.0)], seed=7)
    return rec.isel(run=0)


def _play(runner, recording, seconds, wall_of=float):
    """Feed the recording's seconds (physical units) through a runner; returns its rows."""
    rows = []
    for k in seconds:
        for c in CHANNELS:
            value = float(to_physical(float(recording[c].values[k]), c))
            runner.offer(c, value, T0 + k, wall_of(k))
        rows += runner.step(wall_of(k), 0.0)
    return rows


def _check_against_batch(rows, model_path):
    """The rows equal the batch ``run`` of the channels they hold (NaN where BLIND)."""
    times = np.array([r["time"] for r in rows])
    assert np.all(np.diff(times) == 1)
    channels = xr.Dataset(
        {c: ("time", np.array([r[c] for r in rows])) for c in CHANNELS},
        coords={"time": times.astype(float)},
    )
    batch = OnlineDiagnoser.load(model_path).run(channels)
    np.testing.assert_array_equal([r["status"] for r in rows], batch["status"].values)
    np.testing.assert_array_equal([r["state"] for r in rows], batch["state"].values)
    np.testing.assert_array_equal([r["DD"] for r in rows], batch["DD"].values)
    for name in ("VMV_X", "VU_X", "VMV_F", "VU_F", "r_X", "r_F", "stat_X", "probability"):
        np.testing.assert_array_equal([r[name] for r in rows], batch[name].values, err_msg=name)


def test_runner_equals_the_batch_run_with_gaps(model, recording):
    runner = ValveRunner("V1", OnlineDiagnoser.load(model), PHYSICAL_UNITS, "m")
    seconds = [k for k in range(240) if not (60 <= k < 63 or 150 <= k < 170)]
    rows = _play(runner, recording, seconds)
    rows += runner.step(300.0, 0.0)[:1]  # second 240: BLIND, as the plant stopped
    times = [r["time"] - T0 for r in rows]
    assert times == list(range(241))
    status = np.array([r["status"] for r in rows])
    assert set(np.flatnonzero(status == "BLIND")) == {60, 61, 62, *range(150, 170), 240}
    assert "BLURRED" in status[130:150]  # f1 from second 120 is isolated
    _check_against_batch(rows, model)


def test_a_runner_rebuilt_from_the_log_continues_the_stream_exactly(model, recording, tmp_path):
    diag = OnlineDiagnoser.load(model)
    log = DurableLog(tmp_path, {"V1": group_labels(diag)}, segment_seconds=50)
    runner = ValveRunner("V1", diag, PHYSICAL_UNITS, "m")
    for k in range(100):  # one commit a second, as serve does
        rows = _play(runner, recording, [k])
        log.commit({"V1": rows}, {"V1": runner.checkpoint()})
    # the process dies here; a new one recovers the log and resumes 10 s later
    log2 = DurableLog(tmp_path, {"V1": group_labels(diag)}, segment_seconds=50)
    checkpoints = log2.recover()
    assert checkpoints["V1"].last_second == T0 + 99
    runner2 = ValveRunner("V1", OnlineDiagnoser.load(model), PHYSICAL_UNITS, "m", checkpoints["V1"])
    rows2 = _play(runner2, recording, range(110, 240), wall_of=lambda k: 1000.0 + k)
    log2.commit({"V1": rows2}, {"V1": runner2.checkpoint()})
    log2.flush()
    logged = read_log(tmp_path, "V1")
    assert logged.sizes["time"] == 240
    status = logged["status"].values
    assert set(np.flatnonzero(status == "BLIND")) == set(range(100, 110))
    assert "no data for 10 s" in logged["note"].values[100]
    rows = [{c: logged[c].values[i] for c in ("time", *CHANNELS)} for i in range(240)]
    for r, t in zip(rows, logged["time"].values.astype("datetime64[s]").astype(int), strict=True):
        r["time"] = int(t)
    for name in (
        "status",
        "state",
        "DD",
        "VMV_X",
        "VU_X",
        "VMV_F",
        "VU_F",
        "r_X",
        "r_F",
        "stat_X",
        "probability",
    ):
        for i, r in enumerate(rows):
            r[name] = logged[name].values[i]
    _check_against_batch(rows, model)
    # another model's checkpoint is not resumed
    other = ValveRunner(
        "V1", OnlineDiagnoser.load(model), PHYSICAL_UNITS, "other", checkpoints["V1"]
    )
    assert other.last_second is None and "model file changed" in other.startup_notes[0]


def test_the_log_rotates_days_into_one_netcdf_file_that_diagnose_reads(model, recording, tmp_path):
    from bayes_fdi.datasets.readers import read_recording

    diag = OnlineDiagnoser.load(model)
    log = DurableLog(tmp_path, {"V1": group_labels(diag)}, segment_seconds=40)
    runner = ValveRunner("V1", diag, PHYSICAL_UNITS, "m")
    midnight = 1_800_057_600  # 2027-01-16T00:00:00Z
    rows = []
    for k in range(120):  # 60 s before midnight, 60 after
        for c in CHANNELS:
            runner.offer(
                c, float(to_physical(float(recording[c].values[k]), c)), midnight - 60 + k, float(k)
            )
        rows = runner.step(float(k), 0.0)
        log.commit({"V1": rows}, {"V1": runner.checkpoint()})
    log.flush()
    day = tmp_path / "V1" / "V1_2027-01-15.nc"
    assert day.exists() and not (tmp_path / "V1" / "2027-01-15").exists()
    assert (tmp_path / "V1" / "2027-01-16").is_dir()
    rec = read_recording(str(day))
    assert rec.sizes["time"] == 60
    np.testing.assert_allclose(
        rec["X"].values[0], [float(recording["X"].values[k]) for k in range(60)], rtol=0, atol=1e-12
    )

"""The fit proof (bayes_fdi.diagnosis.online.fit_proof): a detection is read as a fault only after
the stream has seen the normal models fit the valve; hand-counted sequences, chunks, stacked
runs, and the diagnoser's answer (``"mismatch"``) with the reason it gives."""

from __future__ import annotations

import numpy as np
import pytest
from small_online import small_normal_models

from bayes_fdi.actuator import Fault, benchmark_inputs, simulate
from bayes_fdi.diagnosis import OnlineDiagnoser
from bayes_fdi.diagnosis.component_state import stack_states
from bayes_fdi.diagnosis.online import FitProof, FitProofState
from bayes_fdi.model_files import load, save

CHANNELS = ("CV", "P1", "P2", "T1", "X", "F")


def _flags(seconds, dd, counted=None, ages=None):
    dd = np.array(dd, dtype=bool)
    counted = np.ones(dd.size, dtype=bool) if counted is None else np.array(counted, dtype=bool)
    ages = np.ones(dd.size, dtype=np.int64) if ages is None else np.array(ages, dtype=np.int64)
    out, state = FitProof(seconds).run(dd, counted, change_age=ages)
    return out.astype(int).tolist(), state


def test_hand_counted_quiet_stretches_prove_the_fit_once_for_the_rest_of_the_stream():
    # detection at 0 (no quiet second), at 5 after 3 quiet seconds, at 13 after 6, at 16 after 1
    dd = [1, 1, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 1, 1, 0, 1]
    got, state = _flags(5, dd)
    assert got == [1, 1, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]
    assert bool(state.proven[0]) and int(state.quiet[0]) == 0
    # the same stream needs no proof with seconds = 0, and every detection before 6 quiet
    # seconds is unproven with seconds = 7
    assert _flags(0, dd)[0] == [0] * len(dd)
    assert _flags(7, dd)[0] == [int(d) for d in dd]


def test_the_quiet_seconds_are_counted_before_the_change_point_not_the_crossing():
    dd = [0] * 6 + [1, 1]
    # age 3 at the crossing: the excursion began two seconds earlier, in the quiet stretch,
    # which leaves 4 quiet seconds before the change
    assert _flags(5, dd, ages=[0] * 6 + [3, 4])[0] == [0] * 6 + [1, 1]
    assert _flags(4, dd, ages=[0] * 6 + [3, 4])[0] == [0] * 8
    # an age beyond the stretch leaves none
    assert _flags(1, dd, ages=[0] * 6 + [40, 41])[0] == [0] * 6 + [1, 1]


def test_seconds_that_are_not_counted_neither_extend_nor_break_the_stretch():
    dd = [0] * 7 + [1]
    counted = [1, 1, 1, 0, 0, 1, 1, 1]  # 5 counted quiet seconds among 7
    assert _flags(5, dd, counted)[0] == [0] * 8
    assert _flags(6, dd, counted)[0] == [0] * 7 + [1]


def test_chunks_stacked_runs_and_single_seconds_give_the_stream_of_one_call():
    rng = np.random.default_rng(0)
    dd = rng.random((3, 400)) < 0.02
    dd = dd | np.roll(dd, 1, axis=1) | np.roll(dd, 2, axis=1)  # detections of 1-3 s
    counted = rng.random((3, 400)) < 0.9
    ages = rng.integers(1, 6, size=(3, 400))
    proof = FitProof(12)
    whole = [proof.run(dd[r], counted[r], change_age=ages[r]) for r in range(3)]
    assert any(w[0].any() for w in whole) and any((~w[0] & dd[r]).any() for r, w in
                                                  enumerate(whole))  # fmt: skip
    stacked, end = proof.run_stacked(
        dd, counted, stack_states([proof.init_state()] * 3), change_age=ages
    )
    for r in range(3):
        np.testing.assert_array_equal(stacked[r], whole[r][0])
        for a, b in zip(end, whole[r][1], strict=True):
            np.testing.assert_array_equal(a[r], b)
        first, state = proof.run(dd[r, :150], counted[r, :150], change_age=ages[r, :150])
        second, _ = proof.run(dd[r, 150:], counted[r, 150:], state, ages[r, 150:])
        np.testing.assert_array_equal(np.r_[first, second], whole[r][0])
    state, stepwise = None, []
    for t in range(400):
        flag, state = proof.update(dd[0, t], counted[0, t], state, int(ages[0, t]))
        stepwise.append(flag)
    np.testing.assert_array_equal(stepwise, whole[0][0])


def test_bad_settings_and_arrays_are_refused_by_name():
    for bad in (-1, 2.5, True, "600"):
        with pytest.raises(ValueError, match="fit_proof_seconds must be an int >= 0"):
            FitProof(bad).run(np.zeros(3, bool), np.ones(3, bool))
    with pytest.raises(ValueError, match="share one 1-D shape"):
        FitProof(5).run(np.zeros(3, bool), np.ones(4, bool))
    with pytest.raises(ValueError, match="change_age must hold integers"):
        FitProof(5).run(np.zeros(3, bool), np.ones(3, bool), change_age=np.zeros(3))
    with pytest.raises(ValueError, match="fit proof state"):
        FitProof(5).run(np.zeros(3, bool), np.ones(3, bool), state=FitProofState.proven_state((2,)))


@pytest.fixture(scope="module")
def diagnoser():
    normal = simulate(benchmark_inputs(4, 400, seed=1, vary=True), seed=1)
    specs = [Fault(f, s, 100.0) for f in ("f1", "f18") for s in (0.5, 0.7, 0.9, 1.0)]
    faults = simulate(benchmark_inputs(len(specs), 300, seed=2, vary=True), specs, seed=2)
    return OnlineDiagnoser(small_normal_models(), max_signatures_per_fault=20).fit(normal, faults)


@pytest.fixture(scope="module")
def recording():
    return simulate(benchmark_inputs(1, 400, seed=3, vary=True), [Fault("f18", 0.8, 250.0)], seed=3)


def test_a_detection_before_the_proof_is_a_model_mismatch_and_after_it_a_fault(
    diagnoser, recording, tmp_path
):
    diagnoser.set_params(fit_proof_seconds=0)
    named = diagnoser.run(recording)
    dd = named["DD"].values[0]
    assert dd[250:270].any() and not dd[:250].any()  # the fault is the only detection
    assert "mismatch" not in set(named["state"].values[0].astype(str))
    # the change point: the detection's statistics last stood at the clear level (both at it)
    # at second c - 1, so the stream saw c quiet seconds before the change
    first = int(np.flatnonzero(dd)[0])
    stats = np.stack([named["stat_X"].values[0], named["stat_F"].values[0]], axis=-1)
    c = int(np.flatnonzero((stats[:first] <= diagnoser.clear_level_).all(axis=-1))[-1]) + 1
    diagnoser.set_params(fit_proof_seconds=c)
    np.testing.assert_array_equal(diagnoser.run(recording)["state"], named["state"])
    diagnoser.set_params(fit_proof_seconds=c + 1)
    np.testing.assert_array_equal(diagnoser.run(recording)["state"].values[0][dd], "mismatch")
    diagnoser.set_params(fit_proof_seconds=300)
    s = diagnoser.run(recording)
    assert set(s["state"].values[0][dd].astype(str)) == {"mismatch"}
    assert set(s["status"].values[0][dd].astype(str)) == {"DAZZLED"}
    assert s["unproven_onset"].values[0][dd].all() and not s["unproven_onset"].values[0][~dd].any()
    assert not s["indicated"].values[0][dd].any()
    assert s.attrs["fit_proof_seconds"] == 300
    # the detection itself is the same: only its reading changes
    np.testing.assert_array_equal(s["DD"], named["DD"])
    diagnoser.reset()
    records = [diagnoser.update({c: float(recording[c].values[0, t]) for c in CHANNELS})
               for t in range(first + 1)]  # fmt: skip
    reason = records[first].reasons[0]
    assert reason.startswith("model mismatch: commission this valve")
    assert "for 300 s without detection" in reason
    # the setting and the proof's state travel with the model file
    save(diagnoser, tmp_path / "m.npz")
    again = load(tmp_path / "m.npz")
    assert again.fit_proof_seconds == 300
    _, state = diagnoser.run(recording.isel(time=slice(0, 200)), return_state=True)
    assert int(state.proof.quiet[0, 0]) == 200
    rest = again.run(recording.isel(time=slice(200, None)), state=state)
    np.testing.assert_array_equal(rest["state"].values[0], s["state"].values[0][200:])
    diagnoser.set_params(fit_proof_seconds=0)

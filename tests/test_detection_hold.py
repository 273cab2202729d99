"""The detection decision's hold (DD clears only after sustained in-control evidence), its
states across calls and files, files saved before it, and the first-detection indices."""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from bayes_fdi import model_files
from bayes_fdi.datasets import CHANNELS
from bayes_fdi.diagnosis.detection import (
    ARWhitener,
    CUSUMState,
    DecisionState,
    DetectionDecision,
    detection_decision,
)
from bayes_fdi.diagnosis.isolation import SignatureWindow
from bayes_fdi.diagnosis.normal_models import DynamicNormalModels
from bayes_fdi.diagnosis.online import (
    FitProof,
    InputEnvelope,
    PerOutput,
    RunState,
    StreamState,
)
from bayes_fdi.scoring.picalc import first_detection, picalc

NAN = np.nan
#: Two channels, threshold 10, clear level 0 (columns X, F).
STATS = np.array(
    [[0, 0], [11, 0], [0, 0], [0, 12], [0, 0], [NAN, 0], [0, 3], [0, 0], [0, 12], [NAN, NAN],
     [0, 0], [0, 0], [5, 0], [0, 0]],
    dtype=float,
)  # fmt: skip


def _edges(dd):
    return set(np.flatnonzero(dd & ~np.concatenate([[False], dd[:-1]])).tolist())


def test_hold_against_a_hand_computed_sequence():
    # hold 2: on at 11 (t=1); both at 0 at t=2, 1 s after the exceedance: kept; F = 12 at t=3
    # exceeds again; t=4, 5 (X held at 0 through its NaN) are 1, 2 s after it: kept; t=6 is 3 s
    # after, but F = 3 is above the clear level: kept; t=7: 4 s after, both at 0: off. On at
    # t=8 (F = 12), held through the gap t=9 (1 s); t=10 is 2 s after: kept; t=11: off; 5 < 10
    # does not switch it on again
    held = detection_decision(STATS, threshold=10.0, clear=0.0, hold=2)
    T, F = True, False
    assert held.tolist() == [F, T, T, T, T, T, T, F, T, T, T, F, F, F]
    # hold 0 is plain hysteresis: off at the first second with both channels at 0
    plain = detection_decision(STATS, threshold=10.0, clear=0.0)
    assert plain.tolist() == [F, T, F, T, F, F, F, F, T, T, F, F, F, F]
    assert detection_decision(STATS, 10.0, 0.0, hold=0).tolist() == plain.tolist()
    for bad in (-1, 1.5, True):
        with pytest.raises(ValueError, match="hold must be an integer >= 0"):
            detection_decision(STATS, 10.0, 0.0, hold=bad)


def test_a_hold_only_lengthens_and_merges_alarms():
    """Against plain hysteresis on the same statistics: DD with a hold is on wherever plain DD
    is, and each of its rising edges is one of plain DD's (it never adds an alarm)."""
    rng = np.random.default_rng(7)
    stats = np.maximum(rng.normal(0.0, 4.0, size=(5000, 2)), 0.0)
    stats[rng.random(stats.shape) < 0.01] = NAN
    plain = detection_decision(stats, 8.0, 1.0)
    for hold in (1, 5, 40):
        held = detection_decision(stats, 8.0, 1.0, hold=hold)
        assert np.all(held >= plain)
        assert _edges(held) <= _edges(plain)
        assert len(_edges(held)) < len(_edges(plain))


def test_update_run_and_run_stacked_agree_and_states_continue():
    rng = np.random.default_rng(3)
    stats = np.maximum(rng.normal(0.0, 5.0, size=(3, 400, 2)), 0.0)
    stats[rng.random(stats.shape) < 0.02] = NAN
    rule = DetectionDecision(9.0, 0.5, hold=6)
    whole = [rule.run(s) for s in stats]
    stacked_state = DecisionState(*(np.stack([a] * 3) for a in rule.init_state()))
    stacked, end = rule.run_stacked(stats, stacked_state)
    for r, (dd, state) in enumerate(whole):
        np.testing.assert_array_equal(stacked[r], dd)
        for a, b in zip(end, state, strict=True):
            np.testing.assert_array_equal(a[r], b)
        # second by second, and in two chunks, from the carried state: the same
        carried, stepwise = rule.init_state(), []
        for row in stats[r]:
            on, carried = rule.update(row, carried)
            stepwise.append(on)
        assert stepwise == dd.tolist()
        first, mid = rule.run(stats[r, :123])
        rest, _ = rule.run(stats[r, 123:], mid)
        np.testing.assert_array_equal(np.concatenate([first, rest]), dd)
    with pytest.raises(ValueError, match="quiet"):
        rule.run(stats[0], DecisionState(*rule.init_state()[:2], np.zeros(2, np.int64)))


def test_decision_and_state_round_trip_through_a_model_file(tmp_path):
    rng = np.random.default_rng(5)
    stats = np.maximum(rng.normal(0.0, 6.0, size=(300, 2)), 0.0)
    rule = DetectionDecision(9.0, 0.0, hold=12)
    whole, _ = rule.run(stats)
    _, mid = rule.run(stats[:150])
    model_files.save(rule, tmp_path / "rule.npz")
    model_files.save(mid, tmp_path / "state.npz")
    rule_back = model_files.load(tmp_path / "rule.npz")
    mid_back = model_files.load(tmp_path / "state.npz")
    assert rule_back.hold == 12 and isinstance(mid_back, DecisionState)
    rest, _ = rule_back.run(stats[150:], mid_back)
    np.testing.assert_array_equal(rest, whole[150:])


def _as_format_3(src: Path, dst: Path, drop) -> None:
    """Rewrite a model file as a file of format version 3 (before the hold) would be:
    ``drop(root)`` removes what that version did not save."""
    with np.load(src, allow_pickle=False) as npz:
        meta = json.loads(str(npz["metadata"]))
    meta["format_version"] = 3
    drop(meta["root"])
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.array(json.dumps(meta)), allow_pickle=False)
    with zipfile.ZipFile(src) as zin:
        with zipfile.ZipFile(dst, "w") as zout:
            for info in zin.infolist():
                data = buf.getvalue() if info.filename == "metadata.npy" else zin.read(info)
                zout.writestr(info.filename, data)


def test_files_saved_before_the_hold_load_with_plain_hysteresis(tmp_path):
    stats = STATS[:, ::-1]
    rule = DetectionDecision(10.0, 0.0, hold=2)
    _, mid = rule.run(stats[:2])  # on after t=1
    model_files.save(rule, tmp_path / "rule.npz")
    model_files.save(mid, tmp_path / "state.npz")
    _as_format_3(tmp_path / "rule.npz", tmp_path / "old_rule.npz", lambda r: r["state"].pop("hold"))
    _as_format_3(
        tmp_path / "state.npz",
        tmp_path / "old_state.npz",
        lambda r: r["fields"]["__dict__"].pop("quiet"),
    )
    old_rule = model_files.load(tmp_path / "old_rule.npz")
    old_state = model_files.load(tmp_path / "old_state.npz")
    assert old_rule.hold == 0
    np.testing.assert_array_equal(old_state.quiet, [0])
    assert old_state.on.tolist() == [True]
    # the old rule continues the old stream as plain hysteresis did
    rest, _ = old_rule.run(stats[2:], old_state)
    plain = detection_decision(stats, 10.0, 0.0)
    np.testing.assert_array_equal(rest, plain[2:])


def test_a_checkpointed_stream_state_without_the_quiet_count_decodes():
    one = RunState(
        models=DynamicNormalModels().init_state(),
        whiten=PerOutput(*(ARWhitener(order=1).fit(np.arange(40.0) % 3).init_state(),) * 2),
        detect=PerOutput(CUSUMState(np.zeros(2), np.zeros(2)), CUSUMState(np.ones(2), np.ones(2))),
        decision=DetectionDecision(1.0, hold=5).init_state(),
        signature=SignatureWindow().init_state(),
        onset=InputEnvelope().init_state(),
        proof=FitProof().init_state(),
        seconds=4,
    )
    arrays = StreamState.of_runs([one, one]).arrays()
    assert arrays["decision.quiet"].shape == (2, 1)
    old = {k: v for k, v in arrays.items() if k != "decision.quiet"}
    back = StreamState.from_arrays(old)
    np.testing.assert_array_equal(back.decision.quiet, np.zeros((2, 1), np.int64))
    assert back.decision.quiet.dtype == np.int64


def test_first_detection_against_hand_computed_values():
    t = np.arange(0.0, 1500.0)
    zone = {"t_on": 300, "t_from": 900, "t_hor": 1500}
    # first seen 3 s after the fault, dropped at 1200 s for 2 s: PICalc credits 1202 s
    dd = (t >= 903) & ~np.isin(t, [1200, 1201])
    assert first_detection(t, dd, **zone) == {"t_dt_first": 3.0, "dd_permanent": 0.0}
    assert picalc(t, dd, dd, np.zeros_like(t), **zone)["t_dt"] == 302.0
    # kept on: both agree
    kept = t >= 903
    assert first_detection(t, kept, **zone) == {"t_dt_first": 3.0, "dd_permanent": 1.0}
    assert picalc(t, kept, kept, np.zeros_like(t), **zone)["t_dt"] == 3.0
    # a false alarm from 850 s lasting into the fault is a detection at t_from; NaN is low
    early = ((t >= 850) & (t < 910)).astype(float)
    early[t == 905] = NAN
    assert first_detection(t, early, **zone) == {"t_dt_first": 0.0, "dd_permanent": 0.0}
    never = (t >= 300) & (t < 400)
    assert first_detection(t, never, **zone) == {"t_dt_first": -1.0, "dd_permanent": -1.0}
    with pytest.raises(ValueError, match="faulty part"):
        first_detection(t[:1000], kept[:1000], **zone)


def test_training_signatures_are_those_of_plain_hysteresis():
    """The isolator learns from windows that start at a detection after the onset: the
    training stream decides without the hold, so a hold changes neither the signatures nor
    which training runs count as detected."""
    from bayes_fdi.actuator import Fault, benchmark_inputs, simulate
    from bayes_fdi.diagnosis import OnlineDiagnoser
    from bayes_fdi.diagnosis.online.step import Components, init_run_state, step
    from bayes_fdi.diagnosis.online.training import training_signatures

    models = DynamicNormalModels(
        x_widths=(8.0,), f_widths=(0.1,), evidence_max_samples=200, max_train_samples=300,
        calibration_folds=2, random_state=0,
    )  # fmt: skip
    normal = simulate(benchmark_inputs(4, 400, seed=1, vary=True), seed=1)
    diag = OnlineDiagnoser(models).fit(normal)
    assert diag.decision_.hold == 100
    specs = [Fault(f, s, 100.0) for f in ("f1", "f18") for s in (0.3, 0.6, 1.0)]
    faults = simulate(benchmark_inputs(len(specs), 400, seed=2, vary=True), specs, seed=2)
    parts = (diag.normal_models_, PerOutput(diag.whiteners_["X"], diag.whiteners_["F"]))
    rest = (diag.detector_, diag.decision_, diag.signature_, diag.envelope_, FitProof(), None)
    held = training_signatures(Components(*parts, *rest), faults)
    plain_decision = DetectionDecision(diag.threshold_, diag.clear_level_, 2, hold=0)
    rest = (diag.detector_, plain_decision, diag.signature_, diag.envelope_, FitProof(), None)
    plain = training_signatures(Components(*parts, *rest), faults)
    assert held.detected == plain.detected and held.rows.shape[0] > 0
    # while the streams' DD differ on these runs: the hold keeps alarms on longer
    longer = 0
    for r in range(faults.sizes["run"]):
        arrays = {c: faults[c].values[r].astype(np.float64) for c in CHANNELS}
        dd = {}
        for name, decision in (("held", diag.decision_), ("plain", plain_decision)):
            components = Components(*parts, diag.detector_, decision, *rest[2:])
            dd[name] = step(components, arrays, init_run_state(components))[0]["DD"]
        assert np.all(dd["held"] >= dd["plain"])
        longer += int(np.sum(dd["held"] & ~dd["plain"]))
    assert longer > 0
    np.testing.assert_array_equal(held.rows, plain.rows)
    np.testing.assert_array_equal(held.ages, plain.ages)


def test_training_signatures_do_not_depend_on_the_variance_hold():
    """With `VarianceHoldCUSUM` the training stream takes its ages from the mean test alone:
    the signatures and the detected runs equal those of the plain CUSUM at the same threshold,
    while the per-second rows (the recalibration's, the seconds the diagnoser reports) come
    from the stream with the variance hold."""
    from bayes_fdi.actuator import Fault, benchmark_inputs, simulate
    from bayes_fdi.diagnosis import OnlineDiagnoser
    from bayes_fdi.diagnosis.detection import CUSUM, VarianceHoldCUSUM
    from bayes_fdi.diagnosis.online.step import Components
    from bayes_fdi.diagnosis.online.training import training_signatures

    models = DynamicNormalModels(
        x_widths=(8.0,), f_widths=(0.1,), evidence_max_samples=200, max_train_samples=300,
        calibration_folds=2, random_state=0,
    )  # fmt: skip
    normal = simulate(benchmark_inputs(4, 400, seed=1, vary=True), seed=1)
    diag = OnlineDiagnoser(models, detector="variance-hold").fit(normal)
    assert isinstance(diag.detector_, VarianceHoldCUSUM)
    specs = [Fault(f, s, 100.0) for f in ("f11", "f18") for s in (0.5, 1.0)]
    faults = simulate(benchmark_inputs(len(specs), 400, seed=2, vary=True), specs, seed=2)
    parts = (diag.normal_models_, PerOutput(diag.whiteners_["X"], diag.whiteners_["F"]))
    rest = (diag.decision_, diag.signature_, diag.envelope_, FitProof(), None)
    held = Components(*parts, diag.detector_, *rest)
    plain = Components(*parts, CUSUM(k=0.5, threshold=diag.threshold_), *rest)
    a, b = training_signatures(held, faults), training_signatures(plain, faults)
    assert a.detected == b.detected and a.rows.shape[0] > 0
    np.testing.assert_array_equal(a.rows, b.rows)
    np.testing.assert_array_equal(a.ages, b.ages)
    per_second = training_signatures(held, faults, per_second=True)
    assert (
        per_second.rows.shape[0]
        >= training_signatures(plain, faults, per_second=True).rows.shape[0]
    )

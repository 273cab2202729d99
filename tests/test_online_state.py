"""The online diagnoser's stream state (bayes_fdi.diagnosis.online.state) and the translation of
the layouts of bayes_fdi 0.1.0 (bayes_fdi.diagnosis.online.legacy), checked on the data of the
0.1.0 model file in tests/data/model_files_0.1.0 (read from its JSON metadata and arrays)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bayes_fdi.diagnosis import OnlineDiagnoser
from bayes_fdi.diagnosis.detection import ARWhitener, CUSUMState, DetectionDecision, GLRState
from bayes_fdi.diagnosis.isolation import SignatureWindow
from bayes_fdi.diagnosis.normal_models import DynamicNormalModels
from bayes_fdi.diagnosis.online import (
    FitProof,
    InputEnvelope,
    PerOutput,
    RunState,
    StreamState,
)
from bayes_fdi.diagnosis.online.legacy import (
    upgrade_diagnoser,
    upgrade_run_state,
    upgrade_stream_state,
)

FIXTURE = Path(__file__).parent / "data" / "model_files_0.1.0" / "online.npz"


def _plain(node, arrays):
    """The JSON of a 0.1.0 file with its arrays, tuples, dicts and floats resolved (an object as
    its class name and resolved state; references left as they are)."""
    if isinstance(node, list):
        return [_plain(v, arrays) for v in node]
    if not isinstance(node, dict):
        return node
    if "__array__" in node:
        return arrays[node["__array__"]]
    if "__tuple__" in node:
        return tuple(_plain(v, arrays) for v in node["__tuple__"])
    if "__dict__" in node:
        return {k: _plain(v, arrays) for k, v in node["__dict__"].items()}
    if "__float__" in node:
        return float(node["__float__"])
    if "__object__" in node:
        state = {k: _plain(v, arrays) for k, v in node["state"].items()}
        return {"__object__": node["__object__"], "state": state}
    return node


@pytest.fixture(scope="module")
def saved():
    """The 0.1.0 diagnoser's saved attributes (JSON values and arrays)."""
    with np.load(FIXTURE) as npz:
        meta = json.loads(str(npz["metadata"]))
        arrays = {k: npz[k] for k in npz.files if k != "metadata"}
    assert meta["format_version"] == 1
    return {k: _plain(v, arrays) for k, v in meta["root"]["state"].items()}


def _leaves(state, prefix="state"):
    if isinstance(state, tuple) and hasattr(state, "_fields"):
        out = {}
        for name, value in zip(state._fields, state, strict=True):
            out.update(_leaves(value, f"{prefix}.{name}"))
        return out
    return {prefix: np.asarray(state)}


def test_the_0_1_0_run_state_is_nested_field_by_field(saved):
    old = saved["_stream"]
    new = upgrade_run_state(old)
    assert isinstance(new, RunState) and new.seconds == old["seconds"] == 30
    np.testing.assert_array_equal(new.models.history, old["models"][0])
    np.testing.assert_array_equal(new.models.seen, old["models"][1])
    for c in ("X", "F"):
        np.testing.assert_array_equal(getattr(new.whiten, c).history, old["whiten"][c][0])
        np.testing.assert_array_equal(getattr(new.whiten, c).valid, old["whiten"][c][1])
        # the CUSUM kept [S+, S-, n+, n-]
        (flat,) = old["detect"][c]
        detect = getattr(new.detect, c)
        assert isinstance(detect, CUSUMState)
        np.testing.assert_array_equal(detect.sums, flat[:2])
        np.testing.assert_array_equal(detect.lengths, flat[2:])
    assert new.decision.on.dtype == bool and new.decision.on[0] == (old["dd"][0] == 1.0)
    np.testing.assert_array_equal(new.decision.held, old["held"])
    # the signature window kept [n, 16 sums, P1 P2 T1 reference, reference set, DD before]
    f = old["features"]
    np.testing.assert_array_equal(new.signature.count, f[:1])
    np.testing.assert_array_equal(new.signature.sums, f[1:17])
    np.testing.assert_array_equal(new.signature.reference, f[17:20])
    assert new.signature.reference_set.tolist() == [True] and f[20] == 1.0
    assert new.signature.detected.tolist() == [bool(f[21])]
    # the onset check kept [average of CV P1 P2 T1, set, novel at onset, DD before]
    r = old["reference"]
    np.testing.assert_array_equal(new.onset.average, r[:4])
    assert new.onset.average_set.tolist() == [bool(r[4])]
    assert new.onset.novel_at_onset.tolist() == [bool(r[5])]
    assert new.onset.detected.tolist() == [bool(r[6])]
    # the same state as the loaded diagnoser's: its layout checked by every component
    loaded = OnlineDiagnoser.load(FIXTURE).stream_state().run(0)
    got, want = _leaves(new), _leaves(loaded)
    assert got.keys() == want.keys()
    for name in got:
        assert got[name].dtype == want[name].dtype, name
        np.testing.assert_array_equal(got[name], want[name], err_msg=name)


def test_a_0_1_0_glr_state_keeps_its_ring_and_counters():
    ring, counters = np.arange(5.0), np.array([3.0, 4.0])
    old = {
        "models": (np.zeros((2, 2)), np.ones(1, dtype=np.int64)),
        "whiten": {c: (np.zeros(2), np.zeros(1, dtype=np.int64)) for c in ("X", "F")},
        "detect": {c: (ring, counters) for c in ("X", "F")},
        "dd": np.ones(1),
        "held": np.zeros(2),
        "features": np.zeros(22),
        "reference": np.zeros(7),
        "seconds": 4,
    }
    state = upgrade_run_state(old)
    assert isinstance(state.detect.X, GLRState)
    np.testing.assert_array_equal(state.detect.X.buffer, ring)
    assert state.detect.F.stored.tolist() == [3] and state.detect.F.slot.tolist() == [4]
    assert state.detect.F.stored.dtype == np.int64 and state.decision.on.tolist() == [True]


def _flat_fields(runs):
    """The fields of 0.1.0's `StreamState` of run states in 0.1.0's layout: one array per run
    and component, stacked."""

    def stacked(get):
        return np.stack([get(r) for r in runs])

    return {
        "model_history": stacked(lambda r: r["models"][0]),
        "model_seen": stacked(lambda r: r["models"][1]),
        **{f"whiten_{c}": stacked(lambda r, c=c: r["whiten"][c][0]) for c in ("X", "F")},
        **{f"whiten_{c}_valid": stacked(lambda r, c=c: r["whiten"][c][1]) for c in ("X", "F")},
        **{f"detect_{c}": (stacked(lambda r, c=c: r["detect"][c][0]),) for c in ("X", "F")},
        "decision": stacked(lambda r: r["dd"]),
        "held": stacked(lambda r: r["held"]),
        "features": stacked(lambda r: r["features"]),
        "input_reference": stacked(lambda r: r["reference"]),
        "seconds": np.array([r["seconds"] for r in runs]),
    }


def test_a_0_1_0_stream_state_of_two_runs_is_nested_with_its_run_axis(saved):
    old = saved["_stream"]
    runs = [old, dict(old, seconds=31, held=old["held"] + 1.0)]
    flat = _flat_fields(runs)
    state = StreamState(**upgrade_stream_state(flat))
    want = StreamState.of_runs([upgrade_run_state(r) for r in runs])
    got_leaves, want_leaves = _leaves(state), _leaves(want)
    assert got_leaves.keys() == want_leaves.keys()
    for name, value in got_leaves.items():
        np.testing.assert_array_equal(value, want_leaves[name], err_msg=name)
        assert not value.flags.writeable, name
    assert state.n_runs == 2 and state.run(1).seconds == 31
    # fields already in today's layout are left as they are
    assert upgrade_stream_state(want._asdict()) == want._asdict()


def test_the_0_1_0_diagnoser_attributes_get_todays_components(saved):
    data = {
        k: saved[k]
        for k in ("input_low_", "input_high_", "input_margin", "threshold_", "clear_level_")
    }
    data["normal_models_"] = DynamicNormalModels()
    data["_stream"] = saved["_stream"]
    new = upgrade_diagnoser(data)
    assert "input_low_" not in new and "input_high_" not in new
    assert isinstance(new["envelope_"], InputEnvelope)
    np.testing.assert_array_equal(new["envelope_"].low_, saved["input_low_"])
    np.testing.assert_array_equal(new["envelope_"].high_, saved["input_high_"])
    assert new["envelope_"].margin == saved["input_margin"]
    decision = new["decision_"]
    assert isinstance(decision, DetectionDecision)
    assert (decision.threshold, decision.clear) == (saved["threshold_"], saved["clear_level_"])
    assert isinstance(new["signature_"], SignatureWindow)
    assert isinstance(new["_stream"], RunState)
    assert upgrade_diagnoser(new) == new  # today's layout: unchanged


def test_the_0_1_0_whitener_and_normal_models_drop_their_caches(saved):
    whitener = saved["whiteners_"]["F"]["state"]
    assert "_state" in whitener
    new = ARWhitener.upgrade_model_file(whitener, 1)
    assert "_state" not in new and new["order_"] == whitener["order_"]
    unfitted = saved["normal_models"]["state"]
    # the std factors of 0.1.0 were fitted by maximum likelihood (std_coverage=None) per bin
    # of the command speed, and its models took no physics inputs
    upgraded = DynamicNormalModels.upgrade_model_file(dict(unfitted), 1)
    assert upgraded == {
        **unfitted, "std_coverage": None, "physics_inputs": (), "lag_speed_limits": False,
        "lag_as_mean": False, "law_as_mean": False, "std_bins": "speed",
    }  # fmt: skip
    # the fitted models' kernel parameters, rebuilt on loading, hold the values 0.1.0 passed
    # to its kernel (the scalars of its saved `_kernel_args`)
    args = saved["normal_models_"]["state"]["_kernel_args"]
    params = OnlineDiagnoser.load(FIXTURE).normal_models_.params_
    assert (params.x_model.has_bias, params.x_model.noise_var) == (args[5], args[6])
    assert 0.5 / params.x_model.width**2 == args[7]
    assert (params.f_model.has_bias, params.f_model.noise_var) == (args[11], args[12])
    assert 0.5 / params.f_model.width**2 == args[13]
    assert (params.x_std_scale_all, params.f_std_scale_all) == (args[17], args[18])
    assert (params.low, params.high) == (args[19], args[20])


def test_stream_state_layout_is_checked():
    one = RunState(
        models=DynamicNormalModels().init_state(),
        whiten=PerOutput(*(ARWhitener(order=1).fit(np.arange(40.0) % 3).init_state(),) * 2),
        detect=PerOutput(CUSUMState(np.zeros(2), np.zeros(2)), CUSUMState(np.ones(2), np.ones(2))),
        decision=DetectionDecision(1.0).init_state(),
        signature=SignatureWindow().init_state(),
        onset=InputEnvelope().init_state(),
        proof=FitProof(60).init_state(),
        seconds=7,
    )
    state = StreamState.of_runs([one, one])
    state.check_layout()
    assert state.n_runs == 2 and state.run(1).seconds == 7
    np.testing.assert_array_equal(state.detect.F.sums, np.ones((2, 2)))
    with pytest.raises(ValueError, match="read-only"):
        state.signature.sums[0, 0] = 1.0
    bad = state._replace(onset=state.onset._replace(average=np.zeros((3, 4))))
    with pytest.raises(ValueError, match=r"state.onset.average must be an array with a leading"):
        bad.check_layout()


def test_stream_state_arrays_round_trip_by_path():
    one = RunState(
        models=DynamicNormalModels().init_state(),
        whiten=PerOutput(*(ARWhitener(order=1).fit(np.arange(40.0) % 3).init_state(),) * 2),
        detect=PerOutput(
            GLRState(np.arange(4.0), np.ones(1, np.int64), np.zeros(1, np.int64)),
            GLRState(np.zeros(4), np.zeros(1, np.int64), np.ones(1, np.int64)),
        ),
        decision=DetectionDecision(1.0).init_state(),
        signature=SignatureWindow().init_state(),
        onset=InputEnvelope().init_state(),
        proof=FitProof(60).init_state(),
        seconds=3,
    )
    state = StreamState.of_runs([one])
    arrays = state.arrays()
    assert "detect.X.buffer" in arrays and "models.history" in arrays and "seconds" in arrays
    back = StreamState.from_arrays({k: v.copy() for k, v in arrays.items()})
    assert isinstance(back.detect.X, GLRState)
    for path, value in back.arrays().items():
        np.testing.assert_array_equal(value, arrays[path], err_msg=path)
        assert value.dtype == arrays[path].dtype and not value.flags.writeable, path
    with pytest.raises(ValueError, match="unknown stream state arrays"):
        StreamState.from_arrays({**arrays, "detect.X.extra": np.zeros(1)})
    missing = {k: v for k, v in arrays.items() if k != "onset.average"}
    with pytest.raises(ValueError, match="no EnvelopeState at 'onset'"):
        StreamState.from_arrays(missing)
    # a state saved before the fit proof: its fit counts as proven, as its model's detections were
    older = StreamState.from_arrays({k: v for k, v in arrays.items() if not k.startswith("proof.")})
    assert older.proof.proven.tolist() == [[True]] and older.proof.quiet.tolist() == [[0]]
    assert not older.proof.detected.any() and not older.proof.unproven_at_onset.any()


def test_a_checkpoint_of_the_flat_state_decodes_to_todays(saved):
    import base64

    from bayes_fdi.deployment.serve.records import decode_state, encode_state

    def encoded(a):
        a = np.ascontiguousarray(a)
        data = base64.b64encode(a.tobytes()).decode("ascii")
        return {"dtype": a.dtype.str, "shape": list(a.shape), "data": data}

    flat = _flat_fields([saved["_stream"]])
    fields = {
        k: [encoded(a) for a in v] if isinstance(v, tuple) else encoded(v) for k, v in flat.items()
    }
    text = json.dumps({"format": "bayes_fdi.StreamState", "version": 1, "fields": fields})
    state = decode_state(text)
    want = StreamState.of_runs([upgrade_run_state(saved["_stream"])])
    for path, value in want.arrays().items():
        np.testing.assert_array_equal(state.arrays()[path], value, err_msg=path)
    again = decode_state(encode_state(state))  # today's text: the same state, bit for bit
    for path, value in state.arrays().items():
        assert again.arrays()[path].tobytes() == value.tobytes(), path

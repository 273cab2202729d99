"""The online diagnoser (bayes_fdi.diagnosis.online.diagnoser): the decision stream's contract,
update equal to run, gaps, detection only."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
import xarray as xr
from sklearn.base import clone

from bayes_fdi.actuator import Fault, benchmark_inputs, simulate
from bayes_fdi.diagnosis import OnlineDiagnoser
from bayes_fdi.diagnosis.normal_models.dynamic import DynamicNormalModels
from bayes_fdi.diagnosis.online import InputEnvelope
from bayes_fdi.diagnosis.seva.record import SevaRecord, SevaStatus

CHANNELS = ("CV", "P1", "P2", "T1", "X", "F")


def _tiny_models():
    # small fits keep the test fast; the method is the same as the default's
    return DynamicNormalModels(
        x_widths=(8.0,), f_widths=(0.1,), evidence_max_samples=200, max_train_samples=300,
        calibration_folds=2, random_state=0,
    )  # fmt: skip


@pytest.fixture(scope="module")
def fitted():
    from bayes_fdi.calibration import TemperatureScaler

    normal = simulate(benchmark_inputs(4, 400, seed=1, vary=True), seed=1)
    specs = [Fault(f, s, 100.0) for f in ("f1", "f7", "f18") for s in (0.4, 0.6, 0.8, 1.0, 0.5)]
    faults = simulate(benchmark_inputs(len(specs), 300, seed=2, vary=True), specs, seed=2)
    diag = OnlineDiagnoser(
        _tiny_models(), calibrator=TemperatureScaler(), max_signatures_per_fault=20
    ).fit(normal, faults)
    return diag


@pytest.fixture(scope="module")
def recording():
    specs = [None, Fault("f1", 0.6, 100.0), Fault("f18", 0.7, 120.0)]
    rec = simulate(benchmark_inputs(3, 300, seed=3, vary=True), specs, seed=3)
    x = rec["X"].values.copy()
    x[1, 150:160] = np.nan  # a gap while the fault is on
    return rec.assign(X=(("run", "time"), x))


def test_stream_has_the_contract_variables(fitted, recording):
    s = fitted.run(recording)
    for name in ("DD", "FFID", "state", "probability", "status", "X_hat", "X_hat_std", "F_hat",
                 "F_hat_std", "r_X", "r_F", "stat_X", "stat_F", "VMV_X", "VU_X", "VMV_F",
                 "VU_F"):  # fmt: skip
        assert s[name].dims == ("run", "time"), name
    assert s["indicated"].dims == ("run", "time", "group")
    assert s["group_proba"].dims == ("run", "time", "group")
    assert s["fault_proba"].dims == ("run", "time", "fault")
    assert list(s["fault"].values) == [f"f{i}" for i in range(1, 20)]
    groups = json.loads(s.attrs["groups"])
    assert list(groups) == list(s["group"].values)
    assert sorted(f for g in fitted.groups_ for f in g) == sorted(
        f for members in groups.values() for f in members
    )
    assert isinstance(json.loads(s.attrs["undetectable"]), list)
    np.testing.assert_array_equal(s["run"].values, recording["run"].values)
    np.testing.assert_array_equal(s["time"].values, recording["time"].values)
    assert s["true_state"].values.tolist() == ["fn", "f1", "f18"]  # the labels, renamed


def test_stream_semantics(fitted, recording):
    s = fitted.run(recording)
    dd, status = s["DD"].values, s["status"].values.astype(str)
    assert set(np.unique(status)) <= {m.value for m in SevaStatus}
    blind = ~np.isfinite(recording["X"].values)
    np.testing.assert_array_equal(status == "BLIND", blind)
    np.testing.assert_array_equal(s["FFID"].values, ~dd & ~blind)
    assert not s["indicated"].values[~dd].any()
    assert (s["indicated"].values.sum(axis=-1) <= 1).all()
    gp, fp = s["group_proba"].values, s["fault_proba"].values
    defined = np.isfinite(gp).all(axis=-1)
    assert not defined[~dd].any()  # NaN while not detected
    np.testing.assert_allclose(gp[defined].sum(axis=-1), 1.0, rtol=1e-12)
    groups = json.loads(s.attrs["groups"])
    faults = list(s["fault"].values)
    for j, members in enumerate(groups.values()):
        cols = [faults.index(f) for f in members]
        # the fault probabilities share out their group's (calibrated) probability
        np.testing.assert_allclose(fp[defined][:, cols].sum(axis=-1), gp[defined][:, j],
                                   rtol=1e-12, atol=1e-15)  # fmt: skip
    st = s["state"].values.astype(str)
    assert (st[~dd] == "fn").all()
    assert np.isnan(s["probability"].values[~dd]).all()
    # the gap stays a gap: no residual, no statistic, and no exception for the recording
    assert np.isnan(s["r_X"].values[1, 150:160]).all()
    assert np.isnan(s["stat_X"].values[1, 150:160]).all()
    # the faulty runs are detected within seconds of their onsets and stay detected (the
    # false-alarm rate of fault-free data is measured by the benchmark, not by this tiny fit)
    assert dd[1, 100:110].any() and dd[1, 110:].mean() > 0.9
    assert dd[2, 120:130].any() and dd[2, 130:].mean() > 0.9


def test_update_equals_run(fitted, recording):
    s = fitted.run(recording)
    for r in (1, 2):
        fitted.reset()
        recs, last = [], []
        for t in range(recording.sizes["time"]):
            sample = {c: float(recording[c].values[r, t]) for c in CHANNELS}
            recs.append(fitted.update({**sample, "time": float(t)}))
            last.append(dict(fitted.last_))
        assert all(isinstance(x, SevaRecord) for x in recs)
        one = s.isel(run=r)
        # the same compiled kernels on the same state, one second at a time: identical
        np.testing.assert_array_equal([x.state for x in recs], one["state"].values.astype(str))
        np.testing.assert_array_equal([x.status.value for x in recs], one["status"].values)
        np.testing.assert_array_equal([x.probability for x in recs], one["probability"].values)
        np.testing.assert_array_equal([x.x_vmv for x in recs], one["VMV_X"].values)
        np.testing.assert_array_equal([x.x_vu for x in recs], one["VU_X"].values)
        np.testing.assert_array_equal([x.f_vmv for x in recs], one["VMV_F"].values)
        np.testing.assert_array_equal([x.f_vu for x in recs], one["VU_F"].values)
        np.testing.assert_array_equal([x.feature_novelty for x in recs], one["novelty"].values)
        for key in ("DD", "FFID", "stat_X", "stat_F", "r_X", "r_F"):
            np.testing.assert_array_equal([d[key] for d in last], one[key].values)
        np.testing.assert_array_equal(np.array([d["indicated"] for d in last]),
                                      one["indicated"].values)  # fmt: skip
        np.testing.assert_array_equal(np.array([d["group_proba"] for d in last]),
                                      one["group_proba"].values)  # fmt: skip
        detected = [x for x in recs if len(x.distribution)]
        assert detected and all(list(x.distribution) == list(s["group"].values) for x in detected)


def test_one_run_without_a_run_dimension(fitted, recording):
    one = recording.isel(run=1)
    s = fitted.run(one)
    assert "run" not in s.dims and s["DD"].dims == ("time",)
    np.testing.assert_array_equal(s["DD"].values, fitted.run(recording)["DD"].values[1])


def test_detection_only_without_fault_runs(recording):
    normal = simulate(benchmark_inputs(4, 400, seed=1, vary=True), seed=1)
    diag = OnlineDiagnoser(_tiny_models()).fit(normal)
    assert diag.isolator_ is None and diag.groups_ == ()
    s = diag.run(recording)
    dd = s["DD"].values
    assert dd[1].any()
    assert set(s["state"].values[dd].astype(str)) == {"unknown"}
    assert set(s["status"].values[dd & np.isfinite(recording["X"].values)]) == {"DAZZLED"}
    assert s.sizes["group"] == 0
    assert json.loads(s.attrs["undetectable"]) == []


def test_a_detector_object_gives_the_stream_of_its_name(recording):
    """A sequential test passed as an object is calibrated like the built-in one it equals."""
    from bayes_fdi.diagnosis.detection import CUSUM

    normal = simulate(benchmark_inputs(4, 400, seed=1, vary=True), seed=1)
    by_name = OnlineDiagnoser(_tiny_models(), detector="cusum", cusum_k=0.7).fit(normal)
    by_object = OnlineDiagnoser(_tiny_models(), detector=CUSUM(k=0.7, threshold=99.0)).fit(normal)
    assert by_object.threshold_ == by_name.threshold_
    a, b = by_name.run(recording), by_object.run(recording)
    for name in ("DD", "stat_X", "stat_F", "status"):
        np.testing.assert_array_equal(a[name].values, b[name].values)
    with pytest.raises(ValueError, match="'cusum', 'variance-hold', 'glr' or a sequential test"):
        OnlineDiagnoser(_tiny_models(), detector=object()).fit(normal)


def test_the_variance_hold_by_name_is_calibrated_saved_and_loaded(recording, tmp_path):
    """``detector="variance-hold"`` fits the CUSUM with its variance sum; its threshold is the
    mean sums' (the variance sum never exceeds half of it), and a model file gives the stream."""
    from bayes_fdi.diagnosis.detection import VarianceHoldCUSUM

    normal = simulate(benchmark_inputs(4, 400, seed=1, vary=True), seed=1)
    diag = OnlineDiagnoser(_tiny_models(), detector="variance-hold").fit(normal)
    assert isinstance(diag.detector_, VarianceHoldCUSUM)
    assert diag.detector_.threshold == diag.threshold_
    stream = diag.run(recording)
    back = OnlineDiagnoser.load(diag.save(tmp_path / "hold.npz"))
    again = back.run(recording)
    for name in ("DD", "stat_X", "stat_F", "status", "group_proba"):
        np.testing.assert_array_equal(stream[name].values, again[name].values)


def test_clone_refits_and_bad_input_is_named(fitted, recording):
    params = fitted.get_params()
    assert params["max_signatures_per_fault"] == 20
    fresh = clone(fitted)
    assert not hasattr(fresh, "normal_models_")
    with pytest.raises(ValueError, match="not fitted"):
        fresh.run(recording)
    with pytest.raises(ValueError, match="lacks channel"):
        fitted.update({"CV": 0.5, "P1": 0.8})
    with pytest.raises(ValueError, match="detector"):
        OnlineDiagnoser(detector="ewma").fit(recording.isel(run=[0]))


def _assert_streams_equal(a, b):
    # the same compiled kernels continue from the same state: identical, not merely close
    assert set(a.data_vars) == set(b.data_vars)
    for name in a.data_vars:
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)
    assert a.attrs == b.attrs


@pytest.mark.parametrize("cuts", [(150,), (1, 99, 100, 155)])
def test_chunked_run_continues_exactly(fitted, recording, cuts):
    whole = fitted.run(recording)
    edges = [0, *cuts, recording.sizes["time"]]
    parts, state = [], None
    for a, b in itertools.pairwise(edges):
        part, state = fitted.run(recording.isel(time=slice(a, b)), state=state,
                                 return_state=True)  # fmt: skip
        parts.append(part)
    _assert_streams_equal(whole, xr.concat(parts, dim="time"))
    assert state.n_runs == recording.sizes["run"]
    np.testing.assert_array_equal(state.seconds, recording.sizes["time"])
    with pytest.raises(ValueError, match="read-only"):
        state.signature.sums[0, 0] = 1.0  # the state is immutable


def test_update_continues_a_runs_state(fitted, recording):
    one = recording.isel(run=[2])
    whole = fitted.run(one)
    _, state = fitted.run(one.isel(time=slice(0, 130)), return_state=True)
    fitted.reset(state)
    recs = [fitted.update({c: float(one[c].values[0, t]) for c in CHANNELS})
            for t in range(130, one.sizes["time"])]  # fmt: skip
    np.testing.assert_array_equal([r.state for r in recs], whole["state"].values[0, 130:])
    np.testing.assert_array_equal([r.probability for r in recs],
                                  whole["probability"].values[0, 130:])  # fmt: skip
    assert recs[0].t_start == 130.0  # seconds count on from the state
    after = fitted.stream_state()
    _, want = fitted.run(one, return_state=True)
    got, expected = _leaves(after), _leaves(want)
    assert got.keys() == expected.keys()
    for name, value in got.items():
        np.testing.assert_array_equal(value, expected[name], err_msg=name)


def _leaves(state, prefix="state"):
    """Every array of a nested state, by its path."""
    if isinstance(state, tuple):
        out = {}
        for name, value in zip(state._fields, state, strict=True):
            out.update(_leaves(value, f"{prefix}.{name}"))
        return out
    return {prefix: np.asarray(state)}


def test_state_of_another_shape_is_refused(fitted, recording):
    _, state = fitted.run(recording.isel(run=[0]), return_state=True)
    with pytest.raises(ValueError, match="1 run"):
        fitted.run(recording, state=state)
    with pytest.raises(ValueError, match="StreamState"):
        fitted.run(recording, state={"dd": 1})
    # a state of another diagnoser (another whitening order): the field is named
    order = fitted.whiteners_["X"].order_
    whiten = state.whiten._replace(X=state.whiten.X._replace(history=np.zeros((1, order + 1))))
    with pytest.raises(ValueError, match=r"whitener state.history must be a float64 array"):
        fitted.reset(state._replace(whiten=whiten))
    with pytest.raises(ValueError, match=r"state.seconds must be a \(runs,\) array"):
        fitted.run(recording.isel(run=[0]), state=state._replace(seconds=np.int64(3)))


def test_save_load_round_trip_is_exact(fitted, recording, tmp_path):
    path = tmp_path / "online.npz"
    fitted.reset()
    fitted.save(path)
    loaded = OnlineDiagnoser.load(path)
    assert type(loaded) is OnlineDiagnoser
    assert loaded.get_params().keys() == fitted.get_params().keys()
    assert loaded.groups_ == fitted.groups_ and loaded.threshold_ == fitted.threshold_
    _assert_streams_equal(fitted.run(recording), loaded.run(recording))
    sample = {c: float(recording[c].values[1, 120]) for c in CHANNELS}
    # repr: exact float reprs, and NaN fields compare equal (a dataclass's == would not)
    assert repr(loaded.update(sample)) == repr(fitted.reset().update(sample))


def test_normal_runs_as_a_list_of_datasets_of_different_durations(recording):
    a = simulate(benchmark_inputs(2, 400, seed=1, vary=True), seed=1)
    b = simulate(benchmark_inputs(2, 300, seed=4, vary=True), seed=4)
    from_list = OnlineDiagnoser(_tiny_models()).fit([a, b])
    # by hand: the shorter runs padded with NaN (no measurement) to one 4-run dataset
    padded = {c: np.full((4, 400), np.nan) for c in CHANNELS}
    for c in CHANNELS:
        padded[c][:2] = a[c].values
        padded[c][2:, :300] = b[c].values
    by_hand = xr.Dataset({c: (("run", "time"), v) for c, v in padded.items()},
                         coords={"run": np.arange(4), "time": a["time"].values})  # fmt: skip
    from_one = OnlineDiagnoser(_tiny_models()).fit(by_hand)
    assert from_list.threshold_ == from_one.threshold_
    _assert_streams_equal(from_list.run(recording), from_one.run(recording))
    with pytest.raises(ValueError, match="not a dataset"):
        OnlineDiagnoser(_tiny_models()).fit([a, "b.csv"])


def test_the_envelope_onset_check_holds_the_check_of_the_pre_detection_average():
    envelope = InputEnvelope.from_bounds(np.zeros(4), np.full(4, 0.4))
    dd = np.array([0, 0, 0, 1, 1, 1, 0, 0, 1, 1], dtype=bool)
    inside = np.full((10, 4), 0.2)
    inside[3:6, 3] = 0.9  # the fault itself moves T1 far out at the detection: not novel
    np.testing.assert_array_equal(envelope.run(inside, dd)[0], False)
    np.testing.assert_array_equal(
        envelope.outside(inside), (np.arange(10) >= 3) & (np.arange(10) < 6)
    )
    outside = np.full((10, 4), 0.2)
    outside[:, 3] = 0.5  # T1 outside the envelope from the start: every detection is novel
    got, end = envelope.run(outside, dd)
    np.testing.assert_array_equal(got, dd)
    # continued in two chunks, or second by second, from the state: the same
    first, state = envelope.run(outside[:4], dd[:4])
    np.testing.assert_array_equal(
        np.concatenate([first, envelope.run(outside[4:], dd[4:], state)[0]]), got
    )
    state, stepwise = envelope.init_state(), []
    for t in range(10):
        novel, state = envelope.update(outside[t], dd[t], state)
        stepwise.append(novel)
    np.testing.assert_array_equal(stepwise, got)
    np.testing.assert_array_equal(state.average, end.average)


def test_a_detection_outside_the_training_envelope_is_dazzled(fitted, recording):
    shifted = recording.isel(run=[1]).copy()
    shifted["T1"] = shifted["T1"] + 0.3  # another plant temperature than in every training run
    s = fitted.run(shifted)
    dd = s["DD"].values[0]
    status = s["status"].values[0].astype(str)
    ok = np.isfinite(shifted["X"].values[0])
    assert dd.any()
    assert set(status[ok]) == {"DAZZLED"}  # never BLURRED: the normal models extrapolate
    fitted.reset()
    records = [fitted.update({c: float(shifted[c].values[0, t]) for c in CHANNELS})
               for t in range(shifted.sizes["time"])]  # fmt: skip
    first = int(np.flatnonzero(dd)[0])
    assert records[first].reasons[0].startswith("model mismatch: commission this valve")
    # a mismatch names no fault and indicates no group
    assert set(s["state"].values[0][dd].astype(str)) == {"mismatch"}
    assert not s["indicated"].values[0][dd].any()
    assert np.isnan(s["probability"].values[0][dd]).all()


def test_a_detection_from_the_first_second_is_judged_on_its_inputs(fitted, recording):
    """The default model on a plant it never saw alarms at once: with no second without
    detection to average, the first second's inputs decide whether the model fits."""
    from bayes_fdi.diagnosis.online.envelope import InputEnvelope

    envelope = InputEnvelope.from_bounds([0, 0, 0, 0], [1, 0.5, 0.5, 0.5])
    inputs = np.full((5, 4), 0.2)
    inputs[:, 3] = 0.7  # T1 above the envelope from the start
    novel, _ = envelope.run(inputs, np.ones(5, dtype=bool))
    assert novel.all()
    inside, _ = envelope.run(np.full((5, 4), 0.2), np.ones(5, dtype=bool))
    assert not inside.any()


def test_evidence_names_the_residual_that_raised_the_detection_and_its_sign(fitted, recording):
    s = fitted.run(recording)
    dd = s["DD"].values
    ev = s["evidence"].values.astype(str)
    assert (ev[~dd] == "").all() and (ev[dd] != "").all()
    # f1 (valve clogging) holds the stem below its command: X reads low; f18 (bypass open)
    # adds flow: F reads high
    onset = {1: 100, 2: 120}
    for run, word in ((1, "X low"), (2, "F high")):
        after = dd[run] & (s["time"].values >= onset[run] + 30)
        values, counts = np.unique(ev[run][after], return_counts=True)
        assert word in values[np.argmax(counts)], (run, dict(zip(values, counts, strict=True)))


def test_settings_that_are_not_real_numbers_or_out_of_range_are_refused_by_name():
    from bayes_fdi.diagnosis.online.checks import NUMERIC_SETTINGS, check_settings

    params = OnlineDiagnoser().get_params()
    assert set(NUMERIC_SETTINGS) == {
        "false_alarm_hours", "cusum_k", "glr_window", "p_fault", "novelty_ratio", "coverage",
        "detect_rate", "input_margin", "max_signatures_per_fault", "fit_proof_seconds",
    }  # fmt: skip
    check_settings(params)  # the defaults pass
    assert check_settings(dict(params, detect_rate=np.float64(0.25), glr_window=30)) is None
    for name in NUMERIC_SETTINGS:
        for bad in (True, "0.5", None):
            with pytest.raises(ValueError, match=f"{name} must be a real number, got {bad!r}"):
                check_settings(dict(params, **{name: bad}))
    for name, bad in [("detect_rate", 1.5), ("detect_rate", float("nan")), ("p_fault", -0.1),
                      ("coverage", 1.0), ("false_alarm_hours", 0.0), ("glr_window", 2.5),
                      ("max_signatures_per_fault", 1), ("fit_proof_seconds", 2.5),
                      ("fit_proof_seconds", -1)]:  # fmt: skip
        with pytest.raises(ValueError, match=f"{name} is out of range"):
            check_settings(dict(params, **{name: bad}))
    # a fit refuses them too, before fitting anything
    with pytest.raises(ValueError, match="detect_rate must be a real number"):
        OnlineDiagnoser(detect_rate=True).fit(None)

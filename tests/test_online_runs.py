"""Many runs at once: each online component's ``run_stacked`` equals its ``run`` run by run, and
``OnlineDiagnoser.run`` over one second of many runs equals ``update`` of each run, bit for bit,
reasons included (what ``serve`` does every second for the valves of one model)."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from small_online import small_fault_runs, small_normal_models, small_normal_runs

from bayes_fdi.actuator import Fault, benchmark_inputs, simulate
from bayes_fdi.diagnosis import OnlineDiagnoser
from bayes_fdi.diagnosis.component_state import stack_states
from bayes_fdi.diagnosis.detection import GLR
from bayes_fdi.diagnosis.isolation.signatures import SignatureInputs
from bayes_fdi.diagnosis.online.records import stream_reasons

CHANNELS = ("CV", "P1", "P2", "T1", "X", "F")
RUNS, WARM, SECONDS = 4, 9, 6


@pytest.fixture(scope="module")
def fitted():
    from bayes_fdi.calibration import TemperatureScaler

    diag = OnlineDiagnoser(
        small_normal_models(), calibrator=TemperatureScaler(), max_signatures_per_fault=20
    )
    return diag.fit(small_normal_runs(), small_fault_runs())


def _leaves(state, prefix="state"):
    if isinstance(state, tuple):
        out = {}
        for name, value in zip(state._fields, state, strict=True):
            out.update(_leaves(value, f"{prefix}.{name}"))
        return out
    return {prefix: np.asarray(state)}


def _assert_states_equal(stacked, per_run):
    want = _leaves(stack_states(per_run))
    got = _leaves(stacked)
    assert got.keys() == want.keys()
    for path, value in got.items():
        np.testing.assert_array_equal(value, want[path], err_msg=path)


def _series(rng, scale=1.0, nan=0.15, shape=(RUNS, WARM + SECONDS)):
    x = rng.normal(0.0, scale, shape)
    x[rng.random(shape) < nan] = np.nan  # gaps
    return x


def _check_component(run_one, run_stacked, fresh, inputs_of):
    """Each run warmed up alone to its own state, then the next seconds of every run at once
    against each run alone (outputs and states)."""
    states = [run_one(inputs_of(r, slice(0, WARM)), fresh)[1] for r in range(RUNS)]
    alone = [run_one(inputs_of(r, slice(WARM, None)), states[r]) for r in range(RUNS)]
    together, state = run_stacked(inputs_of(slice(None), slice(WARM, None)), stack_states(states))
    for r in range(RUNS):
        want = alone[r][0]
        if isinstance(want, tuple):  # a DetectorOutput
            for name, got in zip(want._fields, together, strict=True):
                np.testing.assert_array_equal(got[r], getattr(want, name), err_msg=name)
        else:
            np.testing.assert_array_equal(together[r], want)
    _assert_states_equal(state, [a[1] for a in alone])


def test_each_component_run_stacked_equals_its_run_run_by_run(fitted):
    rng = np.random.default_rng(11)
    z = _series(rng)
    check = _check_component
    whitener = fitted.whiteners_["X"]
    check(whitener.run, whitener.run_stacked, whitener.init_state(), lambda r, t: z[r, t])
    for detector in (fitted.detector_, GLR(window=5, threshold=3.0)):
        check(detector.run, detector.run_stacked, detector.init_state(), lambda r, t: z[r, t])
    stats = np.abs(np.stack([_series(rng, 4.0), _series(rng, 4.0)], axis=-1))
    decision = fitted.decision_
    check(decision.run, decision.run_stacked, decision.init_state(), lambda r, t: stats[r, t])
    rec = simulate(benchmark_inputs(RUNS, WARM + SECONDS, seed=5, vary=True), seed=5)
    channels = {c: rec[c].values.copy() for c in CHANNELS}
    channels["P1"][1, 3] = channels["CV"][2, 11] = np.nan
    models = fitted.normal_models_
    check(models.run, models.run_stacked, models.init_state(),
          lambda r, t: {c: v[r, t] for c, v in channels.items()})  # fmt: skip
    dd = rng.random((RUNS, WARM + SECONDS)) < 0.6
    window = SignatureInputs(dd, *(_series(rng, nan=0.05) for _ in range(8)))
    signature = fitted.signature_
    check(signature.run, signature.run_stacked, signature.init_state(),
          lambda r, t: SignatureInputs(*(v[r, t] for v in window)))  # fmt: skip
    inputs = rng.uniform(-0.2, 1.2, (RUNS, WARM + SECONDS, 4))
    envelope = fitted.envelope_

    def envelope_run(x, state):
        return envelope.run(x[0], x[1], state)

    def envelope_stacked(x, state):
        return envelope.run_stacked(x[0], x[1], state)

    check(envelope_run, envelope_stacked, envelope.init_state(),
          lambda r, t: (inputs[r, t], dd[r, t]))  # fmt: skip


def test_a_stacked_state_of_another_layout_is_refused(fitted):
    whitener = fitted.whiteners_["X"]
    state = stack_states([whitener.init_state()] * 3)
    with pytest.raises(ValueError, match=r"shape \(2, \d+\) \(2 run\(s\)\), got float64 \(3"):
        whitener.run_stacked(np.zeros((2, 5)), state)
    with pytest.raises(ValueError, match="expected \\(runs, n\\)"):
        whitener.run_stacked(np.zeros(5), state)


def _recording():
    specs = [None, Fault("f1", 0.7, 40.0), Fault("f18", 0.8, 30.0), None, Fault("f7", 0.8, 35.0)]
    rec = simulate(benchmark_inputs(len(specs), 120, seed=6, vary=True), specs, seed=6)
    rec = rec.drop_vars([c for c in rec.coords if c not in ("run", "time")])
    x, cv = rec["X"].values.copy(), rec["CV"].values.copy()
    x[1, 60:64] = np.nan  # BLIND seconds during a detection
    x[3, 10] = np.nan
    cv[3, 70:90] = 1.0 + 0.5 * (cv[3, 70:90] - cv[3, 70:90].min())  # inputs outside the envelope
    return rec.assign(X=(("run", "time"), x), CV=(("run", "time"), cv))


def test_run_over_one_second_of_many_runs_equals_update_of_each(fitted):
    rec = _recording()
    n_runs, n_t = rec.sizes["run"], rec.sizes["time"]
    updates = {name: np.empty((n_runs, n_t), dtype=object) for name in ("record", "last")}
    end_states = []
    for r in range(n_runs):
        fitted.reset()
        for t in range(n_t):
            sample = {c: float(rec[c].values[r, t]) for c in CHANNELS}
            updates["record"][r, t] = fitted.update({**sample, "time": float(t)})
            updates["last"][r, t] = dict(fitted.last_)
        end_states.append(fitted.stream_state().run(0))
    state, seconds = None, []
    for t in range(n_t):
        stream, state = fitted.run(rec.isel(time=[t]), state=state, return_state=True)
        seconds.append(stream.assign(reason=(("run", "time"), stream_reasons(stream))))
    s = xr.concat(seconds, dim="time")
    rec_of = updates["record"]

    def column(get):
        return np.array([[get(rec_of[r, t]) for t in range(n_t)] for r in range(n_runs)])

    np.testing.assert_array_equal(column(lambda x: x.status.value), s["status"].values)
    np.testing.assert_array_equal(column(lambda x: x.state), s["state"].values)
    np.testing.assert_array_equal(column(lambda x: "; ".join(x.reasons)), s["reason"].values)
    pairs = (("probability", "probability"), ("VMV_X", "x_vmv"), ("VU_X", "x_vu"),
             ("VMV_F", "f_vmv"), ("VU_F", "f_vu"), ("novelty", "feature_novelty"))  # fmt: skip
    for name, attr in pairs:
        np.testing.assert_array_equal(column(lambda x, a=attr: getattr(x, a)), s[name].values)
    last = updates["last"]
    for key in ("DD", "FFID", "stat_X", "stat_F", "r_X", "r_F"):
        want = np.array([[last[r, t][key] for t in range(n_t)] for r in range(n_runs)])
        np.testing.assert_array_equal(want, s[key].values, err_msg=key)
    want = np.array([[last[r, t]["group_proba"] for t in range(n_t)] for r in range(n_runs)])
    np.testing.assert_array_equal(want, s["group_proba"].values)
    # the stream went through every case of the reasons
    statuses = set(s["status"].values.ravel())
    assert {"CLEAR", "BLIND", "DAZZLED", "BLURRED"} <= statuses, statuses
    assert s["novel_inputs"].values.any() and s["DD"].values.any()
    _assert_states_equal(state, end_states)  # and the state after the last second

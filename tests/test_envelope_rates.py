"""The input envelope's dynamics check (`InputEnvelope` rates) and model files saved before it.

The envelope learns the largest mean absolute one-second increment of CV and P1 in training;
a command moving faster (a held-out fast sine) reads DAZZLED, and a detection that begins while
it does is a model mismatch, never a named fault. Files of model-file format 3 (written by
``tests/data/model_files_format3/make_fixtures.py`` before the rates existed) load with no rate
check and give the stream they gave.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from bayes_fdi import model_files
from bayes_fdi.actuator import benchmark_inputs, simulate
from bayes_fdi.datasets import make_dataset
from bayes_fdi.diagnosis import OnlineDiagnoser
from bayes_fdi.diagnosis.normal_models.dynamic import DynamicNormalModels
from bayes_fdi.diagnosis.online.envelope import RATE_SECONDS, InputEnvelope

FORMAT3 = Path(__file__).parent / "data" / "model_files_format3"
CHANNELS = ("CV", "P1", "P2", "T1", "X", "F")


def _inputs(cv: np.ndarray, p1: float = 0.8) -> xr.Dataset:
    """Inputs with the given CV rows and constant P1, P2, T1."""
    cv = np.atleast_2d(cv)
    const = np.ones_like(cv)
    return make_dataset({"CV": cv, "P1": p1 * const, "P2": 0.6 * const, "T1": 0.2 * const},
                        state="fn", campaign="test")  # fmt: skip


def _sine(frequency: float, amplitude: float, n: int = 900) -> np.ndarray:
    return 0.5 + amplitude * np.sin(2 * np.pi * frequency * np.arange(n))


def test_the_rate_bound_is_the_largest_average_increment_of_training_widened():
    # a ramp of constant slope d: the average of |increments| converges to d, after the run's
    # first rate_seconds it is d (1 - (1 - 1/tau)^(t - 1)), largest at the run's end
    d, n = 0.004, 200
    ramp = 0.2 + d * np.arange(n)
    envelope = InputEnvelope(rate_margin=0.5).fit(_inputs(ramp))
    tau = RATE_SECONDS
    closed_form = d * (1.0 - (1.0 - 1.0 / tau) ** (n - 1))
    assert envelope.rate_high_[0] == pytest.approx(1.5 * closed_form, rel=1e-12)
    assert envelope.rate_high_[1] == pytest.approx(0.003)  # P1 constant: the floor


def test_a_held_out_fast_sine_is_flagged_and_training_like_inputs_are_not():
    # trained on DGen's sines (CV 0.01 Hz, amplitude 0.25 +- 20 %, P1 0.1 Hz)
    envelope = InputEnvelope().fit(benchmark_inputs(8, 900, seed=1, vary=True))
    # the mean |increment| of a sine A sin(2 pi f t) sampled at 1 Hz is (4 / pi) A sin(pi f):
    # DGen's largest CV sine gives 0.0113, which the bound must hold
    assert envelope.rate_high_[0] >= 4 / math.pi * 0.3 * math.sin(math.pi * 0.01)
    held_out = benchmark_inputs(4, 900, seed=77, vary=True)
    x = np.stack([held_out[c].values for c in ("CV", "P1", "P2", "T1")], axis=-1)
    dd = np.zeros(x.shape[:2], dtype=bool)
    state = envelope.init_state()
    for run in range(4):
        _, fast, _ = envelope.run_flags(x[run], dd[run])
        assert not fast.any()
    # CV at 0.05 Hz, same amplitude: (4 / pi) 0.25 sin(0.05 pi) = 0.0498 per second
    fast_sine = _inputs(_sine(0.05, 0.25))
    x = np.stack([fast_sine[c].values[0] for c in ("CV", "P1", "P2", "T1")], axis=-1)
    novel, fast, state = envelope.run_flags(x, np.zeros(900, dtype=bool))
    assert not novel.any()  # no detection, no onset flag
    assert fast[int(3 * RATE_SECONDS) :].all()  # flagged once the average has risen
    assert 0.045 < state.rate[0] < 0.055
    # a detection beginning while the command moves that fast began outside the envelope
    dd = np.zeros(900, dtype=bool)
    dd[500:520] = True
    novel, _, _ = envelope.run_flags(x, dd)
    np.testing.assert_array_equal(novel, dd)


def test_the_rates_carry_across_chunks_and_seconds():
    envelope = InputEnvelope().fit(_inputs(_sine(0.01, 0.25)))
    cv = _sine(0.04, 0.3, 300)
    x = np.stack([cv, np.full(300, 0.8), np.full(300, 0.6), np.full(300, 0.2)], axis=-1)
    dd = (np.arange(300) % 97) > 80
    whole, fast, end = envelope.run_flags(x, dd)
    first, fast_a, state = envelope.run_flags(x[:130], dd[:130])
    second, fast_b, state = envelope.run_flags(x[130:], dd[130:], state)
    np.testing.assert_array_equal(np.concatenate([first, second]), whole)
    np.testing.assert_array_equal(np.concatenate([fast_a, fast_b]), fast)
    np.testing.assert_array_equal(state.rate, end.rate)
    stacked, fast_s, _ = envelope.run_stacked_flags(
        np.stack([x, x]), np.stack([dd, dd]), _stacked(envelope, 2)
    )
    np.testing.assert_array_equal(stacked, [whole, whole])
    np.testing.assert_array_equal(fast_s, [fast, fast])


def _stacked(envelope, n):
    from bayes_fdi.diagnosis.component_state import stack_states

    return stack_states([envelope.init_state()] * n)


def test_a_command_faster_than_in_training_reads_dazzled_and_names_no_fault():
    normal = simulate(benchmark_inputs(4, 400, seed=1, vary=True), seed=1)
    models = DynamicNormalModels(
        x_widths=(8.0,), f_widths=(0.1,), evidence_max_samples=200, max_train_samples=300,
        calibration_folds=2, random_state=0,
    )  # fmt: skip
    diagnoser = OnlineDiagnoser(models).fit(normal)
    drive = benchmark_inputs(1, 400, seed=5)
    cv = drive["CV"].values.copy()
    cv[0, 200:] = _sine(0.08, 0.25, 200)  # the command speeds up from 200 s
    fast = simulate(drive.assign(CV=(("run", "time"), cv)), seed=5)
    stream = diagnoser.run(fast).isel(run=0)
    status = stream["status"].values.astype(str)
    late = np.arange(400) >= 200 + 3 * RATE_SECONDS
    assert (status[late] == "DAZZLED").all()
    assert (status[:200] == "CLEAR").mean() > 0.9  # before, the inputs are DGen's
    onsets = np.flatnonzero(np.diff(stream["DD"].values.astype(int)) == 1) + 1
    state = stream["state"].values.astype(str)
    assert all(state[t] == "mismatch" for t in onsets if t >= 200 + 3 * RATE_SECONDS)


def test_a_format_3_file_loads_without_rate_check_and_gives_its_stream():
    assert model_files.read_metadata(FORMAT3 / "online.npz")["format_version"] == 3
    model = OnlineDiagnoser.load(FORMAT3 / "online.npz")
    assert np.isinf(model.envelope_.rate_high_).all()
    import importlib.util

    spec = importlib.util.spec_from_file_location("make3", FORMAT3 / "make_fixtures.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    recording = module.online_recording()
    expected = xr.load_dataset(FORMAT3 / "online.expected.nc")
    stream = model.run(recording)[list(module.KEPT)]
    stream.attrs = {}
    xr.testing.assert_identical(stream.reset_coords(drop=True), expected.reset_coords(drop=True))
    # saved after 30 s of run 1 through `update`: the stream continues from its saved state
    loaded = OnlineDiagnoser.load(FORMAT3 / "online.npz")
    for t in range(30, 60):
        record = loaded.update({c: float(recording[c].values[1, t]) for c in CHANNELS})
        assert record.status.value == str(expected["status"].values[1, t])

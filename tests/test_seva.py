"""Tests of the SEVA output (bayes_fdi.diagnosis.seva.windows) on constructed diagnoses."""

from __future__ import annotations

import dataclasses
import json
import pickle

import numpy as np
import pytest
import xarray as xr

from bayes_fdi.datasets import make_dataset
from bayes_fdi.diagnosis.seva.novelty import NoveltyReference
from bayes_fdi.diagnosis.seva.record import (
    ClassDistribution,
    SevaRecord,
    SevaStatus,
    to_frame,
    to_json,
    to_xarray,
)
from bayes_fdi.diagnosis.seva.rules import SevaThresholds, screen_measurements
from bayes_fdi.diagnosis.seva.windows import records_from_diagnosis, seva_records

CLASSES = ["fn", "f1", "f2", "f3"]
T = 200


def _runs(rng, n_runs, *, cv_offset=0.0):
    t = np.arange(T)
    cv = 0.5 + 0.3 * np.sin(2 * np.pi * t / 60 + rng.uniform(0, 6, size=(n_runs, 1))) + cv_offset
    ch = {
        "CV": cv,
        "P1": 0.8 + 0.01 * rng.normal(size=(n_runs, T)),
        "P2": 0.6 + 0.01 * rng.normal(size=(n_runs, T)),
        "T1": 0.5 + 0.005 * rng.normal(size=(n_runs, T)),
        "X": cv + 0.002 * rng.normal(size=(n_runs, T)),
        "F": 0.4 + 0.2 * cv + 0.002 * rng.normal(size=(n_runs, T)),
    }
    return ch


def _diagnosis(runs: xr.Dataset, proba, x_std=0.01, f_std=0.02):
    proba = np.asarray(proba, dtype=float)
    n = runs.sizes["run"]
    k = proba.argmax(axis=1)
    return xr.Dataset(
        {
            "state": ("run", np.array(CLASSES)[k]),
            "proba": (("run", "class"), proba),
            "confidence": ("run", proba.max(axis=1)),
            "X_hat": (("run", "time"), runs["X"].values + 0.001),
            "X_hat_std": (("run", "time"), np.full((n, runs.sizes["time"]), x_std)),
            "F_hat": (("run", "time"), runs["F"].values - 0.002),
            "F_hat_std": (("run", "time"), np.full((n, runs.sizes["time"]), f_std)),
            "features": (("run", "feature"), np.zeros((n, 2))),
        },
        coords={"run": runs["run"].values, "class": CLASSES, "time": runs["time"].values},
    )


CONFIDENT_FN = [0.97, 0.01, 0.01, 0.01]
CONFIDENT_F2 = [0.02, 0.03, 0.93, 0.02]
FLAT = [0.28, 0.24, 0.25, 0.23]


def test_status_of_each_constructed_case(rng):
    ch = _runs(rng, 6)
    ch["X"][0, 50:120] = np.nan  # 35 % missing -> BLIND
    ch["P1"][1, 20:150] = 1.0  # input at the upper rail in 65 % of samples -> BLIND
    runs = _make(ch)
    proba = [CONFIDENT_FN, CONFIDENT_F2, CONFIDENT_FN, CONFIDENT_F2, FLAT, [0.6, 0.3, 0.05, 0.05]]
    recs = records_from_diagnosis(_diagnosis(runs, proba), runs)
    got = [r.status for r in recs]
    assert got == [
        SevaStatus.BLIND,
        SevaStatus.BLIND,
        SevaStatus.CLEAR,
        SevaStatus.BLURRED,
        SevaStatus.DAZZLED,
        SevaStatus.DAZZLED,
    ]
    assert any("X missing in 35%" in s for s in recs[0].reasons)
    assert any("P1 saturated in 65%" in s for s in recs[1].reasons)
    assert recs[0].missing_fraction == pytest.approx(0.35)
    assert recs[1].saturated_fraction == pytest.approx(0.65)
    assert recs[3].state == "f2" and recs[3].probability == pytest.approx(0.93)
    assert any("too flat" in s for s in recs[4].reasons)
    assert any("p_clear" in s for s in recs[5].reasons)  # P(fn)=0.6: not confidently clear
    # entropy is normalised Shannon entropy: uniform -> 1, the FLAT one close to it
    p = np.array(FLAT)
    assert recs[4].entropy == pytest.approx(-(p * np.log(p)).sum() / np.log(4))
    assert recs[4].entropy > 0.99


def _make(ch):
    # make_dataset validates finite values only where it must; NaN gaps are real plant data
    runs = xr.Dataset(
        {k: (("run", "time"), v) for k, v in ch.items()},
        coords={"run": np.arange(ch["X"].shape[0]), "time": np.arange(T, dtype=float)},
    )
    return runs


def test_thresholds_are_parameters(rng):
    runs = make_dataset(_runs(rng, 1))
    diag = _diagnosis(runs, [[0.85, 0.05, 0.05, 0.05]])
    assert records_from_diagnosis(diag, runs)[0].status is SevaStatus.DAZZLED
    th = SevaThresholds(p_clear=0.8)
    assert records_from_diagnosis(diag, runs, thresholds=th)[0].status is SevaStatus.CLEAR
    # lowering the fault threshold lets the entropy rule bind
    diag = _diagnosis(runs, [[0.1, 0.3, 0.45, 0.15]])
    th = SevaThresholds(p_fault=0.4, max_entropy=0.5)
    rec = records_from_diagnosis(diag, runs, thresholds=th)[0]
    assert rec.status is SevaStatus.DAZZLED and rec.entropy > 0.5
    th = th._replace(max_entropy=0.95)
    assert records_from_diagnosis(diag, runs, thresholds=th)[0].status is SevaStatus.BLURRED
    with pytest.raises(ValueError, match="p_clear"):
        records_from_diagnosis(diag, runs, thresholds=SevaThresholds(p_clear=1.5))


def test_out_of_distribution_inputs_are_dazzled(rng):
    train = make_dataset(_runs(rng, 8))
    ref = NoveltyReference.from_runs(train)
    test_in = make_dataset(_runs(rng, 2))
    test_out = make_dataset(_runs(rng, 2, cv_offset=0.0) | {"P1": np.full((2, T), 0.3)})
    runs = xr.concat([test_in, test_out], dim="run").assign_coords(run=np.arange(4))
    diag = _diagnosis(runs, [CONFIDENT_FN, CONFIDENT_F2, CONFIDENT_FN, CONFIDENT_F2])
    recs = records_from_diagnosis(diag, runs, input_reference=ref)
    assert [r.status for r in recs] == [
        SevaStatus.CLEAR,
        SevaStatus.BLURRED,
        SevaStatus.DAZZLED,
        SevaStatus.DAZZLED,
    ]
    assert recs[0].novel_fraction < 0.1
    assert recs[2].novel_fraction == pytest.approx(1.0)
    assert any("inputs unlike training" in s for s in recs[2].reasons)
    # without a reference, the record says the check was not made
    recs = records_from_diagnosis(diag, runs)
    assert any("not checked" in s for s in recs[2].reasons)
    assert np.isnan(recs[2].novel_fraction)


def test_feature_novelty_is_dazzled(rng):
    runs = make_dataset(_runs(rng, 2))
    feat_train = rng.normal(size=(500, 2))
    ref = NoveltyReference().fit(feat_train)
    diag = _diagnosis(runs, [CONFIDENT_F2, CONFIDENT_F2])
    diag["features"] = (("run", "feature"), np.array([[0.1, -0.2], [9.0, 9.0]]))
    recs = records_from_diagnosis(diag, runs, feature_reference=ref)
    assert recs[0].status is SevaStatus.BLURRED and recs[0].feature_novelty < 1
    assert recs[1].status is SevaStatus.DAZZLED and recs[1].feature_novelty > 5


def test_novelty_reference_rate_on_same_distribution(rng):
    ref = NoveltyReference(quantile=0.95).fit(rng.normal(size=(4000, 3)))
    s = ref.score(rng.normal(size=(4000, 3)))
    # nearest-neighbour distances of fresh draws are distributed like leave-one-out ones
    assert np.mean(s > 1) == pytest.approx(0.05, abs=0.02)
    assert ref.score(np.array([[6.0, 6.0, 6.0]]))[0] > 10
    with pytest.raises(ValueError, match="NaN"):
        ref.score(np.array([[np.nan, 0.0, 0.0]]))
    with pytest.raises(ValueError, match="not fitted"):
        NoveltyReference().score(np.zeros((1, 3)))


def test_validated_values_and_uncertainty(rng):
    runs = make_dataset(_runs(rng, 1))
    diag = _diagnosis(runs, [CONFIDENT_FN], x_std=0.01, f_std=0.02)
    r95 = records_from_diagnosis(diag, runs)[0]
    r68 = records_from_diagnosis(diag, runs, coverage=0.6826894921370859)[0]
    assert r95.x_vu == pytest.approx(1.959964 * 0.01, rel=1e-6)
    assert r95.f_vu == pytest.approx(1.959964 * 0.02, rel=1e-6)
    assert r68.x_vu == pytest.approx(0.01, rel=1e-6)  # one sigma
    assert r95.x_measured == pytest.approx(runs["X"].values.mean())
    assert r95.x_vmv == pytest.approx(runs["X"].values.mean() + 0.001)
    assert r95.f_vmv == pytest.approx(runs["F"].values.mean() - 0.002)
    assert (r95.t_start, r95.t_end) == (0.0, T - 1.0)
    # VU at its coverage does contain that share of Gaussian measurements around the VMV
    y = r95.x_vmv + 0.01 * rng.normal(size=100_000)
    assert np.mean(np.abs(y - r95.x_vmv) <= r95.x_vu) == pytest.approx(0.95, abs=0.003)


def test_record_is_immutable_and_converts(rng):
    ch = _runs(rng, 3)
    ch["P2"][2, :] = np.nan
    runs = _make(ch)
    diag = _diagnosis(runs, [CONFIDENT_FN, CONFIDENT_F2, FLAT])
    recs = records_from_diagnosis(diag, runs)
    with pytest.raises(dataclasses.FrozenInstanceError):
        recs[0].status = SevaStatus.BLIND  # type: ignore[misc]
    # (NaN fields compare unequal, so compare the JSON forms)
    assert to_json([pickle.loads(pickle.dumps(recs[1]))]) == to_json([recs[1]])
    assert isinstance(recs[1].distribution, ClassDistribution)
    assert dict(recs[1].distribution) == dict(zip(CLASSES, CONFIDENT_F2, strict=True))
    with pytest.raises(TypeError):
        recs[1].distribution["fn"] = 1.0  # type: ignore[index]

    df = to_frame(recs)
    assert list(df.index) == [0, 1, 2]
    assert list(df["status"]) == ["CLEAR", "BLURRED", "BLIND"]
    np.testing.assert_allclose(df.loc[1, [f"p_{c}" for c in CLASSES]].to_numpy(float), CONFIDENT_F2)

    ds = to_xarray(recs)
    assert ds["proba"].dims == ("run", "class")
    np.testing.assert_allclose(ds["proba"].sel(run=0).values, CONFIDENT_FN)
    assert list(ds["status"].values) == ["CLEAR", "BLURRED", "BLIND"]

    back = json.loads(to_json(recs))
    assert [b["status"] for b in back] == ["CLEAR", "BLURRED", "BLIND"]
    assert back[1]["distribution"] == dict(zip(CLASSES, CONFIDENT_F2, strict=True))
    assert back[2]["reasons"][0].startswith("P2 missing in 100%")
    assert back[0]["novel_fraction"] is None  # NaN -> null, valid JSON
    assert SevaRecord.__dataclass_fields__.keys() >= {"x_vmv", "x_vu", "status", "distribution"}


class _FakeDiagnoser:
    """Contract-conforming stand-in: diagnoses fault-free runs as 'fn', others as 'f2'."""

    def __init__(self):
        self.seen = []

    def diagnose(self, runs):
        if any(np.isnan(runs[c].values).any() for c in ("CV", "P1", "P2", "T1", "X", "F")):
            raise ValueError("NaN in inputs")
        self.seen.append(runs["run"].values.tolist())
        p = np.array([CONFIDENT_FN if s == "fn" else CONFIDENT_F2 for s in runs["state"].values])
        return _diagnosis(runs, p)


def test_seva_records_skips_blind_runs(rng):
    ch = _runs(rng, 3)
    ch["CV"][1, :100] = np.nan
    runs = _make(ch).assign_coords(state=("run", ["fn", "f2", "f2"]))
    fake = _FakeDiagnoser()
    recs = seva_records(fake, runs)
    assert fake.seen == [[0, 2]]
    assert [r.status for r in recs] == [SevaStatus.CLEAR, SevaStatus.BLIND, SevaStatus.BLURRED]
    assert recs[1].state == "" and len(recs[1].distribution) == 0
    assert np.isnan(recs[1].x_vmv)
    scr = screen_measurements(runs)
    assert scr["blind"].tolist() == [False, True, False]
    np.testing.assert_allclose(scr["missing"][1], [0.5, 0, 0, 0, 0, 0])


def test_mismatched_runs_are_rejected(rng):
    runs = make_dataset(_runs(rng, 2))
    diag = _diagnosis(runs.isel(run=[0]), [CONFIDENT_FN])
    with pytest.raises(ValueError, match="same runs"):
        records_from_diagnosis(diag, runs)
    with pytest.raises(ValueError, match="coverage"):
        records_from_diagnosis(_diagnosis(runs, [FLAT, FLAT]), runs, coverage=1.0)


def _windowed_diagnosis(runs, proba_rw, width):
    """Windowed contract: proba (run, window, class), window_start/window_end (end exclusive)."""
    d = _diagnosis(runs, np.asarray(proba_rw)[:, 0])
    n_win = np.asarray(proba_rw).shape[1]
    starts = np.arange(n_win) * width
    d = d.drop_vars(["proba", "state", "confidence", "features"])
    d["proba"] = (("run", "window", "class"), np.asarray(proba_rw, dtype=float))
    return d.assign_coords(
        window_start=("window", starts.astype(float)),
        window_end=("window", (starts + width).astype(float)),
    )


def test_windowed_records(rng):
    ch = _runs(rng, 2)
    ch["F"][1, 100:150] = np.nan  # run 1, window 1 (100..199): 50 % missing -> BLIND
    runs = _make(ch)
    diag = _windowed_diagnosis(
        runs, [[CONFIDENT_FN, CONFIDENT_F2], [CONFIDENT_FN, CONFIDENT_FN]], width=100
    )
    recs = records_from_diagnosis(diag, runs)
    assert [(r.run, r.window) for r in recs] == [(0, 0), (0, 1), (1, 0), (1, 1)]
    assert [r.status for r in recs] == [
        SevaStatus.CLEAR,
        SevaStatus.BLURRED,
        SevaStatus.CLEAR,
        SevaStatus.BLIND,
    ]
    assert (recs[1].t_start, recs[1].t_end) == (100.0, 199.0)
    assert recs[1].x_measured == pytest.approx(ch["X"][0, 100:200].mean())
    assert recs[3].missing_fraction == pytest.approx(0.5)
    assert recs[3].f_measured == pytest.approx(ch["F"][1, 150:200].mean())
    df = to_frame(recs)
    assert list(df.index) == [(0, 0), (0, 1), (1, 0), (1, 1)]
    ds = to_xarray(recs)
    assert ds["proba"].dims == ("record", "class")
    assert ds["window"].values.tolist() == [0, 1, 0, 1]


def test_seva_records_uses_training_features_for_feature_novelty(rng):
    runs = make_dataset(_runs(rng, 2), state=["fn", "f2"])
    fake = _FakeDiagnoser()
    fake.training_features_ = rng.normal(scale=0.1, size=(300, 2))
    recs = seva_records(fake, runs)
    # the fake's features are (0, 0), inside the training cloud
    assert all(r.feature_novelty < 1 for r in recs)
    fake.training_features_ = rng.normal(loc=5.0, scale=0.1, size=(300, 2))
    recs = seva_records(fake, runs)
    assert all(r.status is SevaStatus.DAZZLED and r.feature_novelty > 10 for r in recs)


def test_saturated_output_is_noted_and_blinds_only_when_asked(rng):
    ch = _runs(rng, 1)
    ch["F"][0, :150] = 1.0  # F at its rail 75 % of the time (as DABLib's F' under f18)
    runs = _make(ch)
    diag = _diagnosis(runs, [CONFIDENT_F2])
    rec = records_from_diagnosis(diag, runs)[0]
    assert rec.status is SevaStatus.BLURRED
    assert rec.saturated_fraction == pytest.approx(0.75)
    assert any("F at a rail in 75%" in s for s in rec.reasons)
    th = SevaThresholds(max_output_saturated=0.5)
    rec = records_from_diagnosis(diag, runs, thresholds=th)[0]
    assert rec.status is SevaStatus.BLIND
    assert rec.reasons == ("F saturated in 75% of samples",)


def test_calibrator_is_applied_before_the_rules(rng):
    from bayes_fdi.calibration import TemperatureScaler

    runs = make_dataset(_runs(rng, 2))
    under = [[0.7, 0.1, 0.1, 0.1], [0.1, 0.1, 0.7, 0.1]]
    diag = _diagnosis(runs, under)
    assert [r.status for r in records_from_diagnosis(diag, runs)] == [SevaStatus.DAZZLED] * 2
    # an under-confident model: labels drawn from softmax(2 * log p) -> fitted T ~ 0.5
    logits = rng.normal(size=(5000, 4))
    p = np.exp(logits) / np.exp(logits).sum(1, keepdims=True)
    sharp = p**2 / (p**2).sum(1, keepdims=True)
    y = (rng.random(5000)[:, None] > np.cumsum(sharp, 1)).sum(1).clip(max=3)
    ts = TemperatureScaler(classes=[0, 1, 2, 3]).fit(p, y)
    assert ts.temperature_ == pytest.approx(0.5, rel=0.1)
    recs = records_from_diagnosis(diag, runs, calibrator=ts)
    want = np.array(under[0]) ** (1 / ts.temperature_)
    assert recs[0].probability == pytest.approx(want[0] / want.sum())
    assert [r.status for r in recs] == [SevaStatus.CLEAR, SevaStatus.BLURRED]


def _windowed_fault_diagnoser(rng):
    """A small windowed FaultDiagnoser (kernel ridge normal models, logistic classifier)."""
    from sklearn.linear_model import LogisticRegression

    from bayes_fdi.diagnosis import FaultDiagnoser, KernelRidgeRegressor

    normal = make_dataset(_runs(rng, 4))
    ch = _runs(rng, 6)
    ch["X"][3:] += 0.05  # the faulty runs: a stem offset
    labelled = make_dataset(ch, state=["fn"] * 3 + ["f1"] * 3)
    return FaultDiagnoser(
        KernelRidgeRegressor(width=0.3),
        LogisticRegression(),
        window=25,
        width_search=None,
        interval_calibration=None,
    ).fit(normal, labelled)


def test_all_missing_window_is_blind_not_an_error(rng):
    diag = _windowed_fault_diagnoser(rng)
    ch = _runs(rng, 2)
    ch["X"][1, 25:50] = np.nan  # run 1, window 1: not one complete sample (12.5 % of the run)
    runs = _make(ch)
    with pytest.raises(ValueError, match="not finite"):
        diag.diagnose(runs)  # the whole batch would fail; SEVA must not
    recs = seva_records(diag, runs)
    assert [(r.run, r.window) for r in recs] == [(i, w) for i in range(2) for w in range(8)]
    assert recs[9].status is SevaStatus.BLIND
    assert recs[9].state == "" and len(recs[9].distribution) == 0
    assert "X missing in 100% of samples" in recs[9].reasons
    # every other window is diagnosed exactly as diagnose() does on gap-free data: a window
    # only sees its own samples (static models), so filling window 1 cannot change the others
    filled = ch["X"].copy()
    filled[1, 25:50] = ch["CV"][1, 25:50]
    ref = diag.diagnose(_make({**ch, "X": filled}))["proba"].values.reshape(16, -1)
    others = [k for k in range(16) if k != 9]
    got = np.array([[recs[k].distribution[c] for c in diag.classes_] for k in others])
    np.testing.assert_array_equal(got, ref[others])
    assert all(recs[k].status is not SevaStatus.BLIND for k in others)


def test_infinite_novelty_counts_as_novel(rng):
    ref = NoveltyReference().fit(rng.normal(size=(200, 2)))
    score = ref.score(np.array([[0.0, 0.0], [np.inf, 0.0], [0.0, -np.inf]]))
    assert score[0] < 1 and np.isinf(score[1:]).all()
    with pytest.raises(ValueError, match="NaN"):
        ref.score(np.array([[np.nan, 0.0]]))
    runs = make_dataset(_runs(rng, 2))
    diag = _diagnosis(runs, [CONFIDENT_F2, CONFIDENT_F2])
    diag["features"] = (("run", "feature"), np.array([[0.0, 0.0], [np.inf, 0.0]]))
    recs = records_from_diagnosis(diag, runs, feature_reference=ref)
    assert recs[0].status is SevaStatus.BLURRED
    assert recs[1].feature_novelty == np.inf  # infinitely remote, by construction
    assert recs[1].status is SevaStatus.DAZZLED
    assert any("unlike training" in s for s in recs[1].reasons)

"""Catalogue of bad data in the online SEVA output: an explicit status, never a failed batch.

Each entry builds a batch of runs (or windows) with one bad one and states the SEVA status that
record must get, while the good records of the same batch are still diagnosed. The last two
entries (a window with no complete sample, an infinite novelty score) failed before the online
work on `bayes_fdi.diagnosis.seva.windows`: the batch raised, and the record came out confident.
"""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from sklearn.linear_model import LogisticRegression

from bayes_fdi.datasets import make_dataset
from bayes_fdi.diagnosis import FaultDiagnoser, KernelRidgeRegressor
from bayes_fdi.diagnosis.seva.novelty import NoveltyReference
from bayes_fdi.diagnosis.seva.record import SevaStatus
from bayes_fdi.diagnosis.seva.windows import records_from_diagnosis, seva_records

CLASSES = ["fn", "f1", "f2", "f3"]
T = 200
CONFIDENT_FN = [0.97, 0.01, 0.01, 0.01]


def _channels(rng: np.random.Generator, n_runs: int) -> dict[str, np.ndarray]:
    t = np.arange(T)
    cv = 0.5 + 0.3 * np.sin(2 * np.pi * t / 60 + rng.uniform(0, 6, size=(n_runs, 1)))
    return {
        "CV": cv,
        "P1": 0.8 + 0.01 * rng.normal(size=(n_runs, T)),
        "P2": 0.6 + 0.01 * rng.normal(size=(n_runs, T)),
        "T1": 0.5 + 0.005 * rng.normal(size=(n_runs, T)),
        "X": cv + 0.002 * rng.normal(size=(n_runs, T)),
        "F": 0.4 + 0.2 * cv + 0.002 * rng.normal(size=(n_runs, T)),
    }


def _runs(ch: dict[str, np.ndarray]) -> xr.Dataset:
    """Runs as recorded (NaN gaps allowed: real plant data have them)."""
    n = next(iter(ch.values())).shape[0]
    return xr.Dataset(
        {k: (("run", "time"), v) for k, v in ch.items()},
        coords={"run": np.arange(n), "time": np.arange(T, dtype=float)},
    )


def _diagnosis(runs: xr.Dataset, proba: list, features: np.ndarray) -> xr.Dataset:
    proba = np.asarray(proba, dtype=float)
    n = runs.sizes["run"]
    return xr.Dataset(
        {
            "state": ("run", np.array(CLASSES)[proba.argmax(1)]),
            "proba": (("run", "class"), proba),
            "confidence": ("run", proba.max(1)),
            "X_hat": (("run", "time"), runs["X"].values),
            "X_hat_std": (("run", "time"), np.full((n, T), 0.01)),
            "F_hat": (("run", "time"), runs["F"].values),
            "F_hat_std": (("run", "time"), np.full((n, T), 0.02)),
            "features": (("run", "feature"), features),
        },
        coords={"run": runs["run"].values, "class": CLASSES, "time": runs["time"].values},
    )


def _statuses(rng, change, features=None, proba=None) -> list[SevaStatus]:
    """Statuses of a batch of three runs, run 1 changed by ``change(channels)``."""
    ch = _channels(rng, 3)
    change(ch)
    runs = _runs(ch)
    feats = np.zeros((3, 2)) if features is None else features
    ref = NoveltyReference().fit(rng.normal(size=(200, 2)))
    diag = _diagnosis(runs, proba or [CONFIDENT_FN] * 3, feats)
    return [r.status for r in records_from_diagnosis(diag, runs, feature_reference=ref)]


def _set(name: str, rows: slice, value: float):
    def change(ch):
        ch[name][1, rows] = value

    return change


SEVA_CASES = {
    "X missing in the whole run": (_set("X", slice(None), np.nan), None, SevaStatus.BLIND),
    "F missing in 40 % of the run": (_set("F", slice(0, 80), np.nan), None, SevaStatus.BLIND),
    "input P1 stuck at its upper rail": (_set("P1", slice(0, 150), 1.0), None, SevaStatus.BLIND),
    "CV infinite": (_set("CV", slice(0, 150), np.inf), None, SevaStatus.BLIND),
    "features far from training": (
        lambda ch: None,
        np.array([[0.0, 0.0], [1e6, -1e6], [0.0, 0.0]]),
        SevaStatus.DAZZLED,
    ),
}


@pytest.mark.parametrize("name", list(SEVA_CASES))
def test_bad_run_gets_an_explicit_status(name, rng):
    change, features, expected = SEVA_CASES[name]
    statuses = _statuses(rng, change, features)
    assert statuses[1] is expected
    assert statuses[0] is SevaStatus.CLEAR and statuses[2] is SevaStatus.CLEAR


def test_flat_distribution_is_dazzled(rng):
    flat = [0.28, 0.24, 0.25, 0.23]
    statuses = _statuses(rng, lambda ch: None, proba=[CONFIDENT_FN, flat, CONFIDENT_FN])
    assert statuses == [SevaStatus.CLEAR, SevaStatus.DAZZLED, SevaStatus.CLEAR]


def test_infinite_feature_novelty_is_dazzled(rng):
    features = np.array([[0.0, 0.0], [1e300, -1e300], [0.0, 0.0]])  # distance overflows to inf
    statuses = _statuses(rng, lambda ch: None, features)
    assert statuses[1] is SevaStatus.DAZZLED


def test_all_missing_window_is_blind_and_the_batch_is_diagnosed(rng):
    normal = make_dataset(_channels(rng, 4))
    ch = _channels(rng, 6)
    ch["X"][3:] += 0.05  # faulty runs: a stem offset
    labelled = make_dataset(ch, state=["fn"] * 3 + ["f1"] * 3)
    diagnoser = FaultDiagnoser(
        KernelRidgeRegressor(width=0.3),
        LogisticRegression(),
        window=25,
        width_search=None,
        interval_calibration=None,
    ).fit(normal, labelled)
    ch = _channels(rng, 2)
    ch["X"][1, 25:50] = np.nan  # run 1, window 1: no complete sample
    records = seva_records(diagnoser, _runs(ch))
    assert len(records) == 16
    assert records[9].status is SevaStatus.BLIND
    assert all(r.status is not SevaStatus.BLIND for k, r in enumerate(records) if k != 9)

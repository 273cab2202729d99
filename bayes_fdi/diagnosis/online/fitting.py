"""Fitting the online diagnoser: detection from fault-free runs, isolation from fault runs.

`fit_online` does what `OnlineDiagnoser.fit` promises:

1. the normal models on the fault-free runs, with their out-of-fold standardised residuals
   (every training sample predicted by models that did not see its run or time block);
2. one AR whitening filter per output, fitted on those out-of-fold residuals;
3. the detector threshold for the false-alarm budget: the larger of the threshold that meets
   it on white Gaussian innovations (Siegmund's approximation for the CUSUM, a simulation for
   the GLR) and the one measured on the out-of-fold innovations
   (`~bayes_fdi.diagnosis.detection.thresholds.calibrate_threshold`);
4. the input envelope (training range of CV, P1, P2, T1 widened by ``input_margin`` of its
   span, at least `INPUT_MARGIN_FLOOR`);
5. with fault runs: the detector runs over every fault run as it will online, and the
   isolation signatures at chosen ages after each detection that follows the fault's onset
   (`SIGNATURE_AGES`) become the training, validation and calibration rows of the
   `~bayes_fdi.diagnosis.isolation.isolator.FaultIsolator`. Faults detected in fewer than
   ``detect_rate`` of their training runs are not detectable (DGN0) and not classified.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr
from sklearn.base import clone

from bayes_fdi.datasets import CHANNELS, state_order, validate_dataset
from bayes_fdi.diagnosis.detection.detectors import CUSUM, GLR
from bayes_fdi.diagnosis.detection.thresholds import calibrate_threshold, cusum_threshold
from bayes_fdi.diagnosis.detection.whitening import ARWhitener
from bayes_fdi.diagnosis.isolation.isolator import ISOLATION_FEATURES, FaultIsolator
from bayes_fdi.diagnosis.normal_models.dynamic import DynamicNormalModels
from bayes_fdi.diagnosis.online.state import new_run_state

__all__ = ["SIGNATURE_AGES", "fit_online", "split_fault_runs", "stack_runs"]

#: Seconds after a detection at which a training run contributes its isolation signature.
SIGNATURE_AGES: tuple[int, ...] = (
    0, 1, 2, 3, 4, 6, 8, 11, 15, 20, 30, 45, 60, 90, 120, 180, 250, 350, 500, 700, 1000,
)  # fmt: skip
#: Validation rows younger than this (s) do not enter the group confusion: the groups are
#: what the sensors cannot split once the signature has settled; the calibrated
#: probabilities carry the uncertainty of the first seconds.
GROUP_MIN_AGE = 20
#: Smallest widening of the input envelope (normalised full scale, about 14 sensor-noise
#: standard deviations): an input held constant in training (T1 under the DGen sines) would
#: otherwise have an envelope as narrow as its noise.
INPUT_MARGIN_FLOOR = 0.02
#: White Gaussian samples per channel behind the GLR's theoretical threshold floor.
WHITE_SAMPLES = 200_000


def split_fault_runs(runs: xr.Dataset) -> tuple[xr.Dataset, xr.Dataset, xr.Dataset]:
    """Training, validation and calibration runs: by position within each fault, runs
    ``k % 5`` in 0..2 train, 3 validates, 4 calibrates."""
    state = np.asarray(runs["state"].values).astype(str)
    rank = np.zeros(state.size, dtype=np.int64)
    for f in np.unique(state):
        rows = np.flatnonzero(state == f)
        rank[rows] = np.arange(rows.size) % 5
    pick = [np.flatnonzero(rank <= 2), np.flatnonzero(rank == 3), np.flatnonzero(rank == 4)]
    return tuple(runs.isel(run=p) for p in pick)  # type: ignore[return-value]


def _check_params(diag: Any) -> None:
    if diag.detector not in ("cusum", "glr"):
        raise ValueError(f"detector must be 'cusum' or 'glr', got {diag.detector!r}")
    checks = {
        "false_alarm_hours": diag.false_alarm_hours > 0,
        "cusum_k": diag.cusum_k >= 0,
        "glr_window": isinstance(diag.glr_window, int) and diag.glr_window >= 1,
        "p_fault": 0 <= diag.p_fault <= 1,
        "novelty_ratio": diag.novelty_ratio > 0,
        "coverage": 0 < diag.coverage < 1,
        "detect_rate": 0 <= diag.detect_rate <= 1,
        "input_margin": diag.input_margin >= 0,
        "max_signatures_per_fault": diag.max_signatures_per_fault >= 2,
    }
    for name, ok in checks.items():
        if not ok:
            raise ValueError(f"{name} is out of range: {getattr(diag, name)!r}")


def _detector(diag: Any, threshold: float) -> Any:
    if diag.detector == "cusum":
        return CUSUM(k=float(diag.cusum_k), threshold=threshold)
    return GLR(window=int(diag.glr_window), threshold=threshold)


def _fit_detection(diag: Any, normal_runs: xr.Dataset) -> None:
    nm = diag.normal_models_
    oof = nm.oof_z_
    diag.whiteners_ = {}
    innovations = [np.empty((oof.shape[1], 2)) for _ in range(oof.shape[0])]
    for j, c in enumerate(("X", "F")):
        w = ARWhitener(max_order=int(diag.max_whiten_order)).fit(oof[:, :, j])
        diag.whiteners_[c] = w
        for r in range(oof.shape[0]):
            innovations[r][:, j] = w.advance(oof[r, :, j], w.new_state())
    clear = diag.clear_level
    if clear is None:
        clear = 0.0 if diag.detector == "cusum" else 2.0
    target = float(diag.false_alarm_hours) * 3600.0
    proto = _detector(diag, 1.0)
    if diag.detector == "cusum":
        # two channels x two sides: four one-sided CUSUMs share the budget
        floor = cusum_threshold(target, float(diag.cusum_k), n_sides=4)
    else:
        rng = np.random.default_rng(None if diag.random_state is None else [diag.random_state, 3])
        white = [rng.standard_normal((WHITE_SAMPLES, 2))]
        floor = calibrate_threshold(proto, white, target, clear=clear,
                                    grid=np.arange(2.0, 40.01, 1.0))["threshold"]  # fmt: skip
    report = calibrate_threshold(proto, innovations, target, clear=clear, floor=floor,
                                 grid=np.arange(1.0, 60.01, 1.0))  # fmt: skip
    diag.threshold_ = float(report["threshold"])
    diag.clear_level_ = float(min(clear, diag.threshold_))
    diag.threshold_report_ = report
    diag.detector_ = _detector(diag, diag.threshold_)
    lows, highs = [], []
    for c in ("CV", "P1", "P2", "T1"):
        v = np.asarray(normal_runs[c].values, dtype=np.float64)
        lo, hi = float(np.nanmin(v)), float(np.nanmax(v))
        span = hi - lo
        margin = max(diag.input_margin * span, INPUT_MARGIN_FLOOR)
        lows.append(lo - margin)
        highs.append(hi + margin)
    diag.input_low_, diag.input_high_ = np.array(lows), np.array(highs)


def _signatures(diag: Any, runs: xr.Dataset) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Isolation signatures of fault runs at `SIGNATURE_AGES` after each detection that
    follows the fault's onset: rows, fault labels, ages, and per fault whether each of its
    runs was detected after the onset."""
    validate_dataset(runs, require=CHANNELS, allow_nan=True)
    if "state" not in runs.coords:
        raise ValueError("fault runs need a 'state' coordinate (the fault of each run)")
    states = [str(v) for v in np.asarray(runs["state"].values).astype(str)]
    onset = (np.asarray(runs["onset"].values, dtype=np.float64) if "onset" in runs.coords
             else np.zeros(states.size))  # fmt: skip
    times = np.asarray(runs["time"].values, dtype=np.float64)
    data = {c: np.asarray(runs[c].transpose("run", "time").values, dtype=np.float64)
            for c in CHANNELS}  # fmt: skip
    rows, labels, ages = [], [], []
    detected: dict[str, list[bool]] = {}
    for i, state in enumerate(states):
        if state == "fn":
            continue
        arrays = {c: np.ascontiguousarray(v[i]) for c, v in data.items()}
        out = diag._process(arrays, new_run_state(diag))
        dd = out["DD"]
        rise = np.flatnonzero(dd & ~np.concatenate([[False], dd[:-1]]))
        rise = rise[times[rise] >= onset[i]]
        detected.setdefault(state, []).append(bool(rise.size))
        ends = np.flatnonzero(~dd)
        for t_d in rise:
            stop = ends[ends > t_d]
            stop = int(stop[0]) if stop.size else dd.size
            for a in SIGNATURE_AGES:
                t = t_d + a
                if t < stop and np.all(np.isfinite(out["features"][t])):
                    rows.append(out["features"][t])
                    labels.append(state)
                    ages.append(a)
    X = np.asarray(rows, dtype=np.float64).reshape(-1, len(ISOLATION_FEATURES))
    return X, np.asarray(labels, dtype=str), np.asarray(ages, dtype=np.int64), detected


def _as_list(runs: xr.Dataset | Sequence[xr.Dataset]) -> list[xr.Dataset]:
    return [runs] if isinstance(runs, xr.Dataset) else list(runs)


def _signatures_of(
    diag: Any, runs: xr.Dataset | Sequence[xr.Dataset]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """`_signatures` of a dataset or of several (e.g. campaigns of different durations);
    the last item maps each fault to whether each of its runs was detected."""
    parts = [_signatures(diag, r) for r in _as_list(runs)]
    detected: dict[str, list[bool]] = {}
    for p in parts:
        for f, flags in p[3].items():
            detected.setdefault(f, []).extend(flags)
    return (
        np.concatenate([p[0] for p in parts]),
        np.concatenate([p[1] for p in parts]),
        np.concatenate([p[2] for p in parts]),
        detected,
    )


def stack_runs(runs: xr.Dataset | Sequence[xr.Dataset]) -> xr.Dataset:
    """One dataset of the runs of a dataset or of a list of them (e.g. recordings or campaigns
    of different durations): runs numbered 0, 1, ... in order; a shorter run ends in NaN (no
    measurement: never fitted on, a gap to the detector)."""
    parts = _as_list(runs)
    if not parts:
        raise ValueError("no runs given (an empty list)")
    for k, ds in enumerate(parts):
        if not isinstance(ds, xr.Dataset):
            raise ValueError(f"item {k} of the runs is a {type(ds).__name__}, not a dataset")
        if "run" not in ds.dims:
            parts[k] = ds.drop_vars([c for c in ds.coords if ds[c].ndim == 0]).expand_dims("run")
    if len(parts) == 1:
        return parts[0]
    parts = [ds.drop_vars("run", errors="ignore") for ds in parts]
    out = xr.concat(parts, dim="run", join="outer", combine_attrs="drop_conflicts",
                    coords="minimal", compat="override")  # fmt: skip
    return out.assign_coords(run=np.arange(out.sizes["run"]))


def _cap_rows(y: np.ndarray, cap: int, rng: np.random.Generator) -> np.ndarray:
    keep = []
    for f in np.unique(y):
        rows = np.flatnonzero(y == f)
        if rows.size > cap:
            rows = np.sort(rng.choice(rows, cap, replace=False))
        keep.append(rows)
    return np.sort(np.concatenate(keep)) if keep else np.empty(0, dtype=np.int64)


def fit_online(
    diag: Any,
    normal_runs: xr.Dataset | Sequence[xr.Dataset],
    fault_runs: xr.Dataset | Sequence[xr.Dataset] | None,
    validation_runs: xr.Dataset | Sequence[xr.Dataset] | None,
    calibration_runs: xr.Dataset | Sequence[xr.Dataset] | None,
) -> None:
    """Fit an `OnlineDiagnoser` in place (see the module docstring)."""
    _check_params(diag)
    t_start = time.perf_counter()
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()
    nm = (DynamicNormalModels(random_state=diag.random_state) if diag.normal_models is None
          else clone(diag.normal_models))  # fmt: skip
    normal_runs = stack_runs(normal_runs)
    diag.normal_models_ = nm.fit(normal_runs)
    seconds["normal_models"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    _fit_detection(diag, normal_runs)
    seconds["detection"] = time.perf_counter() - t0
    diag.isolator_ = None
    diag.undetectable_ = ()
    diag.detection_rates_ = {}
    if fault_runs is not None:
        t0 = time.perf_counter()
        if validation_runs is None or calibration_runs is None:
            parts = [split_fault_runs(r) for r in _as_list(fault_runs)]
            train = [p[0] for p in parts]
            validation_runs = [p[1] for p in parts] if validation_runs is None else validation_runs
            calibration_runs = (
                [p[2] for p in parts] if calibration_runs is None else calibration_runs
            )
        else:
            train = fault_runs
        X, y, _, detected = _signatures_of(diag, train)
        rates = {f: float(np.mean(v)) for f, v in detected.items()}
        Xv, yv, av, _ = _signatures_of(diag, validation_runs)
        Xc, yc, _, _ = _signatures_of(diag, calibration_runs)
        seconds["signatures"] = time.perf_counter() - t0
        counts = {f: int(np.sum(y == f)) for f in rates}
        undetectable = sorted(
            (f for f in rates if rates[f] < diag.detect_rate or counts[f] < 5),
            key=state_order,
        )
        known = sorted(set(rates) - set(undetectable), key=state_order)
        diag.detection_rates_ = dict(sorted(rates.items(), key=lambda kv: state_order(kv[0])))
        diag.undetectable_ = tuple(undetectable)
        if len(known) >= 2:
            t0 = time.perf_counter()
            rng = np.random.default_rng(None if diag.random_state is None
                                        else [diag.random_state, 5])  # fmt: skip
            keep = np.flatnonzero(np.isin(y, known))
            keep = keep[_cap_rows(y[keep], int(diag.max_signatures_per_fault), rng)]
            vkeep = np.isin(yv, known) & (av >= GROUP_MIN_AGE)
            ckeep = np.isin(yc, known)
            diag.isolator_ = FaultIsolator(
                diag.isolation_classifier,
                calibrator=diag.calibrator,
                group_threshold=diag.group_threshold,
                random_state=diag.random_state,
            ).fit(
                X[keep], y[keep],
                validation=(Xv[vkeep], yv[vkeep]) if vkeep.any() else None,
                calibration=(Xc[ckeep], yc[ckeep]) if ckeep.any() else None,
            )  # fmt: skip
            seconds["isolation"] = time.perf_counter() - t0
            diag.n_signatures_ = {"train": int(keep.size), "validation": int(vkeep.sum()),
                                  "calibration": int(ckeep.sum())}  # fmt: skip
    seconds["total"] = time.perf_counter() - t_start
    diag.fit_seconds_ = seconds
    if not math.isfinite(diag.threshold_):
        raise ValueError("the detector threshold could not be calibrated (no finite ARL fit)")

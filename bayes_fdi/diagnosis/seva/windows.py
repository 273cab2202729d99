"""The self-validating (SEVA) output of a diagnosed actuator.

A SEVA device (Henry & Clarke 1993; Yang & Clarke 1999) reports not only a value but how far
to trust it. For every run (or window) diagnosed by a
:class:`~bayes_fdi.diagnosis.FaultDiagnoser`, :func:`records_from_diagnosis` builds an
immutable :class:`SevaRecord` with

- the measured values of the outputs X and F (means over the window);
- their validated values: VMV (validated measurement value) = the fault-free normal model's
  prediction, and VU (validated uncertainty) = the half-width of its central predictive
  interval at a stated ``coverage`` (``z * std``, 1.96 std at 95 %);
- the diagnosed state, its probability, the full class distribution and its entropy;
- a status and the reasons for it:

``BLIND``
    no usable measurements: too many missing (NaN/inf) or saturated (at a rail) samples in
    a channel;
``DAZZLED``
    abnormal but not confidently diagnosed: the top probability is too low or the
    distribution too flat, or the inputs or residual features are unlike anything seen in
    training (novelty);
``BLURRED``
    a fault is diagnosed with confidence;
``CLEAR``
    confidently fault-free.

The rules are applied in this order (BLIND first); the thresholds are a
:class:`SevaThresholds`. Records convert to pandas (:func:`to_frame`), xarray
(:func:`to_xarray`) and JSON (:func:`to_json`).

Novelty ("inputs unlike anything in training") is measured by :class:`NoveltyReference`:
the distance of each standardised input sample to its nearest training sample, divided by a
high quantile of the same distance among the training samples themselves. RVM predictive
standard deviations are *not* used for this: with localised kernels the RVR's predictive
variance shrinks back to the noise level far from the data, so it does not flag novel inputs.

The record and its conversions live in `bayes_fdi.diagnosis.seva.record`, the thresholds and
status rules in `bayes_fdi.diagnosis.seva.rules`, the novelty reference in
`bayes_fdi.diagnosis.seva.novelty`; every name stays importable from here. Runs with a window
without a single complete sample are diagnosed by
`bayes_fdi.diagnosis.seva.empty_windows`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
import xarray as xr
from scipy import stats

from bayes_fdi.datasets import CHANNELS, INPUT_CHANNELS
from bayes_fdi.diagnosis.seva.empty_windows import (
    DIAGNOSIS_VARIABLES,
    diagnose_allowing_empty_windows,
)
from bayes_fdi.diagnosis.seva.novelty import NoveltyReference
from bayes_fdi.diagnosis.seva.record import (
    ClassDistribution,
    SevaRecord,
    SevaStatus,
)
from bayes_fdi.diagnosis.seva.rules import (
    DEFAULT_SATURATION_LIMITS,
    SevaThresholds,
    decide_status,
    entropy,
    screen_measurements,
    screen_window,
)

__all__ = ["records_from_diagnosis", "seva_records"]


def _nanmean(a: np.ndarray) -> float:
    a = np.asarray(a, dtype=np.float64)
    ok = np.isfinite(a)
    return float(a[ok].mean()) if ok.any() else math.nan


def _rms(a: np.ndarray) -> float:
    a = np.asarray(a, dtype=np.float64)
    ok = np.isfinite(a)
    return float(np.sqrt(np.mean(a[ok] ** 2))) if ok.any() else math.nan


def records_from_diagnosis(
    diagnosis: xr.Dataset | None,
    runs: xr.Dataset,
    *,
    thresholds: SevaThresholds | None = None,
    coverage: float = 0.95,
    input_reference: NoveltyReference | None = None,
    feature_reference: NoveltyReference | None = None,
    input_channels: Sequence[str] = INPUT_CHANNELS,
    saturation_limits: Mapping[str, tuple[float, float]] | None = None,
    not_diagnosed: Mapping[int, tuple[str, ...]] | None = None,
    calibrator: Any = None,
) -> list[SevaRecord]:
    """Build one :class:`SevaRecord` per run (or per run and window) from a diagnosis.

    Parameters
    ----------
    diagnosis
        The output of ``FaultDiagnoser.diagnose(runs)``: dims ``run``, ``class``[,
        ``window``][, ``time``]; variables ``proba``, ``X_hat``, ``X_hat_std``, ``F_hat``,
        ``F_hat_std``, optionally ``features``; with windows, coordinates ``window_start``
        and ``window_end`` (s, end exclusive). Same runs in the same order as ``runs``. A
        NaN distribution (e.g. a run not diagnosed because BLIND) gives an empty state.
        ``None``: every run must be BLIND (used by :func:`seva_records`).
    runs
        The measured runs (dataset format of :mod:`bayes_fdi.datasets`).
    thresholds
        Decision thresholds (default :class:`SevaThresholds()`).
    coverage
        Central coverage of VMV ± VU (default 0.95).
    input_reference
        Fitted :class:`NoveltyReference` of the training inputs (columns ``input_channels``);
        None skips the input-novelty check (the record says so in ``reasons``).
    feature_reference
        Fitted :class:`NoveltyReference` of the classifier's training features (unscaled, as
        in ``diagnosis["features"]``); None skips it.
    input_channels
        Columns of ``input_reference``.
    saturation_limits
        Rails per channel (default :data:`DEFAULT_SATURATION_LIMITS`).
    not_diagnosed
        ``{run position: BLIND reasons}`` of runs deliberately not diagnosed (their windows
        are BLIND with these reasons); set by :func:`seva_records`.
    calibrator
        Optional recalibration of the class distributions before the rules, an object with
        ``transform(proba) -> proba`` in the diagnosis' class order, e.g. a
        :class:`~bayes_fdi.calibration.TemperatureScaler` fitted on held-out runs. The
        thresholds only mean what they say for calibrated probabilities.

    Returns
    -------
    list of SevaRecord
        Run-major order (all windows of run 0 first).
    """
    th = (thresholds or SevaThresholds()).validate()
    if not 0 < coverage < 1:
        raise ValueError(f"coverage must lie in (0, 1), got {coverage}")
    if "run" not in runs.dims or "time" not in runs.dims:
        raise ValueError("runs must have dims 'run' and 'time'")
    limits = dict(DEFAULT_SATURATION_LIMITS if saturation_limits is None else saturation_limits)
    n_runs = runs.sizes["run"]
    if diagnosis is not None and diagnosis.sizes.get("run") != n_runs:
        raise ValueError(
            f"diagnosis has {diagnosis.sizes.get('run')} runs but runs has {n_runs}; "
            "pass the same runs in the same order"
        )
    if diagnosis is not None and "time" in diagnosis.dims and "time" in diagnosis.coords:
        t_diag = np.asarray(diagnosis["time"].values, dtype=np.float64)
        if np.all(np.isin(t_diag, runs["time"].values)):
            runs = runs.sel(time=t_diag)
    data = _record_data(
        diagnosis,
        runs,
        th,
        limits,
        coverage=coverage,
        calibrator=calibrator,
        input_reference=input_reference,
        input_channels=input_channels,
        feature_reference=feature_reference,
    )
    return [
        _window_record(
            data,
            i,
            w,
            th,
            limits,
            not_diagnosed=not_diagnosed,
            input_reference=input_reference,
            feature_reference=feature_reference,
        )
        for i in range(n_runs)
        for w in range(data.proba.shape[1])
    ]


class _RecordData(NamedTuple):
    """What the records of a diagnosis are built from, per run (and window) and sample."""

    measured: dict[str, np.ndarray]  #: measured channels, (run, time)
    times: np.ndarray
    run_ids: np.ndarray
    z: float  #: VU = z * std
    coverage: float
    windowed: bool
    classes: list[str]
    proba: np.ndarray  #: (run, window, class); NaN rows: not diagnosed
    w_start: np.ndarray  #: window starts (s)
    w_end: np.ndarray  #: window ends (s, exclusive)
    predicted: dict[str, np.ndarray]  #: X_hat, X_hat_std, F_hat, F_hat_std, (run, time)
    features: np.ndarray | None  #: (run, window, feature), for the feature novelty
    novel: np.ndarray | None  #: (run, time): input sample novel (1), not (0), unknown (NaN)


def _record_data(
    diagnosis: xr.Dataset | None,
    runs: xr.Dataset,
    th: SevaThresholds,
    limits: dict[str, tuple[float, float]],
    *,
    coverage: float,
    calibrator: Any,
    input_reference: NoveltyReference | None,
    input_channels: Sequence[str],
    feature_reference: NoveltyReference | None,
) -> _RecordData:
    """Read the measurements, the class distributions, the windows, the predictions, the
    features and the input novelty of ``runs`` (aligned with ``diagnosis``)."""
    n_runs = runs.sizes["run"]
    channels = [c for c in CHANNELS if c in runs]
    measured = {c: np.asarray(runs[c].transpose("run", "time").values) for c in channels}
    times = np.asarray(runs["time"].values, dtype=np.float64)
    run_ids = np.asarray(runs["run"].values) if "run" in runs.coords else np.arange(n_runs)
    z = float(stats.norm.ppf(0.5 + coverage / 2.0))
    windowed = diagnosis is not None and "window" in diagnosis["proba"].dims
    if diagnosis is not None:
        classes, proba = _class_distributions(diagnosis, n_runs, windowed, calibrator)
    else:
        blind = screen_measurements(
            runs, channels=channels, thresholds=th, saturation_limits=limits
        )["blind"]
        if not blind.all():
            raise ValueError("diagnosis is None but some runs are not BLIND")
        classes, proba = [], np.full((n_runs, 1, 0), np.nan)
    if windowed:
        w_start = np.asarray(diagnosis["window_start"].values, dtype=np.float64)
        w_end = np.asarray(diagnosis["window_end"].values, dtype=np.float64)
    else:
        w_start, w_end = np.array([times[0]]), np.array([np.inf])
    predicted = _predictions(diagnosis, n_runs, times.size)
    features = None
    if feature_reference is not None and diagnosis is not None and "features" in diagnosis:
        fv = diagnosis["features"].transpose(*(("run", "window") if windowed else ("run",)), ...)
        features = np.asarray(fv.values, dtype=np.float64).reshape(n_runs, proba.shape[1], -1)
    return _RecordData(
        measured=measured,
        times=times,
        run_ids=run_ids,
        z=z,
        coverage=float(coverage),
        windowed=windowed,
        classes=classes,
        proba=proba,
        w_start=w_start,
        w_end=w_end,
        predicted=predicted,
        features=features,
        novel=_input_novelty(runs, input_reference, input_channels, th),
    )


def _class_distributions(
    diagnosis: xr.Dataset, n_runs: int, windowed: bool, calibrator: Any
) -> tuple[list[str], np.ndarray]:
    """The classes and the ``(run, window, class)`` distributions, recalibrated when asked."""
    if "proba" not in diagnosis:
        raise ValueError("diagnosis lacks 'proba'")
    classes = [str(c) for c in diagnosis["class"].values]
    lead = ("run", "window") if windowed else ("run",)
    proba = np.asarray(diagnosis["proba"].transpose(*lead, "class").values, dtype=np.float64)
    proba = proba.reshape(n_runs, -1, len(classes))
    if calibrator is not None:
        flat = proba.reshape(-1, len(classes))
        ok = np.all(np.isfinite(flat), axis=1)
        cal = np.full_like(flat, np.nan)
        if ok.any():
            cal[ok] = np.asarray(calibrator.transform(flat[ok]), dtype=np.float64)
        proba = cal.reshape(proba.shape)
    return classes, proba


def _predictions(diagnosis: xr.Dataset | None, n_runs: int, n_times: int) -> dict[str, np.ndarray]:
    """The normal models' predictions and stds, ``(run, time)``; NaN where there are none."""
    out = {}
    for name in ("X_hat", "X_hat_std", "F_hat", "F_hat_std"):
        if diagnosis is None or name not in diagnosis:
            out[name] = np.full((n_runs, n_times), np.nan)
        else:
            v = diagnosis[name].transpose("run", ...)
            out[name] = np.asarray(v.values, dtype=np.float64).reshape(n_runs, -1)
    return out


def _input_novelty(
    runs: xr.Dataset,
    input_reference: NoveltyReference | None,
    input_channels: Sequence[str],
    th: SevaThresholds,
) -> np.ndarray | None:
    """``(run, time)``: 1 where the input sample is novel, 0 where not, NaN where an input is
    missing; None without a reference."""
    if input_reference is None:
        return None
    U = np.stack(
        [
            np.asarray(runs[c].transpose("run", "time").values, dtype=np.float64)
            for c in input_channels
        ],
        axis=-1,
    )
    ok = np.all(np.isfinite(U), axis=-1)
    novel = np.full(ok.shape, np.nan)
    novel[ok] = input_reference.score(U[ok]) > th.novelty_ratio
    return novel


def _window_record(
    data: _RecordData,
    i: int,
    w: int,
    th: SevaThresholds,
    limits: dict[str, tuple[float, float]],
    *,
    not_diagnosed: Mapping[int, tuple[str, ...]] | None,
    input_reference: NoveltyReference | None,
    feature_reference: NoveltyReference | None,
) -> SevaRecord:
    """The record of window ``w`` of run ``i``: screening, diagnosis, novelty, status."""
    tm = (data.times >= data.w_start[w]) & (data.times < data.w_end[w])
    if not tm.any():
        raise ValueError(f"window {w} holds no samples of run {i}")
    measured = data.measured
    missing, saturated, blind_why, notes = screen_window(
        {c: a[i, tm] for c, a in measured.items()}, th, limits
    )
    if not_diagnosed and i in not_diagnosed and not blind_why:
        blind_why = tuple(f"run not diagnosed: {r}" for r in not_diagnosed[i])
    p = data.proba[i, w]
    diagnosed = p.size > 0 and bool(np.all(np.isfinite(p)))
    if diagnosed:
        k = int(np.argmax(p))
        state, prob, ent = data.classes[k], float(p[k]), entropy(p)
    else:
        state, prob, ent = "", math.nan, math.nan
    novel_frac = math.nan
    if data.novel is not None:
        nv = data.novel[i, tm]
        nv = nv[np.isfinite(nv)]
        novel_frac = float(nv.mean()) if nv.size else math.nan
    feat_nov = math.nan
    if data.features is not None and not np.isnan(data.features[i, w]).any():
        feat_nov = float(feature_reference.score(data.features[i, w][None, :])[0])
    status, reasons = decide_status(
        th, blind_why, state, prob, ent, diagnosed, novel_frac, feat_nov
    )
    if input_reference is None and status is not SevaStatus.BLIND:
        reasons.append("input novelty not checked (no input reference)")
    reasons.extend(notes)
    t_sel = data.times[tm]
    pred = data.predicted
    return SevaRecord(
        run=int(data.run_ids[i]),
        t_start=float(t_sel[0]),
        t_end=float(t_sel[-1]),
        x_measured=_nanmean(measured["X"][i, tm]) if "X" in measured else math.nan,
        f_measured=_nanmean(measured["F"][i, tm]) if "F" in measured else math.nan,
        x_vmv=_nanmean(pred["X_hat"][i, tm]),
        x_vu=data.z * _rms(pred["X_hat_std"][i, tm]),
        f_vmv=_nanmean(pred["F_hat"][i, tm]),
        f_vu=data.z * _rms(pred["F_hat_std"][i, tm]),
        coverage=data.coverage,
        state=state,
        probability=prob,
        distribution=ClassDistribution(
            list(zip(data.classes, p.tolist(), strict=True)) if diagnosed else []
        ),
        entropy=ent,
        status=status,
        reasons=tuple(reasons),
        missing_fraction=float(missing.max(initial=0.0)),
        saturated_fraction=float(saturated.max(initial=0.0)),
        novel_fraction=novel_frac,
        feature_novelty=feat_nov,
        window=w if data.windowed else None,
    )


def seva_records(
    diagnoser: Any,
    runs: xr.Dataset,
    *,
    thresholds: SevaThresholds | None = None,
    coverage: float = 0.95,
    input_reference: NoveltyReference | None = None,
    feature_reference: NoveltyReference | None = None,
    saturation_limits: Mapping[str, tuple[float, float]] | None = None,
    calibrator: Any = None,
) -> list[SevaRecord]:
    """Diagnose ``runs`` with a fitted diagnoser and return their SEVA records.

    ``calibrator`` (e.g. a fitted :class:`~bayes_fdi.calibration.TemperatureScaler`)
    recalibrates the class distributions first; other arguments as in
    :func:`records_from_diagnosis`.

    BLIND runs (missing/saturated signals over the whole run) are not passed to
    ``diagnoser.diagnose``; their records are BLIND with an empty distribution.

    Novelty references, when not given: ``input_reference`` defaults to the diagnoser's
    ``input_reference_`` attribute (None if absent: the check is skipped and the records say
    so); ``feature_reference`` to its ``feature_reference_``, else a
    :class:`NoveltyReference` fitted on its ``training_features_`` (the unscaled training
    feature rows of :class:`~bayes_fdi.diagnosis.FaultDiagnoser`).
    """
    th = (thresholds or SevaThresholds()).validate()
    if input_reference is None:
        input_reference = getattr(diagnoser, "input_reference_", None)
    if feature_reference is None:
        feature_reference = getattr(diagnoser, "feature_reference_", None)
    if feature_reference is None and getattr(diagnoser, "training_features_", None) is not None:
        tf = np.asarray(diagnoser.training_features_, dtype=np.float64)
        if tf.ndim == 2 and tf.shape[0] >= 3:
            feature_reference = NoveltyReference().fit(tf)
    channels = [c for c in CHANNELS if c in runs]
    screen = screen_measurements(
        runs, channels=channels, thresholds=th, saturation_limits=saturation_limits
    )
    usable = np.flatnonzero(~screen["blind"])
    diag = None
    if usable.size:
        part = diagnose_allowing_empty_windows(diagnoser, runs.isel(run=usable))
        if usable.size == runs.sizes["run"]:
            diag = part
        else:
            # NaN rows for BLIND runs: never diagnosed, never shown as a diagnosis
            part = part[[v for v in DIAGNOSIS_VARIABLES if v in part.data_vars]]
            part = part.assign_coords(run=runs["run"].values[usable])
            diag = part.reindex(run=runs["run"].values)
    skipped = {int(i): tuple(screen["reasons"][i]) for i in np.flatnonzero(screen["blind"])}
    return records_from_diagnosis(
        diag,
        runs,
        thresholds=th,
        coverage=coverage,
        input_reference=input_reference,
        feature_reference=feature_reference,
        saturation_limits=saturation_limits,
        not_diagnosed=skipped,
        calibrator=calibrator,
    )

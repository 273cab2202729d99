"""The training data of the online diagnoser and the fit of its detection and isolation.

`OnlineDiagnoser.fit` (`bayes_fdi.diagnosis.online.diagnoser`) trains on fault-free runs and
fault runs given as datasets or lists of datasets (`stack_runs`). `fit_detection` fits the
whitening filters and the detector's threshold on the normal models' out-of-fold residuals of
the fault-free runs. Without held-out runs the
fault runs are split by position within each fault (`split_fault_runs`). The isolation
classifier learns from the signatures that the stream itself computes on the fault runs
(`training_signatures`: the detection components' `~bayes_fdi.diagnosis.online.step.step` over
each run), taken at chosen ages after each detection that follows the fault's onset
(`detection_signatures`, `SIGNATURE_AGES`); `fit_isolation` fits the
`~bayes_fdi.diagnosis.isolation.isolator.FaultIsolator` on them, a seeded subset bounding the
rows per fault (`cap_rows`), after setting aside the faults the detector misses. The
recalibration of the group probabilities learns instead from every detected faulty second of
the calibration runs (`detected_seconds`, at most `CALIBRATION_SECONDS_PER_RUN` per run): the
probabilities it corrects are those the stream gives second by second, from the first seconds
after a detection to the settled signature, in the proportions in which the diagnoser meets
them.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
import xarray as xr

from bayes_fdi.datasets import CHANNELS, state_order, validate_dataset
from bayes_fdi.diagnosis.detection.decision import CLEAR_HOLD, DetectionDecision
from bayes_fdi.diagnosis.detection.thresholds import fit_threshold
from bayes_fdi.diagnosis.detection.whitening import ARWhitener
from bayes_fdi.diagnosis.isolation.isolator import FaultIsolator
from bayes_fdi.diagnosis.isolation.signatures import ISOLATION_FEATURES
from bayes_fdi.diagnosis.online.fit_proof import FitProof
from bayes_fdi.diagnosis.online.state import PerOutput
from bayes_fdi.diagnosis.online.step import Components, init_run_state, step

__all__ = [
    "CALIBRATION_SECONDS_PER_RUN",
    "GROUP_MIN_AGE",
    "SIGNATURE_AGES",
    "DetectionFit",
    "IsolationFit",
    "Runs",
    "Signatures",
    "attach_isolation",
    "cap_rows",
    "detected_seconds",
    "detection_components",
    "detection_signatures",
    "fit_detection",
    "fit_isolation",
    "runs_as_list",
    "split_fault_runs",
    "stack_runs",
    "training_rows",
    "training_signatures",
]

#: Seconds after a detection at which a training run contributes its isolation signature.
SIGNATURE_AGES: tuple[int, ...] = (
    0, 1, 2, 3, 4, 6, 8, 11, 15, 20, 30, 45, 60, 90, 120, 180, 250, 350, 500, 700, 1000,
)  # fmt: skip
#: Validation rows younger than this (s) do not enter the group confusion: the groups are
#: what the sensors cannot split once the signature has settled; the calibrated
#: probabilities carry the uncertainty of the first seconds.
GROUP_MIN_AGE = 20
#: Each calibration run gives at most this many of its detected faulty seconds (evenly spaced)
#: to the recalibration, so that long runs do not outweigh short ones.
CALIBRATION_SECONDS_PER_RUN = 600

#: Runs given as one dataset or as a list of datasets (e.g. of different durations).
Runs = xr.Dataset | Sequence[xr.Dataset]


class Signatures(NamedTuple):
    """Isolation signatures of fault runs (`training_signatures`)."""

    rows: np.ndarray  #: ``(n, 10)`` signatures
    labels: np.ndarray  #: ``(n,)`` the fault of each
    ages: np.ndarray  #: ``(n,)`` seconds since the detection
    detected: dict[str, list[bool]]  #: per fault: whether each of its runs was detected


class DetectionFit(NamedTuple):
    """What `fit_detection` fits."""

    whiteners: dict[str, ARWhitener]  #: ``{"X": ..., "F": ...}``
    detector: Any  #: the detector with the threshold
    threshold: float
    clear_level: float
    threshold_report: dict[str, Any]  #: `fit_threshold`'s report
    decision: DetectionDecision  #: DD with the threshold, the clear level and the hold


class IsolationFit(NamedTuple):
    """What `fit_isolation` fits."""

    isolator: FaultIsolator | None  #: None when fewer than two faults are detectable
    undetectable: tuple[str, ...]  #: faults detected too rarely (DGN0)
    detection_rates: dict[str, float]  #: fault -> share of its training runs detected
    n_signatures: dict[str, int] | None  #: rows of the training, validation, calibration sets


def runs_as_list(runs: xr.Dataset | Sequence[xr.Dataset]) -> list[xr.Dataset]:
    """A dataset or a list of datasets as a list."""
    return [runs] if isinstance(runs, xr.Dataset) else list(runs)


def stack_runs(runs: xr.Dataset | Sequence[xr.Dataset]) -> xr.Dataset:
    """One dataset of the runs of a dataset or of a list of them (e.g. recordings or campaigns
    of different durations): runs numbered 0, 1, ... in order; a shorter run ends in NaN (no
    measurement: never fitted on, a gap to the detector)."""
    parts = runs_as_list(runs)
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
    out = xr.concat(
        parts,
        dim="run",
        join="outer",
        combine_attrs="drop_conflicts",
        coords="minimal",
        compat="override",
    )
    return out.assign_coords(run=np.arange(out.sizes["run"]))


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


def detection_signatures(
    detected: np.ndarray,
    features: np.ndarray,
    times: np.ndarray,
    onset: float,
    ages: Sequence[int] = SIGNATURE_AGES,
) -> tuple[list[np.ndarray], list[int], bool]:
    """The signatures of one fault run at ``ages`` seconds after each detection that follows
    the fault's onset.

    Parameters
    ----------
    detected
        ``(n,)`` the stream's detection decision DD.
    features
        ``(n, n_features)`` the stream's signatures.
    times
        ``(n,)`` the run's time coordinate (s).
    onset
        The fault's onset (s).
    ages
        Seconds after a detection (a row is kept while DD stays on and the signature is
        finite).

    Returns
    -------
    rows : list of numpy.ndarray
    row_ages : list of int
    detected_after_onset : bool
        Whether DD rose at or after the onset.
    """
    dd = np.asarray(detected, dtype=bool)
    rise = np.flatnonzero(dd & ~np.concatenate([[False], dd[:-1]]))
    rise = rise[times[rise] >= onset]
    ends = np.flatnonzero(~dd)
    rows, row_ages = [], []
    for t_d in rise:
        stop = ends[ends > t_d]
        stop = int(stop[0]) if stop.size else dd.size
        for a in ages:
            t = t_d + a
            if t < stop and np.all(np.isfinite(features[t])):
                rows.append(features[t])
                row_ages.append(a)
    return rows, row_ages, bool(rise.size)


def detected_seconds(
    detected: np.ndarray,
    features: np.ndarray,
    times: np.ndarray,
    onset: float,
    cap: int = CALIBRATION_SECONDS_PER_RUN,
    window_seconds: np.ndarray | None = None,
) -> tuple[list[np.ndarray], list[int], bool]:
    """The signatures of one fault run at its detected seconds after the fault's onset.

    Every second at or after ``onset`` with DD on and a finite signature, at most ``cap`` of
    them evenly spaced over those seconds: the rows whose group probabilities the online
    diagnoser reports for the fault. Parameters and returns as `detection_signatures`; the
    ages are the seconds since the detection each second belongs to or, given the stream's
    ``window_seconds`` (the signature window's complete seconds, second by second), those: the
    age the isolation's calibration reads online.
    """
    dd = np.asarray(detected, dtype=bool)
    rise = np.flatnonzero(dd & ~np.concatenate([[False], dd[:-1]]))
    finite = np.all(np.isfinite(features), axis=1) if len(features) else np.zeros(0, bool)
    seconds = np.flatnonzero(dd & (np.asarray(times) >= onset) & finite)
    if seconds.size > cap:
        seconds = seconds[np.round(np.linspace(0, seconds.size - 1, cap)).astype(np.int64)]
    since = rise[np.searchsorted(rise, seconds, side="right") - 1] if seconds.size else seconds
    rows = [features[t] for t in seconds]
    ages = seconds - since if window_seconds is None else np.asarray(window_seconds)[seconds]
    return rows, [int(a) for a in ages], bool(np.any(times[rise] >= onset))


def cap_rows(y: np.ndarray, cap: int, rng: np.random.Generator) -> np.ndarray:
    """Indices of the rows of ``y`` to keep: all of a label with at most ``cap`` rows, else a
    seeded subset of ``cap`` (sorted)."""
    keep = []
    for f in np.unique(y):
        rows = np.flatnonzero(y == f)
        if rows.size > cap:
            rows = np.sort(rng.choice(rows, cap, replace=False))
        keep.append(rows)
    return np.sort(np.concatenate(keep)) if keep else np.empty(0, dtype=np.int64)


def training_rows(
    y: np.ndarray, known: Sequence[str], cap: int, random_state: int | None
) -> np.ndarray:
    """Indices of the training signatures the classifier is fitted on: those of the ``known``
    (classified) faults, at most ``cap`` per fault (`cap_rows`, seed ``[random_state, 5]``)."""
    rng = np.random.default_rng(None if random_state is None else [random_state, 5])
    keep = np.flatnonzero(np.isin(y, known))
    return keep[cap_rows(y[keep], int(cap), rng)]


def fit_detection(
    oof_z: np.ndarray,
    detector: Any,
    *,
    max_whiten_order: int,
    clear_level: float,
    false_alarm_hours: float,
    random_state: int | None,
    clear_hold: int = CLEAR_HOLD,
) -> DetectionFit:
    """The detection components of `OnlineDiagnoser` (whose parameters the keywords are).

    One AR whitening filter per output on the out-of-fold standardised residuals ``oof_z``
    ``(runs, time, 2)`` of the fault-free runs, and the threshold of ``detector`` (a CUSUM or
    GLR; its own threshold is not used) that meets the false-alarm budget on their innovations
    (`~bayes_fdi.diagnosis.detection.thresholds.fit_threshold`); the clear level is at most the
    threshold. The decision DD clears only after ``clear_hold`` seconds of in-control evidence
    (`~bayes_fdi.diagnosis.detection.decision.CLEAR_HOLD` by default). The threshold is measured
    with plain hysteresis: the hold lengthens alarms and merges those closer than it, never adds
    one, so the budget holds with it too.
    """
    whiteners = {}
    innovations = [np.empty((oof_z.shape[1], 2)) for _ in range(oof_z.shape[0])]
    for j, c in enumerate(("X", "F")):
        whitener = ARWhitener(max_order=int(max_whiten_order)).fit(oof_z[:, :, j])
        whiteners[c] = whitener
        for r in range(oof_z.shape[0]):
            innovations[r][:, j] = whitener.run(oof_z[r, :, j])[0]
    target = float(false_alarm_hours) * 3600.0
    report = fit_threshold(
        detector, innovations, target, clear=clear_level, random_state=random_state
    )
    threshold = float(report["threshold"])
    clear = float(min(clear_level, threshold))
    return DetectionFit(
        whiteners,
        detector.with_threshold(threshold),
        threshold,
        clear,
        report,
        DetectionDecision(threshold, clear, n_channels=2, hold=int(clear_hold)),
    )


def training_signatures(
    components: Components, runs: Runs, *, per_second: bool = False, window_ages: bool = False
) -> Signatures:
    """The isolation signatures of fault runs as the fit uses them.

    Every run but a fault-free one (``state`` ``"fn"``) goes through the stream of
    ``components`` from a fresh state; its signatures at `SIGNATURE_AGES` after each detection
    that follows the fault's onset are kept (`detection_signatures`), or with ``per_second``
    those of its detected seconds after the onset (`detected_seconds`: the seconds the
    diagnoser reports, under its decision with the hold). For the ages the decision is plain
    hysteresis (without its hold) on the detector's mean test (a detector with a ``mean_test``,
    `~bayes_fdi.diagnosis.detection.VarianceHoldCUSUM`, without its variance hold): with a hold,
    an alarm raised before the onset could last into the fault and swallow its own detection,
    and the run would count as undetected; so the signatures, the isolability groups and the
    faults listed as undetectable do not depend on how long alarms are held.

    Parameters
    ----------
    components
        The diagnoser's fitted components (the isolator is not used).
    runs
        Fault runs (coordinates ``state`` and, optionally, ``onset``): a dataset or a list.
    per_second
        Keep the detected seconds (the recalibration's rows) instead of the ages.
    window_ages
        With ``per_second``: the rows' ages are the signature window's complete seconds (what
        the online isolation's calibration reads) rather than the seconds since the detection.
    """
    rows, labels, ages = [], [], []
    detected: dict[str, list[bool]] = {}
    decision, detector = components.decision, components.detector
    if not per_second:  # signatures at ages after each detection: plain hysteresis, mean test
        decision = DetectionDecision(decision.threshold, decision.clear, decision.n_channels)
        if hasattr(detector, "mean_test"):
            detector = detector.mean_test()
    components = components._replace(isolator=None, decision=decision, detector=detector)
    for part in runs_as_list(runs):
        validate_dataset(part, require=CHANNELS, allow_nan=True)
        if "state" not in part.coords:
            raise ValueError("fault runs need a 'state' coordinate (the fault of each run)")
        states = [str(v) for v in np.asarray(part["state"].values).astype(str)]
        onset = np.zeros(len(states))
        if "onset" in part.coords:
            onset = np.asarray(part["onset"].values, dtype=np.float64)
        times = np.asarray(part["time"].values, dtype=np.float64)
        data = {
            c: np.asarray(part[c].transpose("run", "time").values, dtype=np.float64)
            for c in CHANNELS
        }
        for i, state in enumerate(states):
            if state == "fn":
                continue
            arrays = {c: np.ascontiguousarray(v[i]) for c, v in data.items()}
            out, _ = step(components, arrays, init_run_state(components))
            args = (out["DD"], out["features"], times, onset[i])
            if per_second:
                window = out["window_seconds"] if window_ages else None
                found, found_ages, hit = detected_seconds(*args, window_seconds=window)
            else:
                found, found_ages, hit = detection_signatures(*args)
            detected.setdefault(state, []).append(hit)
            rows += found
            labels += [state] * len(found)
            ages += found_ages
    X = np.asarray(rows, dtype=np.float64).reshape(-1, len(ISOLATION_FEATURES))
    return Signatures(X, np.asarray(labels, dtype=str), np.asarray(ages, dtype=np.int64), detected)


def fit_isolation(
    components: Components,
    fault_runs: Runs,
    validation_runs: Runs | None,
    calibration_runs: Runs | None,
    *,
    classifier: Any,
    calibrator: Any,
    group_threshold: float,
    detect_rate: float,
    max_signatures_per_fault: int,
    random_state: int | None,
    seconds: dict[str, float],
    group_rule: str = "pairwise",
) -> IsolationFit:
    """The isolator of `OnlineDiagnoser` (whose parameters the keywords are) from fault runs.

    The signatures of the training runs (`training_signatures`) train the classifier, those of
    the validation runs at least `GROUP_MIN_AGE` s after the detection find the isolability
    groups, those of every detected faulty second of the calibration runs
    (``training_signatures(..., per_second=True)``) fit the calibrator. Without validation or
    calibration runs, `split_fault_runs` splits ``fault_runs``. Faults detected in fewer than
    ``detect_rate`` of their training runs, or with fewer than 5 signatures, are undetectable
    and not classified; each fault keeps at most ``max_signatures_per_fault`` training rows
    (`training_rows`). ``seconds`` receives the timings. With
    ``group_rule="naming"`` (`~bayes_fdi.diagnosis.isolation.isolator.naming_confusion`) the
    groups come from every detected faulty second of the validation runs at least
    `GROUP_MIN_AGE` s after its detection (as the diagnoser names them, and as a benchmark
    scores them) instead of the signatures at `SIGNATURE_AGES`.
    """
    t0 = time.perf_counter()
    if validation_runs is None or calibration_runs is None:
        parts = [split_fault_runs(r) for r in runs_as_list(fault_runs)]
        train: Runs = [p[0] for p in parts]
        if validation_runs is None:
            validation_runs = [p[1] for p in parts]
        if calibration_runs is None:
            calibration_runs = [p[2] for p in parts]
    else:
        train = fault_runs
    X, y, _, detected = training_signatures(components, train)
    rates = {f: float(np.mean(v)) for f, v in detected.items()}
    per_second = group_rule == "naming"
    Xv, yv, av, _ = training_signatures(components, validation_runs, per_second=per_second)
    Xc, yc, ac, _ = training_signatures(
        components, calibration_runs, per_second=True, window_ages=True
    )
    seconds["signatures"] = time.perf_counter() - t0
    counts = {f: int(np.sum(y == f)) for f in rates}
    undetectable = sorted(
        (f for f in rates if rates[f] < detect_rate or counts[f] < 5), key=state_order
    )
    known = sorted(set(rates) - set(undetectable), key=state_order)
    rates = dict(sorted(rates.items(), key=lambda kv: state_order(kv[0])))
    if len(known) < 2:
        return IsolationFit(None, tuple(undetectable), rates, None)
    t0 = time.perf_counter()
    keep = training_rows(y, known, max_signatures_per_fault, random_state)
    vkeep = np.isin(yv, known) & (av >= GROUP_MIN_AGE)
    ckeep = np.isin(yc, known)
    isolator = FaultIsolator(
        classifier,
        calibrator=calibrator,
        group_threshold=group_threshold,
        group_rule=group_rule,
        random_state=random_state,
    ).fit(
        X[keep],
        y[keep],
        validation=(Xv[vkeep], yv[vkeep]) if vkeep.any() else None,
        calibration=(Xc[ckeep], yc[ckeep], ac[ckeep]) if ckeep.any() else None,
    )
    seconds["isolation"] = time.perf_counter() - t0
    counts = {
        "train": int(keep.size),
        "validation": int(vkeep.sum()),
        "calibration": int(ckeep.sum()),
    }
    return IsolationFit(isolator, tuple(undetectable), rates, counts)


def detection_components(diagnoser: Any) -> Components:
    """The fitted detection components of an `OnlineDiagnoser`, without its isolator: what
    the isolation's training signatures are streamed through."""
    return Components(
        normal_models=diagnoser.normal_models_,
        whiteners=PerOutput(diagnoser.whiteners_["X"], diagnoser.whiteners_["F"]),
        detector=diagnoser.detector_,
        decision=diagnoser.decision_,
        signature=diagnoser.signature_,
        envelope=diagnoser.envelope_,
        fit_proof=FitProof(diagnoser.fit_proof_seconds),
        isolator=None,
    )


def attach_isolation(
    diagnoser: Any,
    fault_runs: Runs,
    validation_runs: Runs | None,
    calibration_runs: Runs | None,
    *,
    seconds: dict[str, float],
) -> None:
    """Fit the isolation of ``diagnoser`` (an `OnlineDiagnoser` whose detection is fitted) on
    fault runs with `fit_isolation` and set its ``isolator_``, ``undetectable_``,
    ``detection_rates_`` (and ``n_signatures_``) in place; the diagnoser's parameters set the
    isolation's, ``seconds`` receives the timings."""
    fitted = fit_isolation(
        detection_components(diagnoser),
        fault_runs,
        validation_runs,
        calibration_runs,
        classifier=diagnoser.isolation_classifier,
        calibrator=diagnoser.calibrator,
        group_threshold=diagnoser.group_threshold,
        group_rule=diagnoser.group_rule,
        detect_rate=diagnoser.detect_rate,
        max_signatures_per_fault=diagnoser.max_signatures_per_fault,
        random_state=diagnoser.random_state,
        seconds=seconds,
    )
    diagnoser.isolator_, diagnoser.undetectable_ = fitted.isolator, fitted.undetectable
    diagnoser.detection_rates_ = fitted.detection_rates
    if fitted.n_signatures is not None:
        diagnoser.n_signatures_ = fitted.n_signatures

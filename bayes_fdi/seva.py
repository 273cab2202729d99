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
"""

from __future__ import annotations

import enum
import json
import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
import xarray as xr
from scipy import stats
from scipy.spatial import cKDTree

from bayes_fdi.datasets import CHANNELS, INPUT_CHANNELS

__all__ = [
    "DEFAULT_SATURATION_LIMITS",
    "ClassDistribution",
    "NoveltyReference",
    "SevaRecord",
    "SevaStatus",
    "SevaThresholds",
    "records_from_diagnosis",
    "screen_measurements",
    "seva_records",
    "to_frame",
    "to_json",
    "to_xarray",
]

#: Rails of the normalised channels (DABLib clips every measurement to [0, 1]).
DEFAULT_SATURATION_LIMITS: Mapping[str, tuple[float, float]] = {c: (0.0, 1.0) for c in CHANNELS}


class SevaStatus(enum.StrEnum):
    """Status of a self-validating actuator (Henry & Clarke 1993 naming)."""

    CLEAR = "CLEAR"
    BLURRED = "BLURRED"
    DAZZLED = "DAZZLED"
    BLIND = "BLIND"


class SevaThresholds(NamedTuple):
    """Decision thresholds of the SEVA status (immutable; ``_replace`` to change one).

    Attributes
    ----------
    p_clear
        CLEAR needs ``P(fault-free) >= p_clear`` (default 0.9).
    p_fault
        BLURRED needs the diagnosed fault's probability ``>= p_fault`` (default 0.8).
    max_entropy
        CLEAR and BLURRED need the normalised entropy ``H(p) / log(n_classes)`` (0 = certain,
        1 = uniform) ``<= max_entropy`` (default 0.5). With 10 classes a top probability of
        0.8 already implies an entropy <= 0.41, so this binds only for lower ``p_fault``.
    novelty_fraction
        DAZZLED when more than this fraction of a window's input samples are novel
        (nearest-neighbour distance ratio > 1, see :class:`NoveltyReference`) (default 0.2),
        or when the run's feature vector is novel (ratio > 1).
    max_missing
        BLIND when more than this fraction of a channel's samples are NaN/inf (default 0.2).
    max_saturated
        BLIND when more than this fraction of a channel's samples sit at a rail of
        ``saturation_limits`` (default 0.5: DABLib's F saturates under some faults, e.g. f18,
        without the record becoming useless).
    saturation_tol
        A sample is at a rail when within this distance of it, or beyond it (default 1e-9).
    fault_free
        Label of the fault-free state (default ``"fn"``).
    """

    p_clear: float = 0.9
    p_fault: float = 0.8
    max_entropy: float = 0.5
    novelty_fraction: float = 0.2
    max_missing: float = 0.2
    max_saturated: float = 0.5
    saturation_tol: float = 1e-9
    fault_free: str = "fn"

    def validate(self) -> SevaThresholds:
        """Raise ``ValueError`` naming a threshold outside its range; return self."""
        for name in ("p_clear", "p_fault", "max_entropy", "novelty_fraction"):
            v = getattr(self, name)
            if not 0 <= v <= 1:
                raise ValueError(f"{name} must lie in [0, 1], got {v}")
        for name in ("max_missing", "max_saturated"):
            v = getattr(self, name)
            if not 0 <= v < 1:
                raise ValueError(f"{name} must lie in [0, 1), got {v}")
        if self.saturation_tol < 0:
            raise ValueError("saturation_tol must be >= 0")
        return self


class ClassDistribution(Mapping[str, float]):
    """Immutable, ordered mapping ``class label -> probability`` (picklable, hashable)."""

    __slots__ = ("_items",)

    def __init__(self, items: Mapping[str, float] | Sequence[tuple[str, float]]) -> None:
        pairs = items.items() if isinstance(items, Mapping) else items
        self._items = tuple((str(k), float(v)) for k, v in pairs)

    def __getitem__(self, key: str) -> float:
        for k, v in self._items:
            if k == key:
                return v
        raise KeyError(key)

    def __iter__(self) -> Iterator[str]:
        return (k for k, _ in self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __hash__(self) -> int:
        return hash(self._items)

    def __eq__(self, other: object) -> bool:
        if isinstance(other, Mapping):
            return dict(self._items) == dict(other.items())
        return NotImplemented

    def __repr__(self) -> str:
        inner = ", ".join(f"{k!r}: {v:.3g}" for k, v in self._items)
        return f"ClassDistribution({{{inner}}})"

    def __reduce__(self):
        return (ClassDistribution, (self._items,))


@dataclass(frozen=True, slots=True)
class SevaRecord:
    """The SEVA output for one run or window (immutable).

    Attributes
    ----------
    run
        Run index (the dataset's ``run`` coordinate).
    t_start, t_end
        First and last time (s) of the window.
    x_measured, f_measured
        Mean measured X and F over the window's finite samples (NaN if none).
    x_vmv, f_vmv
        Validated measurement values: mean normal-model prediction of X and F.
    x_vu, f_vu
        Validated uncertainties: ``z * rms(predictive std)`` over the window, ``z`` the
        standard-normal quantile of ``coverage`` (the typical per-sample interval half-width,
        not the uncertainty of the window mean).
    coverage
        Central coverage of VMV ± VU (default 0.95).
    state
        Diagnosed state (the arg-max class; "" when none could be made).
    probability
        Probability of ``state``.
    distribution
        Full class distribution (class order of the diagnoser).
    entropy
        Normalised entropy ``H / log(n_classes)`` of ``distribution`` (0 certain, 1 uniform).
    status
        :class:`SevaStatus`.
    reasons
        Human-readable reasons for the status.
    missing_fraction, saturated_fraction
        Worst fraction over channels of missing and saturated samples.
    novel_fraction
        Fraction of window samples whose inputs are novel (NaN when not checked).
    feature_novelty
        Nearest-neighbour distance ratio of the run's feature vector (NaN when not checked).
    """

    run: int
    t_start: float
    t_end: float
    x_measured: float
    f_measured: float
    x_vmv: float
    x_vu: float
    f_vmv: float
    f_vu: float
    coverage: float
    state: str
    probability: float
    distribution: ClassDistribution
    entropy: float
    status: SevaStatus
    reasons: tuple[str, ...] = field(default=())
    missing_fraction: float = 0.0
    saturated_fraction: float = 0.0
    novel_fraction: float = math.nan
    feature_novelty: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python dict (JSON-ready: status as its name, distribution as a dict)."""
        d = {f: getattr(self, f) for f in self.__dataclass_fields__}
        d["status"] = self.status.value
        d["distribution"] = dict(self.distribution)
        d["reasons"] = list(self.reasons)
        return d


# --------------------------------------------------------------------------------------
# novelty
# --------------------------------------------------------------------------------------
class NoveltyReference:
    """How unlike the training samples new samples are (nearest-neighbour distance ratio).

    Fitted on training rows (e.g. the normal models' input samples CV, P1, P2, T1, or the
    classifier's training features): columns are standardised by the training mean and
    standard deviation; the *scale* is the ``quantile`` of every training sample's distance
    to its nearest other training sample. :meth:`score` returns, per new row, the distance
    to the nearest training row divided by the scale, so about ``1 - quantile`` of samples
    drawn like the training data score above 1, and samples far from all training data
    score >> 1.

    Parameters
    ----------
    quantile
        Quantile of the training nearest-neighbour distances used as the scale (default 0.99).
    max_points
        Training rows kept (a seeded random subset above this size; default 20000).
    random_state
        Seed of that subset.
    """

    def __init__(
        self, *, quantile: float = 0.99, max_points: int = 20_000, random_state: int | None = 0
    ) -> None:
        self.quantile = quantile
        self.max_points = max_points
        self.random_state = random_state

    def fit(self, X: Any) -> NoveltyReference:
        """Fit on training rows ``X`` of shape ``(n, d)`` (finite, n >= 3)."""
        X = np.asarray(X, dtype=np.float64)
        if X.ndim != 2 or X.shape[0] < 3:
            raise ValueError(f"NoveltyReference needs (n >= 3, d) training rows, got {X.shape}")
        if not np.all(np.isfinite(X)):
            raise ValueError("training rows contain NaN or inf")
        if not 0 < self.quantile < 1:
            raise ValueError("quantile must lie in (0, 1)")
        if X.shape[0] > self.max_points:
            rng = np.random.default_rng(self.random_state)
            X = X[rng.choice(X.shape[0], self.max_points, replace=False)]
        self.center_ = X.mean(axis=0)
        sd = X.std(axis=0)
        # constant columns (e.g. a fixed supply pressure) get the scale of the others, so
        # any departure from the constant counts
        floor = np.median(sd[sd > 0]) if np.any(sd > 0) else 1.0
        self.scale_ = np.where(sd > 0, sd, floor)
        Z = (X - self.center_) / self.scale_
        self.tree_ = cKDTree(Z)
        d, _ = self.tree_.query(Z, k=2)
        nn = d[:, 1]
        nn_pos = nn[nn > 0]
        self.threshold_ = float(np.quantile(nn_pos if nn_pos.size else nn, self.quantile))
        if not self.threshold_ > 0:
            self.threshold_ = 1e-12
        self.n_features_in_ = X.shape[1]
        self.n_samples_fit_ = X.shape[0]
        return self

    @classmethod
    def from_runs(
        cls, runs: xr.Dataset, channels: Sequence[str] = INPUT_CHANNELS, **kwargs: Any
    ) -> NoveltyReference:
        """Fit on every finite ``(run, time)`` sample of ``channels`` of a dataset."""
        X = _stack_samples(runs, channels)
        return cls(**kwargs).fit(X[np.all(np.isfinite(X), axis=1)])

    def score(self, X: Any) -> np.ndarray:
        """Nearest-training-row distance ratio per row (> 1: more remote than usual)."""
        if not hasattr(self, "tree_"):
            raise ValueError("NoveltyReference is not fitted; call fit first")
        X = np.asarray(X, dtype=np.float64)
        if X.ndim != 2 or X.shape[1] != self.n_features_in_:
            raise ValueError(f"expected (n, {self.n_features_in_}) rows, got {X.shape}")
        if not np.all(np.isfinite(X)):
            raise ValueError("rows to score contain NaN or inf")
        d, _ = self.tree_.query((X - self.center_) / self.scale_, k=1)
        return d / self.threshold_


def _stack_samples(runs: xr.Dataset, channels: Sequence[str]) -> np.ndarray:
    missing = [c for c in channels if c not in runs]
    if missing:
        raise ValueError(f"dataset lacks channel(s) {missing}")
    return np.stack([runs[c].values.reshape(-1) for c in channels], axis=1)


# --------------------------------------------------------------------------------------
# measurement screening (BLIND)
# --------------------------------------------------------------------------------------
def screen_measurements(
    runs: xr.Dataset,
    *,
    channels: Sequence[str] = CHANNELS,
    thresholds: SevaThresholds | None = None,
    saturation_limits: Mapping[str, tuple[float, float]] | None = None,
) -> dict[str, np.ndarray]:
    """Per-run missing and saturated fractions and a BLIND flag.

    Returns
    -------
    dict
        ``missing`` and ``saturated``: ``(n_runs, n_channels)`` fractions; ``blind``:
        ``(n_runs,)`` bool; ``reasons``: ``(n_runs,)`` object array of tuples of strings.
    """
    th = (thresholds or SevaThresholds()).validate()
    limits = dict(DEFAULT_SATURATION_LIMITS if saturation_limits is None else saturation_limits)
    absent = [c for c in channels if c not in runs]
    if absent:
        raise ValueError(f"dataset lacks channel(s) {absent}")
    n_runs = runs.sizes["run"]
    missing = np.zeros((n_runs, len(channels)))
    saturated = np.zeros((n_runs, len(channels)))
    for j, c in enumerate(channels):
        v = np.asarray(runs[c].transpose("run", "time").values, dtype=np.float64)
        bad = ~np.isfinite(v)
        missing[:, j] = bad.mean(axis=1)
        if c in limits:
            lo, hi = limits[c]
            with np.errstate(invalid="ignore"):
                rail = (v <= lo + th.saturation_tol) | (v >= hi - th.saturation_tol)
            saturated[:, j] = (rail & ~bad).mean(axis=1)
    blind = np.zeros(n_runs, dtype=bool)
    reasons = np.empty(n_runs, dtype=object)
    for i in range(n_runs):
        why = []
        for j, c in enumerate(channels):
            if missing[i, j] > th.max_missing:
                why.append(f"{c} missing in {missing[i, j]:.0%} of samples")
            if saturated[i, j] > th.max_saturated:
                why.append(f"{c} saturated in {saturated[i, j]:.0%} of samples")
        blind[i] = bool(why)
        reasons[i] = tuple(why)
    return {"missing": missing, "saturated": saturated, "blind": blind, "reasons": reasons}


# --------------------------------------------------------------------------------------
# records
# --------------------------------------------------------------------------------------
def _entropy(p: np.ndarray) -> float:
    if p.size < 2 or not np.all(np.isfinite(p)):
        return math.nan
    q = p[p > 0]
    return float(-np.sum(q * np.log(q)) / np.log(p.size))


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
) -> list[SevaRecord]:
    """Build one :class:`SevaRecord` per run from a diagnosis and the measured runs.

    Parameters
    ----------
    diagnosis
        The output of ``FaultDiagnoser.diagnose(runs)`` (dims ``run``, ``class``[, ``time``];
        variables ``proba``, ``X_hat``, ``X_hat_std``, ``F_hat``, ``F_hat_std``, optionally
        ``features``), with the same runs in the same order as ``runs``. Runs whose
        distribution is NaN (e.g. not diagnosed because BLIND) get an empty state. ``None``:
        every run must be BLIND (used by :func:`seva_records` when no run is usable).
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
        Fitted :class:`NoveltyReference` of the classifier's training features; None skips it.
    input_channels
        Columns of ``input_reference``.
    saturation_limits
        Rails per channel (default :data:`DEFAULT_SATURATION_LIMITS`).

    Returns
    -------
    list of SevaRecord
    """
    th = (thresholds or SevaThresholds()).validate()
    if not 0 < coverage < 1:
        raise ValueError(f"coverage must lie in (0, 1), got {coverage}")
    if "run" not in runs.dims or "time" not in runs.dims:
        raise ValueError("runs must have dims 'run' and 'time'")
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
    channels = [c for c in CHANNELS if c in runs]
    screen = screen_measurements(
        runs, channels=channels, thresholds=th, saturation_limits=saturation_limits
    )
    z = float(stats.norm.ppf(0.5 + coverage / 2.0))
    times = np.asarray(runs["time"].values, dtype=np.float64)
    run_ids = np.asarray(runs["run"].values) if "run" in runs.coords else np.arange(n_runs)
    if diagnosis is not None:
        if "proba" not in diagnosis:
            raise ValueError("diagnosis lacks 'proba'")
        classes = [str(c) for c in diagnosis["class"].values]
        proba = np.asarray(diagnosis["proba"].transpose("run", "class").values, dtype=np.float64)
    else:
        if not screen["blind"].all():
            raise ValueError("diagnosis is None but some runs are not BLIND")
        classes, proba = [], np.full((n_runs, 0), np.nan)

    def per_time(name: str) -> np.ndarray:
        if diagnosis is None or name not in diagnosis:
            return np.full((n_runs, 1), np.nan)
        v = diagnosis[name]
        return np.asarray(v.transpose("run", ...).values, dtype=np.float64).reshape(n_runs, -1)

    x_hat, x_std, f_hat, f_std = (per_time(k) for k in ("X_hat", "X_hat_std", "F_hat", "F_hat_std"))
    feats = None
    if feature_reference is not None and diagnosis is not None and "features" in diagnosis:
        feats = np.asarray(diagnosis["features"].transpose("run", ...).values, dtype=np.float64)

    records = []
    for i in range(n_runs):
        reasons: list[str] = []
        p = proba[i]
        diagnosed = p.size > 0 and np.all(np.isfinite(p))
        if diagnosed:
            k = int(np.argmax(p))
            state, prob = classes[k], float(p[k])
        else:
            state, prob = "", math.nan
        ent = _entropy(p) if diagnosed else math.nan
        # novelty of the inputs, sample by sample, on the finite samples
        novel_frac = math.nan
        if input_reference is not None:
            U = np.stack(
                [np.asarray(runs[c].isel(run=i).values, dtype=np.float64) for c in input_channels],
                axis=1,
            )
            ok = np.all(np.isfinite(U), axis=1)
            if ok.any():
                novel_frac = float(np.mean(input_reference.score(U[ok]) > 1.0))
        feat_nov = math.nan
        if feats is not None and np.all(np.isfinite(feats[i])):
            feat_nov = float(feature_reference.score(feats[i][None, :])[0])

        if screen["blind"][i]:
            status = SevaStatus.BLIND
            reasons.extend(screen["reasons"][i])
        elif not diagnosed:
            status = SevaStatus.DAZZLED
            reasons.append("no class distribution available")
        else:
            novel_in = np.isfinite(novel_frac) and novel_frac > th.novelty_fraction
            novel_ft = np.isfinite(feat_nov) and feat_nov > 1.0
            if novel_in:
                reasons.append(
                    f"inputs unlike training in {novel_frac:.0%} of samples "
                    f"(> {th.novelty_fraction:.0%})"
                )
            if novel_ft:
                reasons.append(f"residual features unlike training (ratio {feat_nov:.2g} > 1)")
            flat = ent > th.max_entropy
            if flat:
                reasons.append(
                    f"class distribution too flat (entropy {ent:.2f} > {th.max_entropy})"
                )
            if state == th.fault_free:
                confident = prob >= th.p_clear
                if not confident:
                    reasons.append(f"P({state}) = {prob:.3f} < p_clear = {th.p_clear}")
                ok_status = SevaStatus.CLEAR
            else:
                confident = prob >= th.p_fault
                if not confident:
                    reasons.append(f"P({state}) = {prob:.3f} < p_fault = {th.p_fault}")
                ok_status = SevaStatus.BLURRED
            if confident and not flat and not novel_in and not novel_ft:
                status = ok_status
                reasons.append(
                    f"P({state}) = {prob:.3f} >= "
                    f"{th.p_clear if ok_status is SevaStatus.CLEAR else th.p_fault}"
                )
            else:
                status = SevaStatus.DAZZLED
        if input_reference is None and status is not SevaStatus.BLIND:
            reasons.append("input novelty not checked (no input reference)")

        xm = np.asarray(runs["X"].isel(run=i).values) if "X" in runs else np.array([np.nan])
        fm = np.asarray(runs["F"].isel(run=i).values) if "F" in runs else np.array([np.nan])
        records.append(
            SevaRecord(
                run=int(run_ids[i]),
                t_start=float(times[0]),
                t_end=float(times[-1]),
                x_measured=_nanmean(xm),
                f_measured=_nanmean(fm),
                x_vmv=_nanmean(x_hat[i]),
                x_vu=z * _rms(x_std[i]),
                f_vmv=_nanmean(f_hat[i]),
                f_vu=z * _rms(f_std[i]),
                coverage=float(coverage),
                state=state,
                probability=prob,
                distribution=ClassDistribution(
                    list(zip(classes, p.tolist(), strict=True)) if diagnosed else []
                ),
                entropy=ent,
                status=status,
                reasons=tuple(reasons),
                missing_fraction=float(screen["missing"][i].max(initial=0.0)),
                saturated_fraction=float(screen["saturated"][i].max(initial=0.0)),
                novel_fraction=novel_frac,
                feature_novelty=feat_nov,
            )
        )
    return records


def seva_records(
    diagnoser: Any,
    runs: xr.Dataset,
    *,
    thresholds: SevaThresholds | None = None,
    coverage: float = 0.95,
    input_reference: NoveltyReference | None = None,
    feature_reference: NoveltyReference | None = None,
    saturation_limits: Mapping[str, tuple[float, float]] | None = None,
) -> list[SevaRecord]:
    """Diagnose ``runs`` with a fitted diagnoser and return their SEVA records.

    BLIND runs (missing/saturated signals) are not passed to ``diagnoser.diagnose``; they get
    a record with an empty distribution. The novelty references default to the diagnoser's
    ``input_reference_`` and ``feature_reference_`` attributes when it has them.
    """
    th = (thresholds or SevaThresholds()).validate()
    input_reference = input_reference or getattr(diagnoser, "input_reference_", None)
    feature_reference = feature_reference or getattr(diagnoser, "feature_reference_", None)
    channels = [c for c in CHANNELS if c in runs]
    screen = screen_measurements(
        runs, channels=channels, thresholds=th, saturation_limits=saturation_limits
    )
    usable = np.flatnonzero(~screen["blind"])
    diag = None
    if usable.size:
        part = diagnoser.diagnose(runs.isel(run=usable))
        if usable.size == runs.sizes["run"]:
            diag = part
        else:
            # NaN rows for BLIND runs: never diagnosed, never shown as a diagnosis
            names = ("proba", "X_hat", "X_hat_std", "F_hat", "F_hat_std", "features")
            part = part[[v for v in names if v in part.data_vars]]
            part = part.assign_coords(run=runs["run"].values[usable])
            diag = part.reindex(run=runs["run"].values)
    return records_from_diagnosis(
        diag,
        runs,
        thresholds=th,
        coverage=coverage,
        input_reference=input_reference,
        feature_reference=feature_reference,
        saturation_limits=saturation_limits,
    )


def diag_vars(ds: xr.Dataset) -> list[str]:
    return list(ds.data_vars)


# --------------------------------------------------------------------------------------
# conversions
# --------------------------------------------------------------------------------------
_SCALAR_FIELDS = (
    "run", "t_start", "t_end", "x_measured", "f_measured", "x_vmv", "x_vu", "f_vmv", "f_vu",
    "coverage", "state", "probability", "entropy", "status", "missing_fraction",
    "saturated_fraction", "novel_fraction", "feature_novelty",
)  # fmt: skip


def _all_classes(records: Sequence[SevaRecord]) -> list[str]:
    classes: list[str] = []
    for r in records:
        for c in r.distribution:
            if c not in classes:
                classes.append(c)
    return classes


def to_frame(records: Sequence[SevaRecord]):
    """A :class:`pandas.DataFrame`, one row per record, indexed by run.

    The class distribution becomes columns ``p_<class>`` (NaN where absent); ``reasons`` is
    joined with ``"; "``; ``status`` is its string value.
    """
    import pandas as pd

    classes = _all_classes(records)
    rows = []
    for r in records:
        row = {f: getattr(r, f) for f in _SCALAR_FIELDS}
        row["status"] = r.status.value
        row.update({f"p_{c}": r.distribution.get(c, math.nan) for c in classes})
        row["reasons"] = "; ".join(r.reasons)
        rows.append(row)
    cols = [*_SCALAR_FIELDS, *(f"p_{c}" for c in classes), "reasons"]
    return pd.DataFrame(rows, columns=cols).set_index("run")


def to_xarray(records: Sequence[SevaRecord]) -> xr.Dataset:
    """An :class:`xarray.Dataset` with dims ``run`` and ``class``.

    Scalar fields become ``(run,)`` variables, the distribution a ``proba (run, class)``
    variable (NaN where absent), ``reasons`` a ``(run,)`` string variable.
    """
    classes = _all_classes(records)
    run = np.array([r.run for r in records], dtype=np.int64)
    data: dict[str, Any] = {}
    for f in _SCALAR_FIELDS[1:]:
        if f not in ("state", "status"):
            data[f] = ("run", np.asarray([getattr(r, f) for r in records], dtype=np.float64))
    data["state"] = ("run", np.asarray([r.state for r in records], dtype=str))
    data["status"] = ("run", np.asarray([r.status.value for r in records], dtype=str))
    data["reasons"] = ("run", np.asarray(["; ".join(r.reasons) for r in records], dtype=str))
    proba = np.array([[r.distribution.get(c, math.nan) for c in classes] for r in records])
    data["proba"] = (("run", "class"), proba.reshape(len(records), len(classes)))
    return xr.Dataset(data, coords={"run": run, "class": np.asarray(classes, dtype=str)})


def _json_safe(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: _json_safe(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_json_safe(x) for x in v]
    return v


def to_json(records: Sequence[SevaRecord], *, indent: int | None = 2) -> str:
    """JSON text: a list of :meth:`SevaRecord.to_dict` objects (NaN written as ``null``)."""
    return json.dumps([_json_safe(r.to_dict()) for r in records], indent=indent)

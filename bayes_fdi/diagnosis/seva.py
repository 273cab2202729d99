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

from bayes_fdi.datasets import CHANNELS, INPUT_CHANNELS, OUTPUT_CHANNELS

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
    novelty_ratio
        A sample (or a feature vector) is *novel* when its nearest-neighbour distance ratio
        (:class:`NoveltyReference`: distance to the nearest training row over the 99 % quantile
        of the training rows' own nearest-neighbour distances) exceeds this (default 1.5).
        About 1 % of samples drawn like the training data exceed ratio 1, so 1 would flag
        ordinary runs of small training sets; 1.5 leaves room for that sampling noise while
        inputs or residual features outside the training envelope score far higher.
    novelty_fraction
        DAZZLED when more than this fraction of a window's input samples are novel
        (default 0.2), or when the run's feature vector is novel.
    max_missing
        BLIND when more than this fraction of a channel's samples are NaN/inf (default 0.2).
    max_saturated
        BLIND when more than this fraction of an *input* channel's samples (CV, P1, P2, T1)
        sit at a rail of ``saturation_limits`` (default 0.5): the normal models cannot be
        evaluated on them.
    max_output_saturated
        BLIND when more than this fraction of an *output* channel's samples (X, F) sit at a
        rail (default 1.0: never). In the DAMADICS benchmark F' saturates at its 40 t/h range
        even fault-free (about 40 % of the samples of paper-simulated fn runs) and
        saturation is a learned symptom of f1, f6 and f18, so a saturated output is reported
        in ``reasons`` (from ``max_saturated`` on) but does not blind the diagnosis. Lower it
        for plants where a railed output means a broken sensor.
    saturation_tol
        A sample is at a rail when within this distance of it, or beyond it (default 1e-9).
    fault_free
        Label of the fault-free state (default ``"fn"``).
    """

    p_clear: float = 0.9
    p_fault: float = 0.8
    max_entropy: float = 0.5
    novelty_ratio: float = 1.5
    novelty_fraction: float = 0.2
    max_missing: float = 0.2
    max_saturated: float = 0.5
    max_output_saturated: float = 1.0
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
        if not 0 <= self.max_output_saturated <= 1:
            raise ValueError(
                f"max_output_saturated must lie in [0, 1], got {self.max_output_saturated}"
            )
        if not self.novelty_ratio > 0:
            raise ValueError(f"novelty_ratio must be > 0, got {self.novelty_ratio}")
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
    window
        Window index within the run for windowed diagnoses, else None.
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
    window: int | None = None

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
def _screen_one(
    values: Mapping[str, np.ndarray],
    th: SevaThresholds,
    limits: Mapping[str, tuple[float, float]],
) -> tuple[np.ndarray, np.ndarray, tuple[str, ...], tuple[str, ...]]:
    """Missing/saturated fractions per channel of one run/window, BLIND reasons and notes."""
    names = list(values)
    missing = np.zeros(len(names))
    saturated = np.zeros(len(names))
    why, notes = [], []
    for j, c in enumerate(names):
        v = np.asarray(values[c], dtype=np.float64)
        if v.size == 0:
            raise ValueError("a run or window holds no samples")
        bad = ~np.isfinite(v)
        missing[j] = bad.mean()
        if c in limits:
            lo, hi = limits[c]
            with np.errstate(invalid="ignore"):
                rail = (v <= lo + th.saturation_tol) | (v >= hi - th.saturation_tol)
            saturated[j] = (rail & ~bad).mean()
        if missing[j] > th.max_missing:
            why.append(f"{c} missing in {missing[j]:.0%} of samples")
        limit = th.max_output_saturated if c in OUTPUT_CHANNELS else th.max_saturated
        if saturated[j] > limit:
            why.append(f"{c} saturated in {saturated[j]:.0%} of samples")
        elif saturated[j] > th.max_saturated:
            notes.append(f"{c} at a rail in {saturated[j]:.0%} of samples (measured mean clipped)")
    return missing, saturated, tuple(why), tuple(notes)


def screen_measurements(
    runs: xr.Dataset,
    *,
    channels: Sequence[str] = CHANNELS,
    thresholds: SevaThresholds | None = None,
    saturation_limits: Mapping[str, tuple[float, float]] | None = None,
) -> dict[str, np.ndarray]:
    """Per-run missing and saturated fractions and a BLIND flag.

    A sample is missing when NaN/inf, saturated when within ``saturation_tol`` of (or beyond)
    a rail of ``saturation_limits`` (default: [0, 1] for every normalised channel). BLIND
    rules: see :class:`SevaThresholds` (``max_missing``, ``max_saturated`` for inputs,
    ``max_output_saturated`` for X and F).

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
    arrays = {c: np.asarray(runs[c].transpose("run", "time").values) for c in channels}
    missing = np.zeros((n_runs, len(channels)))
    saturated = np.zeros((n_runs, len(channels)))
    blind = np.zeros(n_runs, dtype=bool)
    reasons = np.empty(n_runs, dtype=object)
    for i in range(n_runs):
        missing[i], saturated[i], why, _ = _screen_one(
            {c: a[i] for c, a in arrays.items()}, th, limits
        )
        blind[i] = bool(why)
        reasons[i] = why
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


def _status(
    th: SevaThresholds,
    blind_reasons: tuple[str, ...],
    state: str,
    prob: float,
    ent: float,
    diagnosed: bool,
    novel_frac: float,
    feat_nov: float,
) -> tuple[SevaStatus, list[str]]:
    """The SEVA decision rules, in order: BLIND, DAZZLED, then CLEAR or BLURRED."""
    if blind_reasons:
        return SevaStatus.BLIND, list(blind_reasons)
    if not diagnosed:
        return SevaStatus.DAZZLED, ["no class distribution available"]
    reasons: list[str] = []
    novel_in = np.isfinite(novel_frac) and novel_frac > th.novelty_fraction
    novel_ft = np.isfinite(feat_nov) and feat_nov > th.novelty_ratio
    if novel_in:
        reasons.append(
            f"inputs unlike training in {novel_frac:.0%} of samples (> {th.novelty_fraction:.0%})"
        )
    if novel_ft:
        reasons.append(
            f"residual features unlike training (ratio {feat_nov:.2g} > {th.novelty_ratio})"
        )
    flat = ent > th.max_entropy
    if flat:
        reasons.append(f"distribution too flat (entropy {ent:.2f} > {th.max_entropy})")
    if state == th.fault_free:
        ok_status, need = SevaStatus.CLEAR, ("p_clear", th.p_clear)
    else:
        ok_status, need = SevaStatus.BLURRED, ("p_fault", th.p_fault)
    confident = prob >= need[1]
    if not confident:
        reasons.append(f"P({state}) = {prob:.3f} < {need[0]} = {need[1]}")
    if confident and not (flat or novel_in or novel_ft):
        return ok_status, [f"P({state}) = {prob:.3f} >= {need[0]} = {need[1]}"]
    return SevaStatus.DAZZLED, reasons


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
    channels = [c for c in CHANNELS if c in runs]
    arrays = {c: np.asarray(runs[c].transpose("run", "time").values) for c in channels}
    times = np.asarray(runs["time"].values, dtype=np.float64)
    run_ids = np.asarray(runs["run"].values) if "run" in runs.coords else np.arange(n_runs)
    z = float(stats.norm.ppf(0.5 + coverage / 2.0))

    windowed = diagnosis is not None and "window" in diagnosis["proba"].dims
    if diagnosis is not None:
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
    else:
        blind = screen_measurements(runs, channels=channels, thresholds=th,
                                    saturation_limits=limits)["blind"]  # fmt: skip
        if not blind.all():
            raise ValueError("diagnosis is None but some runs are not BLIND")
        classes, proba = [], np.full((n_runs, 1, 0), np.nan)
    n_win = proba.shape[1]
    if windowed:
        w_start = np.asarray(diagnosis["window_start"].values, dtype=np.float64)
        w_end = np.asarray(diagnosis["window_end"].values, dtype=np.float64)
    else:
        w_start, w_end = np.array([times[0]]), np.array([np.inf])

    def per_time(name: str) -> np.ndarray:
        if diagnosis is None or name not in diagnosis:
            return np.full((n_runs, times.size), np.nan)
        v = diagnosis[name].transpose("run", ...)
        return np.asarray(v.values, dtype=np.float64).reshape(n_runs, -1)

    x_hat, x_std, f_hat, f_std = (per_time(k) for k in ("X_hat", "X_hat_std", "F_hat", "F_hat_std"))
    feats = None
    if feature_reference is not None and diagnosis is not None and "features" in diagnosis:
        fv = diagnosis["features"].transpose(*(("run", "window") if windowed else ("run",)), ...)
        feats = np.asarray(fv.values, dtype=np.float64).reshape(n_runs, n_win, -1)
    novel_all = None
    if input_reference is not None:
        U = np.stack([np.asarray(runs[c].transpose("run", "time").values, dtype=np.float64)
                      for c in input_channels], axis=-1)  # fmt: skip
        ok = np.all(np.isfinite(U), axis=-1)
        novel_all = np.full(ok.shape, np.nan)
        novel_all[ok] = input_reference.score(U[ok]) > th.novelty_ratio

    records = []
    for i in range(n_runs):
        for w in range(n_win):
            tm = (times >= w_start[w]) & (times < w_end[w])
            if not tm.any():
                raise ValueError(f"window {w} holds no samples of run {i}")
            missing, saturated, blind_why, notes = _screen_one(
                {c: a[i, tm] for c, a in arrays.items()}, th, limits
            )
            if not_diagnosed and i in not_diagnosed and not blind_why:
                blind_why = tuple(f"run not diagnosed: {r}" for r in not_diagnosed[i])
            p = proba[i, w]
            diagnosed = p.size > 0 and bool(np.all(np.isfinite(p)))
            if diagnosed:
                k = int(np.argmax(p))
                state, prob, ent = classes[k], float(p[k]), _entropy(p)
            else:
                state, prob, ent = "", math.nan, math.nan
            novel_frac = math.nan
            if novel_all is not None:
                nv = novel_all[i, tm]
                nv = nv[np.isfinite(nv)]
                novel_frac = float(nv.mean()) if nv.size else math.nan
            feat_nov = math.nan
            if feats is not None and np.all(np.isfinite(feats[i, w])):
                feat_nov = float(feature_reference.score(feats[i, w][None, :])[0])
            status, reasons = _status(th, blind_why, state, prob, ent, diagnosed, novel_frac,
                                      feat_nov)  # fmt: skip
            if input_reference is None and status is not SevaStatus.BLIND:
                reasons.append("input novelty not checked (no input reference)")
            reasons.extend(notes)
            t_sel = times[tm]
            records.append(
                SevaRecord(
                    run=int(run_ids[i]),
                    t_start=float(t_sel[0]),
                    t_end=float(t_sel[-1]),
                    x_measured=_nanmean(arrays["X"][i, tm]) if "X" in arrays else math.nan,
                    f_measured=_nanmean(arrays["F"][i, tm]) if "F" in arrays else math.nan,
                    x_vmv=_nanmean(x_hat[i, tm]),
                    x_vu=z * _rms(x_std[i, tm]),
                    f_vmv=_nanmean(f_hat[i, tm]),
                    f_vu=z * _rms(f_std[i, tm]),
                    coverage=float(coverage),
                    state=state,
                    probability=prob,
                    distribution=ClassDistribution(
                        list(zip(classes, p.tolist(), strict=True)) if diagnosed else []
                    ),
                    entropy=ent,
                    status=status,
                    reasons=tuple(reasons),
                    missing_fraction=float(missing.max(initial=0.0)),
                    saturated_fraction=float(saturated.max(initial=0.0)),
                    novel_fraction=novel_frac,
                    feature_novelty=feat_nov,
                    window=w if windowed else None,
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
        part = diagnoser.diagnose(runs.isel(run=usable))
        if usable.size == runs.sizes["run"]:
            diag = part
        else:
            # NaN rows for BLIND runs: never diagnosed, never shown as a diagnosis
            names = ("proba", "X_hat", "X_hat_std", "F_hat", "F_hat_std", "features")
            part = part[[v for v in names if v in part.data_vars]]
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


# --------------------------------------------------------------------------------------
# conversions
# --------------------------------------------------------------------------------------
_SCALAR_FIELDS = (
    "run", "window", "t_start", "t_end", "x_measured", "f_measured", "x_vmv", "x_vu", "f_vmv",
    "f_vu", "coverage", "state", "probability", "entropy", "status", "missing_fraction",
    "saturated_fraction", "novel_fraction", "feature_novelty",
)  # fmt: skip


def _all_classes(records: Sequence[SevaRecord]) -> list[str]:
    classes: list[str] = []
    for r in records:
        for c in r.distribution:
            if c not in classes:
                classes.append(c)
    return classes


def _windowed(records: Sequence[SevaRecord]) -> bool:
    return any(r.window is not None for r in records)


def to_frame(records: Sequence[SevaRecord]):
    """A :class:`pandas.DataFrame`, one row per record.

    Indexed by ``run`` (or ``(run, window)`` for windowed records). The class distribution
    becomes columns ``p_<class>`` (NaN where absent); ``reasons`` is joined with ``"; "``;
    ``status`` is its string value.
    """
    import pandas as pd

    classes = _all_classes(records)
    windowed = _windowed(records)
    fields = [f for f in _SCALAR_FIELDS if windowed or f != "window"]
    rows = []
    for r in records:
        row = {f: getattr(r, f) for f in fields}
        row["status"] = r.status.value
        if windowed:
            row["window"] = -1 if r.window is None else r.window
        row.update({f"p_{c}": r.distribution.get(c, math.nan) for c in classes})
        row["reasons"] = "; ".join(r.reasons)
        rows.append(row)
    cols = [*fields, *(f"p_{c}" for c in classes), "reasons"]
    return pd.DataFrame(rows, columns=cols).set_index(["run", "window"] if windowed else "run")


def to_xarray(records: Sequence[SevaRecord]) -> xr.Dataset:
    """An :class:`xarray.Dataset` of the records.

    Dims ``run`` and ``class`` (windowed records: ``record`` and ``class``, with ``run`` and
    ``window`` coordinates on ``record``; window -1 for records without one). Scalar fields
    become variables along the first dim, the distribution ``proba (.., class)`` (NaN where
    absent), ``reasons`` a string variable.
    """
    classes = _all_classes(records)
    windowed = _windowed(records)
    dim = "record" if windowed else "run"
    data: dict[str, Any] = {}
    for f in _SCALAR_FIELDS:
        if f in ("run", "window", "state", "status"):
            continue
        data[f] = (dim, np.asarray([getattr(r, f) for r in records], dtype=np.float64))
    data["state"] = (dim, np.asarray([r.state for r in records], dtype=str))
    data["status"] = (dim, np.asarray([r.status.value for r in records], dtype=str))
    data["reasons"] = (dim, np.asarray(["; ".join(r.reasons) for r in records], dtype=str))
    proba = np.array([[r.distribution.get(c, math.nan) for c in classes] for r in records])
    data["proba"] = ((dim, "class"), proba.reshape(len(records), len(classes)))
    run = np.array([r.run for r in records], dtype=np.int64)
    coords: dict[str, Any] = {"class": np.asarray(classes, dtype=str)}
    if windowed:
        win = np.array([-1 if r.window is None else r.window for r in records], dtype=np.int64)
        coords |= {"run": (dim, run), "window": (dim, win)}
    else:
        coords["run"] = run
    return xr.Dataset(data, coords=coords)


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

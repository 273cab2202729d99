"""The SEVA decision rules: thresholds, measurement screening (BLIND) and the status rules.

:class:`SevaThresholds` holds every threshold; :func:`screen_measurements` finds runs (or
windows) without usable measurements; :func:`decide_status` applies the rules in order
(BLIND, DAZZLED, then CLEAR or BLURRED) to one diagnosis.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np
import xarray as xr

from bayes_fdi.datasets import CHANNELS, OUTPUT_CHANNELS
from bayes_fdi.diagnosis.seva.record import SevaStatus

__all__ = [
    "DEFAULT_SATURATION_LIMITS",
    "SevaThresholds",
    "decide_status",
    "entropy",
    "screen_measurements",
]

#: Rails of the normalised channels (DABLib clips every measurement to [0, 1]).
DEFAULT_SATURATION_LIMITS: Mapping[str, tuple[float, float]] = {c: (0.0, 1.0) for c in CHANNELS}


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


def screen_window(
    values: Mapping[str, np.ndarray],
    th: SevaThresholds,
    limits: Mapping[str, tuple[float, float]],
) -> tuple[np.ndarray, np.ndarray, tuple[str, ...], tuple[str, ...]]:
    """Screen one run or window: missing and saturated fractions, BLIND reasons and notes.

    Parameters
    ----------
    values
        ``{channel: samples}`` of the run or window.
    th
        The thresholds (``max_missing``, ``max_saturated``, ``max_output_saturated``,
        ``saturation_tol``).
    limits
        Rails per channel.

    Returns
    -------
    missing, saturated : numpy.ndarray
        Fractions per channel (in the order of ``values``).
    blind_reasons, notes : tuple of str
        Why the window is BLIND (empty: it is not) and notes on railed outputs.
    """
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
        missing[i], saturated[i], why, _ = screen_window(
            {c: a[i] for c, a in arrays.items()}, th, limits
        )
        blind[i] = bool(why)
        reasons[i] = why
    return {"missing": missing, "saturated": saturated, "blind": blind, "reasons": reasons}


def entropy(p: np.ndarray) -> float:
    """Normalised Shannon entropy ``H(p) / log(len(p))`` (NaN for < 2 classes or NaN entries)."""
    if p.size < 2 or not np.all(np.isfinite(p)):
        return math.nan
    q = p[p > 0]
    return float(-np.sum(q * np.log(q)) / np.log(p.size))


def decide_status(
    th: SevaThresholds,
    blind_reasons: tuple[str, ...],
    state: str,
    prob: float,
    ent: float,
    diagnosed: bool,
    novel_frac: float,
    feat_nov: float,
) -> tuple[SevaStatus, list[str]]:
    """The SEVA decision rules, in order: BLIND, DAZZLED, then CLEAR or BLURRED.

    ``novel_frac`` (share of novel input samples) and ``feat_nov`` (feature novelty ratio) are
    NaN when not checked; an infinite ratio (a feature vector infinitely far from the training
    rows, or a zero scale) counts as novel.

    Returns
    -------
    status : SevaStatus
    reasons : list of str
    """
    if blind_reasons:
        return SevaStatus.BLIND, list(blind_reasons)
    if not diagnosed:
        return SevaStatus.DAZZLED, ["no class distribution available"]
    reasons: list[str] = []
    # NaN means "not checked"; +inf is as novel as it gets (NaN > x is False, inf > x True)
    novel_in = bool(novel_frac > th.novelty_fraction)
    novel_ft = bool(feat_nov > th.novelty_ratio)
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

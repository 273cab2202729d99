"""The decision stream of the online diagnoser: the per-second decisions and the stream dataset.

`decide` turns one run's per-second quantities (detection, isolation probabilities, novelty,
input envelope) into the SEVA decisions: the diagnosed state and its probability, the SEVA
status, the indicated isolability group, fault-free indication and the novelty flags; it does
no arithmetic on the measurements. `assemble_stream` lays the runs' quantities and decisions out
as the stream dataset `OnlineDiagnoser.run` returns (its variables are listed in that method's
docstring and in ``docs/online.md``).
"""

from __future__ import annotations

import functools
import json
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr
from scipy import stats as sps

from bayes_fdi.datasets import CHANNELS
from bayes_fdi.diagnosis.isolation.signatures import ISOLATION_FEATURES
from bayes_fdi.diagnosis.seva.record import SevaStatus

__all__ = [
    "FAULTS",
    "MISMATCH",
    "MODEL_OUTPUTS",
    "NOVELTY_FLAGS",
    "NO_FAULT",
    "UNKNOWN",
    "UNNAMED_STATES",
    "assemble_stream",
    "coverage_quantile",
    "decide",
    "stream_attrs",
]

#: The fault names of the stream's ``fault`` coordinate.
FAULTS: tuple[str, ...] = tuple(f"f{i}" for i in range(1, 20))
#: The state of a detection whose estimated change began while the inputs lay outside the normal
#: models' envelope: the model does not fit this valve or operating point, which is not a fault.
MISMATCH = "mismatch"
#: The state of a detection the diagnoser cannot name: it has no fault library, or the
#: signature is unlike every fault it knows.
UNKNOWN = "unknown"
#: The state of a second without detection.
NO_FAULT = "fn"
#: The states that name no isolability group (in this order after the groups in `decide`).
UNNAMED_STATES = (MISMATCH, UNKNOWN, NO_FAULT)
#: A statistic at or above this share of the threshold counts as raising the detection.
RAISED_SHARE = 0.5
#: The normal models' outputs in the stream.
MODEL_OUTPUTS = ("X_hat", "X_hat_std", "F_hat", "F_hat_std")
#: The stream's flags of what makes a second DAZZLED (with a detection not yet isolated).
NOVELTY_FLAGS = ("novel_inputs", "novel_signature", "novel_onset", "unproven_onset")


@functools.lru_cache(maxsize=16)
def coverage_quantile(coverage: float) -> float:
    """The standard normal quantile ``z`` of a two-sided ``coverage`` (1.96 for 0.95)."""
    return float(sps.norm.ppf(0.5 + coverage / 2.0))


def evidence(out: Mapping[str, Any], threshold: float) -> np.ndarray:
    """Per second of detection, which residual raised it and its sign: ``"X high"``,
    ``"F low"``, ``"X low, F high"``; ``""`` while DD is off.

    An output counts when its detector statistic is at least `RAISED_SHARE` of the threshold,
    or when its statistic is the larger one; its sign is that of its mean residual over the
    window since the detection (the isolation signature's ``mean_rX``, ``mean_rF``), or of the
    second's innovation before the window has a value.
    """
    dd = np.asarray(out["DD"], dtype=bool)
    stats = np.column_stack([out["stat_X"], out["stat_F"]])
    feats = np.asarray(out["features"])
    means = (
        feats[:, :2] if feats.ndim == 2 and feats.shape[1] >= 2 else np.full(stats.shape, np.nan)
    )
    innovations = np.column_stack([out["r_X"], out["r_F"]])
    sign = np.where(np.isfinite(means), np.sign(means), np.sign(innovations))
    with np.errstate(invalid="ignore"):
        top = np.nanargmax(np.where(np.isfinite(stats), stats, -np.inf), axis=1)
        raised = (stats >= RAISED_SHARE * threshold) | (np.arange(2)[None, :] == top[:, None])
    words = np.full(dd.size, "", dtype=object)
    for t in np.flatnonzero(dd):
        parts = [
            f"{c} {'high' if sign[t, j] > 0 else 'low'}"
            for j, c in enumerate(("X", "F"))
            if raised[t, j] and sign[t, j] != 0 and np.isfinite(sign[t, j])
        ]
        words[t] = ", ".join(parts)
    return words.astype(str)


def decide(
    channels: Mapping[str, np.ndarray],
    out: Mapping[str, Any],
    *,
    threshold: float,
    group_labels: Sequence[str],
    novelty_ratio: float,
    p_fault: float,
    coverage: float,
) -> dict[str, Any]:
    """The SEVA decisions of consecutive seconds of one run.

    Parameters
    ----------
    channels
        The run's ``(n,)`` channels CV, P1, P2, T1, X, F (NaN = missing).
    out
        The per-second quantities: ``DD``, ``group_proba`` ``(n, n_groups)``, ``novelty``,
        ``novel_inputs`` (inputs outside the envelope now), ``novel_onset`` (the detection's
        estimated change began outside it, or its command has left it since) and
        ``unproven_onset`` (it began before the fit proof,
        `bayes_fdi.diagnosis.online.fit_proof.FitProof`).
    group_labels
        The isolability groups' labels, columns of ``group_proba``.
    threshold
        The detector's threshold (for `evidence`).
    novelty_ratio, p_fault, coverage
        The diagnoser's parameters.

    Returns
    -------
    dict
        ``state``, ``probability``, ``status``, ``indicated`` ``(n, n_groups)``, ``FFID``,
        ``blind``, ``novel_inputs``, ``novel_signature``, ``novel_onset``, ``unproven_onset``,
        ``evidence``
        (arrays of ``n``) and ``z`` (the normal quantile of ``coverage``).

    A detection is named ``"mismatch"`` when its estimated change began while the inputs lay
    outside the normal models' envelope (or its command has left it since), or before the stream
    had seen the normal models fit the valve (the model does not fit this valve: commission it),
    ``"unknown"`` when no isolator is fitted or the signature is unlike every known fault, else
    by the most probable isolability group.
    """
    n = channels["CV"].size
    blind = np.zeros(n, dtype=bool)
    for c in CHANNELS:
        blind |= ~np.isfinite(channels[c])
    novel_in = out["novel_inputs"]
    dd = out["DD"]
    labels = np.asarray((*group_labels, *UNNAMED_STATES), dtype=object)
    gq = out["group_proba"]
    isolated = np.isfinite(gq).all(axis=1) & (gq.shape[1] > 0) & dd
    if gq.shape[1]:
        top = np.argmax(np.where(isolated[:, None], gq, -1.0), axis=1)
    else:
        top = np.zeros(n, dtype=np.int64)
    prob = np.where(isolated, gq[np.arange(n), top] if gq.shape[1] else np.nan, np.nan)
    novel_onset, unproven = out["novel_onset"], out["unproven_onset"]
    mismatch = novel_onset | unproven
    novel_sig = isolated & (out["novelty"] > novelty_ratio) & ~mismatch
    known = isolated & ~novel_sig & ~mismatch
    unnamed = np.where(mismatch, len(labels) - 3, len(labels) - 2)
    code = np.where(~dd, len(labels) - 1, np.where(known, top, unnamed))
    state = labels[code].astype(str)
    prob = np.where(known, prob, np.nan)
    trusted = known & (prob >= p_fault)
    detected_status = np.where(trusted, SevaStatus.BLURRED.value, SevaStatus.DAZZLED.value)
    quiet_status = np.where(novel_in, SevaStatus.DAZZLED.value, SevaStatus.CLEAR.value)
    status = np.where(blind, SevaStatus.BLIND.value, np.where(dd, detected_status, quiet_status))
    indicated = np.zeros((n, len(group_labels)), dtype=bool)
    if indicated.shape[1]:
        indicated[np.flatnonzero(known), top[known]] = True
    z = coverage_quantile(coverage)
    return {
        "state": state,
        "probability": prob,
        "status": status.astype(str),
        "indicated": indicated,
        "FFID": ~dd & ~blind,
        "blind": blind,
        "novel_inputs": novel_in,
        "novel_signature": novel_sig,
        "novel_onset": novel_onset,
        "unproven_onset": unproven,
        "evidence": evidence(out, threshold),
        "z": z,
    }


def assemble_stream(
    recording: xr.Dataset,
    out: Mapping[str, Any],
    decisions: Mapping[str, Any],
    *,
    faults: Sequence[str],
    group_labels: Sequence[str],
    attrs: Mapping[str, Any],
) -> xr.Dataset:
    """The stream dataset (dims ``run``, ``time``, ``group``, ``fault``) of the runs'
    per-second quantities ``out`` and decisions (`decide`'s), each a ``(runs, time, ...)``
    array over the runs of ``recording`` (which has a ``run`` dimension).

    ``faults`` are the columns of the quantities' ``fault_proba`` (the classifier's faults):
    the stream's ``fault_proba`` has one column per fault of `FAULTS` (0 once detected for a
    fault the classifier does not know), then one per other fault it knows (a fault of one
    reading, such as ``bias_X``). Coordinates of ``recording`` over ``run`` and ``time``
    are kept, those named like a stream variable (a truth label such as ``state``) renamed
    ``true_<name>``.
    """
    z = decisions["z"]
    dims = ("run", "time")
    fault_cols = {f: j for j, f in enumerate(faults)}
    axis = (*FAULTS, *(f for f in faults if f not in FAULTS))  # then faults of one reading
    fault = np.full((*out["DD"].shape, len(axis)), np.nan)
    if faults:
        fq = out["fault_proba"]
        for k, f in enumerate(axis):
            if f in fault_cols:
                fault[:, :, k] = fq[:, :, fault_cols[f]]
            else:  # undetectable or untrained faults: probability 0 once detected
                fault[:, :, k] = np.where(np.isfinite(fq[:, :, 0]), 0.0, np.nan)
    quantities = (*MODEL_OUTPUTS, "r_X", "r_F", "stat_X", "stat_F")
    data = {
        "DD": (dims, out["DD"]),
        "FFID": (dims, decisions["FFID"]),
        "indicated": ((*dims, "group"), decisions["indicated"]),
        "group_proba": ((*dims, "group"), out["group_proba"]),
        "fault_proba": ((*dims, "fault"), fault),
        **{k: (dims, decisions[k]) for k in ("state", "evidence", "probability", "status")},
        "novelty": (dims, out["novelty"]),
        **{k: (dims, out[k]) for k in quantities},
        "VMV_X": (dims, out["X_hat"]),
        "VU_X": (dims, z * out["X_hat_std"]),
        "VMV_F": (dims, out["F_hat"]),
        "VU_F": (dims, z * out["F_hat_std"]),
        **{k: (dims, decisions[k]) for k in NOVELTY_FLAGS},
    }
    coords = {k: v.variable for k, v in recording.coords.items() if set(v.dims) <= {"run", "time"}}
    for k in [k for k in coords if k in data]:  # a truth label such as `state` is kept
        coords[f"true_{k}"] = coords.pop(k)
    coords["group"] = np.asarray(group_labels, dtype=str)
    coords["fault"] = np.asarray(axis, dtype=str)
    stream = xr.Dataset(data, coords=coords)
    stream.attrs.update(attrs)
    return stream


def stream_attrs(
    groups: Sequence[Sequence[str]],
    undetectable: Sequence[str],
    *,
    detector: str,
    threshold: float,
    clear_level: float,
    coverage: float,
    p_fault: float,
    novelty_ratio: float,
    fit_proof_seconds: int = 0,
) -> dict[str, Any]:
    """The stream's attributes: ``groups`` and ``undetectable`` (JSON), the detector, its
    threshold and clear level, the coverage of VU, the decision's ``p_fault``,
    ``novelty_ratio`` and ``fit_proof_seconds`` and the isolation features."""
    return {
        "groups": json.dumps({"|".join(g): list(g) for g in groups}),
        "undetectable": json.dumps(list(undetectable)),
        "detector": str(detector),
        "threshold": float(threshold),
        "clear_level": float(clear_level),
        "coverage": float(coverage),
        "p_fault": float(p_fault),
        "novelty_ratio": float(novelty_ratio),
        "fit_proof_seconds": int(fit_proof_seconds),
        "features": ",".join(ISOLATION_FEATURES),
    }

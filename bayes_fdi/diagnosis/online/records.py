"""The SEVA record of one second of the online diagnoser, and the reasons it gives.

`OnlineDiagnoser.update` (`bayes_fdi.diagnosis.online.diagnoser`) returns, for each second, a
`~bayes_fdi.diagnosis.seva.record.SevaRecord` built by `second_record` from that second's
quantities and decisions (`bayes_fdi.diagnosis.online.stream.decide`): the validated values and
uncertainties, the diagnosed state with its probability and distribution over the groups, the
SEVA status and the reason for it in words (`status_reasons`); `last_values` are the second's
other stream values. `stream_reasons` gives the same words for every second of
`OnlineDiagnoser.run`'s stream.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.datasets import CHANNELS
from bayes_fdi.diagnosis.online.stream import NOVELTY_FLAGS
from bayes_fdi.diagnosis.seva.record import ClassDistribution, SevaRecord, SevaStatus
from bayes_fdi.diagnosis.seva.rules import entropy

__all__ = ["last_values", "second_record", "status_reasons", "stream_reasons"]


def status_reasons(
    out: Mapping[str, Any],
    dec: Mapping[str, Any],
    threshold: float,
    isolating: bool,
    novelty_ratio: float,
    p_fault: float,
    i: int = 0,
    *,
    fit_proof_seconds: int = 0,
) -> tuple[str, ...]:
    """Why second ``i`` of ``out``/``dec`` has its status, in words (``isolating``: an
    isolator is fitted; ``fit_proof_seconds``: the diagnoser's)."""
    if dec["blind"][i]:
        return ("a measurement is missing this second",)
    if not out["DD"][i]:
        if dec["novel_inputs"][i]:
            return ("inputs outside the training envelope: the normal models extrapolate",)
        return (
            f"no detection (statistics X {out['stat_X'][i]:.3g}, F "
            f"{out['stat_F'][i]:.3g} <= threshold {threshold:.3g})",
        )
    raised = f" ({dec['evidence'][i]})" if dec["evidence"][i] else ""
    if dec["novel_onset"][i]:
        return (
            f"model mismatch: commission this valve (a detection{raised} whose change began while "
            "the inputs lay outside what the normal models were fitted on, or whose command has "
            "left that range since; it is not read as a fault)",
        )
    if dec["unproven_onset"][i]:
        return (
            f"model mismatch: commission this valve (a detection{raised} before the stream had "
            f"seen the normal models fit this valve for {fit_proof_seconds} s without detection; "
            "it is not read as a fault)",
        )
    if not isolating:
        return (
            f"fault detected{raised}; detection only: this model has no fault library and "
            "cannot name the fault",
        )
    if dec["novel_signature"][i]:
        return (
            f"unknown fault{raised}: signature unlike every known fault (novelty "
            f"{out['novelty'][i]:.3g} > {novelty_ratio})",
        )
    p = dec["probability"][i]
    need = ">=" if p >= p_fault else "<"
    return (f"fault detected{raised}; P({dec['state'][i]}) = {p:.3f} {need} p_fault = {p_fault}",)


def stream_reasons(stream: xr.Dataset) -> np.ndarray:
    """Why each second of `OnlineDiagnoser.run`'s stream has its status, in words: the text
    `update`'s record gives that second (its reasons joined by ``"; "``), an array of the
    shape of the stream's ``status``."""
    shape = stream["status"].shape

    def flat(name: str) -> np.ndarray:
        return np.asarray(stream[name].values).reshape(-1)

    out = {k: flat(k) for k in ("DD", "stat_X", "stat_F", "novelty")}
    dec = {k: flat(k) for k in (*NOVELTY_FLAGS, "evidence", "probability", "state")}
    dec["blind"] = flat("status") == SevaStatus.BLIND.value
    isolating = stream.sizes.get("group", 0) > 0
    a = stream.attrs
    texts = [
        "; ".join(
            status_reasons(
                out,
                dec,
                a["threshold"],
                isolating,
                a["novelty_ratio"],
                a["p_fault"],
                i,
                fit_proof_seconds=int(a.get("fit_proof_seconds", 0)),
            )
        )
        for i in range(int(np.prod(shape)))
    ]
    return np.asarray(texts, dtype=object).reshape(shape)


def second_record(
    channels: Mapping[str, np.ndarray],
    out: Mapping[str, Any],
    dec: Mapping[str, Any],
    t: float,
    group_labels: Sequence[str],
    coverage: float,
    reasons: tuple[str, ...],
) -> SevaRecord:
    """The `SevaRecord` of a one-second ``channels``/``out``/``dec`` at time ``t``."""
    z = dec["z"]
    gq = out["group_proba"][0]
    detected = bool(out["DD"][0]) and np.isfinite(gq).all() and gq.size > 0
    pairs = list(zip(group_labels, gq.tolist(), strict=True)) if detected else []
    rails = sum(1 for c in CHANNELS if channels[c][0] <= 0.0 or channels[c][0] >= 1.0)
    missing = sum(1 for c in CHANNELS if not np.isfinite(channels[c][0])) / len(CHANNELS)
    return SevaRecord(
        run=0,
        t_start=t,
        t_end=t,
        x_measured=float(channels["X"][0]),
        f_measured=float(channels["F"][0]),
        x_vmv=float(out["X_hat"][0]),
        x_vu=z * float(out["X_hat_std"][0]),
        f_vmv=float(out["F_hat"][0]),
        f_vu=z * float(out["F_hat_std"][0]),
        coverage=float(coverage),
        state=str(dec["state"][0]),
        probability=float(dec["probability"][0]),
        distribution=ClassDistribution(pairs),
        entropy=entropy(gq) if detected else math.nan,
        status=SevaStatus(str(dec["status"][0])),
        reasons=reasons,
        missing_fraction=float(dec["blind"][0]) and missing,
        saturated_fraction=rails / len(CHANNELS),
        novel_fraction=float(dec["novel_inputs"][0]),
        feature_novelty=float(out["novelty"][0]),
    )


def last_values(out: Mapping[str, Any], dec: Mapping[str, Any], t: float) -> dict[str, Any]:
    """The stream values of a one-second ``out``/``dec`` that the record does not hold."""
    return {
        "time": t,
        "DD": bool(out["DD"][0]),
        "FFID": bool(dec["FFID"][0]),
        "indicated": dec["indicated"][0].copy(),
        "stat_X": float(out["stat_X"][0]),
        "stat_F": float(out["stat_F"][0]),
        "r_X": float(out["r_X"][0]),
        "r_F": float(out["r_F"][0]),
        "fault_proba": out["fault_proba"][0].copy(),
        "group_proba": out["group_proba"][0].copy(),
        "evidence": str(dec["evidence"][0]),
    }

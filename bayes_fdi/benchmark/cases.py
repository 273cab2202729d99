"""One case of the commissioning benchmark scored: PICalc's indices, wrong answers, confusion.

A *case* is one run with one fault, a known onset and the benchmark's zones (set-up zone
``[0, t_on)``, fault-free part ``[t_on, t_from)``, faulty part ``[t_from, t_hor)``), diagnosed
by one diagnoser. `score_case` derives the benchmark's decision signals from its 1 Hz stream
(`bayes_fdi.scoring.decision_signals`) and computes PICalc's indices
(`bayes_fdi.scoring.picalc`) exactly as the DAMADICS harness does, the seconds named by a
confident wrong group, and how the faulty seconds were named (the row of a confusion matrix).
`clean_summary` scores a run without a fault (alarms, CLEAR share), and `innovation_effect`
measures how far a fault moves the diagnoser's own whitened innovations against their noise.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.benchmark.collection import confident_wrong, declared_share, faulty_states
from bayes_fdi.benchmark.report import DETECTABLE_DEFLECTION
from bayes_fdi.scoring.decision_signals import decision_high, decision_signals, rising_edges
from bayes_fdi.scoring.picalc import picalc

__all__ = [
    "clean_summary",
    "groups_of",
    "innovation_effect",
    "innovation_noise",
    "score_case",
    "zeroed",
]

#: The whitened innovations of the normal models, one per measured output.
INNOVATIONS = ("r_X", "r_F")


def zeroed(stream: xr.Dataset) -> xr.Dataset:
    """The stream of one run with its time counted from its first sample (the case's frame)."""
    t = np.asarray(stream["time"].values, dtype=np.float64)
    return stream.assign_coords(time=t - t[0])


def score_case(
    one: xr.Dataset,
    fault: str,
    *,
    t_on: float,
    t_from: float,
    t_hor: float,
    strength: np.ndarray,
) -> dict[str, Any]:
    """Score the stream ``one`` (one run, time from 0 s) of a case with fault ``fault``.

    Parameters
    ----------
    one
        The diagnoser's decision stream of the run, its time counted in the case's frame.
    fault
        The true fault (``f1`` .. ``f19`` or a measurement fault such as ``bias_X``).
    t_on, t_from, t_hor
        The benchmark's zones (s).
    strength
        The fault's strength (magnitude) per second, PICalc's ``fs`` stream.

    Returns
    -------
    dict
        ``indices`` (PICalc's, group level: PID = the true fault's group is indicated; a fault
        the diagnoser declares undetectable has PID = not DD), ``declared_r_fd`` (the share of
        the fault-free part with DD on and the answer not "mismatch": the false detections the
        diagnoser declares faults), ``faulty_seconds``,
        ``confident_wrong_seconds`` (faulty seconds answered with a group other than the true
        fault's at a probability above `~bayes_fdi.benchmark.collection.CONFIDENT`; for a
        fault in no group every confident answer is wrong),
        ``confident_wrong_probabilities_seconds`` (faulty seconds whose most probable group
        is above it and wrong, the seconds answered "unknown" included; see
        `~bayes_fdi.benchmark.collection.confident_wrong`), ``true_group`` (its label,
        ``"DGN0"`` for an undetectable fault, None for a fault the diagnoser does not know)
        and ``states`` (faulty seconds per diagnosed state while DD is on, and
        `~bayes_fdi.benchmark.collection.NOT_DETECTED`).
    """
    t = np.asarray(one["time"].values, dtype=np.float64)
    sig = decision_signals(one, fault)
    indices = picalc(
        t,
        sig.dd,
        sig.pid,
        sig.cid,
        t_on=t_on,
        t_from=t_from,
        t_hor=t_hor,
        strength=strength,
        indicated=sig.indicated,
        group_sizes=sig.group_sizes,
    )
    faulty = (t >= t_from) & (t < t_hor)
    labels = [str(g) for g in one["group"].values]
    undetectable = fault in set(_json_list(one.attrs.get("undetectable")))
    true_label = (
        labels[sig.true_group] if sig.true_group is not None else "DGN0" if undetectable else None
    )
    states = faulty_states(one["state"].values, sig.dd, faulty)
    answers, wrong = confident_wrong(one, sig.true_group)
    return {
        "indices": indices,
        "declared_r_fd": declared_share(sig.dd, one["state"].values, (t >= t_on) & (t < t_from)),
        "faulty_seconds": int(faulty.sum()),
        "confident_wrong_seconds": int((answers & faulty).sum()),
        "confident_wrong_probabilities_seconds": int((wrong & faulty).sum()),
        "true_group": true_label,
        "states": states,
    }


def _json_list(text: Any) -> list[str]:
    import json

    return list(json.loads(text)) if text else []


def clean_summary(one: xr.Dataset, *, warmup: float = 0.0) -> dict[str, Any]:
    """Alarms (rising edges of DD), share of DD high and of CLEAR seconds, and the statuses of
    a fault-free run's stream (time from 0 s), counted from ``warmup`` s on."""
    counted = np.asarray(one["time"].values, dtype=np.float64) >= warmup
    dd = decision_high(one["DD"].values)[counted]
    status = np.asarray(one["status"].values).astype(str)[counted]
    state = np.asarray(one["state"].values).astype(str)[counted]
    return {
        "seconds": int(counted.sum()),
        "alarms": rising_edges(dd),
        "r_fd": float(dd.mean()),
        "clear_share": float(np.mean(status == "CLEAR")),
        "status_counts": {str(s): int(np.sum(status == s)) for s in sorted(set(status))},
        "states_while_detected": {str(s): int(np.sum(state[dd] == s)) for s in set(state[dd])},
    }


def innovation_noise(healthy: xr.Dataset) -> dict[str, float]:
    """Standard deviation of each whitened innovation over a fault-free stream (one run)."""
    return {c: float(np.nanstd(healthy[c].values)) for c in INNOVATIONS}


def _standardised(stream: xr.Dataset, data: xr.Dataset, channel: str) -> np.ndarray:
    measured = np.asarray(data[channel].values, dtype=np.float64).ravel()
    hat = np.asarray(stream[f"{channel}_hat"].values, dtype=np.float64)
    return (measured - hat) / np.asarray(stream[f"{channel}_hat_std"].values, dtype=np.float64)


def innovation_effect(
    faulty: xr.Dataset,
    healthy: xr.Dataset,
    *,
    t_from: float,
    noise: Mapping[str, float],
    faulty_data: xr.Dataset | None = None,
    healthy_data: xr.Dataset | None = None,
) -> dict[str, Any]:
    """How far a fault moves the diagnoser's whitened innovations, against their noise.

    ``faulty`` and ``healthy`` are the streams (one run each, time from 0 s) of the same run
    with and without the fault (same inputs, same noise), so their difference is the fault's
    effect alone. Over the faulty part, per innovation: the RMS and the largest absolute
    difference in units of its standard deviation on fault-free data (``noise``);
    ``deflection`` is ``sqrt(sum_t sum_c (d_c(t) / sigma_c)^2)``, the separation a matched
    filter knowing the effect would reach on these innovations (white, by the normal models'
    whitening), and ``oracle_time`` the first second after ``t_from`` its running value
    reaches `DETECTABLE_DEFLECTION` (None if never). Below that deflection no detector that
    sees the fault through these normal models can find it.

    ``late_shift``: the mean effect on each innovation over the second half of the faulty part
    (noise units): what a sequential test still sees once the fault's onset has passed. With
    the recordings (``faulty_data``, ``healthy_data``), ``residual_shift`` is the same for the
    normal models' standardised residuals ``(y - y_hat) / std`` before the whitening.
    """
    t = np.asarray(faulty["time"].values, dtype=np.float64)
    part = t >= t_from
    late = t >= t_from + (t[-1] + 1.0 - t_from) / 2.0
    effects = []
    for c in INNOVATIONS:
        d = np.asarray(faulty[c].values, float) - np.asarray(healthy[c].values, float)
        effects.append(np.nan_to_num(d) / noise[c])
    e_all = np.stack(effects)
    e = e_all[:, part]
    running = np.sqrt(np.cumsum((e**2).sum(axis=0)))
    reach = np.flatnonzero(running >= DETECTABLE_DEFLECTION)
    out: dict[str, Any] = {
        "rms": {c: float(np.sqrt(np.mean(e[i] ** 2))) for i, c in enumerate(INNOVATIONS)},
        "max": {c: float(np.max(np.abs(e[i]))) for i, c in enumerate(INNOVATIONS)},
        "deflection": float(running[-1]) if running.size else 0.0,
        "oracle_time": float(reach[0]) if reach.size else None,
        "late_shift": {c: float(np.mean(e_all[i, late])) for i, c in enumerate(INNOVATIONS)},
    }
    if faulty_data is not None and healthy_data is not None:
        shift = {}
        for c in ("X", "F"):
            d = _standardised(faulty, faulty_data, c) - _standardised(healthy, healthy_data, c)
            shift[c] = float(np.nanmean(d[late]))
        out["residual_shift"] = shift
    return out


def groups_of(diagnoser: Any) -> dict[str, Any]:
    """A fitted online diagnoser's isolability groups (label -> members) and DGN0."""
    return {
        "groups": {"|".join(g): list(g) for g in diagnoser.groups_},
        "undetectable": list(diagnoser.undetectable_),
    }

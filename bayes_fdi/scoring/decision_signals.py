"""The benchmark's decision signals (DD, PID, CID, the indicated groups) of a decision stream.

PICalc (`bayes_fdi.scoring.picalc`) reads, per second, the detection decision DD, whether the
true fault's group is indicated (PID) and how many other groups are (CID). `decision_signals`
derives them from one run of an online diagnoser's 1 Hz stream and the run's true fault;
`rising_edges` counts alarms.
"""

from __future__ import annotations

import json
from typing import Any, NamedTuple

import numpy as np
import xarray as xr

__all__ = ["DecisionSignals", "decision_high", "decision_signals", "rising_edges"]


class DecisionSignals(NamedTuple):
    """The benchmark's decision signals of one run, per second (see :func:`decision_signals`)."""

    dd: np.ndarray
    pid: np.ndarray
    cid: np.ndarray
    indicated: np.ndarray
    group_sizes: np.ndarray
    true_group: int | None


def rising_edges(high: Any) -> int:
    """Number of rising edges of a 0/1 stream (a stream high at its first sample counts one)."""
    h = np.asarray(high, dtype=bool)
    return int(h[:1].sum() + (h[1:] & ~h[:-1]).sum())


def decision_high(values: Any) -> np.ndarray:
    """A decision as bool; NaN (no decision, e.g. BLIND) is low, as in
    `bayes_fdi.scoring.picalc`."""
    a = np.asarray(values)
    return a.astype(bool) if a.dtype == bool else np.nan_to_num(a.astype(float)) != 0


def decision_signals(stream: xr.Dataset, fault: str) -> DecisionSignals:
    """DD, PID, CID and the indicated groups of one run, given its true fault.

    Following the benchmark's definitions, from the stream of
    `bayes_fdi.diagnosis.OnlineDiagnoser.run`: ``PID = indicated[:, g]`` for the group ``g``
    holding ``fault`` and ``CID`` = the number of other groups indicated.
    A fault of DGN0 (the stream's ``undetectable`` attribute) has ``PID = not DD`` and an
    extra DGN0 column (``not DD``, holding the undetectable faults plus the OK state) in
    ``indicated`` for ``dacc``. A fault in no group and not in DGN0 is never isolated
    (``PID`` always low, ``true_group`` None).
    """
    if "run" in stream.dims:
        raise ValueError("decision_signals: pass the stream of one run (no 'run' dimension)")
    groups = json.loads(stream.attrs["groups"])
    undetectable = list(json.loads(stream.attrs.get("undetectable", "[]")))
    labels = [str(g) for g in stream["group"].values]
    dd = decision_high(stream["DD"].values)
    ind = decision_high(stream["indicated"].transpose("time", "group").values)
    sizes = np.array([len(groups[g]) for g in labels], dtype=np.int64)
    true_group = next((i for i, g in enumerate(labels) if fault in groups[g]), None)
    n_named = ind.sum(axis=1)
    if fault in undetectable:
        pid = ~dd
        ind = np.concatenate([ind, pid[:, None]], axis=1)
        sizes = np.append(sizes, len(undetectable) + 1)
        return DecisionSignals(dd, pid, n_named, ind, sizes, None)
    if true_group is None:
        return DecisionSignals(dd, np.zeros_like(dd), n_named, ind, sizes, None)
    pid = ind[:, true_group]
    return DecisionSignals(dd, pid, n_named - pid, ind, sizes, true_group)

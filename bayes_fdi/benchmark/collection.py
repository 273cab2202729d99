"""What the benchmark collects run by run, and the calibration of the group probabilities.

`RunCollector` scores each run's 1 Hz decision stream against its scenario (the decision
signals of `bayes_fdi.scoring.decision_signals`, PICalc's indices of
`bayes_fdi.scoring.picalc` and the first detection beside them), counts confident wrong
isolations, keeps the normal models' spread and a sample of detected faulty seconds;
`group_calibration` turns that sample into the top-label ECE of the group probabilities with a
run-level bootstrap interval.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.benchmark.report_detection import alarm_at_onset
from bayes_fdi.benchmark.scenarios import BenchmarkScenario
from bayes_fdi.diagnosis.online.stream import MISMATCH
from bayes_fdi.scoring.decision_signals import decision_signals
from bayes_fdi.scoring.picalc import first_detection, picalc

__all__ = [
    "CALIBRATION_SECONDS_PER_RUN",
    "CONFIDENT",
    "NOT_DETECTED",
    "RunCollector",
    "confident_wrong",
    "declared_share",
    "faulty_states",
    "group_calibration",
]

#: Each run contributes at most this many detected faulty seconds (evenly spaced) to the
#: calibration sample, so the day-long ramps (84 600 faulty s) do not outweigh the abrupt
#: faults (600 faulty s).
CALIBRATION_SECONDS_PER_RUN = 600
#: A group probability above this is "confident" (the isolation target counts confident wrong
#: groups).
CONFIDENT = 0.9


#: The column of faulty seconds with no detection, in a run's count of its diagnosed states.
NOT_DETECTED = "not detected"


def _seconds_per_state(states: np.ndarray) -> dict[str, int]:
    """How many seconds each state of ``states`` (strings) holds."""
    return {str(s): int(n) for s, n in zip(*np.unique(states, return_counts=True), strict=True)}


def faulty_states(state: np.ndarray, detected: np.ndarray, faulty: np.ndarray) -> dict[str, int]:
    """How a run's faulty seconds were answered: seconds per diagnosed state while DD was on,
    and `NOT_DETECTED` (a row of the confusion matrix)."""
    counts = _seconds_per_state(np.asarray(state).astype(str)[faulty & detected])
    counts[NOT_DETECTED] = int((faulty & ~detected).sum())
    return counts


def declared_share(dd: np.ndarray, state: Any, part: np.ndarray) -> float:
    """The share of the seconds ``part`` (bool) with DD on and the answer ``state`` other than
    "mismatch": over a fault-free part, the false detections the diagnoser declares faults (0.0
    for an empty part)."""
    if not part.any():
        return 0.0
    declared = np.asarray(dd, dtype=bool) & (np.asarray(state).astype(str) != MISMATCH)
    return float(declared[part].mean())


def confident_wrong(one: xr.Dataset, true_group: int | None) -> tuple[np.ndarray, np.ndarray]:
    """The seconds of a stream that name a wrong group confidently, counted two ways.

    Parameters
    ----------
    one
        The decision stream of one run (`bayes_fdi.diagnosis.OnlineDiagnoser.run`).
    true_group
        Index of the true fault's group among the stream's groups (None for a fault in no
        group: every confident group is wrong).

    Returns
    -------
    answers, probabilities
        Boolean arrays over the seconds. ``answers``: the diagnoser's answer (``state``) is a
        group other than the true one with ``probability`` above `CONFIDENT`, what the SEVA
        output says. ``probabilities``: the most probable column of ``group_proba`` is above
        `CONFIDENT` and wrong, also in the seconds the diagnoser answers "unknown" or
        "mismatch", where the stream still carries the isolation's probabilities (an upper
        bound of ``answers``).
    """
    proba = one["group_proba"].transpose("time", "group").values
    n = proba.shape[0]
    if proba.shape[1] == 0:  # a detection-only diagnoser names no group
        return np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    known = np.isfinite(proba).all(axis=1)
    filled = np.where(known[:, None], proba, 0.0)  # undefined rows are never confident
    wrong = filled.max(axis=1) > CONFIDENT
    if true_group is not None:
        wrong &= filled.argmax(axis=1) != true_group
    indicated = np.asarray(one["indicated"].transpose("time", "group").values, dtype=bool)
    probability = np.asarray(one["probability"].values, dtype=np.float64)
    named = indicated.copy()
    if true_group is not None:
        named[:, true_group] = False
    answers = named.any(axis=1) & (np.nan_to_num(probability, nan=0.0) > CONFIDENT)
    return answers, wrong


def seconds_since_detection(t: np.ndarray, dd: np.ndarray) -> np.ndarray:
    """Per second, the time since DD last rose (0 at its rising edge; a DD on from the first
    second counts from there), NaN where DD is off: the age of the isolation signature."""
    t = np.asarray(t, dtype=np.float64)
    dd = np.asarray(dd, dtype=bool)
    rising = dd & ~np.concatenate(([False], dd[:-1]))
    last = np.maximum.accumulate(np.where(rising, np.arange(t.size), -1))
    age = np.full(t.size, np.nan)
    on = dd & (last >= 0)
    age[on] = t[on] - t[last[on]]
    return age


class RunCollector:
    """Accumulates per-run indices, calibration samples and counts over the batches.

    `add` scores one run's decision stream; the attributes hold what the benchmark reports:
    ``rows`` (one per run: fault, mode, size, seed, PICalc indices, ``first_detection``:
    `bayes_fdi.scoring.picalc.first_detection`'s ``t_dt_first`` and ``dd_permanent``;
    ``alarm_at_onset``: DD on at the last second before the fault; ``declared_r_fd``: the share
    of the fault-free part with DD on and the answer not ``"mismatch"``, the false detections
    the diagnoser declares faults (r_fd counts its "model mismatch" alarms too); the run's
    ``faulty_seconds``, ``confident_wrong_seconds`` and ``confident_wrong_named``, the wrong
    groups those seconds named and how often; ``states``, `faulty_states`); over all runs,
    ``faulty_seconds``, ``confident_wrong`` (faulty seconds answered with a wrong group above
    `CONFIDENT`) and ``confident_wrong_probabilities`` (faulty seconds whose most probable
    group is above it and wrong, the seconds answered "unknown" included; see
    `confident_wrong`),
    ``model_std`` (median predictive std of X and F before each fault), ``innovation_rms``
    (per run, the RMS of the whitened innovations of X and F before the fault; the whitening
    is fitted on out-of-fold training residuals, so it lies well above 1 where the normal models
    do not fit the inputs) and the calibration
    sample (``proba``, ``true``, ``cluster``: at most `CALIBRATION_SECONDS_PER_RUN` detected
    faulty seconds per run; ``index``: their positions in the run; ``answered``: those whose
    answer is not "mismatch"; ``age``: their seconds since the detection,
    `seconds_since_detection`) with the
    stream's group ``labels`` and ``attrs``.
    """

    def __init__(self, seed: int) -> None:
        self.rows: list[dict[str, Any]] = []
        self.proba: list[np.ndarray] = []
        self.true: list[np.ndarray] = []
        self.cluster: list[np.ndarray] = []
        self.answered: list[np.ndarray] = []
        self.age: list[np.ndarray] = []
        self.index: list[np.ndarray] = []
        self.labels: list[str] | None = None
        self.attrs: dict[str, Any] = {}
        self.faulty_seconds = 0
        self.confident_wrong = 0
        self.confident_wrong_probabilities = 0
        self.model_std: dict[str, list[float]] = {"X": [], "F": []}
        self.innovation_rms: dict[str, list[float]] = {"X": [], "F": []}
        self.rng = np.random.default_rng(seed)

    def add(self, scenario: BenchmarkScenario, seed: int, one: xr.Dataset) -> dict[str, Any]:
        """Score the decision stream ``one`` of ``scenario`` with noise ``seed``; its row."""
        t = np.asarray(one["time"].values, dtype=np.float64)
        sig = decision_signals(one, scenario.fault)
        indices = picalc(
            t,
            sig.dd,
            sig.pid,
            sig.cid,
            t_on=scenario.t_on,
            t_from=scenario.t_from,
            t_hor=scenario.t_hor,
            strength=scenario.strength_at(t),
            indicated=sig.indicated,
            group_sizes=sig.group_sizes,
        )
        first = first_detection(
            t, sig.dd, t_on=scenario.t_on, t_from=scenario.t_from, t_hor=scenario.t_hor
        )
        faulty = (t >= scenario.t_from) & (t < scenario.t_hor)
        fault_free = (t >= scenario.t_on) & (t < scenario.t_from)
        answers, wrong = confident_wrong(one, sig.true_group)
        state = np.asarray(one["state"].values).astype(str)
        row = {
            "fault": scenario.fault,
            "mode": scenario.mode,
            "size": scenario.size,
            "seed": int(seed),
            "indices": indices,
            "first_detection": first,
            "alarm_at_onset": alarm_at_onset(t, sig.dd, t_from=scenario.t_from),
            "declared_r_fd": declared_share(sig.dd, state, fault_free),
            "faulty_seconds": int(faulty.sum()),
            "confident_wrong_seconds": int((answers & faulty).sum()),
            "confident_wrong_named": _seconds_per_state(state[answers & faulty]),
            "states": faulty_states(state, sig.dd, faulty),
        }
        self.rows.append(row)
        labels = [str(g) for g in one["group"].values]
        if self.labels is None:
            self.labels = labels
            keys = ("groups", "undetectable", "fit_proof_seconds")
            self.attrs = {k: one.attrs.get(k) for k in keys}
        elif labels != self.labels:
            raise ValueError("run_benchmark: the stream's groups changed between runs")
        proba = one["group_proba"].transpose("time", "group").values
        known = np.isfinite(proba).all(axis=1)
        self.faulty_seconds += row["faulty_seconds"]
        self.confident_wrong += row["confident_wrong_seconds"]
        self.confident_wrong_probabilities += int((wrong & faulty).sum())
        for c in ("X", "F"):
            std = one[f"{c}_hat_std"].values[fault_free]
            if np.isfinite(std).any():
                self.model_std[c].append(float(np.nanmedian(std)))
            innovations = one[f"r_{c}"].values[fault_free]
            if np.isfinite(innovations).any():
                self.innovation_rms[c].append(float(np.sqrt(np.nanmean(innovations**2))))
        keep = np.flatnonzero(faulty & sig.dd & known)
        if sig.true_group is not None and keep.size:
            if keep.size > CALIBRATION_SECONDS_PER_RUN:
                pos = np.linspace(0, keep.size - 1, CALIBRATION_SECONDS_PER_RUN)
                keep = keep[np.round(pos).astype(np.int64)]
            self.proba.append(proba[keep])
            self.answered.append(state[keep] != MISMATCH)
            self.age.append(seconds_since_detection(t, sig.dd)[keep])
            self.index.append(keep)
            self.true.append(np.full(keep.size, sig.true_group))
            self.cluster.append(np.full(keep.size, len(self.rows) - 1))
        return row


def _ece_interval(
    y: np.ndarray,
    proba: np.ndarray,
    labels: np.ndarray,
    cluster: np.ndarray,
    n_bootstrap: int,
    seed: int,
) -> Any:
    """Top-label ECE (15 bins) with a basic bootstrap interval over whole runs (``cluster``)."""
    from bayes_fdi.calibration import expected_calibration_error

    res = expected_calibration_error(y, proba, classes=labels, n_bins=15)
    # seconds of one run are strongly correlated: resample whole runs, not seconds
    runs = np.unique(cluster)
    members = [np.flatnonzero(cluster == r) for r in runs]
    rng = np.random.default_rng(seed)
    boots = np.empty(n_bootstrap)
    for b in range(n_bootstrap):
        take = np.concatenate([members[i] for i in rng.integers(0, runs.size, runs.size)])
        boots[b] = expected_calibration_error(y[take], proba[take], classes=labels, n_bins=15).value
    lo = hi = float("nan")
    if n_bootstrap:
        q_lo, q_hi = np.quantile(boots, [0.025, 0.975])
        lo, hi = max(0.0, 2 * res.value - q_hi), max(0.0, 2 * res.value - q_lo)  # basic interval
    return res._replace(ci_low=float(lo), ci_high=float(hi))


def _accuracy_confidence(y: np.ndarray, proba: np.ndarray, labels: np.ndarray) -> dict:
    """The share of seconds whose most probable group is the true one, and the mean of that
    probability."""
    return {
        "accuracy": float(np.mean(labels[np.argmax(proba, axis=1)] == y)),
        "mean_confidence": float(np.mean(np.max(proba, axis=1))),
    }


def group_calibration(
    col: RunCollector, n_bootstrap: int, seed: int, figure: Path | None
) -> dict[str, Any]:
    """Top-label ECE of the group probabilities with a run-level (cluster) bootstrap interval.

    Draws the reliability diagram into ``figure`` (a path, or None for no figure); returns the
    ``calibration`` entry of ``benchmark.json``. Where some of the seconds were answered
    "mismatch" (the probabilities stand behind a model-mismatch answer, not a diagnosis),
    ``"answered"`` gives the same figures over the other seconds.
    """
    from bayes_fdi.calibration import reliability_diagram

    if not col.proba:
        return {"n_seconds": 0, "note": "no detected faulty second of an isolable fault"}
    proba = np.concatenate(col.proba)
    labels = np.asarray(col.labels)
    y = labels[np.concatenate(col.true)]
    cluster = np.concatenate(col.cluster)
    runs = np.unique(cluster)
    res = _ece_interval(y, proba, labels, cluster, n_bootstrap, seed)
    lo, hi = res.ci_low, res.ci_high
    if figure is not None:
        import matplotlib.pyplot as plt

        from bayes_fdi.atomic import save_figure

        fig, ax = plt.subplots(figsize=(5, 5))
        reliability_diagram(
            res,
            ax=ax,
            title=f"group-level top-label ECE = {res.value:.3f} "
            f"[{lo:.3f}, {hi:.3f}] (runs resampled)\n{len(y)} s of {runs.size} runs",
        )
        save_figure(fig, figure, dpi=110)
    out = {
        "n_seconds": len(y),
        "n_runs": int(runs.size),
        "ece": res.value,
        "ci_low": res.ci_low,
        "ci_high": res.ci_high,
        "noise_floor": res.noise_floor,
        "mce": res.mce,
        **_accuracy_confidence(y, proba, labels),
        "bins": {
            "edges": res.bin_edges,
            "counts": res.bin_counts,
            "confidence": res.bin_confidence,
            "accuracy": res.bin_accuracy,
        },
        "n_bootstrap": int(n_bootstrap),
    }
    answered = np.concatenate(col.answered)  # appended with every proba
    if answered.any() and not answered.all():
        sub = _ece_interval(
            y[answered], proba[answered], labels, cluster[answered], n_bootstrap, seed
        )
        out["answered"] = {
            "n_seconds": int(answered.sum()),
            "ece": sub.value,
            "ci_low": sub.ci_low,
            "ci_high": sub.ci_high,
            **_accuracy_confidence(y[answered], proba[answered], labels),
        }
    return out

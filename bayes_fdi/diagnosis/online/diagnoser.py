"""The online self-validating diagnoser: every second, detect, isolate and say how far to trust
X and F.

`OnlineDiagnoser` chains, per second of a recording:

1. the dynamic normal models (`~bayes_fdi.diagnosis.normal_models.dynamic.DynamicNormalModels`):
   predicted X and F with calibrated predictive standard deviations;
2. standardised residuals ``z = (y - y_hat) / std``, whitened by an AR filter fitted on
   fault-free out-of-fold residuals (`~bayes_fdi.diagnosis.detection.whitening.ARWhitener`);
3. a sequential test per output (`~bayes_fdi.diagnosis.detection.detectors.CUSUM` by default, or
   `~bayes_fdi.diagnosis.detection.detectors.GLR`) whose threshold meets a false-alarm budget
   (default: on average at most one alarm per 8 h of fault-free data), and the detection
   decision DD with hysteresis;
4. after a detection, the isolation signature over the window since the detection and the
   fault and group probabilities with novelty (`~bayes_fdi.diagnosis.isolation.isolator`);
5. the SEVA status: BLIND (a channel missing), CLEAR (no detection, inputs within the
   training envelope), BLURRED (a detected fault isolated with probability >= ``p_fault``),
   DAZZLED (otherwise: a detection not yet isolated with confidence, a novel signature, or
   inputs outside the training envelope).

``run(recording)`` returns the whole 1 Hz decision stream (the contract of
``ONLINE_CONTRACT.md``); ``update(sample)`` processes one second and returns its
`~bayes_fdi.diagnosis.seva.windows.SevaRecord` in O(1) time and memory. Both go through the same
compiled kernels with the same state, so feeding a run second by second gives exactly the
stream of ``run`` (tested). The fitting lives in `bayes_fdi.diagnosis.online.fitting`.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr
from scipy import stats as sps
from sklearn.base import BaseEstimator

from bayes_fdi import model_files
from bayes_fdi.datasets import CHANNELS, validate_dataset
from bayes_fdi.diagnosis.detection.detectors import detection_decision
from bayes_fdi.diagnosis.isolation.isolator import (
    ISOLATION_FEATURES,
    isolate_rows,
    isolation_features,
)
from bayes_fdi.diagnosis.normal_models.dynamic import signed_root, standardised_residuals
from bayes_fdi.diagnosis.online.fitting import fit_online
from bayes_fdi.diagnosis.online.state import (
    StreamState,
    check_state,
    onset_inputs_novel,
    pack_states,
    run_state,
)
from bayes_fdi.diagnosis.seva.record import ClassDistribution, SevaRecord, SevaStatus
from bayes_fdi.diagnosis.seva.rules import entropy

__all__ = ["FAULTS", "OnlineDiagnoser", "StreamState"]

#: The fault names of the stream's ``fault`` coordinate.
FAULTS: tuple[str, ...] = tuple(f"f{i}" for i in range(1, 20))
_OUTPUTS = ("X_hat", "X_hat_std", "F_hat", "F_hat_std")


class OnlineDiagnoser(BaseEstimator):
    """Online detection, isolation and SEVA validation of an actuator, one second at a time.

    Parameters
    ----------
    normal_models
        Unfitted normal models with the interface of `DynamicNormalModels` (cloned); None:
        ``DynamicNormalModels(random_state=random_state)``.
    detector
        ``"cusum"`` (default) or ``"glr"``.
    cusum_k
        CUSUM reference value, in innovation standard deviations (default 0.5).
    glr_window
        GLR window, in seconds (default 60).
    false_alarm_hours
        False-alarm budget: the mean time between false alarms on fault-free data must be at
        least this many hours (default 8). The threshold is the larger of the one that meets
        it on white Gaussian innovations and the one measured on the fault-free training
        runs' out-of-fold innovations (see
        `bayes_fdi.diagnosis.detection.thresholds.calibrate_threshold`).
    clear_level
        DD turns off when every statistic is at or below this (default: 0 for the CUSUM, i.e.
        the evidence is fully gone; 2 for the GLR, about the 95 % point of its in-control
        one-sample value).
    max_whiten_order
        Largest AR order of the whitening (chosen by BIC).
    isolation_classifier
        Unfitted classifier over the faults (default: the k-means tree of RVCs; the SVM
        baseline is ``HierarchicalClassifier(svm_classifier())``).
    calibrator
        Unfitted recalibrator of the group probabilities, fitted on the calibration runs (e.g.
        ``bayes_fdi.calibration.TemperatureScaler()``); None: none.
    max_signatures_per_fault
        Training signatures kept per fault for the classifier (a seeded subset; bounds the
        cost of the RVC tree, default 80).
    group_threshold
        Held-out pairwise confusion from which two faults form one isolability group.
    detect_rate
        A fault whose training runs are detected less often than this is treated as not
        detectable (DGN0, the stream's ``undetectable``; default 0.5).
    p_fault
        BLURRED needs the diagnosed group's probability >= this (default 0.8).
    novelty_ratio
        A signature whose class-novelty score exceeds this is an unknown fault (default 1.5).
    input_margin
        Inputs (CV, P1, P2, T1) further than this share of the training range outside it are
        novel: the normal models extrapolate, the second is DAZZLED (default 0.1).
    coverage
        Coverage of the validated uncertainty VU = z * std (default 0.95).
    random_state
        Seed of the normal models, the isolation tree, the splits and the white-noise floor.

    Attributes
    ----------
    normal_models_ : DynamicNormalModels
    whiteners_ : dict
        ``{"X": ARWhitener, "F": ARWhitener}``.
    detector_ : CUSUM or GLR
        The detector prototype with the calibrated threshold.
    threshold_ : float
    clear_level_ : float
    threshold_report_ : dict
        The empirical ARL measurements behind the threshold.
    input_low_, input_high_ : numpy.ndarray
        The input envelope (CV, P1, P2, T1).
    isolator_ : FaultIsolator or None
        None when fitted without fault runs (detection only).
    groups_ : tuple of tuple of str
    undetectable_ : tuple of str
    detection_rates_ : dict
        Fault -> share of its training runs detected after the onset.
    fit_seconds_ : dict
    """

    def __init__(
        self,
        normal_models: Any = None,
        *,
        detector: str = "cusum",
        cusum_k: float = 0.5,
        glr_window: int = 60,
        false_alarm_hours: float = 8.0,
        clear_level: float | None = None,
        max_whiten_order: int = 8,
        isolation_classifier: Any = None,
        calibrator: Any = None,
        max_signatures_per_fault: int = 80,
        group_threshold: float = 0.15,
        detect_rate: float = 0.5,
        p_fault: float = 0.8,
        novelty_ratio: float = 1.5,
        input_margin: float = 0.1,
        coverage: float = 0.95,
        random_state: int | None = 0,
    ) -> None:
        self.normal_models = normal_models
        self.detector = detector
        self.cusum_k = cusum_k
        self.glr_window = glr_window
        self.false_alarm_hours = false_alarm_hours
        self.clear_level = clear_level
        self.max_whiten_order = max_whiten_order
        self.isolation_classifier = isolation_classifier
        self.calibrator = calibrator
        self.max_signatures_per_fault = max_signatures_per_fault
        self.group_threshold = group_threshold
        self.detect_rate = detect_rate
        self.p_fault = p_fault
        self.novelty_ratio = novelty_ratio
        self.input_margin = input_margin
        self.coverage = coverage
        self.random_state = random_state

    # ------------------------------------------------------------------ fitting
    def fit(
        self,
        normal_runs: xr.Dataset | Sequence[xr.Dataset],
        fault_runs: xr.Dataset | Sequence[xr.Dataset] | None = None,
        *,
        validation_runs: xr.Dataset | Sequence[xr.Dataset] | None = None,
        calibration_runs: xr.Dataset | Sequence[xr.Dataset] | None = None,
    ) -> OnlineDiagnoser:
        """Fit detection on fault-free runs and, given fault runs, isolation.

        Parameters
        ----------
        normal_runs
            Fault-free runs (channels CV, P1, P2, T1, X, F; NaN gaps allowed): a dataset, or a
            list of them (runs of different durations are padded with NaN, never fitted on).
        fault_runs
            Runs with a fault (coordinates ``state``, ``onset``; ``strength`` optional) to
            train the isolation classifier on (a dataset, or a list of datasets such as campaigns
            of different durations). None: detection only (a detection is then an
            ``"unknown"`` fault).
        validation_runs, calibration_runs
            Held-out fault runs for the isolability groups and the probability calibration.
            None: every fifth run of each fault of ``fault_runs`` (by position) validates and
            the next fifth calibrates; the other three fifths train.
        """
        fit_online(self, normal_runs, fault_runs, validation_runs, calibration_runs)
        self.reset()
        return self

    def _check_fitted(self) -> None:
        if not hasattr(self, "normal_models_"):
            raise ValueError("OnlineDiagnoser is not fitted; call fit(normal_runs) first")

    @property
    def groups_(self) -> tuple[tuple[str, ...], ...]:
        """The isolability groups (tuples of fault names) of the ``indicated`` decision."""
        self._check_fitted()
        return self.isolator_.groups_ if self.isolator_ is not None else ()

    # ------------------------------------------------------------------ persistence
    def save(self, path: str | os.PathLike[str]) -> str:
        """Write the fitted diagnoser to ``path`` (`bayes_fdi.model_files.format`: a
        versioned ``.npz`` of JSON and arrays, no pickle; written atomically).

        Everything fitted is saved (normal models, whitening filters, detector, isolator,
        groups), and the `update` stream's state, so a loaded diagnoser gives exactly the same
        stream and continues `update` where this one stopped. Returns the path written.
        """
        self._check_fitted()
        return model_files.save(self, path)

    @classmethod
    def load(cls, path: str | os.PathLike[str], **kwargs: Any) -> OnlineDiagnoser:
        """Read a diagnoser written by `save` (``kwargs``: those of
        `bayes_fdi.model_files.format.load`); a ``ValueError`` names a corrupt, foreign or
        newer file, or one that holds another class."""
        return model_files.load(path, expected=cls, **kwargs)

    # ------------------------------------------------------------------ the per-second core
    def _process(self, arrays: Mapping[str, np.ndarray], st: dict[str, Any]) -> dict[str, Any]:
        """Every per-second quantity of consecutive samples of one run (updates ``st``)."""
        nm = self.normal_models_
        n = arrays["CV"].size
        pred = np.empty((n, 5))
        nm.stream(arrays["CV"], arrays["P1"], arrays["P2"], st["models"], pred)
        out: dict[str, Any] = {k: pred[:, j] for j, k in enumerate(_OUTPUTS)}
        r_x, z_x = standardised_residuals(arrays["X"], pred[:, 0], pred[:, 1])
        r_f, z_f = standardised_residuals(arrays["F"], pred[:, 2], pred[:, 3])
        stats = np.empty((n, 2))
        for j, (c, z) in enumerate((("X", z_x), ("F", z_f))):
            e = self.whiteners_[c].advance(z, st["whiten"][c])
            out[f"r_{c}"] = e
            stats[:, j] = self.detector_.advance(e, st["detect"][c])[0]
        out["stat_X"], out["stat_F"] = stats[:, 0], stats[:, 1]
        dd = detection_decision(stats, self.threshold_, self.clear_level_,
                                state=st["dd"], held=st["held"])  # fmt: skip
        out["DD"] = dd
        s = signed_root(arrays["P1"], arrays["P2"])
        feats = isolation_features(dd, r_x, r_f, pred[:, 0], pred[:, 2], s, arrays["P1"],
                                   arrays["P2"], arrays["T1"], state=st["features"])  # fmt: skip
        out["features"] = feats
        inputs = np.column_stack([arrays[c] for c in ("CV", "P1", "P2", "T1")])
        out["novel_onset"] = onset_inputs_novel(dd, inputs, self.input_low_, self.input_high_,
                                                st["reference"])  # fmt: skip
        out.update(self._isolate(feats))
        st["seconds"] += n
        return out

    def _isolate(self, feats: np.ndarray) -> dict[str, np.ndarray]:
        """Fault/group probabilities and novelty of feature rows (NaN rows stay NaN)."""
        iso = self.isolator_
        n = feats.shape[0]
        if iso is None:
            return {"fault_proba": np.full((n, 0), np.nan), "group_proba": np.full((n, 0), np.nan),
                    "novelty": np.full(n, np.nan)}  # fmt: skip
        n_f, n_g = iso.faults_.size, len(iso.groups_)
        fq, gq, nov = np.empty((n, n_f)), np.empty((n, n_g)), np.empty(n)
        T = iso.temperature()
        if iso.lean_ is not None and (iso.calibrator_ is None or T is not None):
            tree = iso.lean_
            scratch = np.empty(max(1, int(np.diff(tree.woffsets).max(initial=1))))
            isolate_rows(
                np.ascontiguousarray(feats), *tree.args(), self._group_of, n_g,
                0.0 if T is None else T, float(getattr(iso.calibrator_, "floor", 1e-12)),
                *iso.novelty_.args(), scratch, np.empty(tree.offsets.size - 1),
                np.empty(feats.shape[1]), np.empty(n_f), np.empty(n_g), fq, gq, nov,
            )  # fmt: skip
            return {"fault_proba": fq, "group_proba": gq, "novelty": nov}
        # a classifier or calibrator without a compiled form: through their own predict
        fq[:], gq[:], nov[:] = np.nan, np.nan, np.nan
        ok = np.all(np.isfinite(feats), axis=1)
        if ok.any():
            p = iso.fault_proba(feats[ok])
            gp = p @ iso.membership_
            g = iso.calibrator_.transform(gp) if iso.calibrator_ is not None else gp
            with np.errstate(invalid="ignore", divide="ignore"):
                share = np.where(gp[:, self._group_of] > 0, p / gp[:, self._group_of], 1.0)
            gq[ok] = g
            fq[ok] = g[:, self._group_of] * share
            nov[ok] = iso.novelty_.score(feats[ok])
        return {"fault_proba": fq, "group_proba": gq, "novelty": nov}

    def _decide(self, arrays: Mapping[str, np.ndarray], out: dict[str, Any]) -> dict[str, Any]:
        """States, probabilities, statuses and the indicated groups (no arithmetic)."""
        n = arrays["CV"].size
        blind = np.zeros(n, dtype=bool)
        for c in CHANNELS:
            blind |= ~np.isfinite(arrays[c])
        novel_in = np.zeros(n, dtype=bool)
        for j, c in enumerate(("CV", "P1", "P2", "T1")):
            with np.errstate(invalid="ignore"):
                novel_in |= (arrays[c] < self.input_low_[j]) | (arrays[c] > self.input_high_[j])
        dd = out["DD"]
        labels = np.asarray((*self._group_labels, "unknown", "fn"), dtype=object)
        gq = out["group_proba"]
        isolated = np.isfinite(gq).all(axis=1) & (gq.shape[1] > 0) & dd
        top = np.argmax(np.where(isolated[:, None], gq, -1.0), axis=1) if gq.shape[1] else \
            np.zeros(n, dtype=np.int64)  # fmt: skip
        prob = np.where(isolated, gq[np.arange(n), top] if gq.shape[1] else np.nan, np.nan)
        novel_sig = isolated & (out["novelty"] > self.novelty_ratio)
        known = isolated & ~novel_sig
        novel_onset = out["novel_onset"]
        code = np.where(~dd, len(labels) - 1, np.where(known, top, len(labels) - 2))
        state = labels[code].astype(str)
        prob = np.where(known, prob, np.nan)
        status = np.where(
            blind, SevaStatus.BLIND.value,
            np.where(dd, np.where(known & (prob >= self.p_fault) & ~novel_onset,
                                  SevaStatus.BLURRED.value, SevaStatus.DAZZLED.value),
                     np.where(novel_in, SevaStatus.DAZZLED.value, SevaStatus.CLEAR.value)),
        )  # fmt: skip
        indicated = np.zeros((n, len(self._group_labels)), dtype=bool)
        if indicated.shape[1]:
            indicated[np.flatnonzero(known), top[known]] = True
        z = float(sps.norm.ppf(0.5 + self.coverage / 2.0))
        return {
            "state": state, "probability": prob, "status": status.astype(str),
            "indicated": indicated, "FFID": ~dd & ~blind, "blind": blind,
            "novel_inputs": novel_in, "novel_signature": novel_sig, "novel_onset": novel_onset,
            "z": z,
        }  # fmt: skip

    # ------------------------------------------------------------------ streaming
    def reset(self, state: StreamState | None = None) -> OnlineDiagnoser:
        """Start a new stream for `update` (second 0), or continue from ``state``.

        Parameters
        ----------
        state
            A one-run `StreamState` (from `stream_state` or ``run(..., return_state=True)``):
            `update` continues that stream exactly. None: a fresh stream.
        """
        self._check_fitted()
        if state is not None:
            check_state(self, state, 1)
        self._stream = run_state(self, state, 0)
        return self

    def stream_state(self) -> StreamState:
        """The state of the `update` stream after its last second (a read-only copy)."""
        self._check_fitted()
        if not hasattr(self, "_stream"):
            self.reset()
        return pack_states([self._stream])

    def update(self, sample: Mapping[str, Any]) -> SevaRecord:
        """Process one second of one actuator; returns its SEVA record (O(1) time, memory).

        Parameters
        ----------
        sample
            Mapping with ``CV, P1, P2, T1, X, F`` (normalised; NaN = missing) and optionally
            ``time`` (s; default the number of seconds since `reset`).

        Returns
        -------
        SevaRecord
            The second's record; the stream's other values of that second (``DD``, ``FFID``,
            ``indicated``, the statistics, innovations and probabilities over the classifier's
            faults) are in ``last_``.
        """
        self._check_fitted()
        if not hasattr(self, "_stream"):
            self.reset()
        missing = [c for c in CHANNELS if c not in sample]
        if missing:
            raise ValueError(f"sample lacks channel(s) {missing}")
        arrays = {c: np.array([float(sample[c])], dtype=np.float64) for c in CHANNELS}
        t = float(sample.get("time", self._stream["seconds"]))
        out = self._process(arrays, self._stream)
        dec = self._decide(arrays, out)
        self.last_ = {
            "time": t, "DD": bool(out["DD"][0]), "FFID": bool(dec["FFID"][0]),
            "indicated": dec["indicated"][0].copy(), "stat_X": float(out["stat_X"][0]),
            "stat_F": float(out["stat_F"][0]), "r_X": float(out["r_X"][0]),
            "r_F": float(out["r_F"][0]), "fault_proba": out["fault_proba"][0].copy(),
            "group_proba": out["group_proba"][0].copy(),
        }  # fmt: skip
        return self._record(arrays, out, dec, t)

    def _record(self, arrays, out, dec, t: float) -> SevaRecord:
        z = dec["z"]
        gq = out["group_proba"][0]
        detected = bool(out["DD"][0]) and np.isfinite(gq).all() and gq.size > 0
        dist = ClassDistribution(list(zip(self._group_labels, gq.tolist(), strict=True))
                                 if detected else [])  # fmt: skip
        status = SevaStatus(str(dec["status"][0]))
        reasons = self._reasons(out, dec)
        rails = sum(1 for c in CHANNELS if arrays[c][0] <= 0.0 or arrays[c][0] >= 1.0)
        return SevaRecord(
            run=0, t_start=t, t_end=t,
            x_measured=float(arrays["X"][0]), f_measured=float(arrays["F"][0]),
            x_vmv=float(out["X_hat"][0]), x_vu=z * float(out["X_hat_std"][0]),
            f_vmv=float(out["F_hat"][0]), f_vu=z * float(out["F_hat_std"][0]),
            coverage=float(self.coverage), state=str(dec["state"][0]),
            probability=float(dec["probability"][0]), distribution=dist,
            entropy=entropy(gq) if detected else math.nan, status=status,
            reasons=reasons, missing_fraction=float(dec["blind"][0]) and
            sum(1 for c in CHANNELS if not np.isfinite(arrays[c][0])) / len(CHANNELS),
            saturated_fraction=rails / len(CHANNELS),
            novel_fraction=float(dec["novel_inputs"][0]),
            feature_novelty=float(out["novelty"][0]),
        )  # fmt: skip

    def _reasons(self, out, dec) -> tuple[str, ...]:
        if dec["blind"][0]:
            return ("a measurement is missing this second",)
        if not out["DD"][0]:
            if dec["novel_inputs"][0]:
                return ("inputs outside the training envelope: the normal models extrapolate",)
            return (f"no detection (statistics X {out['stat_X'][0]:.3g}, F "
                    f"{out['stat_F'][0]:.3g} <= threshold {self.threshold_:.3g})",)  # fmt: skip
        if self.isolator_ is None:
            return ("fault detected; no isolation fitted",)
        if dec["novel_signature"][0]:
            return (f"fault detected; signature unlike every known fault (novelty "
                    f"{out['novelty'][0]:.3g} > {self.novelty_ratio})",)  # fmt: skip
        p = dec["probability"][0]
        if dec["novel_onset"][0]:
            return (f"fault detected while the inputs were outside the training envelope: the "
                    f"normal models extrapolate, P({dec['state'][0]}) = {p:.3f} is not "
                    f"trusted",)  # fmt: skip
        need = ">=" if p >= self.p_fault else "<"
        return (f"fault detected; P({dec['state'][0]}) = {p:.3f} {need} p_fault = "
                f"{self.p_fault}",)  # fmt: skip

    # ------------------------------------------------------------------ batch
    def run(
        self,
        recording: xr.Dataset,
        *,
        state: StreamState | None = None,
        return_state: bool = False,
    ) -> xr.Dataset | tuple[xr.Dataset, StreamState]:
        """The 1 Hz decision stream of a recording (dims ``run``, ``time`` or just ``time``).

        Each run starts from a fresh stream state (as after `reset`) unless ``state`` is given;
        the result equals feeding each run through `update` second by second. See
        ``ONLINE_CONTRACT.md`` for the variables.

        Parameters
        ----------
        recording
            Channels CV, P1, P2, T1, X, F (normalised; NaN = missing).
        state
            The `StreamState` returned by an earlier call with ``return_state=True`` on the
            preceding part of the same runs (same number of runs): the stream continues
            exactly, so ``run(a ++ b)`` equals ``run(a)`` followed by ``run(b, state=...)``.
        return_state
            Also return the state after the last second.

        Returns
        -------
        xarray.Dataset, or (xarray.Dataset, StreamState) with ``return_state``
        """
        self._check_fitted()
        single = "run" not in recording.dims
        ds = recording
        if single:  # one run: scalar coordinates (a selected run's labels) are not carried
            ds = ds.drop_vars([c for c in ds.coords if ds[c].ndim == 0]).expand_dims("run")
        channels = ds[[c for c in CHANNELS if c in ds.data_vars]].reset_coords(drop=True)
        validate_dataset(channels, require=CHANNELS, allow_nan=True)
        n_runs, n_t = ds.sizes["run"], ds.sizes["time"]
        if state is not None:
            check_state(self, state, n_runs)
        data = {c: np.asarray(ds[c].transpose("run", "time").values, dtype=np.float64)
                for c in CHANNELS}  # fmt: skip
        per_run, states = [], []
        for i in range(n_runs):
            arrays = {c: np.ascontiguousarray(v[i]) for c, v in data.items()}
            st = run_state(self, state, i)
            out = self._process(arrays, st)
            per_run.append((out, self._decide(arrays, out)))
            states.append(st)
        stream = self._assemble(ds, per_run, n_t, single)
        if return_state:
            return stream, pack_states(states) if states else state
        return stream

    def _assemble(self, ds, per_run, n_t: int, single: bool) -> xr.Dataset:
        def stack(key: str, src: int) -> np.ndarray:
            return np.stack([pr[src][key] for pr in per_run])

        z = per_run[0][1]["z"] if per_run else 1.96
        dims = ("run", "time")
        fault_cols = {f: j for j, f in enumerate(self._faults)}
        fault = np.full((len(per_run), n_t, len(FAULTS)), np.nan)
        if per_run and self._faults:
            fq = stack("fault_proba", 0)
            for k, f in enumerate(FAULTS):
                if f in fault_cols:
                    fault[:, :, k] = fq[:, :, fault_cols[f]]
                else:  # undetectable or untrained faults: probability 0 once detected
                    fault[:, :, k] = np.where(np.isfinite(fq[:, :, 0]), 0.0, np.nan)
        data = {
            "DD": (dims, stack("DD", 0)),
            "FFID": (dims, stack("FFID", 1)),
            "indicated": ((*dims, "group"), stack("indicated", 1)),
            "group_proba": ((*dims, "group"), stack("group_proba", 0)),
            "fault_proba": ((*dims, "fault"), fault),
            "state": (dims, stack("state", 1)),
            "probability": (dims, stack("probability", 1)),
            "status": (dims, stack("status", 1)),
            "novelty": (dims, stack("novelty", 0)),
            **{k: (dims, stack(k, 0)) for k in (*_OUTPUTS, "r_X", "r_F", "stat_X", "stat_F")},
            "VMV_X": (dims, stack("X_hat", 0)),
            "VU_X": (dims, z * stack("X_hat_std", 0)),
            "VMV_F": (dims, stack("F_hat", 0)),
            "VU_F": (dims, z * stack("F_hat_std", 0)),
        }
        coords = {k: v.variable for k, v in ds.coords.items() if set(v.dims) <= {"run", "time"}}
        for k in [k for k in coords if k in data]:  # a truth label such as `state` is kept
            coords[f"true_{k}"] = coords.pop(k)
        coords["group"] = np.asarray(self._group_labels, dtype=str)
        coords["fault"] = np.asarray(FAULTS, dtype=str)
        out = xr.Dataset(data, coords=coords)
        out.attrs.update(
            groups=json.dumps({"|".join(g): list(g) for g in self.groups_}),
            undetectable=json.dumps(list(self.undetectable_)),
            detector=str(self.detector), threshold=float(self.threshold_),
            clear_level=float(self.clear_level_), coverage=float(self.coverage),
            features=",".join(ISOLATION_FEATURES),
        )  # fmt: skip
        return out.isel(run=0, drop=True) if single else out

    @property
    def _faults(self) -> tuple[str, ...]:
        return tuple(self.isolator_.faults_) if self.isolator_ is not None else ()

    @property
    def _group_labels(self) -> tuple[str, ...]:
        return tuple(self.isolator_.group_labels_) if self.isolator_ is not None else ()

    @property
    def _group_of(self) -> np.ndarray:
        iso = self.isolator_
        return np.ascontiguousarray(np.argmax(iso.membership_, axis=1).astype(np.int64))

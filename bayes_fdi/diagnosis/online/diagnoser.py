"""The online self-validating diagnoser: every second, detect, isolate and say how far to trust
X and F.

`OnlineDiagnoser` fits its online components (normal models, whiteners, detector, decision,
signature window, input envelope, isolator) and runs them second by second (``online.step``):
``run(recording)`` gives the 1 Hz decision stream, ``update(sample)`` one second's
`~bayes_fdi.diagnosis.seva.record.SevaRecord` in O(1) time and memory, through the same
compiled kernels and state (``online.state``): second by second equals ``run`` exactly (tested).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
import xarray as xr
from sklearn.base import BaseEstimator, clone

from bayes_fdi import model_files
from bayes_fdi.datasets import CHANNELS, validate_dataset
from bayes_fdi.datasets.known_ranges import channel_ranges, units_of
from bayes_fdi.diagnosis.detection.detectors import CUSUM, sequential_test
from bayes_fdi.diagnosis.isolation.signatures import SignatureWindow
from bayes_fdi.diagnosis.normal_models.dynamic import DynamicNormalModels
from bayes_fdi.diagnosis.online.checks import check_fitted_values, check_settings
from bayes_fdi.diagnosis.online.clock import check_next_time, check_time_axis
from bayes_fdi.diagnosis.online.envelope import InputEnvelope
from bayes_fdi.diagnosis.online.legacy import upgrade_diagnoser
from bayes_fdi.diagnosis.online.records import last_values, second_record, status_reasons
from bayes_fdi.diagnosis.online.state import StreamState
from bayes_fdi.diagnosis.online.step import (
    Components,
    check_stream_state,
    init_run_state,
    step,
    step_runs,
)
from bayes_fdi.diagnosis.online.stream import assemble_stream, decide, stream_attrs
from bayes_fdi.diagnosis.online.training import (
    Runs,
    attach_isolation,
    detection_components,
    fit_detection,
    stack_runs,
)
from bayes_fdi.diagnosis.seva.record import SevaRecord

__all__ = ["OnlineDiagnoser"]


class OnlineDiagnoser(BaseEstimator):
    """Online detection, isolation and SEVA validation of an actuator, one second at a time.

    Per second: the dynamic normal models' predictions of X and F with calibrated standard
    deviations; the standardised residuals, whitened by an AR filter; a sequential test per output
    (CUSUM or GLR) with a threshold for a false-alarm budget and the detection decision DD with
    hysteresis; after a detection, the isolation signature since the detection and its fault and
    group probabilities with novelty; and the SEVA status
    (`bayes_fdi.diagnosis.online.stream.decide`): BLIND (a channel missing), CLEAR (no detection,
    inputs within the training envelope), BLURRED (a detected fault isolated with probability >=
    ``p_fault``), DAZZLED (otherwise: a detection not yet isolated with confidence, a novel
    signature, or inputs outside the training envelope).

    Parameters
    ----------
    normal_models
        Unfitted normal models with the interface of `DynamicNormalModels` (``fit``,
        ``oof_z_``, and as an online component ``init_state``, ``check_state``, ``run``;
        cloned); None: ``DynamicNormalModels(random_state=random_state)``.
    detector
        ``"cusum"`` (default), ``"variance-hold"`` (the CUSUM whose alarm holds while the
        innovations' variance stays high, `bayes_fdi.diagnosis.detection.VarianceHoldCUSUM`;
        the default model's), ``"glr"``, or an unfitted sequential test with the interface of
        `bayes_fdi.diagnosis.detection.CUSUM` (``init_state``, ``check_state``, ``update``,
        ``run``, ``with_threshold``, ``gaussian_threshold``): its threshold is calibrated here.
    cusum_k
        CUSUM reference value, in innovation standard deviations (default 0.5).
    glr_window
        GLR window, in seconds (default 60).
    false_alarm_hours
        False-alarm budget: the mean time between false alarms on fault-free data must be at
        least this many hours (default 8). The threshold is the larger of the one that meets
        it on white Gaussian innovations and the one measured on the fault-free training
        runs' out-of-fold innovations (see
        `bayes_fdi.diagnosis.detection.thresholds.fit_threshold`).
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
        Unfitted recalibrator of the group probabilities, fitted on the calibration runs' seconds
        (e.g. ``bayes_fdi.calibration.AgeTemperatureScaler()``, by the signature's age); None: none.
    max_signatures_per_fault
        Training signatures kept per fault for the classifier (a seeded subset; bounds the
        cost of the RVC tree, default 80).
    group_threshold, group_rule
        Held-out confusion from which two faults form one isolability group, and how it is
        measured (``"pairwise"``, default, or ``"naming"``: `fit_isolation`'s ``group_rule``).
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
    fit_proof_seconds
        Seconds without detection (inputs inside the envelope, every channel measured) the
        stream must have seen, before a detection's estimated change point, for the detection
        to be read as a fault (`bayes_fdi.diagnosis.online.fit_proof.FitProof`); a detection
        before that proof is a model mismatch (``"mismatch"``). 0 (default): every detection
        is read as a fault, for normal models fitted on the valve's own data. The default
        model, trained on the simulator, sets it
        (`bayes_fdi.default_diagnoser.DEFAULT_FIT_PROOF_SECONDS`). Read at every
        ``run``/``update``, so it may be changed after fitting.
    random_state
        Seed of the normal models, the isolation tree, the splits and the white-noise floor.

    Attributes
    ----------
    normal_models_ : DynamicNormalModels
    whiteners_ : dict
        ``{"X": ARWhitener, "F": ARWhitener}``.
    detector_ : CUSUM or GLR
        The detector with the calibrated threshold.
    threshold_ : float
    clear_level_ : float
    threshold_report_ : dict
        The empirical ARL measurements behind the threshold.
    decision_ : DetectionDecision
        DD with the threshold and the clear level.
    signature_ : SignatureWindow
        The isolation signatures' window.
    envelope_ : InputEnvelope
        The input envelope (``input_low_``, ``input_high_``: its bounds of CV, P1, P2, T1).
    training_ranges_, training_units_ : dict
        Channel -> 1st, 50th, 99th percentile of the fault-free data (normalised), and -> the
        unit its recordings were declared in, if known (`bayes_fdi.datasets.known_ranges`).
    isolator_ : FaultIsolator or None
        None when fitted without fault runs (detection only).
    groups_ : tuple of tuple of str
    undetectable_ : tuple of str
    detection_rates_ : dict
        Fault -> share of its training runs detected after the onset.
    n_signatures_ : dict
        Signatures of the isolator's training, validation and calibration sets.
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
        group_rule: str = "pairwise",
        detect_rate: float = 0.5,
        p_fault: float = 0.8,
        novelty_ratio: float = 1.5,
        input_margin: float = 0.1,
        coverage: float = 0.95,
        fit_proof_seconds: int = 0,
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
        self.group_rule = group_rule
        self.detect_rate = detect_rate
        self.p_fault = p_fault
        self.novelty_ratio = novelty_ratio
        self.input_margin = input_margin
        self.coverage = coverage
        self.fit_proof_seconds = fit_proof_seconds
        self.random_state = random_state

    # ------------------------------------------------------------------ fitting
    def fit(
        self,
        normal_runs: Runs,
        fault_runs: Runs | None = None,
        *,
        validation_runs: Runs | None = None,
        calibration_runs: Runs | None = None,
    ) -> OnlineDiagnoser:
        """Fit detection on fault-free runs and, given fault runs, isolation.

        The normal models, whitening filters, detector's threshold (`fit_detection`) and input
        envelope on the fault-free runs; the isolator on the fault runs (`fit_isolation`).

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
        self._check_params()
        t_start = time.perf_counter()
        seconds: dict[str, float] = {}
        t0 = time.perf_counter()
        models = self.normal_models
        models = DynamicNormalModels(random_state=self.random_state) if models is None else models
        normal_runs = stack_runs(normal_runs)
        self.normal_models_ = clone(models).fit(normal_runs)
        seconds["normal_models"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        prototype = self._detector_prototype()
        clear = self.clear_level
        if clear is None:
            clear = 0.0 if isinstance(prototype, CUSUM) else 2.0
        detection = fit_detection(
            self.normal_models_.oof_z_,
            prototype,
            max_whiten_order=self.max_whiten_order,
            clear_level=clear,
            false_alarm_hours=self.false_alarm_hours,
            random_state=self.random_state,
        )
        self.whiteners_, self.detector_ = detection.whiteners, detection.detector
        self.threshold_, self.clear_level_ = detection.threshold, detection.clear_level
        self.threshold_report_, self.decision_ = detection.threshold_report, detection.decision
        if not math.isfinite(self.threshold_):
            raise ValueError("the detector threshold could not be calibrated (no finite ARL fit)")
        self.envelope_ = InputEnvelope(margin=self.input_margin).fit(normal_runs)
        self.training_ranges_ = channel_ranges(normal_runs)
        self.training_units_ = units_of(normal_runs)
        self.signature_ = SignatureWindow()
        seconds["detection"] = time.perf_counter() - t0
        self.isolator_ = None
        self.undetectable_: tuple[str, ...] = ()
        self.detection_rates_: dict[str, float] = {}
        if fault_runs is not None:
            attach_isolation(self, fault_runs, validation_runs, calibration_runs, seconds=seconds)
        seconds["total"] = time.perf_counter() - t_start
        self.fit_seconds_ = seconds
        self.reset()
        return self

    def _detector_prototype(self) -> Any:
        """The unfitted sequential test (threshold 1) whose threshold the fit calibrates."""
        return sequential_test(self.detector, cusum_k=self.cusum_k, glr_window=self.glr_window)

    def _check_params(self) -> None:
        self._detector_prototype()
        check_settings(self.get_params())

    def check_model_file(self) -> None:
        """Called by the model-file loader: refuse fitted values that cannot be right
        (`bayes_fdi.diagnosis.online.checks.check_fitted_values`)."""
        check_fitted_values(vars(self))

    def _check_fitted(self) -> None:
        if not hasattr(self, "normal_models_"):
            raise ValueError("OnlineDiagnoser is not fitted; call fit(normal_runs) first")

    @property
    def groups_(self) -> tuple[tuple[str, ...], ...]:
        """The isolability groups (tuples of fault names) of the ``indicated`` decision."""
        self._check_fitted()
        return self.isolator_.groups_ if self.isolator_ is not None else ()

    @property
    def input_low_(self) -> np.ndarray:
        """Lower bounds of the input envelope (CV, P1, P2, T1)."""
        return self.envelope_.low_

    @property
    def input_high_(self) -> np.ndarray:
        """Upper bounds of the input envelope (CV, P1, P2, T1)."""
        return self.envelope_.high_

    # ------------------------------------------------------------------ persistence
    def save(self, path: str | os.PathLike[str]) -> str:
        """Write the fitted diagnoser to ``path`` (a versioned ``.npz``, no pickle, atomically).

        Everything fitted is saved (normal models, whitening filters, detector, isolator,
        groups), and the `update` stream's state, so a loaded diagnoser gives exactly the same
        stream and continues `update` where this one stopped. Returns the path written.
        """
        self._check_fitted()
        return model_files.save(self, path)

    @classmethod
    def load(cls, path: str | os.PathLike[str], **kwargs: Any) -> OnlineDiagnoser:
        """Read a diagnoser written by `save` (``kwargs``: those of `model_files.format.load`);
        a ``ValueError`` names a corrupt, foreign or newer file, or another class in it."""
        return model_files.load(path, expected=cls, **kwargs)

    @classmethod
    def upgrade_model_file(cls, data: dict, format_version: int) -> dict:
        """A saved diagnoser's attributes in today's layout (``online.legacy``)."""
        return upgrade_diagnoser(data)

    # ------------------------------------------------------------------ the per-second core
    def _components(self) -> Components:
        """The fitted components, in the order a second goes through them."""
        return detection_components(self)._replace(isolator=self.isolator_)

    def _decide(self, arrays: Mapping[str, np.ndarray], out: Mapping[str, Any]) -> dict[str, Any]:
        return decide(
            arrays,
            out,
            threshold=self.threshold_,
            group_labels=self._group_labels,
            novelty_ratio=self.novelty_ratio,
            p_fault=self.p_fault,
            coverage=self.coverage,
        )

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
        self._last_time = None  # the first sample may carry any time
        if state is None:
            self._stream = init_run_state(self._components())
        else:
            check_stream_state(self._components(), state, 1)
            self._stream = state.run(0)
        return self

    def stream_state(self) -> StreamState:
        """The state of the `update` stream after its last second (read-only)."""
        self._check_fitted()
        if not hasattr(self, "_stream"):
            self.reset()
        return StreamState.of_runs([self._stream])

    def update(self, sample: Mapping[str, Any]) -> SevaRecord:
        """Process one second of one actuator; returns its SEVA record (O(1) time, memory).

        Parameters
        ----------
        sample
            Mapping with ``CV, P1, P2, T1, X, F`` (normalised; NaN = missing) and optionally
            ``time`` (s; default the number of seconds since `reset`), which must follow the
            previous sample's by 1 s (`bayes_fdi.diagnosis.online.clock.check_next_time`).

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
        t = float(sample.get("time", self._stream.seconds))
        check_next_time(getattr(self, "_last_time", None), t)
        self._last_time = t
        out, self._stream = step(self._components(), arrays, self._stream)
        dec = self._decide(arrays, out)
        self.last_ = last_values(out, dec, t)
        reasons = status_reasons(
            out, dec, self.threshold_, self.isolator_ is not None, self.novelty_ratio, self.p_fault,
            fit_proof_seconds=self.fit_proof_seconds,
        )  # fmt: skip
        return second_record(arrays, out, dec, t, self._group_labels, self.coverage, reasons)

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
        the result equals feeding each run through `update` second by second.

        Parameters
        ----------
        recording
            Channels CV, P1, P2, T1, X, F (normalised; NaN = missing); its ``time``, if any,
            a 1 Hz grid (`bayes_fdi.diagnosis.online.clock.check_time_axis`).
        state
            The `StreamState` returned by an earlier call with ``return_state=True`` on the
            preceding part of the same runs (same number of runs): the stream continues exactly, so
            ``run(a ++ b)`` equals ``run(a)`` followed by ``run(b, state=...)``.
        return_state
            Also return the state after the last second.

        Returns
        -------
        xarray.Dataset, or (xarray.Dataset, StreamState) with ``return_state``
            The decision stream, with the recording's ``run`` and ``time`` coordinates (and
            its other coordinates over them; one named like a variable, such as the truth
            label ``state``, is renamed ``true_<name>``), ``group`` (the isolability groups'
            labels, members joined by ``|``) and ``fault`` (f1 .. f19, then the faults of one
            reading the model knows, such as ``bias_X``). Per run and second:

            - ``DD`` (bool): the detection decision; ``FFID`` (bool): fault-free indication, not DD
              and no channel missing;
            - ``state`` (str): the diagnosed group's label, ``"unknown"`` (detected, but no fault
              library or a signature unlike every known fault), ``"mismatch"`` (a detection whose
              change began with the inputs outside the normal models' envelope, or before the
              stream had seen the normal models fit the valve for ``fit_proof_seconds``: the
              model does not fit this valve) or ``"fn"`` (no detection); ``probability``: that
              group's calibrated probability (NaN unless isolated); ``evidence`` (str): while DD
              is on, which residual raised it and its sign (``"X high"``, ``"F low"``, ``"X low,
              F high"``), else ``""``;
            - ``status`` (str): the SEVA status ``CLEAR``, ``BLURRED``, ``DAZZLED`` or ``BLIND``;
            - ``indicated`` (bool, per group): the diagnosed group; ``group_proba`` (per group) and
              ``fault_proba`` (per fault: the group's probability shared in proportion to the
              classifier's, 0 for a fault it does not know): calibrated probabilities, NaN while
              there is no signature; ``novelty``: the signature's class-novelty score;
            - ``X_hat``, ``X_hat_std``, ``F_hat``, ``F_hat_std``: the normal models' predictions and
              predictive standard deviations; ``VMV_X``, ``VMV_F`` (the same predictions, the
              validated measurement values) and ``VU_X``, ``VU_F`` (validated uncertainties, ``z``
              standard deviations for the ``coverage``);
            - ``r_X``, ``r_F``: the whitened innovations; ``stat_X``, ``stat_F``: the sequential
              test statistics (NaN in a gap).

            Attributes: ``groups`` (JSON: label -> members), ``undetectable`` (JSON list, DGN0),
            ``detector``, ``threshold``, ``clear_level``, ``coverage``, ``features`` (the
            signature's features). A ``recording`` without a ``run`` dimension gives none either.
        """
        self._check_fitted()
        ds, single = recording, "run" not in recording.dims
        if single:  # one run: scalar coordinates (a selected run's labels) are not carried
            ds = ds.drop_vars([c for c in ds.coords if ds[c].ndim == 0]).expand_dims("run")
        channels = ds[[c for c in CHANNELS if c in ds.data_vars]].reset_coords(drop=True)
        validate_dataset(channels, require=CHANNELS, allow_nan=True)
        if "time" in ds.coords:
            check_time_axis(ds["time"].values)
        n_runs, n_t = ds.sizes["run"], ds.sizes["time"]
        if n_runs == 0:
            raise ValueError("the recording has no runs")
        components = self._components()
        if state is not None:
            check_stream_state(components, state, n_runs)
        state = state or StreamState.of_runs([init_run_state(components)] * n_runs)
        data = {c: channels[c].transpose("run", "time").values.astype(np.float64) for c in CHANNELS}
        out, end = step_runs(components, data, state)  # every run at once

        def rows(arrays: Mapping[str, Any]) -> dict[str, Any]:  # (runs, time, ...) -> rows
            return {k: v.reshape(n_runs * n_t, *v.shape[2:]) for k, v in arrays.items()}

        decisions = {
            k: v.reshape(n_runs, n_t, *v.shape[1:]) if isinstance(v, np.ndarray) else v
            for k, v in self._decide(rows(data), rows(out)).items()
        }
        attrs = stream_attrs(
            self.groups_,
            self.undetectable_,
            detector=self.detector if isinstance(self.detector, str) else repr(self.detector),
            threshold=self.threshold_,
            clear_level=self.clear_level_,
            coverage=self.coverage,
            p_fault=self.p_fault,
            novelty_ratio=self.novelty_ratio,
            fit_proof_seconds=self.fit_proof_seconds,
        )
        stream = assemble_stream(
            ds, out, decisions, faults=self._faults, group_labels=self._group_labels, attrs=attrs
        )
        if single:
            stream = stream.isel(run=0, drop=True)
        return (stream, end) if return_state else stream

    @property
    def _faults(self) -> tuple[str, ...]:
        return tuple(self.isolator_.faults_) if self.isolator_ is not None else ()

    @property
    def _group_labels(self) -> tuple[str, ...]:
        return tuple(self.isolator_.group_labels_) if self.isolator_ is not None else ()

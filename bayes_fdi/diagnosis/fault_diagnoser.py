"""The fault-diagnosis pipeline: normal models -> residual features -> hierarchical classifier.

`FaultDiagnoser` follows the paper's Figure 21:

1. fit the fault-free models ``g1``, ``g2``
   (`bayes_fdi.diagnosis.normal_models.static.NormalModels`) on
   fault-free runs;
2. compute the residuals of the labelled runs and their features (by default the paper's mean
   ``r1`` and mean ``r2`` over each run, `bayes_fdi.diagnosis.isolation.features`);
3. standardise the features (mean 0, std 1 over the labelled training runs) so that the paper's
   fixed Gaussian kernel width sigma = 2 means "two training standard deviations" whatever the
   units, and fit the classifier (default: a k-means-designed
   `bayes_fdi.diagnosis.isolation.tree.HierarchicalClassifier` of RVCs).

``diagnose(runs)`` returns, per run (or per window), the most probable state, the full class
distribution and the residuals with their predictive standard deviations.
"""

from __future__ import annotations

import os
import time
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr
from sklearn.base import BaseEstimator, clone
from sklearn.preprocessing import StandardScaler

from bayes_fdi.datasets import INPUT_CHANNELS, OUTPUT_CHANNELS, validate_dataset
from bayes_fdi.diagnosis.isolation.features import DEFAULT_FEATURES, extract_features, window_bounds
from bayes_fdi.diagnosis.isolation.svm import svm_classifier
from bayes_fdi.diagnosis.isolation.tree import HierarchicalClassifier
from bayes_fdi.diagnosis.normal_models.kernel_ridge import KernelRidgeRegressor
from bayes_fdi.diagnosis.normal_models.static import NormalModels
from bayes_fdi.diagnosis.seva.novelty import NoveltyReference
from bayes_fdi.diagnosis.seva.record import SevaRecord
from bayes_fdi.diagnosis.seva.windows import seva_records

__all__ = ["FaultDiagnoser", "ShortRunWarning", "svm_fault_diagnoser"]

#: Runs shorter than this fraction of the training runs get a :class:`ShortRunWarning`.
SHORT_RUN_FRACTION = 0.5


class ShortRunWarning(UserWarning):
    """Runs diagnosed with per-run features are much shorter than the training runs."""


def _default_classifier(random_state: int | None) -> HierarchicalClassifier:
    from bayes_fdi.rvm import RVC

    return HierarchicalClassifier(RVC(kernel="rbf", width=2.0), random_state=random_state)


class FaultDiagnoser(BaseEstimator):
    """Residual-based fault diagnosis of actuator runs (the paper's RVM method by default).

    Parameters
    ----------
    regressor
        Unfitted regressor for the normal models (``fit``; ``predict(X, return_std=True)``).
        ``None``: ``RVR(kernel="rbf", width="auto")``.
    classifier
        Unfitted probabilistic multi-class classifier on the features (``fit``,
        ``predict_proba``, ``classes_``). ``None``:
        ``HierarchicalClassifier(RVC(kernel="rbf", width=2.0))`` with a k-means tree.
    features
        Registered feature names (`bayes_fdi.diagnosis.isolation.features.FEATURES`); default the
        paper's
        ``("mean_r1", "mean_r2")``.
    window, step
        Feature window and hop in samples; ``None`` = one feature vector per run (the paper).
        With windows, each window is a training sample; a window whose samples all precede its
        run's fault ``onset`` is labelled ``"fn"`` (the fault is not yet present).
    standardize
        Standardise the features with the labelled training runs' mean and std before the
        classifier (keeps a fixed kernel width meaningful for flat classifiers; the default
        tree, which scales per node, is invariant to it).
    width_search, max_train_samples
        Passed to `bayes_fdi.diagnosis.normal_models.static.NormalModels`.
        ``width_search="evidence-grid"`` (default) gives the default regressor (``width="auto"``)
        the width of largest summed log evidence over the grid ``(0.05, 0.1, 0.2, 0.4, 0.8)`` on 600
        fault-free samples, as `bayes_fdi.paper.reproduce.select_regression_width` does;
        ``"evidence"`` runs the RVR's own finer search instead (slow on trajectory data, see
        `NormalModels`).
    random_state
        Seed for subsampling, the GA and the tree design.
    interval_calibration
        Passed to `bayes_fdi.diagnosis.normal_models.static.NormalModels`: ``"cross-fit"`` (default)
        calibrates
        the predictive standard deviations ``X_hat_std``, ``F_hat_std`` on held-out fault-free
        runs; ``None`` keeps the regressors' own.
    input_lags
        Passed to `bayes_fdi.diagnosis.normal_models.static.NormalModels`: lags ``L`` (seconds) of
        extra normal-model
        inputs ``CV(t - L)`` (dynamic normal models, beyond the paper; the command is taken as
        held at its first value before a run's first sample). Default ``()``: the paper's
        static inputs ``(CV, sqrt(P1 - P2), T1)``.

    Attributes
    ----------
    normal_models_ : NormalModels
    classifier_ : fitted classifier
    scaler_ : StandardScaler or None
    classes_ : numpy.ndarray
        State names in the classifier's class order (columns of ``proba``).
    feature_names_ : tuple of str
    training_features_ : numpy.ndarray
        Unscaled training feature matrix (one row per labelled run or window).
    training_labels_ : numpy.ndarray
    input_reference_ : bayes_fdi.diagnosis.seva.windows.NoveltyReference
        Nearest-neighbour reference of the training inputs (fault-free and labelled runs),
        used by :meth:`seva` to flag inputs unlike anything seen in training.
    fit_seconds_ : dict
        Wall-clock seconds: ``normal_models``, ``residuals``, ``classifier``, ``total``.
    training_run_seconds_ : int
        Length (samples) of the labelled training runs; with per-run features (``window=None``)
        :meth:`diagnose` warns (:class:`ShortRunWarning`) on runs shorter than half of it.
    """

    def __init__(
        self,
        regressor: Any = None,
        classifier: Any = None,
        features: Sequence[str] = DEFAULT_FEATURES,
        *,
        window: int | None = None,
        step: int | None = None,
        standardize: bool = True,
        width_search: str | None = "evidence-grid",
        max_train_samples: int | None = None,
        random_state: int | None = 0,
        interval_calibration: str | None = "cross-fit",
        input_lags: Sequence[float] = (),
    ) -> None:
        self.regressor = regressor
        self.classifier = classifier
        self.features = features
        self.window = window
        self.step = step
        self.standardize = standardize
        self.width_search = width_search
        self.max_train_samples = max_train_samples
        self.random_state = random_state
        self.interval_calibration = interval_calibration
        self.input_lags = input_lags

    # ------------------------------------------------------------------ helpers
    def _feature_rows(self, res: xr.Dataset, what: str) -> np.ndarray:
        feats, _ = extract_features(res, self.features, self.window, self.step)
        bad = ~np.isfinite(feats)
        if bad.any():
            runs = sorted({int(r) for r in np.argwhere(bad)[:, 0]})
            raise ValueError(
                f"{what}: features are not finite for run(s) {runs[:10]} "
                "(a window with no finite residual, e.g. an all-NaN gap)"
            )
        return feats

    def _flat(self, feats: np.ndarray) -> np.ndarray:
        return feats.reshape(-1, feats.shape[-1])

    # ------------------------------------------------------------------ fitting
    def fit(self, normal_runs: xr.Dataset, labelled_runs: xr.Dataset) -> FaultDiagnoser:
        """Fit the normal models on ``normal_runs`` and the classifier on ``labelled_runs``.

        Parameters
        ----------
        normal_runs
            Fault-free runs (all channels).
        labelled_runs
            Runs with all channels and a ``state`` coordinate; at least two states.

        Returns
        -------
        FaultDiagnoser
            ``self``.
        """
        t_start = time.perf_counter()
        validate_dataset(labelled_runs, require=INPUT_CHANNELS + OUTPUT_CHANNELS, allow_nan=True)
        if "state" not in labelled_runs.coords:
            raise ValueError("labelled_runs has no 'state' coordinate (the run labels)")
        states = np.asarray(labelled_runs["state"].values).astype(str)
        if np.unique(states).size < 2:
            raise ValueError(
                f"labelled_runs holds one class only ({str(states[0])!r}); need at least two states"
            )
        self.fit_seconds_: dict[str, float] = {}
        t0 = time.perf_counter()
        self.normal_models_ = NormalModels(
            self.regressor,
            width_search=self.width_search,
            max_train_samples=self.max_train_samples,
            random_state=self.random_state,
            interval_calibration=self.interval_calibration,
            input_lags=self.input_lags,
        ).fit(normal_runs)
        self.fit_seconds_["normal_models"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        res = self.normal_models_.residuals(labelled_runs)
        feats = self._feature_rows(res, "labelled_runs")
        self.fit_seconds_["residuals"] = time.perf_counter() - t0
        if self.window is None:
            labels = states
        else:
            bounds = window_bounds(labelled_runs.sizes["time"], self.window, self.step)
            times = np.asarray(labelled_runs["time"].values, dtype=np.float64)
            last = times[bounds[:, 1] - 1]  # time of the last sample of each window
            onset = (
                np.asarray(labelled_runs["onset"].values, dtype=np.float64)
                if "onset" in labelled_runs.coords
                else np.full(states.size, -np.inf)
            )
            labels = np.where(last[None, :] < onset[:, None], "fn", states[:, None]).ravel()
        X = self._flat(feats)
        if np.unique(labels).size < 2:
            raise ValueError("the labelled windows hold one class only; need at least two")
        self.feature_names_ = tuple(
            (self.features,) if isinstance(self.features, str) else self.features
        )
        self.training_features_ = X
        self.training_labels_ = labels
        if self.standardize:
            self.scaler_: StandardScaler | None = StandardScaler().fit(X)
            Xs = self.scaler_.transform(X)
        else:
            self.scaler_ = None
            Xs = X
        t0 = time.perf_counter()
        clf = (
            _default_classifier(self.random_state)
            if self.classifier is None
            else clone(self.classifier)
        )
        self.classifier_ = clf.fit(Xs, labels)
        self.fit_seconds_["classifier"] = time.perf_counter() - t0
        self.classes_ = np.asarray(self.classifier_.classes_)
        self.input_reference_ = NoveltyReference.from_runs(
            xr.concat(
                [normal_runs[list(INPUT_CHANNELS)], labelled_runs[list(INPUT_CHANNELS)]],
                dim="run",
                coords="minimal",
                compat="override",
                join="override",
            )
        )
        self.training_run_seconds_ = int(labelled_runs.sizes["time"])
        self.fit_seconds_["total"] = time.perf_counter() - t_start
        return self

    # ---------------------------------------------------------------- diagnosis
    def _check_fitted(self) -> None:
        if not hasattr(self, "classifier_"):
            raise ValueError("FaultDiagnoser is not fitted; call fit(normal_runs, labelled_runs)")

    def predict_features(self, features: np.ndarray) -> np.ndarray:
        """Class probabilities ``(n, n_classes)`` for unscaled feature rows ``(n, n_features)``."""
        self._check_fitted()
        X = np.asarray(features, dtype=np.float64)
        if X.ndim != 2 or X.shape[1] != len(self.feature_names_):
            raise ValueError(
                f"features must be (n, {len(self.feature_names_)}), got shape {X.shape}"
            )
        if self.scaler_ is not None:
            X = self.scaler_.transform(X)
        return np.asarray(self.classifier_.predict_proba(X), dtype=np.float64)

    def diagnose(self, runs: xr.Dataset) -> xr.Dataset:
        """Diagnose runs: state, class distribution, residuals and their uncertainty.

        Parameters
        ----------
        runs
            Runs with channels ``CV, P1, P2, T1, X, F`` (labels, if present, are copied).

        Returns
        -------
        xarray.Dataset
            Dims ``run``, ``time``, ``class``, ``feature`` (and ``window`` when windowed):
            ``state`` (run[, window]) predicted label, ``proba`` (run[, window], class) summing
            to 1, ``confidence`` = max proba, ``features`` (run[, window], feature) unscaled,
            and ``X_hat``, ``X_hat_std``, ``F_hat``, ``F_hat_std``, ``r1``, ``r2``, ``z1``,
            ``z2`` (run, time). Run coordinates of ``runs`` (e.g. the true ``state``) are kept,
            the true state renamed ``true_state``. Windowed output has ``window_start`` and
            ``window_end`` coordinates (seconds, end exclusive).
        """
        self._check_fitted()
        trained = getattr(self, "training_run_seconds_", None)
        if self.window is None and trained and runs.sizes["time"] < SHORT_RUN_FRACTION * trained:
            warnings.warn(
                f"diagnosing runs of {runs.sizes['time']} s with a diagnoser trained on runs of "
                f"{trained} s: per-run features average fewer residuals, so they are noisier "
                "than in training and the diagnosis is less reliable",
                ShortRunWarning,
                stacklevel=2,
            )
        res = self.normal_models_.residuals(runs)
        feats = self._feature_rows(res, "runs")
        proba = self.predict_features(self._flat(feats))
        n_runs = runs.sizes["run"]
        n_classes = self.classes_.size
        best = np.argmax(proba, axis=1)
        state = self.classes_[best].astype(str)
        conf = proba[np.arange(proba.shape[0]), best]
        if "state" in res.coords:
            res = res.rename({"state": "true_state"})
        out = res.assign_coords(
            {"class": self.classes_.astype(str), "feature": list(self.feature_names_)}
        )
        if self.window is None:
            lead: tuple[str, ...] = ("run",)
            shape: tuple[int, ...] = (n_runs,)
        else:
            bounds = window_bounds(runs.sizes["time"], self.window, self.step)
            times = np.asarray(runs["time"].values, dtype=np.float64)
            out = out.assign_coords(
                window_start=("window", times[bounds[:, 0]]),
                window_end=("window", times[bounds[:, 1] - 1] + 1.0),
            )
            lead = ("run", "window")
            shape = (n_runs, bounds.shape[0])
        out["state"] = (lead, state.reshape(shape))
        out["proba"] = ((*lead, "class"), proba.reshape((*shape, n_classes)))
        out["confidence"] = (lead, conf.reshape(shape))
        out["features"] = ((*lead, "feature"), feats.reshape((*shape, feats.shape[-1])))
        out.attrs.update(
            {
                "classifier": type(self.classifier_).__name__,
                "features": ",".join(self.feature_names_),
            }
        )
        return out

    # ------------------------------------------------------------------ persistence
    def save(self, path: str | os.PathLike[str]) -> str:
        """Write the fitted diagnoser to ``path`` (no pickle; see
        `bayes_fdi.model_files.format` for the format); returns the path.

        Everything fitted is saved: the normal models with their regressors and interval
        scalers, the feature scaler, the classifier (tree of RVCs or SVMs), the novelty
        reference. `load` gives a diagnoser whose `diagnose`, `predict_features` and `seva`
        outputs equal this one's exactly.
        """
        from bayes_fdi import model_files

        self._check_fitted()
        return model_files.save(self, path)

    @classmethod
    def load(cls, path: str | os.PathLike[str], **kwargs: Any) -> FaultDiagnoser:
        """Read a diagnoser written by `save`.

        Keyword arguments (``max_bytes``, ``device``) go to
        `bayes_fdi.model_files.format.load`. Raises ``ValueError`` for a corrupt, foreign or
        newer file, or one holding something other than a ``FaultDiagnoser``.
        """
        from bayes_fdi import model_files

        return model_files.load(path, expected=cls, **kwargs)

    def seva(self, runs: xr.Dataset, **kwargs: Any) -> list[SevaRecord]:
        """The self-validating output: one immutable `bayes_fdi.diagnosis.seva.windows.SevaRecord`
        per run/window.

        Each record holds the measured X and F, their validated values (VMV) and uncertainties
        (VU at ``coverage``, default 95 %), the diagnosed state with its probability, the full
        class distribution and a status (``CLEAR``, ``BLURRED``, ``DAZZLED`` or ``BLIND``).

        Parameters
        ----------
        runs
            Runs to diagnose (channels ``CV, P1, P2, T1, X, F``).
        **kwargs
            Passed to `bayes_fdi.diagnosis.seva.windows.seva_records`: ``thresholds`` (a
            `bayes_fdi.diagnosis.seva.windows.SevaThresholds`), ``coverage``, ``calibrator`` (e.g. a
            fitted
            `bayes_fdi.calibration.TemperatureScaler`), ``saturation_limits``.

        Returns
        -------
        list of SevaRecord
            Convert with :func:`~bayes_fdi.diagnosis.seva.to_frame`,
            :func:`~bayes_fdi.diagnosis.seva.to_xarray` or
            :func:`~bayes_fdi.diagnosis.seva.to_json`.
        """
        self._check_fitted()
        return seva_records(self, runs, **kwargs)


def svm_fault_diagnoser(
    *,
    sigma: float = 2.0,
    C: float = 1.0,
    regression_width: float = 0.1,
    max_train_samples: int | None = 2000,
    random_state: int | None = 0,
    **kwargs: Any,
) -> FaultDiagnoser:
    """The paper's SVM baseline as a `FaultDiagnoser`.

    Kernel ridge normal models (`KernelRidgeRegressor`, fitted on at most
    ``max_train_samples`` fault-free samples: its cost is cubic) and a
    `bayes_fdi.diagnosis.isolation.tree.HierarchicalClassifier` of `svm_classifier` nodes, on the
    same features as the RVM pipeline. Extra keyword arguments go to ``FaultDiagnoser``.
    """
    return FaultDiagnoser(
        regressor=KernelRidgeRegressor(width=regression_width),
        classifier=HierarchicalClassifier(
            svm_classifier(sigma=sigma, C=C),
            random_state=random_state,
        ),
        max_train_samples=max_train_samples,
        random_state=random_state,
        **kwargs,
    )

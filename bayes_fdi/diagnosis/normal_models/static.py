"""Normal (fault-free) models of the actuator outputs: the residual generator.

The paper (eqs. 16-20) models the two measured outputs of a fault-free actuator, the stem
position ``X`` and the flow ``F``, as functions of three inputs,

    X_hat = g1(CV, sqrt(P1 - P2), T1),    F_hat = g2(CV, sqrt(P1 - P2), T1),

each a relevance vector regression fitted on fault-free runs, and diagnoses faults from the
residuals ``r1 = X - X_hat`` and ``r2 = F - F_hat``. Because the RVR is Bayesian, each
prediction has a predictive standard deviation, so standardised residuals
``z1 = r1 / X_hat_std`` and ``z2 = r2 / F_hat_std`` are available too.

Pressure drop: where ``P1 < P2`` (reverse flow under fault f17, or bad data), the square root
is replaced by the signed root ``sign(D) * sqrt(|D|)`` with ``D = P1 - P2``; such samples are
kept (never dropped) and counted, with a `NegativePressureDropWarning`.

Dynamic inputs (beyond the paper): ``input_lags=(L1, L2, ...)`` appends the delayed commands
``CV(t - L1), CV(t - L2), ...`` (lags in seconds of the ``time`` coordinate) to the three inputs,
so the models can follow the actuator's lag behind its command. Before a run's first sample the
command is taken as held at its first value (no sample is dropped). The default ``()`` gives the
paper's static models.

Missing values: samples with a NaN input are not passed to the regressors; their predictions
and residuals are NaN (counted in the output's attributes). In ``fit``, samples with a NaN
input or output are left out of the training set with a warning giving their number.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr
from sklearn.base import BaseEstimator, clone

from bayes_fdi.datasets import INPUT_CHANNELS, OUTPUT_CHANNELS, validate_dataset
from bayes_fdi.diagnosis.normal_models.fit_steps import (
    check_width_grid,
    choose_widths,
    training_samples,
    with_width,
)
from bayes_fdi.diagnosis.normal_models.inputs import check_lags, input_names, model_inputs
from bayes_fdi.diagnosis.normal_models.interval_calibration import (
    command_speed,
    cross_fit_std_scales,
    predict_with_std,
)
from bayes_fdi.diagnosis.normal_models.speed_factors import speed_bins
from bayes_fdi.diagnosis.normal_models.width_search import WIDTH_GRID, GAResult
from bayes_fdi.rvm.threads import limit_fit_threads

__all__ = ["NormalModels"]


def _default_regressor() -> Any:
    from bayes_fdi.rvm import RVR

    return RVR(kernel="rbf", width="auto")


class NormalModels(BaseEstimator):
    """Fault-free models ``X_hat = g1(u)``, ``F_hat = g2(u)`` with ``u = (CV, sqrt(P1-P2), T1)``.

    With ``input_lags`` the inputs also hold the delayed commands ``CV(t - L)`` (see
    `model_inputs`), everywhere the inputs are built: the width searches, the fits,
    `predict` and `residuals`.

    Parameters
    ----------
    regressor
        Unfitted regressor with ``fit(X, y)`` and ``predict(X, return_std=True)``, cloned once
        per output. ``None``: ``bayes_fdi.rvm.RVR(kernel="rbf", width="auto")`` (kernel width
        by maximum evidence, see ``width_search``).
    width_search
        How a width ``"auto"`` of the regressor is resolved (a regressor with any other width
        is kept as given by ``"evidence-grid"`` and ``"evidence"``):

        ``"evidence-grid"`` (default): fit the regressor at every width of ``width_grid`` on a
        seeded subsample of at most ``evidence_max_samples`` fault-free samples (the same
        samples for ``X`` and ``F``), take the width of largest log evidence summed over the
        two models, and fit both outputs on all samples at that width (see Notes). Ten small
        fits, well under a second on the paper's data.
        ``"evidence"``: run the RVR's own ``width="auto"`` search (`bayes_fdi.rvm.width`,
        bounded below by 3x the median nearest-neighbour distance) per output on a seeded
        subsample of at most ``evidence_max_samples`` samples, then fit on all samples at the
        width found. On trajectory data (sine-driven runs lie on thin curves of the input
        space, so nearest-neighbour distances are tiny) it can choose very small widths
        (0.006-0.016 on the paper's campaigns) that keep about a hundred relevance vectors
        and make the whole fit 7-15 times slower (40-75 s against 5-6 s on the paper's 20
        fault-free runs).
        ``None``: keep the regressor as given (``"auto"`` then searches on every sample).
        ``"ga"``: choose the width parameter of each output's regressor with
        `genetic_width_search`, minimising the MSE on held-out fault-free runs (the
        paper's method), then refit on all fault-free runs with that width.
    width_param
        Name of the regressor's kernel-width parameter set by the GA.
    ga_bounds, ga_population, ga_generations
        GA search range (of the width) and sizes.
    ga_validation_fraction
        Fraction of the fault-free runs held out for the GA's validation MSE (at least one run;
        the GA needs two or more runs).
    ga_max_samples
        Training samples per GA fit (random subset; keeps the search affordable).
    evidence_max_samples
        Samples of the ``"evidence-grid"`` and ``"evidence"`` width searches (random subset).
    max_train_samples
        If set, fit each regressor on a random subset of this many fault-free samples
        (without replacement); ``None`` uses every sample. The paper used 20 runs x 350 s.
    chunk_size
        Samples per ``predict`` call (bounds memory).
    random_state
        Seed for subsampling, the GA's validation split, the GA itself and the calibration
        folds.
    interval_calibration
        ``"cross-fit"`` (default): make the predictive standard deviations honest out of
        sample (see Notes). ``None``: use the regressors' own predictive standard deviations
        (their in-sample noise estimate, optimistic on new runs).
    calibration_folds
        Number of folds (>= 2) of the cross-fit; the fault-free runs are split into folds by
        run.
    calibration_bins
        Number of bins (>= 1) of ``|dCV/dt|`` with their own scale factor; 1 gives a single
        factor per output.
    calibration_method
        How a bin's factor is fitted to its standardised held-out residuals ``z``: ``"mle"``
        (``sqrt(mean(z**2))``, Gaussian maximum likelihood) or ``"coverage"`` (matches the
        empirical 95 % coverage); see `bayes_fdi.calibration.StdScaler`.
    calibration_max_samples
        Training samples of each fold's refit (random subset; bounds the cost). ``None``: all
        samples of the other folds.
    input_lags
        Lags ``L`` in seconds of extra inputs ``CV(t - L)`` (dynamic normal models, beyond the
        paper; positive, distinct, whole multiples of the sampling step). Before a run's first
        sample the command is taken as held at its first value. Default ``()``: the paper's
        static models on ``(CV, sqrt(P1 - P2), T1)``.
    width_grid
        Candidate widths of the ``"evidence-grid"`` search (positive, finite, distinct;
        default `WIDTH_GRID`, ``(0.05, 0.1, 0.2, 0.4, 0.8)``).

    Attributes
    ----------
    regressors_ : dict
        ``{"X": fitted g1, "F": fitted g2}``.
    ga_results_ : dict
        ``{"X": GAResult, "F": GAResult}`` when ``width_search="ga"``, else empty.
    widths_ : dict
        ``{"X": width, "F": width}`` chosen by the width search (empty when none ran).
    width_log_evidence_ : dict
        ``"evidence-grid"`` search: grid width -> log evidence summed over ``X`` and ``F``
        (empty when the search did not run).
    width_log_evidence_by_output_ : dict
        ``"evidence-grid"`` search: ``{"X": {width: log evidence}, "F": {...}}`` (empty when
        the search did not run).
    n_train_samples_ : int
        Samples used to fit each regressor.
    n_negative_pressure_drop_ : int
        Fault-free training samples with ``P1 < P2`` (signed root used).
    n_dropped_nan_ : int
        Training samples left out because an input or output was NaN.
    fit_seconds_ : dict
        Wall-clock seconds: ``"X"``, ``"F"`` (final fits), ``"ga"``, ``"evidence-grid"`` or
        ``"evidence"`` (search, if any) and ``"calibration"`` (cross-fit, if any).
    interval_calibration_ : str or None
        The calibration applied (``None`` when none was, see above).
    std_scale_ : dict
        ``{"X": factors, "F": factors}``: one factor per ``|dCV/dt|`` bin (all 1 without
        calibration).
    std_scale_all_ : dict
        ``{"X": factor, "F": factor}`` fitted on all held-out residuals together (used where
        ``|dCV/dt|`` is not finite).
    std_scale_edges_ : numpy.ndarray
        Inner bin edges of ``|dCV/dt|`` (per second); bin ``b`` holds
        ``edges[b-1] <= |dCV/dt| < edges[b]``.
    calibration_fold_ : numpy.ndarray
        ``(n_runs, n_times)`` fold of each training sample in the cross-fit (-1: not used,
        e.g. NaN); absent without calibration.
    input_lags_ : tuple of float
        The validated lags (seconds) the models were fitted with; `predict` uses these.
    input_names_ : tuple of str
        Names of the model inputs, e.g. ``("CV", "sqrt_dP", "T1", "CV_lag1s", "CV_lag2s")``.
    n_features_in_ : int
        Number of model inputs (``3 + len(input_lags)``).

    Notes
    -----
    Width search. The default ``"evidence-grid"`` gives ``X`` and ``F`` one shared width, the
    grid width of largest summed log evidence, because that is exactly what
    `bayes_fdi.paper.reproduce.select_regression_width` does (both call
    `evidence_grid_search`):
    with ``random_state=0`` and ``evidence_max_samples=600`` (the defaults; ``bayes-fdi
    reproduce`` uses seed 0 and 600 samples) the chosen width is the one of the reproduction.
    The grid spans the widths where the evidence peaks on inputs normalised to [0, 1]. A
    per-output choice was not taken: ``X``'s evidence is nearly flat over the grid, so its own
    argmax jumps with the subsample (0.2, 0.8, 0.4 on the paper-simulated fault-free training
    runs for subsample seeds 0, 1, 2), while the summed evidence moves by at most one grid
    step (0.05, 0.05, 0.1; ``F`` alone: 0.1 for all three). Both outputs' evidences are
    recorded in ``width_log_evidence_by_output_``.

    Interval calibration. With ``interval_calibration="cross-fit"``, ``fit`` ends by splitting
    the fault-free runs into ``calibration_folds`` folds by run (seeded; a whole run is always
    in one fold, so autocorrelated samples of a run never calibrate their own prediction). When
    there are fewer runs than folds, every run is cut into contiguous time blocks and the blocks
    are assigned to folds. For each fold and output the regressor is refitted at the width
    already chosen on at most ``calibration_max_samples`` samples of the other folds, and the
    held-out samples' standardised residuals ``z = (y - mean) / std`` are collected. The samples
    are then binned by ``|dCV/dt|`` (per second, central differences along each run; bin edges
    are quantiles of the training samples) and each bin gets the factor ``calibration_method``
    fits to its ``z``. ``predict`` multiplies the predictive std by the factor of each sample's
    bin (samples whose ``|dCV/dt|`` is not finite, e.g. next to a gap or in one-sample runs, get
    the factor fitted on all bins together). The means are not changed. Only fault-free training
    runs are used. The static models' error grows where CV moves fast (the stem lags its
    command), and F's error vanishes at its flow rail, hence a factor per speed bin rather than
    one constant. When the training data cannot be split (fewer than ``2 * calibration_folds``
    finite samples), a warning is given and the factors stay 1 (``interval_calibration_`` is
    then ``None``).
    """

    def __init__(
        self,
        regressor: Any = None,
        *,
        width_search: str | None = "evidence-grid",
        width_param: str = "width",
        ga_bounds: tuple[float, float] = (1e-3, 10.0),
        ga_population: int = 12,
        ga_generations: int = 10,
        ga_validation_fraction: float = 0.25,
        ga_max_samples: int = 1000,
        evidence_max_samples: int = 600,
        max_train_samples: int | None = None,
        chunk_size: int = 20000,
        random_state: int | None = 0,
        interval_calibration: str | None = "cross-fit",
        calibration_folds: int = 4,
        calibration_bins: int = 5,
        calibration_method: str = "mle",
        calibration_max_samples: int | None = 2000,
        input_lags: Sequence[float] = (),
        width_grid: Sequence[float] = WIDTH_GRID,
    ) -> None:
        self.regressor = regressor
        self.width_search = width_search
        self.width_param = width_param
        self.ga_bounds = ga_bounds
        self.ga_population = ga_population
        self.ga_generations = ga_generations
        self.ga_validation_fraction = ga_validation_fraction
        self.ga_max_samples = ga_max_samples
        self.evidence_max_samples = evidence_max_samples
        self.max_train_samples = max_train_samples
        self.chunk_size = chunk_size
        self.random_state = random_state
        self.interval_calibration = interval_calibration
        self.calibration_folds = calibration_folds
        self.calibration_bins = calibration_bins
        self.calibration_method = calibration_method
        self.calibration_max_samples = calibration_max_samples
        self.input_lags = input_lags
        self.width_grid = width_grid

    # ------------------------------------------------------------------ fitting
    def _base(self) -> Any:
        return _default_regressor() if self.regressor is None else self.regressor

    @limit_fit_threads
    def fit(self, normal_runs: xr.Dataset) -> NormalModels:
        """Fit ``g1`` and ``g2`` on fault-free runs.

        Parameters
        ----------
        normal_runs
            Dataset with channels ``CV, P1, P2, T1, X, F``. If it has a ``state`` coordinate,
            every run must be ``"fn"``.

        Returns
        -------
        NormalModels
            ``self``.
        """
        grid, lags = self._check_fit(normal_runs)
        rng = np.random.default_rng(self.random_state)
        base = self._base()
        samples = training_samples(normal_runs, lags)
        U, targets = samples.U, samples.targets
        idx = np.flatnonzero(samples.finite)
        choice = choose_widths(
            base,
            U,
            targets,
            idx,
            samples.run_of,
            rng,
            method=self.width_search,
            width_param=self.width_param,
            grid=grid,
            evidence_max_samples=int(self.evidence_max_samples),
            ga_bounds=self.ga_bounds,
            ga_population=self.ga_population,
            ga_generations=self.ga_generations,
            ga_validation_fraction=self.ga_validation_fraction,
            ga_max_samples=self.ga_max_samples,
            random_state=self.random_state,
        )
        self.ga_results_: dict[str, GAResult] = choice.ga_results
        self.fit_seconds_: dict[str, float] = dict(choice.seconds)
        self.width_log_evidence_: dict[float, float] = choice.log_evidence
        self.width_log_evidence_by_output_: dict[str, dict[float, float]] = (
            choice.log_evidence_by_output
        )
        self.widths_ = dict(choice.widths)

        if self.max_train_samples is not None and idx.size > self.max_train_samples:
            idx = np.sort(rng.choice(idx, size=int(self.max_train_samples), replace=False))
        self.regressors_: dict[str, Any] = {}
        for name, y in targets.items():
            est = (
                with_width(base, self.width_param, choice.widths[name])
                if name in choice.widths
                else clone(base)
            )
            t0 = time.perf_counter()
            est.fit(U[idx], y[idx])
            self.fit_seconds_[name] = time.perf_counter() - t0
            self.regressors_[name] = est
        self.n_train_samples_ = int(idx.size)
        self.n_negative_pressure_drop_ = samples.n_negative_pressure_drop
        self.n_dropped_nan_ = samples.n_dropped
        self.input_lags_ = lags
        self.input_names_ = input_names(lags)
        self.n_features_in_ = len(self.input_names_)
        self._fit_interval_calibration(normal_runs, U, targets, samples.finite)
        return self

    def _check_fit(self, normal_runs: xr.Dataset) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """Check the fault-free runs and the parameters; the width grid and the input lags."""
        validate_dataset(normal_runs, require=INPUT_CHANNELS + OUTPUT_CHANNELS, allow_nan=True)
        if "state" in normal_runs.coords:
            states = sorted(set(map(str, normal_runs["state"].values)) - {"fn"})
            if states:
                raise ValueError(
                    f"normal models must be fitted on fault-free runs; got states {states}"
                )
        if self.width_search not in (None, "ga", "evidence", "evidence-grid"):
            raise ValueError(
                "width_search must be None, 'evidence-grid', 'evidence' or 'ga', got "
                f"{self.width_search!r}"
            )
        grid = check_width_grid(self.width_grid)
        m = self.evidence_max_samples
        if isinstance(m, bool) or not isinstance(m, int | np.integer) or m < 2:
            raise ValueError(f"evidence_max_samples must be an integer >= 2, got {m!r}")
        if self.max_train_samples is not None and int(self.max_train_samples) < 2:
            raise ValueError("max_train_samples must be at least 2")
        self._check_calibration_params()
        return grid, check_lags(self.input_lags)

    # ------------------------------------------------------- interval calibration
    def _check_calibration_params(self) -> None:
        if self.interval_calibration not in (None, "cross-fit"):
            raise ValueError(
                "interval_calibration must be None or 'cross-fit', got "
                f"{self.interval_calibration!r}"
            )
        for name, low in (("calibration_folds", 2), ("calibration_bins", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
                raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
        if self.calibration_method not in ("mle", "coverage"):
            raise ValueError(
                f"calibration_method must be 'mle' or 'coverage', got {self.calibration_method!r}"
            )
        m = self.calibration_max_samples
        if m is not None and (isinstance(m, bool) or not isinstance(m, int | np.integer) or m < 2):
            raise ValueError(f"calibration_max_samples must be None or an integer >= 2, got {m!r}")

    def _fit_interval_calibration(
        self,
        runs: xr.Dataset,
        U: np.ndarray,
        targets: dict[str, np.ndarray],
        finite: np.ndarray,
    ) -> None:
        """Cross-fitted scale factors of the predictive stds (see the class docstring)."""
        self.interval_calibration_: str | None = None
        self.std_scale_ = {name: np.ones(int(self.calibration_bins)) for name in OUTPUT_CHANNELS}
        self.std_scale_all_ = dict.fromkeys(OUTPUT_CHANNELS, 1.0)
        self.std_scale_edges_ = np.empty(0)
        if self.interval_calibration is None:
            return
        k = int(self.calibration_folds)
        if int(finite.sum()) < 2 * k:
            warnings.warn(
                f"only {int(finite.sum())} finite fault-free samples: too few for "
                f"{k}-fold interval calibration; predictive stds are not calibrated",
                UserWarning,
                stacklevel=3,
            )
            return
        scales = cross_fit_std_scales(
            runs,
            U,
            targets,
            finite,
            self.regressors_,
            width_param=self.width_param,
            n_folds=k,
            n_bins=int(self.calibration_bins),
            method=self.calibration_method,
            max_samples=self.calibration_max_samples,
            chunk_size=int(self.chunk_size),
            random_state=self.random_state,
        )
        self.fit_seconds_["calibration"] = scales.seconds
        self.std_scale_edges_ = scales.edges
        self.std_scale_all_ = scales.scale_all
        self.std_scale_ = scales.scale
        self.calibration_fold_ = scales.fold
        self.interval_calibration_ = self.interval_calibration

    def _std_factors(self, runs: xr.Dataset) -> dict[str, np.ndarray]:
        """Calibration factor of each sample of ``runs`` (flattened), per output name."""
        n = runs.sizes["run"] * runs.sizes["time"]
        if getattr(self, "interval_calibration_", None) is None:
            return {name: np.ones(n) for name in self.regressors_}
        bins = speed_bins(self.std_scale_edges_, command_speed(runs))
        factors = {}
        for name in self.regressors_:
            scales = self.std_scale_[name]
            per_bin = scales[np.clip(bins, 0, scales.size - 1)]
            factors[name] = np.where(bins >= 0, per_bin, self.std_scale_all_[name])
        return factors

    # --------------------------------------------------------------- prediction
    def _check_fitted(self) -> None:
        if not hasattr(self, "regressors_"):
            raise ValueError("NormalModels is not fitted; call fit(normal_runs) first")

    def predict(self, runs: xr.Dataset) -> xr.Dataset:
        """Predicted fault-free outputs and their predictive standard deviations.

        Parameters
        ----------
        runs
            Dataset with at least ``CV, P1, P2, T1``.

        Returns
        -------
        xarray.Dataset
            ``X_hat``, ``X_hat_std``, ``F_hat``, ``F_hat_std`` with dims ``(run, time)`` and the
            coordinates of ``runs``; attrs ``n_negative_pressure_drop`` and ``n_nan_inputs``.
        """
        self._check_fitted()
        U, n_neg = model_inputs(runs, input_lags=getattr(self, "input_lags_", ()))
        shape = (runs.sizes["run"], runs.sizes["time"])
        ok = np.isfinite(U).all(axis=1)
        factors = self._std_factors(runs) if ok.any() else {}
        data = {}
        for name, est in self.regressors_.items():
            mean = np.full(U.shape[0], np.nan)
            std = np.full(U.shape[0], np.nan)
            if ok.any():
                mean[ok], std[ok] = predict_with_std(est, U[ok], int(self.chunk_size))
                std *= factors[name]
            data[f"{name}_hat"] = (("run", "time"), mean.reshape(shape))
            data[f"{name}_hat_std"] = (("run", "time"), std.reshape(shape))
        coords = {k: v for k, v in runs.coords.items() if set(v.dims) <= {"run", "time"}}
        return xr.Dataset(
            data,
            coords=coords,
            attrs={"n_negative_pressure_drop": n_neg, "n_nan_inputs": int((~ok).sum())},
        )

    def residuals(self, runs: xr.Dataset) -> xr.Dataset:
        """Predictions plus residuals ``r1 = X - X_hat``, ``r2 = F - F_hat`` and ``z1``, ``z2``.

        ``z = r / predictive std`` (NaN where the std is not positive or the sample is NaN).

        Parameters
        ----------
        runs
            Dataset with ``CV, P1, P2, T1, X, F``.

        Returns
        -------
        xarray.Dataset
            The `predict` variables plus ``r1``, ``r2``, ``z1``, ``z2``.
        """
        validate_dataset(runs, require=INPUT_CHANNELS + OUTPUT_CHANNELS, allow_nan=True)
        out = self.predict(runs)
        for k, name in enumerate(OUTPUT_CHANNELS, start=1):
            r = runs[name].transpose("run", "time").values - out[f"{name}_hat"].values
            std = out[f"{name}_hat_std"].values
            z = np.full_like(r, np.nan)
            np.divide(r, std, out=z, where=np.isfinite(std) & (std > 0))
            out[f"r{k}"] = (("run", "time"), r)
            out[f"z{k}"] = (("run", "time"), z)
        return out

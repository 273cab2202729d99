"""Calibration of probabilistic diagnoses and of the normal models' predictive intervals.

A diagnoser is *calibrated* when its stated probabilities are frequencies: among the runs
it diagnoses as ``f2`` with probability 0.8, about 80 % really are ``f2``. A normal model
is calibrated when its 95 % predictive intervals contain about 95 % of fault-free
measurements. This module measures both, and recalibrates a whole tree's class
distribution (one temperature, vector scaling or Dirichlet calibration).

Classification
--------------
:func:`expected_calibration_error`
    Top-label or classwise ECE with equal-width (``"uniform"``) or equal-mass
    (``"quantile"``) bins, per-bin counts, the maximum calibration error (MCE) and seeded
    bootstrap confidence intervals.
:func:`log_loss`, :func:`brier`
    Proper scoring rules (scikit-learn's implementations, with the class order made explicit).
:func:`reliability_diagram`
    Matplotlib reliability diagram with the bin counts shown.
:class:`TemperatureScaler`
    One temperature fitted on held-out data by minimising the negative log-likelihood.
:class:`DirichletScaler`
    Dirichlet calibration (a linear map of the log-probabilities with ODIR penalty chosen
    by cross-validation), vector scaling, or one temperature.
:func:`cross_val_log_loss`
    Cross-validated log loss of a recalibrator, to choose one on calibration data only.
:func:`node_calibration`
    Binary calibration of every node of a hierarchical classifier on the samples of its classes.

Regression
----------
:func:`interval_coverage`, :func:`pit_values`, :func:`pit_histogram`, :func:`crps_gaussian`
    For Gaussian predictive distributions ``N(mean, std**2)``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np
from scipy import optimize, stats
from sklearn.base import BaseEstimator

__all__ = [
    "DEFAULT_LEVELS",
    "DEFAULT_REG_GRID",
    "CoverageResult",
    "DirichletScaler",
    "ECEResult",
    "NodeCalibration",
    "StdScaler",
    "TemperatureScaler",
    "brier",
    "cross_val_log_loss",
    "crps_gaussian",
    "expected_calibration_error",
    "interval_coverage",
    "log_loss",
    "node_calibration",
    "pit_histogram",
    "pit_values",
    "plot_pit_histogram",
    "reliability_diagram",
]

#: Central-interval levels reported by default for the normal models.
DEFAULT_LEVELS: tuple[float, ...] = (0.5, 0.8, 0.9, 0.95)


# --------------------------------------------------------------------------------------
# input checking
# --------------------------------------------------------------------------------------
def _check_proba(
    y_true: Any, proba: Any, classes: Sequence | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Validate labels and a probability matrix; return (labels, proba, classes)."""
    y = np.asarray(y_true)
    p = np.asarray(proba, dtype=np.float64)
    if y.ndim != 1:
        raise ValueError(f"y_true must be 1-D, got shape {y.shape}")
    if p.ndim != 2:
        raise ValueError(f"proba must be 2-D (n_samples, n_classes), got shape {p.shape}")
    if p.shape[0] != y.shape[0]:
        raise ValueError(f"y_true has {y.shape[0]} samples but proba has {p.shape[0]} rows")
    if p.shape[0] == 0:
        raise ValueError("no samples: y_true and proba are empty")
    if not np.all(np.isfinite(p)):
        raise ValueError("proba contains NaN or inf")
    if np.any(p < 0) or np.any(p > 1):
        raise ValueError("proba must lie in [0, 1]")
    if not np.allclose(p.sum(axis=1), 1.0, atol=1e-6):
        worst = float(np.max(np.abs(p.sum(axis=1) - 1.0)))
        raise ValueError(f"rows of proba must sum to 1 (largest deviation {worst:.3g})")
    cls = np.unique(y) if classes is None else np.asarray(classes)
    if cls.ndim != 1 or len(np.unique(cls)) != len(cls):
        raise ValueError("classes must be a 1-D sequence of distinct labels")
    if len(cls) != p.shape[1]:
        raise ValueError(
            f"proba has {p.shape[1]} columns but there are {len(cls)} classes; "
            "pass `classes` in the column order of proba"
        )
    unknown = np.setdiff1d(np.unique(y), cls)
    if unknown.size:
        raise ValueError(f"y_true contains labels not in classes: {unknown.tolist()}")
    return y, p, cls


def _check_gaussian(y: Any, mean: Any, std: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Validate and broadcast observations and Gaussian predictive moments."""
    try:
        y_, m_, s_ = np.broadcast_arrays(
            np.asarray(y, dtype=np.float64),
            np.asarray(mean, dtype=np.float64),
            np.asarray(std, dtype=np.float64),
        )
    except ValueError as err:
        raise ValueError(f"y, mean and std do not broadcast together: {err}") from None
    for name, a in (("y", y_), ("mean", m_), ("std", s_)):
        if not np.all(np.isfinite(a)):
            raise ValueError(
                f"{name} contains NaN or inf; select the finite samples explicitly before scoring"
            )
    if np.any(s_ <= 0):
        raise ValueError("std must be strictly positive")
    if y_.size == 0:
        raise ValueError("no samples to score")
    return y_, m_, s_


# --------------------------------------------------------------------------------------
# expected calibration error
# --------------------------------------------------------------------------------------
class ECEResult(NamedTuple):
    """Expected calibration error with its bins (immutable).

    For the top-label ECE the bin arrays have shape ``(n_bins,)``; for the classwise ECE
    they have shape ``(n_classes, n_bins)`` (one row per class, in ``classes`` order).
    Empty bins have count 0 and NaN confidence/accuracy.

    Attributes
    ----------
    value
        ECE: sum over bins of ``count / n * |accuracy - confidence|`` (classwise: averaged
        over classes).
    ci_low, ci_high
        Bootstrap confidence interval of the population ECE (NaN when ``n_bootstrap == 0``);
        by default the *basic* (bias-reversing) interval ``[2 v - q_hi, 2 v - q_lo]``
        clipped at 0, see :func:`expected_calibration_error`.
    bin_edges
        Bin edges, ``n_bins + 1`` per row.
    bin_counts
        Number of samples in each bin.
    bin_confidence
        Mean predicted probability in each bin.
    bin_accuracy
        Observed frequency (top-label: fraction correct; classwise: fraction of that class).
    mce
        Maximum calibration error: largest ``|accuracy - confidence|`` over non-empty bins
        (classwise: over all classes).
    strategy
        ``"uniform"`` or ``"quantile"``.
    classwise
        Whether this is the classwise ECE.
    classes
        Class labels in column order.
    debiased
        Bootstrap bias-corrected ECE ``max(0, 2 v - mean(bootstrap ECEs))`` (NaN without
        bootstrap).
    noise_floor
        Expected ECE of a *perfectly calibrated* model with the same bins and confidences
        (normal approximation: ``sqrt(2/pi) * sum_b sqrt(sum_{i in b} c_i (1 - c_i)) / n``).
        An ECE near this value is indistinguishable from sampling noise.
    """

    value: float
    ci_low: float
    ci_high: float
    bin_edges: np.ndarray
    bin_counts: np.ndarray
    bin_confidence: np.ndarray
    bin_accuracy: np.ndarray
    mce: float
    strategy: str = "uniform"
    classwise: bool = False
    classes: np.ndarray | None = None
    debiased: float = float("nan")
    noise_floor: float = float("nan")

    @property
    def n_samples(self) -> int:
        """Number of samples the ECE was computed on (per class for the classwise ECE)."""
        counts = np.atleast_2d(self.bin_counts)
        return int(counts[0].sum())


def _bin_stats(
    conf: np.ndarray, hit: np.ndarray, n_bins: int, strategy: str
) -> tuple[float, float, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """Bin ``conf``: (ece, mce, edges, counts, mean conf, mean hit, noise floor)."""
    n = conf.shape[0]
    if strategy == "uniform":
        edges = np.linspace(0.0, 1.0, n_bins + 1)
        # bin b holds edges[b] < conf <= edges[b+1] (bin 0 also holds conf == 0), as
        # sklearn.calibration.calibration_curve does.
        idx = np.searchsorted(edges[1:-1], conf, side="left")
    else:
        # Equal mass by rank: the sorted samples are cut into n_bins chunks whose sizes
        # differ by at most one, even when confidences are tied.
        order = np.argsort(conf, kind="stable")
        idx = np.empty(n, dtype=np.intp)
        chunks = np.array_split(order, n_bins)
        inner = []
        for b, chunk in enumerate(chunks):
            idx[chunk] = b
        sorted_conf = conf[order]
        sizes = np.cumsum([len(c) for c in chunks])[:-1]
        for s in sizes:
            lo = sorted_conf[s - 1] if s > 0 else 0.0
            hi = sorted_conf[s] if s < n else 1.0
            inner.append(0.5 * (lo + hi))
        edges = np.concatenate([[0.0], inner, [1.0]])
    counts = np.bincount(idx, minlength=n_bins).astype(np.int64)
    sum_conf = np.bincount(idx, weights=conf, minlength=n_bins)
    sum_hit = np.bincount(idx, weights=hit, minlength=n_bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_conf = np.where(counts > 0, sum_conf / counts, np.nan)
        mean_hit = np.where(counts > 0, sum_hit / counts, np.nan)
    gap = np.abs(sum_hit - sum_conf)  # = count * |acc - conf|
    ece = float(gap.sum() / n)
    nonempty = counts > 0
    mce = float(np.max(np.abs(mean_hit[nonempty] - mean_conf[nonempty])))
    var_sum = np.bincount(idx, weights=conf * (1.0 - conf), minlength=n_bins)
    floor = float(np.sqrt(2.0 / np.pi) * np.sum(np.sqrt(var_sum)) / n)
    return ece, mce, edges, counts, mean_conf, mean_hit, floor


def _conf_hit(y_idx: np.ndarray, p: np.ndarray, classwise: bool) -> tuple[np.ndarray, np.ndarray]:
    """Confidences and outcomes, one column per binned quantity (1 top-label, K classwise)."""
    if classwise:
        hit = (y_idx[:, None] == np.arange(p.shape[1])[None, :]).astype(np.float64)
        return p, hit
    pred = np.argmax(p, axis=1)
    conf = p[np.arange(p.shape[0]), pred]
    return conf[:, None], (pred == y_idx).astype(np.float64)[:, None]


def _ece_arrays(
    conf: np.ndarray, hit: np.ndarray, n_bins: int, strategy: str, classwise: bool
) -> tuple[float, float, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    rows = [_bin_stats(conf[:, k], hit[:, k], n_bins, strategy) for k in range(conf.shape[1])]
    if not classwise:
        return rows[0]
    ece = float(np.mean([r[0] for r in rows]))
    mce = float(np.max([r[1] for r in rows]))
    stacked = [np.stack([r[i] for r in rows]) for i in range(2, 6)]
    floor = float(np.mean([r[6] for r in rows]))
    return (ece, mce, *stacked, floor)


def expected_calibration_error(
    y_true: Any,
    proba: Any,
    *,
    classes: Sequence | None = None,
    n_bins: int = 15,
    strategy: str = "uniform",
    classwise: bool = False,
    n_bootstrap: int = 0,
    confidence_level: float = 0.95,
    ci_method: str = "basic",
    random_state: int | np.random.Generator | None = None,
) -> ECEResult:
    """Expected calibration error of a class distribution.

    Top-label ECE (default): the confidence of each sample is its largest probability and
    the outcome is whether that class is the true one; the ECE is the count-weighted mean
    over bins of ``|accuracy - mean confidence|``. Classwise ECE (``classwise=True``, Kull
    et al. 2019): the same for every class ``k`` with confidence ``proba[:, k]`` and outcome
    ``y == k``, averaged over classes. Both are binned estimators and biased upwards for
    finite samples (even a perfectly calibrated model has ECE > 0, of order
    ``sqrt(n_bins / n)``, returned as ``noise_floor``), which is why bin counts, a
    bias-corrected value and bootstrap intervals are returned too.

    The bootstrap resamples the samples with replacement and recomputes the ECE (equal-mass
    bins are re-cut on every resample). Because the ECE of a resample is biased upwards
    relative to the ECE of the sample, just as the sample's is relative to the population's,
    the default interval is the *basic* bootstrap interval ``[2 v - q_hi, 2 v - q_lo]``
    (clipped at 0), which moves the bias the right way; ``ci_method="percentile"`` gives
    ``[q_lo, q_hi]`` (the spread of resampled ECEs, which can lie entirely above ``v``).

    Parameters
    ----------
    y_true
        True labels, shape ``(n,)``.
    proba
        Class probabilities, shape ``(n, n_classes)``, rows summing to 1, columns in the
        order of ``classes``.
    classes
        Labels of the columns of ``proba``; default: the sorted unique labels of ``y_true``.
    n_bins
        Number of bins (default 15).
    strategy
        ``"uniform"``: equal-width bins on [0, 1], bin ``b`` holding
        ``edges[b] < conf <= edges[b+1]``; ``"quantile"``: equal-mass bins, the samples
        sorted by confidence cut into ``n_bins`` chunks whose sizes differ by at most one
        (ties are split by sample order); reported edges are midpoints between neighbouring
        chunks.
    classwise
        Compute the classwise ECE instead of the top-label ECE.
    n_bootstrap
        Number of bootstrap resamples (of samples, with replacement) for the confidence
        interval and ``debiased``; 0 (default) skips them (NaN).
    confidence_level
        Coverage of the bootstrap interval (default 0.95).
    ci_method
        ``"basic"`` (default) or ``"percentile"`` bootstrap interval.
    random_state
        Seed or generator of the bootstrap.

    Returns
    -------
    ECEResult
    """
    y, p, cls = _check_proba(y_true, proba, classes)
    if strategy not in ("uniform", "quantile"):
        raise ValueError(f"strategy must be 'uniform' or 'quantile', got {strategy!r}")
    if int(n_bins) != n_bins or n_bins < 1:
        raise ValueError(f"n_bins must be a positive integer, got {n_bins!r}")
    n_bins = int(n_bins)
    if strategy == "quantile" and n_bins > y.shape[0]:
        raise ValueError(f"quantile strategy needs at least n_bins={n_bins} samples")
    if n_bootstrap < 0:
        raise ValueError("n_bootstrap must be >= 0")
    if not 0 < confidence_level < 1:
        raise ValueError("confidence_level must lie in (0, 1)")
    if ci_method not in ("basic", "percentile"):
        raise ValueError(f"ci_method must be 'basic' or 'percentile', got {ci_method!r}")
    lookup = {c: i for i, c in enumerate(cls.tolist())}
    y_idx = np.array([lookup[v] for v in y.tolist()], dtype=np.intp)
    c_all, h_all = _conf_hit(y_idx, p, classwise)
    ece, mce, edges, counts, conf, acc, floor = _ece_arrays(
        c_all, h_all, n_bins, strategy, classwise
    )
    lo = hi = debiased = float("nan")
    if n_bootstrap:
        rng = np.random.default_rng(random_state)
        n = y.shape[0]
        boots = np.empty(n_bootstrap)
        for i in range(n_bootstrap):
            take = rng.integers(0, n, size=n)
            boots[i] = _ece_arrays(c_all[take], h_all[take], n_bins, strategy, classwise)[0]
        alpha = (1.0 - confidence_level) / 2.0
        q_lo, q_hi = (float(v) for v in np.quantile(boots, [alpha, 1.0 - alpha]))
        if ci_method == "percentile":
            lo, hi = q_lo, q_hi
        else:
            lo, hi = max(0.0, 2 * ece - q_hi), max(0.0, 2 * ece - q_lo)
        debiased = max(0.0, 2 * ece - float(np.mean(boots)))
    return ECEResult(
        value=ece,
        ci_low=lo,
        ci_high=hi,
        bin_edges=edges,
        bin_counts=counts,
        bin_confidence=conf,
        bin_accuracy=acc,
        mce=mce,
        strategy=strategy,
        classwise=bool(classwise),
        classes=cls,
        debiased=debiased,
        noise_floor=floor,
    )


# --------------------------------------------------------------------------------------
# proper scoring rules
# --------------------------------------------------------------------------------------
def _sorted_columns(y, proba, classes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Reorder the columns of proba to sorted class order (scikit-learn's convention)."""
    y, p, cls = _check_proba(y, proba, classes)
    order = np.argsort(cls, kind="stable")
    return y, p[:, order], cls[order]


def log_loss(y_true: Any, proba: Any, *, classes: Sequence | None = None) -> float:
    """Mean negative log-likelihood of the true class (natural log).

    Uses :func:`sklearn.metrics.log_loss`; the columns of ``proba`` are given in the order
    of ``classes`` (default: sorted unique labels of ``y_true``) and are re-ordered here
    for scikit-learn, which assumes sorted labels. Probabilities of exactly 0 are clipped
    by scikit-learn to the float64 machine epsilon.
    """
    from sklearn.metrics import log_loss as _sk_log_loss

    y, p, cls = _sorted_columns(y_true, proba, classes)
    return float(_sk_log_loss(y, p, labels=cls))


def brier(
    y_true: Any, proba: Any, *, classes: Sequence | None = None, scale_by_half: bool = False
) -> float:
    """Multi-class Brier score: mean squared distance of the probability vector to the one-hot.

    ``brier = mean_i sum_k (proba[i, k] - [y_i == k])**2``, which lies in [0, 2] for every
    number of classes (also for two classes: twice the usual binary Brier score of the
    positive-class probability). ``scale_by_half=True`` divides by two ([0, 1]; for two
    classes the usual binary Brier score). Computed by
    :func:`sklearn.metrics.brier_score_loss` with the class order made explicit.
    """
    from sklearn.metrics import brier_score_loss

    y, p, cls = _sorted_columns(y_true, proba, classes)
    return float(brier_score_loss(y, p, labels=cls, scale_by_half=bool(scale_by_half)))


# --------------------------------------------------------------------------------------
# reliability diagram
# --------------------------------------------------------------------------------------
def reliability_diagram(
    result_or_y: ECEResult | Any,
    proba: Any | None = None,
    *,
    ax: Any = None,
    title: str | None = None,
    show_counts: bool = True,
    class_index: int | None = None,
    **ece_kwargs: Any,
):
    """Draw a reliability diagram (observed frequency against mean confidence per bin).

    Parameters
    ----------
    result_or_y
        An :class:`ECEResult`, or the true labels (then pass ``proba`` and optionally the
        keyword arguments of :func:`expected_calibration_error`).
    proba
        Class probabilities when ``result_or_y`` holds labels.
    ax
        Matplotlib axes to draw into (default: a new figure).
    title
        Axes title; default states the ECE (with its bootstrap interval if present).
    show_counts
        Write each bin's sample count above its bar.
    class_index
        For a classwise result, which class row to draw (default: all bins pooled, the
        bars then show each bin summed over classes).

    Returns
    -------
    matplotlib.axes.Axes
    """
    import matplotlib.pyplot as plt

    if isinstance(result_or_y, ECEResult):
        if proba is not None:
            raise ValueError("pass either an ECEResult or (y_true, proba), not both")
        res = result_or_y
    else:
        if proba is None:
            raise ValueError("reliability_diagram needs proba when given labels")
        res = expected_calibration_error(result_or_y, proba, **ece_kwargs)
    edges = np.asarray(res.bin_edges, dtype=float)
    counts = np.asarray(res.bin_counts)
    conf = np.asarray(res.bin_confidence, dtype=float)
    acc = np.asarray(res.bin_accuracy, dtype=float)
    if res.classwise:
        if class_index is None:
            if res.strategy != "uniform":
                raise ValueError(
                    "pooling classwise bins needs uniform bins; pass class_index to draw one class"
                )
            tot = counts.sum(axis=0)
            with np.errstate(invalid="ignore", divide="ignore"):
                conf = np.where(tot > 0, np.nansum(conf * counts, axis=0) / tot, np.nan)
                acc = np.where(tot > 0, np.nansum(acc * counts, axis=0) / tot, np.nan)
            counts, edges = tot, edges[0]
        else:
            conf, acc = conf[class_index], acc[class_index]
            counts, edges = counts[class_index], edges[class_index]
    if ax is None:
        _, ax = plt.subplots(figsize=(4.5, 4.5))
    left, width = edges[:-1], np.diff(edges)
    ok = counts > 0
    ax.plot([0, 1], [0, 1], ls="--", color="0.5", lw=1, label="perfect calibration")
    ax.bar(
        left[ok], acc[ok], width=width[ok], align="edge", color="C0", alpha=0.75,
        edgecolor="k", lw=0.5, label="observed frequency",
    )  # fmt: skip
    ax.bar(
        left[ok], conf[ok] - acc[ok], bottom=acc[ok], width=width[ok], align="edge",
        color="C3", alpha=0.3, edgecolor="C3", lw=0.5, hatch="//", label="gap to confidence",
    )  # fmt: skip
    ax.plot(conf[ok], acc[ok], "o", color="k", ms=3, label="(mean confidence, frequency)")
    if show_counts:
        for lo_, w_, a_, c_ in zip(left[ok], width[ok], acc[ok], counts[ok], strict=True):
            ax.text(lo_ + w_ / 2, min(a_ + 0.02, 0.97), str(int(c_)), ha="center", fontsize=6)
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.set_xlabel("confidence" if not res.classwise else "predicted probability")
    ax.set_ylabel("observed frequency")
    if title is None:
        kind = "classwise ECE" if res.classwise else "ECE"
        title = f"{kind} = {res.value:.3f}"
        if np.isfinite(res.ci_low):
            title += f" [{res.ci_low:.3f}, {res.ci_high:.3f}]"
        title += f", n = {res.n_samples}"
    ax.set_title(title, fontsize=9)
    ax.legend(loc="upper left", fontsize=7)
    return ax


# --------------------------------------------------------------------------------------
# temperature scaling
# --------------------------------------------------------------------------------------
def _log_softmax(z: np.ndarray) -> np.ndarray:
    shifted = z - np.max(z, axis=1, keepdims=True)
    return shifted - np.log(np.sum(np.exp(shifted), axis=1, keepdims=True))


class TemperatureScaler(BaseEstimator):
    """Recalibrate class distributions with one temperature (Guo et al. 2017).

    ``q = softmax(log(p) / T)``: ``T > 1`` softens over-confident distributions, ``T < 1``
    sharpens under-confident ones; the arg-max (the diagnosed class) never changes. ``T``
    is fitted on held-out data by minimising the mean negative log-likelihood with a
    bounded 1-D optimiser (Brent) on the inverse temperature, where the NLL is convex.

    It is meant for the output of a whole hierarchical tree: products of node
    probabilities along tree paths are typically miscalibrated even when every node is.

    Parameters
    ----------
    input
        ``"proba"`` (default): ``fit``/``transform`` take probabilities, whose logarithms
        serve as logits; ``"logits"``: they take unnormalised log-probabilities.
    floor
        Probabilities below ``floor`` are raised to ``floor`` before taking logarithms
        (default 1e-12, so that a class the model excludes stays excluded up to
        ``floor ** (1/T)`` and log(0) never occurs). Only used with ``input="proba"``.
    bounds
        Search interval of ``T`` (default (0.02, 50)). A fitted value at a bound is reported
        in ``at_bound_``.
    classes
        Column labels; default: the sorted unique labels seen in ``fit``.

    Attributes
    ----------
    temperature_ : float
    classes_ : numpy.ndarray
    nll_before_, nll_after_ : float
        Mean NLL on the fitting data at ``T = 1`` and at ``temperature_``.
    at_bound_ : bool
    n_samples_ : int
    """

    def __init__(
        self,
        *,
        input: str = "proba",
        floor: float = 1e-12,
        bounds: tuple[float, float] = (0.02, 50.0),
        classes: Sequence | None = None,
    ) -> None:
        self.input = input
        self.floor = floor
        self.bounds = bounds
        self.classes = classes

    def _logits(self, values: Any) -> np.ndarray:
        a = np.asarray(values, dtype=np.float64)
        if a.ndim != 2 or a.shape[1] < 2:
            raise ValueError(f"expected a 2-D array with >= 2 class columns, got shape {a.shape}")
        if self.input == "logits":
            if not np.all(np.isfinite(a)):
                raise ValueError("logits contain NaN or inf")
            return a
        if self.input != "proba":
            raise ValueError(f"input must be 'proba' or 'logits', got {self.input!r}")
        if not 0 < self.floor < 1:
            raise ValueError("floor must lie in (0, 1)")
        if not np.all(np.isfinite(a)) or np.any(a < 0) or np.any(a > 1):
            raise ValueError("probabilities must be finite and lie in [0, 1]")
        if not np.allclose(a.sum(axis=1), 1.0, atol=1e-6):
            raise ValueError("rows of the probabilities must sum to 1")
        return np.log(np.maximum(a, self.floor))

    def fit(self, proba_or_logits: Any, y: Any) -> TemperatureScaler:
        """Fit the temperature on held-out ``(proba_or_logits, y)``."""
        z = self._logits(proba_or_logits)
        y_idx, cls = _class_indices(y, z.shape[0], self.classes, z.shape[1])
        t_lo, t_hi = (float(b) for b in self.bounds)
        if not 0 < t_lo < t_hi:
            raise ValueError(f"bounds must satisfy 0 < low < high, got {self.bounds}")
        rows = np.arange(z.shape[0])

        def nll(beta: float) -> float:
            return float(-np.mean(_log_softmax(beta * z)[rows, y_idx]))

        res = optimize.minimize_scalar(
            nll, bounds=(1.0 / t_hi, 1.0 / t_lo), method="bounded", options={"xatol": 1e-8}
        )
        beta = float(res.x)
        self.temperature_ = 1.0 / beta
        self.classes_ = cls
        self.nll_before_ = nll(1.0)
        self.nll_after_ = float(res.fun)
        rel = 1e-3
        self.at_bound_ = bool(
            abs(self.temperature_ - t_lo) <= rel * t_lo
            or abs(self.temperature_ - t_hi) <= rel * t_hi
        )
        self.n_samples_ = int(z.shape[0])
        return self

    def transform(self, proba_or_logits: Any) -> np.ndarray:
        """Recalibrated probabilities ``softmax(logits / T)``; rows sum to 1."""
        if not hasattr(self, "temperature_"):
            raise ValueError("TemperatureScaler is not fitted; call fit first")
        z = self._logits(proba_or_logits)
        if z.shape[1] != len(self.classes_):
            raise ValueError(f"expected {len(self.classes_)} columns, got {z.shape[1]}")
        return np.exp(_log_softmax(z / self.temperature_))

    def fit_transform(self, proba_or_logits: Any, y: Any) -> np.ndarray:
        """``fit`` then ``transform`` on the same data."""
        return self.fit(proba_or_logits, y).transform(proba_or_logits)

    def __repr__(self) -> str:
        t = f", temperature_={self.temperature_:.4g}" if hasattr(self, "temperature_") else ""
        return f"TemperatureScaler(input={self.input!r}, floor={self.floor!r}{t})"


# --------------------------------------------------------------------------------------
# Dirichlet (matrix) and vector scaling
# --------------------------------------------------------------------------------------
#: Default grid of the ODIR penalty searched by :class:`DirichletScaler`'s cross-validation.
DEFAULT_REG_GRID: tuple[float, ...] = (1e-3, 1e-2, 3e-2, 0.1, 0.3, 1.0, 10.0)

_PARAMETRIZATIONS = ("full", "diagonal", "scalar")


def _class_indices(y: Any, n_rows: int, classes: Sequence | None, n_cols: int):
    """Labels as column indices (validated); returns (indices, classes)."""
    y = np.asarray(y)
    if y.ndim != 1 or y.shape[0] != n_rows:
        raise ValueError(f"y must be 1-D with {n_rows} labels, got shape {y.shape}")
    if n_rows == 0:
        raise ValueError("no samples to fit on")
    cls = np.unique(y) if classes is None else np.asarray(classes)
    if cls.ndim != 1 or len(np.unique(cls)) != len(cls):
        raise ValueError("classes must be a 1-D sequence of distinct labels")
    if len(cls) != n_cols:
        raise ValueError(f"{n_cols} columns but {len(cls)} classes; pass `classes` in column order")
    lookup = {c: i for i, c in enumerate(cls.tolist())}
    try:
        y_idx = np.array([lookup[v] for v in y.tolist()], dtype=np.intp)
    except KeyError as err:
        raise ValueError(f"label {err.args[0]!r} is not among the classes") from None
    return y_idx, cls


def _fold_indices(y_idx: np.ndarray, n_folds: int, seed: int | None) -> list[np.ndarray]:
    """Seeded folds, stratified by class (each class dealt round-robin after shuffling)."""
    rng = np.random.default_rng(seed)
    fold = np.empty(y_idx.shape[0], dtype=np.intp)
    start = 0
    for c in np.unique(y_idx):
        idx = rng.permutation(np.flatnonzero(y_idx == c))
        fold[idx] = (start + np.arange(idx.size)) % n_folds
        start += idx.size  # continue the round robin so fold sizes stay balanced
    return [np.flatnonzero(fold == f) for f in range(n_folds)]


class DirichletScaler(BaseEstimator):
    """Recalibrate class distributions with a linear map of the log-probabilities.

    ``q = softmax(W log(p) + b)`` (Kull et al. 2019, *Beyond temperature scaling: obtaining
    well-calibrated multiclass probabilities with Dirichlet calibration*, NeurIPS). ``W`` is
    a ``K x K`` matrix and ``b`` a ``K``-vector, fitted on held-out data by minimising the mean
    negative log-likelihood plus the ODIR penalty (off-diagonal and intercept regularisation)

    ``reg_lambda / (K (K - 1)) * sum_{i != j} W_ij**2 + reg_mu / K * sum_j b_j**2``,

    so that with a strong penalty the map shrinks towards per-class powers
    ``q_k ∝ p_k ** W_kk`` and never to zero (the diagonal is not penalised). ``W = I``,
    ``b = 0`` is the identity on probabilities. Unlike :class:`TemperatureScaler` the map
    can move probability between classes, so the arg-max (the diagnosed class) **can
    change**: compare the accuracy before and after.

    The penalty is chosen by ``cv``-fold cross-validation on the fitting data (folds
    stratified by class and seeded by ``random_state``): the value of ``reg_grid`` with the
    lowest mean held-out NLL (ties: the larger penalty); ``reg_mu`` is tied to ``reg_lambda``
    unless given.

    Parameters
    ----------
    parametrization
        ``"full"`` (default): Dirichlet calibration, full ``W`` and ``b``;
        ``"diagonal"``: vector scaling, ``W`` diagonal (one power per class) and ``b``;
        ``"scalar"``: ``W = I / T``, ``b = 0`` (temperature scaling, no penalty, no
        cross-validation).
    reg_lambda
        Off-diagonal penalty; ``None`` (default) chooses it from ``reg_grid`` by
        cross-validation. Ignored unless ``parametrization="full"``.
    reg_mu
        Intercept penalty; ``None`` (default) uses the same value as ``reg_lambda`` (for
        ``"diagonal"``: cross-validated on ``reg_grid``).
    reg_grid
        Penalties tried by the cross-validation.
    cv
        Number of cross-validation folds (>= 2).
    min_samples
        Fewer fitting samples than this, or fewer than ``2 * cv``, and the scaler falls back
        to one temperature (``parametrization="scalar"``), recorded in ``fallback_``.
        ``None`` (default): ``10 * K`` for ``"full"``, ``3 * K`` for ``"diagonal"``.
    input
        ``"proba"`` (default) or ``"logits"`` (unnormalised log-probabilities), as for
        :class:`TemperatureScaler`.
    floor
        Probabilities below ``floor`` are raised to it before taking logarithms (default
        1e-12, as :class:`TemperatureScaler`).
    classes
        Column labels; default: the sorted unique labels seen in ``fit``.
    random_state
        Seed of the cross-validation folds.
    max_iter
        Iteration limit of the (damped Newton) optimiser.

    Attributes
    ----------
    coef_ : numpy.ndarray
        ``W``, shape ``(K, K)``; rows are output classes. Adding one constant to a whole
        column of ``W`` leaves the map unchanged for probability input, so compare maps (or
        column-centred ``W``), not raw matrices.
    intercept_ : numpy.ndarray
        ``b``, shape ``(K,)`` (defined up to a common constant).
    reg_lambda_, reg_mu_ : float
        Penalties used for the final fit.
    cv_results_ : dict
        Penalty -> mean held-out NLL (empty when no cross-validation ran).
    classes_ : numpy.ndarray
    nll_before_, nll_after_ : float
        Mean NLL on the fitting data before recalibration and after it (without penalty).
    fallback_ : str or None
        Why the requested parametrization was replaced by ``"scalar"``, else None.
    parametrization_ : str
        The parametrization actually fitted.
    converged_ : bool
    n_samples_ : int
    """

    def __init__(
        self,
        *,
        parametrization: str = "full",
        reg_lambda: float | None = None,
        reg_mu: float | None = None,
        reg_grid: Sequence[float] = DEFAULT_REG_GRID,
        cv: int = 5,
        min_samples: int | None = None,
        input: str = "proba",
        floor: float = 1e-12,
        classes: Sequence | None = None,
        random_state: int | None = 0,
        max_iter: int = 100,
    ) -> None:
        self.parametrization = parametrization
        self.reg_lambda = reg_lambda
        self.reg_mu = reg_mu
        self.reg_grid = reg_grid
        self.cv = cv
        self.min_samples = min_samples
        self.input = input
        self.floor = floor
        self.classes = classes
        self.random_state = random_state
        self.max_iter = max_iter

    def _logits(self, values: Any) -> np.ndarray:
        return TemperatureScaler(input=self.input, floor=self.floor)._logits(values)

    # ---- the optimisation problem
    @staticmethod
    def _basis(k: int, kind: str) -> np.ndarray:
        """Matrix mapping the free parameters to ``vec([W | b])`` (row-major, k x (k+1))."""
        full = np.eye(k * (k + 1))
        if kind == "full":
            return full
        diag_cols = [a * (k + 1) + a for a in range(k)]
        if kind == "diagonal":
            return full[:, diag_cols + [a * (k + 1) + k for a in range(k)]]
        return full[:, diag_cols].sum(axis=1, keepdims=True)

    @staticmethod
    def _identity(k: int, kind: str) -> np.ndarray:
        if kind == "full":
            return np.concatenate([np.eye(k), np.zeros((k, 1))], axis=1).ravel()
        if kind == "diagonal":
            return np.concatenate([np.ones(k), np.zeros(k)])
        return np.ones(1)

    @staticmethod
    def _unpack(theta: np.ndarray, basis: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        m = (basis @ theta).reshape(k, k + 1)
        return m[:, :k], m[:, k]

    def _solve(
        self,
        z: np.ndarray,
        y_idx: np.ndarray,
        kind: str,
        lam: float,
        mu: float,
        theta0: np.ndarray | None = None,
    ) -> tuple[np.ndarray, bool]:
        """Penalised multinomial logistic regression on ``[z, 1]`` by damped Newton steps.

        The objective is convex; Newton's method with a backtracking line search converges in
        a few tens of steps where first-order methods crawl (log-probabilities of a tree are
        strongly correlated). The Hessian is singular along ``W -> W + 1 v^T`` (a constant
        added to every logit) when the penalty does not fix it: steps are least-squares.
        ``theta0`` warm-starts the iteration (the penalty path of the cross-validation).
        """
        n, k = z.shape
        x = np.concatenate([z, np.ones((n, 1))], axis=1)
        onehot = np.zeros((n, k))
        onehot[np.arange(n), y_idx] = 1.0
        basis = self._basis(k, kind)
        pen = np.zeros((k, k + 1))
        if k > 1:
            pen[:, :k] = lam / (k * (k - 1)) * (1.0 - np.eye(k))
        pen[:, k] = mu / k
        pen_phi = basis.T @ (pen.ravel()[:, None] * basis)  # penalty = theta' pen_phi theta
        xx = (x[:, :, None] * x[:, None, :]).reshape(n, -1)

        def value(theta: np.ndarray) -> tuple[float, np.ndarray]:
            m = (basis @ theta).reshape(k, k + 1)
            logq = _log_softmax(x @ m.T)
            return float(-np.sum(onehot * logq) / n + theta @ pen_phi @ theta), logq

        theta = self._identity(k, kind) if theta0 is None else np.array(theta0, dtype=np.float64)
        f, logq = value(theta)
        ok = False
        for _ in range(int(self.max_iter)):
            q = np.exp(logq)
            grad_m = ((q - onehot).T @ x) / n
            g = basis.T @ grad_m.ravel() + 2.0 * pen_phi @ theta
            if np.max(np.abs(g)) < 1e-9:
                ok = True
                break
            s = (q[:, :, None] * (np.eye(k)[None] - q[:, None, :])).reshape(n, -1)
            h = (s.T @ xx / n).reshape(k, k, k + 1, k + 1).transpose(0, 2, 1, 3)
            h = basis.T @ h.reshape(k * (k + 1), -1) @ basis + 2.0 * pen_phi
            try:  # positive definite when the penalty fixes every direction: Cholesky
                chol = np.linalg.cholesky(h)
                step = -np.linalg.solve(chol.T, np.linalg.solve(chol, g))
            except np.linalg.LinAlgError:  # singular along W -> W + 1 v^T: least squares
                step = -np.linalg.lstsq(h, g, rcond=1e-12)[0]
            slope = float(g @ step)
            if slope >= 0:  # numerically flat: no descent direction left
                step, slope = -g, -float(g @ g)
            t = 1.0
            while True:
                f_new, logq_new = value(theta + t * step)
                if f_new <= f + 1e-4 * t * slope or t < 1e-10:
                    break
                t *= 0.5
            if t < 1e-10 or f - f_new < 1e-15 * max(1.0, abs(f)):
                ok = f_new <= f and np.max(np.abs(g)) < 1e-6
                if f_new <= f:
                    theta, f = theta + t * step, f_new
                break
            theta, f, logq = theta + t * step, f_new, logq_new
        return theta, ok

    def _nll(self, theta: np.ndarray, z: np.ndarray, y_idx: np.ndarray, kind: str) -> float:
        k = z.shape[1]
        w, b = self._unpack(theta, self._basis(k, kind), k)
        logq = _log_softmax(z @ w.T + b)
        return float(-np.mean(logq[np.arange(z.shape[0]), y_idx]))

    def fit(self, proba_or_logits: Any, y: Any) -> DirichletScaler:
        """Fit ``W`` and ``b`` (and choose the penalty) on held-out ``(proba_or_logits, y)``."""
        if self.parametrization not in _PARAMETRIZATIONS:
            raise ValueError(
                f"parametrization must be one of {_PARAMETRIZATIONS}, got {self.parametrization!r}"
            )
        if int(self.cv) != self.cv or self.cv < 2:
            raise ValueError(f"cv must be an integer >= 2, got {self.cv!r}")
        grid = np.asarray(self.reg_grid, dtype=np.float64)
        if grid.ndim != 1 or grid.size == 0 or np.any(~np.isfinite(grid)) or np.any(grid < 0):
            raise ValueError("reg_grid must be a non-empty sequence of finite penalties >= 0")
        for name in ("reg_lambda", "reg_mu"):
            v = getattr(self, name)
            if v is not None and not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0 or None, got {v!r}")
        if int(self.max_iter) != self.max_iter or self.max_iter < 1:
            raise ValueError(f"max_iter must be a positive integer, got {self.max_iter!r}")
        z = self._logits(proba_or_logits)
        n, k = z.shape
        y_idx, cls = _class_indices(y, n, self.classes, k)
        kind = self.parametrization
        min_n = self.min_samples
        if min_n is None:
            min_n = {"full": 10 * k, "diagonal": 3 * k, "scalar": 1}[kind]
        self.fallback_ = None
        if kind != "scalar" and (n < min_n or n < 2 * self.cv):
            self.fallback_ = (
                f"{n} fitting samples < {max(min_n, 2 * self.cv)} needed for "
                f"{kind!r}: fitted one temperature instead"
            )
            kind = "scalar"
        # ---- penalty
        self.cv_results_ = {}
        if kind == "scalar":
            lam = mu = 0.0
        elif kind == "full" and self.reg_lambda is not None:
            lam = float(self.reg_lambda)
            mu = lam if self.reg_mu is None else float(self.reg_mu)
        elif kind == "diagonal" and self.reg_mu is not None:
            lam = mu = float(self.reg_mu)
        else:
            folds = _fold_indices(y_idx, int(self.cv), self.random_state)
            fixed_mu = None if kind == "diagonal" else self.reg_mu
            scores = {}
            warm: list[np.ndarray | None] = [None] * len(folds)
            for r in sorted(grid.tolist(), reverse=True):  # strong to weak penalty
                m = r if fixed_mu is None else float(fixed_mu)
                losses = []
                for i, f in enumerate(folds):
                    train = np.setdiff1d(np.arange(n), f)
                    theta, _ = self._solve(z[train], y_idx[train], kind, r, m, warm[i])
                    warm[i] = theta
                    losses.append(self._nll(theta, z[f], y_idx[f], kind) * f.size)
                scores[r] = float(np.sum(losses) / n)
            self.cv_results_ = scores
            best = min(scores.values())
            lam = max(r for r, s in scores.items() if s <= best + 1e-12)
            mu = lam if fixed_mu is None else float(fixed_mu)
        theta, ok = self._solve(z, y_idx, kind, lam, mu)
        w, b = self._unpack(theta, self._basis(k, kind), k)
        self.coef_ = np.array(w)
        self.intercept_ = np.array(b)
        self.reg_lambda_ = lam if kind == "full" else 0.0
        self.reg_mu_ = mu
        self.parametrization_ = kind
        self.converged_ = ok
        self.classes_ = cls
        rows = np.arange(n)
        self.nll_before_ = float(-np.mean(_log_softmax(z)[rows, y_idx]))
        self.nll_after_ = self._nll(theta, z, y_idx, kind)
        self.n_samples_ = int(n)
        return self

    def transform(self, proba_or_logits: Any) -> np.ndarray:
        """Recalibrated probabilities ``softmax(W log(p) + b)``; rows sum to 1."""
        if not hasattr(self, "coef_"):
            raise ValueError("DirichletScaler is not fitted; call fit first")
        z = self._logits(proba_or_logits)
        if z.shape[1] != len(self.classes_):
            raise ValueError(f"expected {len(self.classes_)} columns, got {z.shape[1]}")
        return np.exp(_log_softmax(z @ self.coef_.T + self.intercept_))

    def fit_transform(self, proba_or_logits: Any, y: Any) -> np.ndarray:
        """``fit`` then ``transform`` on the same data."""
        return self.fit(proba_or_logits, y).transform(proba_or_logits)

    def __repr__(self) -> str:
        fitted = f", reg_lambda_={self.reg_lambda_:.3g}" if hasattr(self, "coef_") else ""
        return f"DirichletScaler(parametrization={self.parametrization!r}{fitted})"


def cross_val_log_loss(
    scaler: Any,
    proba: Any,
    y: Any,
    *,
    classes: Sequence | None = None,
    cv: int = 5,
    random_state: int | None = 0,
) -> float:
    """Mean held-out log loss of a recalibrator, by ``cv``-fold cross-validation.

    Each fold is recalibrated by a fresh copy of ``scaler`` (same ``get_params``, with
    ``classes`` set) fitted on the other folds; folds are stratified by class and seeded.
    Use it to choose a recalibrator on the calibration data only.

    Parameters
    ----------
    scaler
        An unfitted recalibrator with ``get_params``, ``fit(proba, y)`` and
        ``transform(proba)`` (:class:`TemperatureScaler`, :class:`DirichletScaler`).
    proba, y
        Calibration probabilities ``(n, K)`` and labels.
    classes
        Column labels; default: the sorted unique labels of ``y``.
    cv
        Number of folds (>= 2, at most ``n``).
    random_state
        Seed of the folds.

    Returns
    -------
    float
        Sum over folds of the held-out NLL, divided by ``n``.
    """
    yv, p, cls = _check_proba(y, proba, classes)
    if int(cv) != cv or not 2 <= cv <= yv.shape[0]:
        raise ValueError(f"cv must be an integer in [2, n_samples={yv.shape[0]}], got {cv!r}")
    y_idx, _ = _class_indices(yv, yv.shape[0], cls, p.shape[1])
    total = 0.0
    for f in _fold_indices(y_idx, int(cv), random_state):
        train = np.setdiff1d(np.arange(yv.shape[0]), f)
        est = type(scaler)(**(scaler.get_params() | {"classes": cls}))
        q = est.fit(p[train], yv[train]).transform(p[f])
        total += -np.sum(np.log(np.maximum(q[np.arange(f.size), y_idx[f]], 1e-300)))
    return float(total / yv.shape[0])


# --------------------------------------------------------------------------------------
# per-node calibration of a hierarchical classifier
# --------------------------------------------------------------------------------------
class NodeCalibration(NamedTuple):
    """Binary calibration of one tree node on the samples of its classes.

    ``right`` is the positive outcome: the node's probability is ``P(right | x)``.
    ``ece`` is the top-label ECE of the node's 2-class distribution (None when the node has
    no test samples, then the scores are NaN).
    """

    index: int
    left: tuple
    right: tuple
    n_samples: int
    ece: ECEResult | None
    log_loss: float
    brier: float
    accuracy: float


def _default_p_right(node: Any, X: np.ndarray) -> np.ndarray:
    """P(right) from a node's estimator, whose positive class (right) is labelled 1/True.

    A node that standardises its inputs (``node.scaler``, as the tree's ``node_scaling``
    does) gets them standardised exactly as in the tree's own prediction.
    """
    est = node.estimator
    scaler = getattr(node, "scaler", None)
    if scaler is not None:
        X = scaler.transform(X)
    proba = np.asarray(est.predict_proba(X), dtype=np.float64)
    labels = list(np.asarray(getattr(est, "classes_", [0, 1])).tolist())
    for pos in (1, True, "right"):
        if pos in labels:
            return proba[:, labels.index(pos)]
    raise ValueError(
        f"cannot tell which column of node {node.left} | {node.right} is 'right' from "
        f"classes_={labels}; pass p_right=..."
    )


def node_calibration(
    nodes: Sequence[Any],
    X: Any,
    y_true: Any,
    *,
    n_bins: int = 10,
    strategy: str = "uniform",
    n_bootstrap: int = 0,
    random_state: int | None = None,
    p_right: Callable[[Any, np.ndarray], np.ndarray] | None = None,
) -> list[NodeCalibration]:
    """Calibration of every node of a hierarchical classifier.

    Each node separates the classes ``node.left`` from ``node.right`` with a binary
    ``node.estimator``; it is evaluated on the samples whose true label is in either group,
    with outcome "label in right" and the node's probability ``P(right | x)``.

    Parameters
    ----------
    nodes
        The tree's nodes (objects with ``.left``, ``.right`` (class collections) and
        ``.estimator``), e.g. ``diagnoser.classifier_.nodes_``.
    X
        The classifier's input features, shape ``(n, d)``.
    y_true
        True class labels, shape ``(n,)``.
    n_bins, strategy, n_bootstrap, random_state
        As in :func:`expected_calibration_error`.
    p_right
        ``p_right(node, X) -> (m,)`` probability of the right group; default: the column of
        ``node.estimator.predict_proba`` whose label in ``estimator.classes_`` is 1/True.

    Returns
    -------
    list of NodeCalibration
        In the order of ``nodes``.
    """
    X = np.asarray(X, dtype=np.float64)
    y = np.asarray(y_true)
    if X.ndim != 2 or X.shape[0] != y.shape[0]:
        raise ValueError(f"X must be (n, d) with n = len(y_true) = {y.shape[0]}, got {X.shape}")
    if not np.all(np.isfinite(X)):
        raise ValueError("X contains NaN or inf")
    get_p = p_right or _default_p_right
    out = []
    for i, node in enumerate(nodes):
        left, right = tuple(node.left), tuple(node.right)
        in_left, in_right = np.isin(y, left), np.isin(y, right)
        mask = in_left | in_right
        m = int(mask.sum())
        if m == 0:
            nan = float("nan")
            out.append(NodeCalibration(i, left, right, 0, None, nan, nan, nan))
            continue
        p1 = np.clip(np.asarray(get_p(node, X[mask]), dtype=np.float64), 0.0, 1.0)
        target = in_right[mask].astype(int)
        p2 = np.column_stack([1.0 - p1, p1])
        ece = expected_calibration_error(
            target, p2, classes=[0, 1], n_bins=n_bins,
            strategy=strategy if m >= n_bins else "uniform",
            n_bootstrap=n_bootstrap, random_state=random_state,
        )  # fmt: skip
        out.append(
            NodeCalibration(
                index=i,
                left=left,
                right=right,
                n_samples=m,
                ece=ece,
                log_loss=log_loss(target, p2, classes=[0, 1]),
                brier=brier(target, p2, classes=[0, 1], scale_by_half=True),
                accuracy=float(np.mean((p1 > 0.5) == (target == 1))),
            )
        )
    return out


# --------------------------------------------------------------------------------------
# regression: Gaussian predictive distributions
# --------------------------------------------------------------------------------------
class CoverageResult(NamedTuple):
    """Central-interval coverage of Gaussian predictive distributions.

    Attributes
    ----------
    levels
        Nominal levels, e.g. (0.5, 0.8, 0.9, 0.95).
    coverage
        Fraction of observations inside ``mean ± z_{(1+level)/2} * std``, per level.
    mean_width
        Mean interval width ``2 * z * std``, per level (units of ``y``).
    n
        Number of observations.
    """

    levels: np.ndarray
    coverage: np.ndarray
    mean_width: np.ndarray
    n: int

    def as_dict(self) -> dict[str, dict[str, float]]:
        """``{"95%": {"nominal": .95, "coverage": ..., "mean_width": ...}, ...}``."""
        return {
            f"{100 * lv:g}%": {"nominal": float(lv), "coverage": float(c), "mean_width": float(w)}
            for lv, c, w in zip(self.levels, self.coverage, self.mean_width, strict=True)
        }


def interval_coverage(
    y: Any, mean: Any, std: Any, levels: Sequence[float] = DEFAULT_LEVELS
) -> CoverageResult:
    """Empirical coverage and mean width of central Gaussian predictive intervals.

    Parameters
    ----------
    y, mean, std
        Observations and predictive means and standard deviations (broadcastable arrays of
        finite values, ``std > 0``). NaN is rejected: select finite samples explicitly.
    levels
        Nominal central coverages in (0, 1).

    Returns
    -------
    CoverageResult
    """
    y_, m_, s_ = _check_gaussian(y, mean, std)
    lv = np.asarray(levels, dtype=np.float64).ravel()
    if lv.size == 0 or np.any((lv <= 0) | (lv >= 1)):
        raise ValueError(f"levels must lie in (0, 1), got {levels}")
    z = stats.norm.ppf(0.5 + lv / 2.0)
    absz = np.abs(y_ - m_).ravel() / s_.ravel()
    cov = np.array([np.mean(absz <= zi) for zi in z])
    width = 2.0 * z * float(np.mean(s_))
    return CoverageResult(levels=lv, coverage=cov, mean_width=width, n=int(absz.size))


def pit_values(y: Any, mean: Any, std: Any) -> np.ndarray:
    """Probability integral transform ``Phi((y - mean) / std)``.

    Uniform on [0, 1] when the Gaussian predictive distributions are calibrated; a U shape
    means too narrow (over-confident), a hump too wide, a slope a bias.
    """
    y_, m_, s_ = _check_gaussian(y, mean, std)
    return stats.norm.cdf((y_ - m_) / s_)


def pit_histogram(pit: Any, n_bins: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Normalised PIT histogram: ``(density, edges)``; density 1 everywhere is ideal."""
    u = np.asarray(pit, dtype=np.float64).ravel()
    if u.size == 0 or not np.all(np.isfinite(u)) or np.any((u < 0) | (u > 1)):
        raise ValueError("PIT values must be finite and lie in [0, 1]")
    if int(n_bins) != n_bins or n_bins < 1:
        raise ValueError("n_bins must be a positive integer")
    density, edges = np.histogram(u, bins=int(n_bins), range=(0.0, 1.0), density=True)
    return density, edges


def plot_pit_histogram(pit: Any, n_bins: int = 10, *, ax: Any = None, title: str | None = None):
    """Bar plot of :func:`pit_histogram` with the uniform density and a ±2 s.e. band."""
    import matplotlib.pyplot as plt

    density, edges = pit_histogram(pit, n_bins)
    n = np.asarray(pit).size
    if ax is None:
        _, ax = plt.subplots(figsize=(4.5, 3.2))
    ax.bar(edges[:-1], density, width=np.diff(edges), align="edge", color="C0", alpha=0.75,
           edgecolor="k", lw=0.5)  # fmt: skip
    # binomial standard error of a bin's density under uniformity (independent samples)
    se = np.sqrt(n_bins * (1 - 1 / n_bins) / n) * 1.0
    ax.axhline(1.0, color="k", lw=1, ls="--", label="uniform")
    ax.axhspan(1 - 2 * se, 1 + 2 * se, color="0.8", alpha=0.5, label="±2 s.e. (iid)")
    ax.set_xlim(0, 1)
    ax.set_xlabel("PIT")
    ax.set_ylabel("density")
    ax.set_title(title or f"PIT histogram, n = {n}", fontsize=9)
    ax.legend(fontsize=7)
    return ax


def crps_gaussian(y: Any, mean: Any, std: Any) -> np.ndarray:
    """Continuous ranked probability score of ``N(mean, std**2)`` at ``y`` (per sample).

    Closed form (Gneiting & Raftery 2007):
    ``std * [z (2 Phi(z) - 1) + 2 phi(z) - 1/sqrt(pi)]`` with ``z = (y - mean) / std``.
    Lower is better; in the units of ``y``; reduces to ``|y - mean|`` as ``std -> 0``.
    Average it yourself (``crps_gaussian(...).mean()``).
    """
    y_, m_, s_ = _check_gaussian(y, mean, std)
    z = (y_ - m_) / s_
    return s_ * (z * (2.0 * stats.norm.cdf(z) - 1.0) + 2.0 * stats.norm.pdf(z) - 1 / np.sqrt(np.pi))


class StdScaler:
    """Recalibrate Gaussian predictive standard deviations with one factor.

    ``std_new = scale_ * std``. The factor is fitted on held-out fault-free data
    ``(y, mean, std)``: ``method="mle"`` (default) maximises the Gaussian likelihood,
    ``scale_ = sqrt(mean(((y - mean) / std) ** 2))``; ``method="coverage"`` matches the
    empirical central coverage at ``level``, ``scale_ = quantile(|y - mean| / std, level) /
    z_{(1+level)/2}``. The mean is not changed, so a bias is not fixed (look at the PIT).

    Parameters
    ----------
    method
        ``"mle"`` or ``"coverage"``.
    level
        Coverage level matched by ``method="coverage"`` (default 0.95).

    Attributes
    ----------
    scale_ : float
    n_samples_ : int
    """

    def __init__(self, *, method: str = "mle", level: float = 0.95) -> None:
        self.method = method
        self.level = level

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """Constructor parameters (scikit-learn convention)."""
        return {"method": self.method, "level": self.level}

    def fit(self, y: Any, mean: Any, std: Any) -> StdScaler:
        """Fit the factor on held-out observations and predictions (finite, ``std > 0``)."""
        y_, m_, s_ = _check_gaussian(y, mean, std)
        z = np.abs(y_ - m_).ravel() / s_.ravel()
        if self.method == "mle":
            self.scale_ = float(np.sqrt(np.mean(z**2)))
        elif self.method == "coverage":
            if not 0 < self.level < 1:
                raise ValueError(f"level must lie in (0, 1), got {self.level}")
            self.scale_ = float(np.quantile(z, self.level) / stats.norm.ppf(0.5 + self.level / 2))
        else:
            raise ValueError(f"method must be 'mle' or 'coverage', got {self.method!r}")
        if not self.scale_ > 0:
            raise ValueError("the fitted scale is 0: predictions equal the observations exactly")
        self.n_samples_ = int(z.size)
        return self

    def transform(self, std: Any) -> np.ndarray:
        """Recalibrated standard deviations ``scale_ * std``."""
        if not hasattr(self, "scale_"):
            raise ValueError("StdScaler is not fitted; call fit first")
        return self.scale_ * np.asarray(std, dtype=np.float64)

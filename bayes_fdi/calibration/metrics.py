"""Calibration metrics of probabilistic diagnoses: ECE, proper scores, reliability diagrams.

A diagnoser is *calibrated* when its stated probabilities are frequencies: among the runs it
diagnoses as ``f2`` with probability 0.8, about 80 % really are ``f2``.

:func:`expected_calibration_error`
    Top-label or classwise ECE with equal-width (``"uniform"``) or equal-mass (``"quantile"``)
    bins, per-bin counts, the maximum calibration error (MCE), seeded bootstrap confidence
    intervals and the noise floor.
:func:`log_loss`, :func:`brier`
    Proper scoring rules (scikit-learn's implementations, with the class order made explicit).
:func:`reliability_diagram`
    Matplotlib reliability diagram with the bin counts shown.

Written by hand: the ECE with its bootstrap intervals and noise floor (no maintained library in
the dependencies offers classwise ECE with these). From scikit-learn: the log loss and Brier
score (`sklearn.metrics`) and the equal-width reliability bins
(`sklearn.calibration.calibration_curve`); the bootstrap re-bins its resamples with the same
rule by hand (``np.bincount``), which is hundreds of times faster per resample.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

__all__ = [
    "PROBABILITY_ROUNDING",
    "ECEResult",
    "brier",
    "check_proba",
    "expected_calibration_error",
    "log_loss",
    "probability_rows",
    "reliability_diagram",
]


# --------------------------------------------------------------------------------------
# input checking
# --------------------------------------------------------------------------------------
#: How far a probability may lie outside [0, 1] by rounding alone (a mean or sum of probabilities
#: can by a few units in the last place, ~1e-16 each); such entries are set to the bound.
PROBABILITY_ROUNDING = 1e-9


def probability_rows(proba: Any, name: str = "proba") -> np.ndarray:
    """Rows of probabilities ``(n, n_classes)`` as float64, validated.

    Every entry finite and in [0, 1] up to `PROBABILITY_ROUNDING` (an entry outside by less is
    rounding and is set to 0 or 1; by more, an error), every row summing to 1 within 1e-6.

    Raises
    ------
    ValueError
        naming ``name`` and what is wrong with it.
    """
    p = np.array(proba, dtype=np.float64)
    if not np.all(np.isfinite(p)):
        raise ValueError(f"{name} contains NaN or inf")
    if np.any(p < -PROBABILITY_ROUNDING) or np.any(p > 1 + PROBABILITY_ROUNDING):
        worst = float(max(-p.min(initial=0.0), p.max(initial=1.0) - 1.0))
        raise ValueError(f"{name} must lie in [0, 1] (an entry lies {worst:.3g} outside)")
    np.clip(p, 0.0, 1.0, out=p)
    if p.ndim == 2 and not np.allclose(p.sum(axis=1), 1.0, atol=1e-6):
        worst = float(np.max(np.abs(p.sum(axis=1) - 1.0)))
        raise ValueError(f"rows of {name} must sum to 1 (largest deviation {worst:.3g})")
    return p


def check_proba(
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
    p = probability_rows(p, "proba")
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


def _sklearn_reliability(
    conf: np.ndarray, hit: np.ndarray, n_bins: int, counts: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Mean confidence and observed frequency per equal-width bin, by scikit-learn.

    `sklearn.calibration.calibration_curve` returns the non-empty bins only (with the same
    bin edges and the same ``edges[b] < conf <= edges[b+1]`` rule as `_bin_stats`); they are
    placed back among the empty ones (NaN).
    """
    from sklearn.calibration import calibration_curve

    prob_true, prob_pred = calibration_curve(
        hit, conf, n_bins=n_bins, strategy="uniform", pos_label=1.0
    )
    mean_conf = np.full(n_bins, np.nan)
    mean_hit = np.full(n_bins, np.nan)
    mean_conf[counts > 0] = prob_pred
    mean_hit[counts > 0] = prob_true
    return mean_conf, mean_hit


def _conf_hit(y_idx: np.ndarray, p: np.ndarray, classwise: bool) -> tuple[np.ndarray, np.ndarray]:
    """Confidences and outcomes, one column per binned quantity (1 top-label, K classwise)."""
    if classwise:
        hit = (y_idx[:, None] == np.arange(p.shape[1])[None, :]).astype(np.float64)
        return p, hit
    pred = np.argmax(p, axis=1)
    conf = p[np.arange(p.shape[0]), pred]
    return conf[:, None], (pred == y_idx).astype(np.float64)[:, None]


def _ece_arrays(
    conf: np.ndarray,
    hit: np.ndarray,
    n_bins: int,
    strategy: str,
    classwise: bool,
    *,
    sklearn_bins: bool = False,
) -> tuple[float, float, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    rows = [_bin_stats(conf[:, k], hit[:, k], n_bins, strategy) for k in range(conf.shape[1])]
    if sklearn_bins and strategy == "uniform":
        # the reported reliability bins (and the ECE from them) are scikit-learn's
        fixed = []
        for k, (_, _, edges, counts, _, _, floor) in enumerate(rows):
            mean_conf, mean_hit = _sklearn_reliability(conf[:, k], hit[:, k], n_bins, counts)
            ok = counts > 0
            gaps = np.abs(mean_hit[ok] - mean_conf[ok])
            ece = float(np.sum(counts[ok] * gaps) / counts.sum())
            fixed.append((ece, float(gaps.max()), edges, counts, mean_conf, mean_hit, floor))
        rows = fixed
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
    y, p, cls = check_proba(y_true, proba, classes)
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
        c_all, h_all, n_bins, strategy, classwise, sklearn_bins=True
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
    y, p, cls = check_proba(y, proba, classes)
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

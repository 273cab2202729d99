"""Calibration of Gaussian predictive distributions (the normal models' intervals).

:func:`interval_coverage`, :func:`pit_values`, :func:`pit_histogram`, :func:`plot_pit_histogram`,
:func:`crps_gaussian` for predictive distributions ``N(mean, std**2)``; the recalibration of
the standard deviations, :class:`StdScaler`, lives with the normal models that use it
(`bayes_fdi.diagnosis.normal_models.std_scaler`) and is re-exported here.

Written by hand: the PIT and the closed-form Gaussian CRPS are a few lines of scipy.stats
(no maintained library in the dependencies offers them for Gaussian predictions).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from scipy import stats

from bayes_fdi.diagnosis.normal_models.std_scaler import check_gaussian

__all__ = [
    "DEFAULT_LEVELS",
    "CoverageResult",
    "crps_gaussian",
    "interval_coverage",
    "pit_histogram",
    "pit_values",
    "plot_pit_histogram",
]

#: Central-interval levels reported by default for the normal models.
DEFAULT_LEVELS: tuple[float, ...] = (0.5, 0.8, 0.9, 0.95)


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
    y_, m_, s_ = check_gaussian(y, mean, std)
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
    y_, m_, s_ = check_gaussian(y, mean, std)
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
    y_, m_, s_ = check_gaussian(y, mean, std)
    z = (y_ - m_) / s_
    return s_ * (z * (2.0 * stats.norm.cdf(z) - 1.0) + 2.0 * stats.norm.pdf(z) - 1 / np.sqrt(np.pi))

"""Figures of the reproduction: residuals against time and the two features of every run.

- :func:`plot_residuals` — ``r1`` and ``r2`` against time for a few states (the paper's
  Figures 12-19);
- :func:`plot_features` — the two residual features of every run, one colour per state, with a
  classifier's decision regions behind them.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bayes_fdi.atomic import save_figure

__all__ = [
    "plot_features",
    "plot_residuals",
]


def _save(fig: Any, path: str | os.PathLike) -> Path:
    """Lay out ``fig``, write it to ``path`` (PNG, 110 dpi), close it; return the path."""
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)


def plot_residuals(
    residuals: Mapping[str, tuple[np.ndarray, np.ndarray, np.ndarray]],
    path: str | os.PathLike,
    *,
    title: str = "",
) -> Path:
    """Residuals ``r1`` and ``r2`` against time, one row per state (the paper's Figures 12-19).

    Parameters
    ----------
    residuals
        State -> ``(time, r1, r2)``, 1-D arrays of one run.
    path
        Output image (PNG).
    title
        Figure title.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    if not residuals:
        raise ValueError("no residuals to plot")
    n = len(residuals)
    fig, axes = plt.subplots(n, 2, figsize=(9, 1.9 * n + 0.6), sharex=True, squeeze=False)
    limits = [0.0, 0.0]
    for row, (state, (time, r1, r2)) in enumerate(residuals.items()):
        for col, (name, r) in enumerate((("r1", r1), ("r2", r2))):
            ax = axes[row, col]
            ax.plot(np.asarray(time), np.asarray(r), lw=0.8, color="C0" if col == 0 else "C3")
            ax.axhline(0.0, color="0.6", lw=0.6)
            ax.set_ylabel(f"{state}: {name}")
            finite = np.asarray(r)[np.isfinite(r)]
            if finite.size:
                limits[col] = max(limits[col], float(np.max(np.abs(finite))))
    for col in range(2):
        lim = 1.05 * limits[col] if limits[col] > 0 else 1.0
        for row in range(n):
            axes[row, col].set_ylim(-lim, lim)
        axes[-1, col].set_xlabel("time (s)")
    if title:
        fig.suptitle(title)
    return _save(fig, path)


def plot_features(
    features: np.ndarray,
    labels: Sequence[str],
    path: str | os.PathLike,
    *,
    feature_names: Sequence[str] = ("mean r1", "mean r2"),
    predict: Callable[[np.ndarray], np.ndarray] | None = None,
    title: str = "",
) -> Path:
    """Scatter of the two residual features, one colour per state.

    Parameters
    ----------
    features
        ``(n, 2)`` feature values.
    labels
        ``n`` state names.
    path
        Output image (PNG).
    feature_names
        Axis titles.
    predict
        Optional classifier ``predict`` (``(m, 2) -> m`` labels); its decision regions are
        shaded behind the points.
    title
        Figure title.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    features = np.asarray(features, dtype=float)
    labels = np.asarray([str(s) for s in labels])
    if features.ndim != 2 or features.shape[1] != 2:
        raise ValueError(f"features must have shape (n, 2), got {features.shape}")
    if labels.shape[0] != features.shape[0]:
        raise ValueError(f"{labels.shape[0]} labels for {features.shape[0]} feature rows")
    states = list(dict.fromkeys(labels))
    cmap = plt.get_cmap("tab20" if len(states) > 10 else "tab10")
    colour = {s: cmap(i % cmap.N) for i, s in enumerate(states)}
    fig, ax = plt.subplots(figsize=(7.5, 6))
    lo, hi = features.min(axis=0), features.max(axis=0)
    pad = 0.08 * np.maximum(hi - lo, 1e-9)
    lo, hi = lo - pad, hi + pad
    if predict is not None:
        g0, g1 = np.meshgrid(np.linspace(lo[0], hi[0], 200), np.linspace(lo[1], hi[1], 200))
        grid = np.column_stack([g0.ravel(), g1.ravel()])
        region = np.asarray(predict(grid)).astype(str).reshape(g0.shape)
        index = {s: i for i, s in enumerate(states)}
        codes = np.vectorize(lambda s: index.get(s, -1))(region).astype(float)
        codes[codes < 0] = np.nan
        from matplotlib.colors import ListedColormap

        ax.pcolormesh(
            g0,
            g1,
            codes,
            cmap=ListedColormap([colour[s] for s in states]),
            vmin=-0.5,
            vmax=len(states) - 0.5,
            alpha=0.18,
            shading="auto",
        )
    markers = "os^D"
    for i, s in enumerate(states):
        mask = labels == s
        ax.scatter(
            features[mask, 0],
            features[mask, 1],
            s=12,
            color=colour[s],
            marker=markers[(i // 10) % len(markers)],
            label=s,
        )
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_xlabel(feature_names[0])
    ax.set_ylabel(feature_names[1])
    ax.legend(fontsize=8, ncol=2, loc="best", markerscale=1.5)
    if title:
        ax.set_title(title)
    return _save(fig, path)

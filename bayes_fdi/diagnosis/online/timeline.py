"""Timeline figure of one recording and its 1 Hz decision stream (online diagnosis).

:func:`plot_timeline` draws, against time, one panel each for: the stem position X and the
flow F in physical units with the normal models' predictions and their 95 % bands, the inputs
(CV, P1, P2, T1), the standardised residuals with their 95 % band, the detection decision DD
with the SEVA status (and, given the truth, the fault strength), the indicated groups, and
the isolation probabilities. It needs only the decision stream of
:meth:`bayes_fdi.diagnosis.OnlineDiagnoser.run` and the recording, so ``bayes-fdi benchmark``
and ``bayes-fdi diagnose`` share it.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi import atomic
from bayes_fdi.datasets.plotting import physical_range
from bayes_fdi.diagnosis.seva.names import describe_state

__all__ = ["STATUS_COLOURS", "plot_timeline"]

#: Colours of the SEVA statuses in the status strip.
STATUS_COLOURS: dict[str, str] = {
    "CLEAR": "#2ca02c",
    "BLURRED": "#d62728",
    "DAZZLED": "#ff7f0e",
    "BLIND": "#7f7f7f",
}
#: Longest recording drawn sample by sample; longer ones are drawn as per-bin means with their
#: min-max envelope (a day of 1 Hz sines is a solid block otherwise).
RAW_LIMIT = 6000
_Z95 = 1.959963984540054  # 97.5 % quantile of the standard normal


def _one_run(ds: xr.Dataset, what: str) -> xr.Dataset:
    if "run" in ds.dims:
        if ds.sizes["run"] != 1:
            raise ValueError(f"plot_timeline: {what} must hold one run, got {ds.sizes['run']}")
        ds = ds.isel(run=0)
    if "time" not in ds.dims:
        raise ValueError(f"plot_timeline: {what} has no 'time' dimension")
    return ds


def _bin_width(n: int) -> int:
    """1 (every sample drawn) up to :data:`RAW_LIMIT` samples, else at most about 1500 bins of a
    whole number of 100 s (the period of DGen's CV sine: shorter or odd bins make beats)."""
    return 1 if n <= RAW_LIMIT else 100 * math.ceil(n / 1500 / 100)


def _reduce(values: np.ndarray, w: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-bin mean, min and max of ``w`` consecutive samples (NaN-aware)."""
    v = np.asarray(values, dtype=np.float64)
    if w == 1:
        return v, v, v
    pad = (-v.size) % w
    b = np.concatenate([v, np.full(pad, np.nan)]).reshape(-1, w)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN bins stay NaN
        return np.nanmean(b, axis=1), np.nanmin(b, axis=1), np.nanmax(b, axis=1)


def _line(ax: Any, t: np.ndarray, values: np.ndarray, w: int, **kw: Any) -> None:
    """A line, or for ``w > 1`` the per-bin mean with the min-max envelope shaded."""
    mean, lo, hi = _reduce(values, w)
    ax.plot(t, mean, **kw)
    if w > 1:
        ax.fill_between(t, lo, hi, color=kw.get("color"), alpha=0.2, lw=0)


def _band(ax: Any, t: np.ndarray, w: int, stream: xr.Dataset, channel: str, recording):
    factor, unit = physical_range(recording, channel)
    measured = recording[channel].values
    _line(ax, t, measured * factor, w, lw=0.6, color="k", label=f"{channel}' measured")
    mean_name, std_name = f"{channel}_hat", f"{channel}_hat_std"
    if mean_name in stream and std_name in stream:
        mean = _reduce(stream[mean_name].values * factor, w)[0]
        half = _Z95 * _reduce(stream[std_name].values * factor, w)[0]
        ax.plot(t, mean, lw=0.8, color="C0", label=f"{channel} normal model")
        ax.fill_between(
            t, mean - half, mean + half, color="C0", alpha=0.25, lw=0, label="95 % predictive band"
        )
    ax.set_ylabel(f"{channel} [{unit}]")
    ax.legend(loc="upper right", fontsize=7, ncol=3)


def _truth_fields(truth: Mapping[str, Any] | None, t: np.ndarray):
    if truth is None:
        return None, None, None
    unknown = set(truth) - {"fault", "onset", "strength", "label"}
    if unknown:
        raise ValueError(f"plot_timeline: unknown truth key(s) {sorted(unknown)}")
    onset = truth.get("onset")
    strength = truth.get("strength")
    if strength is not None:
        strength = np.asarray(strength, dtype=np.float64)
        if strength.shape != t.shape:
            raise ValueError("plot_timeline: truth['strength'] needs one value per time sample")
    return truth.get("fault"), onset, strength


def plot_timeline(
    stream: xr.Dataset,
    recording: xr.Dataset,
    *,
    truth: Mapping[str, Any] | None = None,
    path: str | os.PathLike | None = None,
    title: str | None = None,
):
    """Draw the timeline of one recording and its decision stream.

    Parameters
    ----------
    stream
        The decision stream of one run (dims ``time`` and ``group``/``fault``; a ``run`` dimension
        of size 1 is dropped), as :meth:`~bayes_fdi.diagnosis.OnlineDiagnoser.run` returns it.
        Variables used when present: ``X_hat``, ``X_hat_std``, ``F_hat``, ``F_hat_std``,
        ``r_X``, ``r_F``, ``DD``, ``status``, ``indicated``, ``group_proba``.
    recording
        The recording it was computed from (same ``time``; channels CV, P1, P2, T1, X, F,
        normalised).
    truth
        Optional: ``{"fault": "f7", "onset": 900.0, "strength": array per second, "label": ...}``
        (any subset); the onset is marked, the strength drawn, the true fault's group
        highlighted.
    path
        Write the figure there (PNG; atomically) and close it.
    title
        Figure title (default: the truth's label, or the fault by code and name).

    Returns
    -------
    matplotlib.figure.Figure or pathlib.Path
        The figure, or the path written when ``path`` is given.
    """
    import matplotlib.pyplot as plt

    stream = _one_run(stream, "stream")
    recording = _one_run(recording, "recording")
    t = np.asarray(stream["time"].values, dtype=np.float64)
    if recording.sizes["time"] != t.size or not np.array_equal(recording["time"].values, t):
        raise ValueError("plot_timeline: stream and recording must share the time coordinate")
    fault, onset, strength = _truth_fields(truth, t)
    scale, unit = (3600.0, "h") if t[-1] - t[0] > 4 * 3600 else (1.0, "s")
    tt = t / scale

    fig, axes = plt.subplots(
        7,
        1,
        figsize=(11, 15),
        sharex=True,
        layout="constrained",
        gridspec_kw={"height_ratios": [2, 2, 1.5, 1.5, 1, 1.6, 1.6]},
    )
    w = _bin_width(t.size)
    tw = _reduce(tt, w)[0]
    for ax, channel in zip(axes[:2], ("X", "F"), strict=True):
        _band(ax, tw, w, stream, channel, recording)
    if w > 1:
        axes[0].set_title(f"signals: mean per {w} s, min-max shaded", fontsize=8, loc="left")
    _inputs_panel(axes[2], tw, w, recording)
    _residuals_panel(axes[3], tw, w, stream)
    _status_panel(axes[4], tt, stream, strength)
    _groups_panels(axes[5], axes[6], tt, stream, fault)
    for ax in axes:
        if onset is not None:
            ax.axvline(float(onset) / scale, color="k", ls="--", lw=0.8)
    axes[-1].set_xlabel(f"time [{unit}]")
    label = (truth or {}).get("label") or (describe_state(fault) if fault else None)
    fig.suptitle(title or label or "online diagnosis", fontsize=11)
    if path is not None:
        return atomic.save_figure(fig, path, dpi=100)
    return fig


def _inputs_panel(ax: Any, tw: np.ndarray, w: int, recording: xr.Dataset) -> None:
    """CV on ``ax``, P1 and P2 on a twin axis, the range of T1 in the title."""
    cv_factor, cv_unit = physical_range(recording, "CV")
    cv_label = f"CV [{cv_unit}]"
    _line(ax, tw, recording["CV"].values * cv_factor, w, lw=0.6, color="C2", label=cv_label)
    ax.set_ylabel(f"CV [{cv_unit}]")
    twin = ax.twinx()
    for name, colour in (("P1", "C4"), ("P2", "C5")):
        factor, p_unit = physical_range(recording, name)
        values = recording[name].values * factor
        _line(twin, tw, values, w, lw=0.5, color=colour, label=f"{name} [{p_unit}]")
    twin.set_ylabel(f"P [{p_unit}]")
    t1_factor, t1_unit = physical_range(recording, "T1")
    t1 = recording["T1"].values * t1_factor
    t1_text = f"T1 {np.nanmin(t1):.1f} .. {np.nanmax(t1):.1f} {t1_unit}"
    ax.set_title(t1_text, fontsize=8, loc="right")
    lines = ax.get_lines() + twin.get_lines()
    ax.legend(lines, [ln.get_label() for ln in lines], loc="upper left", fontsize=7, ncol=3)


def _residuals_panel(ax: Any, tw: np.ndarray, w: int, stream: xr.Dataset) -> None:
    """The innovations with their 95 % band."""
    for name, colour in (("r_X", "C0"), ("r_F", "C1")):
        if name in stream:
            _line(ax, tw, stream[name].values, w, lw=0.5, color=colour, label=name)
    ax.axhspan(-_Z95, _Z95, color="0.85", zorder=0, label="95 % band")
    ax.set_ylabel("residual [σ]")
    ax.legend(loc="upper right", fontsize=7, ncol=3)


def _status_panel(ax: Any, tt: np.ndarray, stream: xr.Dataset, strength: Any) -> None:
    """DD, the SEVA status strip and, given the truth, the fault strength."""
    if "DD" in stream:
        ax.fill_between(
            tt,
            0,
            stream["DD"].values.astype(float),
            step="post",
            color="C3",
            alpha=0.6,
            lw=0,
            label="DD",
        )
    if "status" in stream:
        status = np.asarray(stream["status"].values).astype(str)
        for name, colour in STATUS_COLOURS.items():
            ax.fill_between(
                tt, -0.35, -0.1, where=status == name, step="post", color=colour, lw=0, label=name
            )
    if strength is not None:
        ax.plot(tt, strength, color="k", lw=1, label="fault strength")
    ax.set_ylim(-0.4, 1.1)
    ax.set_yticks([0, 1])
    ax.set_ylabel("DD / status")
    ax.legend(loc="upper left", fontsize=7, ncol=6)


def _groups_panels(ax_ind: Any, ax_p: Any, tt: np.ndarray, stream: xr.Dataset, fault):
    if "group" not in stream.coords:
        ax_ind.set_visible(False)
        ax_p.set_visible(False)
        return
    labels = [str(g) for g in stream["group"].values]
    groups = json.loads(stream.attrs["groups"]) if "groups" in stream.attrs else {}
    true_label = next((g for g in labels if fault in groups.get(g, g.split("|"))), None)
    if "indicated" in stream:
        ind = stream["indicated"].transpose("time", "group").values.astype(bool)
        for g, label in enumerate(labels):
            colour = "C3" if label == true_label else "C0"
            ax_ind.fill_between(
                tt, g - 0.4, g + 0.4, where=ind[:, g], step="post", color=colour, lw=0
            )
    ax_ind.set_yticks(range(len(labels)))
    ax_ind.set_yticklabels(labels, fontsize=6)
    ax_ind.set_ylim(-0.6, len(labels) - 0.4)
    ax_ind.set_ylabel("indicated")
    if "group_proba" in stream:
        proba = stream["group_proba"].transpose("time", "group").values
        shown = 0
        for g, label in enumerate(labels):
            col = proba[:, g]
            if label != true_label and not (np.nanmax(col, initial=0.0) > 0.2):
                continue  # keep the legend readable: groups that never reach 0.2 are omitted
            width, colour = (1.6, "C3") if label == true_label else (0.7, f"C{shown % 10}")
            ax_p.plot(tt, col, lw=width, color=colour, label=describe_state(label))
            shown += 1
        if shown:  # groups by code and name, two to a row
            ax_p.legend(loc="upper left", fontsize=6, ncol=2)
    ax_p.set_ylim(-0.02, 1.02)
    ax_p.set_ylabel("P(group)")

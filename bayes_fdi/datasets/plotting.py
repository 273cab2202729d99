"""Plots of actuator runs: the signals of chosen runs, like the paper's Figures 4–11.

:func:`plot_runs` draws, for each chosen channel, one panel with the selected runs over time in
physical units (``ax=`` a single Axes overlays all channels in it, normalised, as the paper's
figures do). The ``bayes-fdi
plot FILE.nc`` command wraps it.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Sequence

import numpy as np
import xarray as xr

from bayes_fdi.atomic import atomic_path, check_output_path
from bayes_fdi.cli_arguments import UsageError, input_file, output_file, positive_int
from bayes_fdi.datasets import CHANNELS, load_dataset, validate_dataset
from bayes_fdi.datasets.units import DABLIB_RANGES

__all__ = ["configure_parser", "physical_range", "plot_runs", "run_from_cli", "select_runs"]

#: Names of the channels on the axes of physical units.
CHANNEL_NAMES: dict[str, str] = {
    "CV": "CV, control value",
    "P1": "P1, inlet pressure",
    "P2": "P2, outlet pressure",
    "T1": "T1, temperature",
    "X": "X, stem position",
    "F": "F, flow",
}
#: Axis labels of the normalised channels.
CHANNEL_LABELS: dict[str, str] = {
    "CV": "CV (control value)",
    "P1": "P1' (inlet pressure)",
    "P2": "P2' (outlet pressure)",
    "T1": "T1' (temperature)",
    "X": "X' (stem position)",
    "F": "F' (flow)",
}


def select_runs(
    ds: xr.Dataset, runs: Sequence[int] | int | None = None, states: Sequence[str] | None = None
) -> list[int]:
    """Positional indices of the runs to plot.

    Parameters
    ----------
    ds
        A dataset in the project's format.
    runs
        Run positions (0-based); default the first run (or, with ``states``, the first run of each
        listed state).
    states
        State labels; the first run of each state is chosen (added to ``runs``).

    Returns
    -------
    list of int
    """
    n = ds.sizes["run"]
    chosen: list[int] = []
    if runs is not None:
        for r in np.atleast_1d(runs).tolist():
            if not isinstance(r, int | np.integer) or isinstance(r, bool):
                raise ValueError(f"runs must be integers, got {r!r}")
            if not -n <= r < n:
                raise ValueError(f"run {r} out of range: the dataset has {n} run(s)")
            chosen.append(int(r) % n)
    if states is not None:
        if "state" not in ds.coords:
            raise ValueError("the dataset has no 'state' coordinate to select by")
        labels = np.asarray(ds["state"].values).astype(str)
        for s in states:
            hits = np.flatnonzero(labels == s)
            if not len(hits):
                raise ValueError(
                    f"no run with state {s!r} (states here: {sorted(set(labels.tolist()))})"
                )
            chosen.append(int(hits[0]))
    if not chosen:
        chosen = [0]
    return chosen


def _run_label(ds: xr.Dataset, r: int) -> str:
    if "state" not in ds.coords:
        return f"run {r}"
    state = str(ds["state"].values[r])
    if state == "fn" or "strength" not in ds.coords:
        return f"run {r}: {state}"
    text = f"run {r}: {state} ({float(ds['strength'].values[r]):+.2f}"
    if "profile" in ds.coords and str(ds["profile"].values[r]) == "incipient":
        text += f", ramp {float(ds['ramp'].values[r]):g} s"
    if "onset" in ds.coords and float(ds["onset"].values[r]) > 0:
        text += f", from {float(ds['onset'].values[r]):g} s"
    return text + ")"


def physical_range(ds: xr.Dataset, channel: str) -> tuple[float, str]:
    """``(factor, unit)`` turning a normalised channel of ``ds`` into physical units.

    A real record of Lublin Actuator 1 or 2 (attribute ``actuator``) uses that actuator's
    ranges (`bayes_fdi.datasets.lublin.ACTUATOR_RANGES`); anything else DABLib's
    (:data:`DABLIB_RANGES`).
    """
    from bayes_fdi.datasets.lublin import ACTUATOR_RANGES

    actuator = ds.attrs.get("actuator")
    if actuator in (1, 2):
        factor, unit = ACTUATOR_RANGES[int(actuator)][channel]
        return float(factor), unit.replace("degC", "°C").replace("m3/h", "m³/h")
    return DABLIB_RANGES[channel]


def plot_runs(
    ds: xr.Dataset,
    runs: Sequence[int] | int | None = None,
    channels: Sequence[str] | None = None,
    ax=None,
    *,
    states: Sequence[str] | None = None,
    title: str | None = None,
    units: str | None = None,
):
    """Plot the signals of chosen runs against time, in physical units by default.

    Parameters
    ----------
    ds
        A dataset in the project's format (NaN gaps are drawn as breaks).
    runs
        Run positions to draw (default the first run); see :func:`select_runs`.
    channels
        Channels to draw, default every channel present in ``CHANNELS`` order.
    ax
        ``None``: a new figure with one panel per channel (shared time axis). A single
        ``matplotlib.axes.Axes``: every channel overlaid in it, as in the paper's Figures 4–11.
        A sequence of Axes: one per channel.
    states
        Also draw the first run of each of these states.
    title
        Figure (or axes) title; default the campaign name.
    units
        ``"physical"`` (default of the panels: %, MPa, °C, t/h, see :func:`physical_range`) or
        ``"normalised"`` (default, and the only choice, of the overlay in one Axes, where the
        channels share one axis as in the paper's figures).

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt
    from matplotlib.axes import Axes

    validate_dataset(ds, require=(), allow_nan=True)
    if channels is None:
        channels = [c for c in CHANNELS if c in ds.data_vars]
    channels = list(channels)
    if not channels:
        raise ValueError("no channel to plot")
    unknown = [c for c in channels if c not in ds.data_vars]
    if unknown:
        raise ValueError(
            f"channel(s) {unknown} not in the dataset (it has {list(map(str, ds.data_vars))})"
        )
    chosen = select_runs(ds, runs, states)
    time = ds["time"].values
    title = ds.attrs.get("campaign", "") if title is None else title
    if units not in (None, "physical", "normalised"):
        raise ValueError(f"units must be 'physical' or 'normalised', got {units!r}")

    if isinstance(ax, Axes):
        if units == "physical":
            raise ValueError("an overlay of several channels in one Axes is drawn normalised")
        fig = ax.figure
        for c in channels:
            for r in chosen:
                label = c if len(chosen) == 1 else f"{c}, {_run_label(ds, r)}"
                ax.plot(time, ds[c].values[r], lw=1.0, label=label)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("normalised value")
        ax.legend(fontsize="small", loc="best")
        ax.set_title(title + (f" — {_run_label(ds, chosen[0])}" if len(chosen) == 1 else ""))
        return fig

    if ax is None:
        fig, axes = plt.subplots(
            len(channels), 1, sharex=True, figsize=(8.0, 1.6 + 1.4 * len(channels)), squeeze=False
        )
        axes = list(axes[:, 0])
    else:
        axes = list(ax)
        if len(axes) != len(channels):
            raise ValueError(f"got {len(axes)} axes for {len(channels)} channel(s)")
        fig = axes[0].figure
    physical = units in (None, "physical")
    for a, c in zip(axes, channels, strict=True):
        factor, unit = physical_range(ds, c) if physical else (1.0, "")
        for r in chosen:
            a.plot(time, ds[c].values[r] * factor, lw=1.0, label=_run_label(ds, r))
        label = f"{CHANNEL_NAMES[c]} [{unit}]" if physical else CHANNEL_LABELS.get(c, c)
        a.set_ylabel(label, fontsize="small")
        a.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    axes[0].legend(fontsize="small", loc="best")
    if title:
        fig.suptitle(title)
    return fig


#: Image formats ``bayes-fdi plot --out`` writes (chosen by the file name).
IMAGE_SUFFIXES: tuple[str, ...] = (".png", ".pdf", ".svg", ".jpg", ".jpeg")


def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``bayes-fdi plot``."""
    parser.add_argument(
        "dataset", type=input_file, help="a dataset file (.nc) written by `bayes-fdi simulate`"
    )
    parser.add_argument(
        "--runs", type=int, nargs="+", default=None, help="run positions to draw (default 0)"
    )
    parser.add_argument(
        "--states", nargs="+", default=None, help="also draw the first run of each state"
    )
    parser.add_argument(
        "--channels",
        nargs="+",
        default=None,
        choices=CHANNELS,
        help="channels to draw (default all)",
    )
    parser.add_argument(
        "--overlay", action="store_true", help="draw every channel in one panel (as the paper)"
    )
    parser.add_argument(
        "--out",
        type=output_file(*IMAGE_SUFFIXES),
        default=None,
        help="image file, .png/.pdf/.svg/.jpg (default: DATASET stem + .png), written atomically",
    )
    parser.add_argument("--dpi", type=positive_int, default=120)


def run_from_cli(args: argparse.Namespace) -> int:
    """Run ``bayes-fdi plot``: the output path and the selection are checked before drawing."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = args.out or os.path.splitext(args.dataset)[0] + ".png"
    try:
        check_output_path(out, suffixes=IMAGE_SUFFIXES, what="image file")
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    ds = load_dataset(args.dataset)  # an unreadable file: a runtime error (exit 1)
    try:
        select_runs(ds, args.runs, args.states)
        missing = [c for c in args.channels or () if c not in ds.data_vars]
        if missing:
            raise ValueError(f"channel(s) {missing} not in {args.dataset}")
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if args.overlay:
        fig, ax = plt.subplots(figsize=(8.0, 4.5))
        plot_runs(ds, runs=args.runs, channels=args.channels, ax=ax, states=args.states)
    else:
        fig = plot_runs(ds, runs=args.runs, channels=args.channels, states=args.states)
    try:
        with atomic_path(out) as tmp:
            fig.savefig(tmp, dpi=args.dpi, bbox_inches="tight", format=out.rsplit(".", 1)[-1])
    finally:
        plt.close(fig)
    print(out)
    return 0

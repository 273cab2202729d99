"""Plots of runs: requested panels, plotted data equal to the dataset, CLI output."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest

from bayes_fdi.cli import main
from bayes_fdi.datasets import make_dataset, save_dataset
from bayes_fdi.datasets.plotting import plot_runs, select_runs


@pytest.fixture
def ds(rng):
    shape = (4, 60)
    channels = {c: rng.uniform(0, 1, shape) for c in ("CV", "P1", "P2", "T1", "X", "F")}
    return make_dataset(
        channels,
        state=["fn", "f1", "f1", "f17"],
        strength=[0.0, 0.6, 0.8, 0.7],
        profile=["abrupt", "abrupt", "abrupt", "incipient"],
        ramp=[0.0, 0.0, 0.0, 30.0],
        campaign="unit",
        seed=1,
    )


def test_one_panel_per_requested_channel(ds):
    fig = plot_runs(ds, runs=[0, 2], channels=["X", "F"])
    axes = fig.get_axes()
    assert len(axes) == 2
    # physical units: X in % (x 100), F in t/h (x 40), DABLib's ranges
    assert [a.get_ylabel() for a in axes] == ["X, stem position [%]", "F, flow [t/h]"]
    for a, c, factor in zip(axes, ["X", "F"], [100.0, 40.0], strict=True):
        lines = a.get_lines()
        assert len(lines) == 2
        np.testing.assert_array_equal(lines[0].get_ydata(), ds[c].values[0] * factor)
        np.testing.assert_array_equal(lines[1].get_ydata(), ds[c].values[2] * factor)
        np.testing.assert_array_equal(lines[1].get_xdata(), np.arange(60.0))
    assert "f1 (+0.80)" in axes[0].get_legend().get_texts()[1].get_text()
    plt.close(fig)


def test_default_is_all_channels_of_first_run(ds):
    fig = plot_runs(ds)
    assert len(fig.get_axes()) == 6
    assert all(len(a.get_lines()) == 1 for a in fig.get_axes())
    plt.close(fig)


def test_overlay_in_given_axes_and_state_selection(ds):
    fig, ax = plt.subplots()
    out = plot_runs(ds, channels=["CV", "X", "F"], ax=ax, states=["f17"])
    assert out is fig and fig.get_axes() == [ax]
    assert len(ax.get_lines()) == 3
    np.testing.assert_array_equal(ax.get_lines()[1].get_ydata(), ds["X"].values[3])
    assert "ramp 30 s" in ax.get_title()
    plt.close(fig)


def test_selection_and_errors(ds):
    assert select_runs(ds, runs=[-1], states=["f1", "fn"]) == [3, 1, 0]
    with pytest.raises(ValueError, match="run 7 out of range"):
        plot_runs(ds, runs=[7])
    with pytest.raises(ValueError, match="no run with state 'f5'"):
        plot_runs(ds, states=["f5"])
    with pytest.raises(ValueError, match=r"\['Q'\] not in the dataset"):
        plot_runs(ds, channels=["Q"])
    _fig, axes = plt.subplots(3)
    with pytest.raises(ValueError, match="3 axes for 2 channel"):
        plot_runs(ds, channels=["X", "F"], ax=axes)
    plt.close("all")


def test_cli_writes_png(ds, tmp_path, capsys):
    save_dataset(ds, tmp_path / "d.nc")
    out = tmp_path / "fig.png"
    assert main(["plot", str(tmp_path / "d.nc"), "--runs", "1", "--channels", "X", "F",
                 "--out", str(out)]) == 0  # fmt: skip
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert capsys.readouterr().out.strip() == str(out)
    assert main(["plot", str(tmp_path / "d.nc"), "--states", "f17", "--overlay"]) == 0
    assert (tmp_path / "d.png").stat().st_size > 1000


def test_cli_errors_are_reported(ds, tmp_path, capsys):
    assert main(["plot", str(tmp_path / "missing.nc")]) == 2
    assert "missing.nc" in capsys.readouterr().err
    save_dataset(ds, tmp_path / "d.nc")
    assert main(["plot", str(tmp_path / "d.nc"), "--runs", "9"]) == 2
    assert "run 9 out of range" in capsys.readouterr().err


def test_units_normalised_and_actuator_ranges(ds):
    fig = plot_runs(ds, channels=["P1"], units="normalised")
    np.testing.assert_array_equal(fig.get_axes()[0].get_lines()[0].get_ydata(), ds["P1"].values[0])
    plt.close(fig)
    act1 = ds.assign_attrs(actuator=1)  # Lublin Actuator 1: P over 0-1000 kPa
    fig = plot_runs(act1, channels=["P1"])
    assert fig.get_axes()[0].get_ylabel() == "P1, inlet pressure [kPa]"
    np.testing.assert_array_equal(
        fig.get_axes()[0].get_lines()[0].get_ydata(), ds["P1"].values[0] * 1000.0
    )
    plt.close(fig)
    fig, ax = plt.subplots()
    with pytest.raises(ValueError, match="drawn normalised"):
        plot_runs(ds, ax=ax, units="physical")
    plt.close(fig)

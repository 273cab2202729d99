"""``bayes-fdi reproduce``: the paper's experiments, end to end, in one command.

For each dataset (``paper-simulated``: the DAMADICS actuator driven by sine inputs;
``paper-lublin``: the model driven by the real Lublin Actuator-3 hour) this module

1. simulates the campaign (or loads it from the netCDF cache, keyed by the campaign file's
   SHA-256, the seed and the ``small`` flag);
2. splits every state's runs: the first ``n_train`` (20, as the paper) train, the rest test;
3. fits the normal models (RVR, on the fault-free training runs) and computes the two
   residual features ``mean_r1``, ``mean_r2`` of every run;
4. trains the paper's classifier (a k-means designed tree of RVM classifiers) and the SVM
   baseline (the same tree with SVMs) on the same training features, and scores both on the
   test runs: identification ratios, confusion, log loss, Brier score, top-label ECE, fit and
   predict times, relevance/support vectors per node;
5. goes beyond the paper: the same pipeline on all 20 states, with a data-driven analysis of
   which states the two features can separate and which form groups no classifier can split.

Everything is written to ``--out DIR``: ``report.md`` (and the PNG figures it links) and
``results.json``. Same seed, same numbers.

This module holds the job (`reproduce`; its command line is
`bayes_fdi.commands.reproduce`); the steps live in
`bayes_fdi.campaigns.cache` (datasets and their cache),
`bayes_fdi.paper.setup` (states, widths, node classifiers),
`bayes_fdi.paper.pipeline` (`evaluate_dataset`),
`bayes_fdi.paper.scores`, `bayes_fdi.paper.separability` and
`bayes_fdi.paper.calibration_headlines`, and the report in
`bayes_fdi.paper.report`.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import xarray as xr

from bayes_fdi.atomic import write_text
from bayes_fdi.campaigns.cache import load_or_simulate
from bayes_fdi.datasets import validate_dataset
from bayes_fdi.paper.calibration_headlines import calibration_headlines
from bayes_fdi.paper.pipeline import evaluate_dataset
from bayes_fdi.paper.setup import (
    DATASETS,
    DYNAMIC_LAGS,
    N_TRAIN,
    PAPER_STATES,
)

__all__ = ["reproduce"]


class _Progress:
    """Stage messages on stderr (one line per long step, with elapsed time)."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.t0 = time.perf_counter()

    def __call__(self, message: str) -> None:
        if self.enabled:
            elapsed = time.perf_counter() - self.t0
            print(f"[reproduce {elapsed:7.1f} s] {message}", file=sys.stderr, flush=True)


def reproduce(
    out_dir: str | os.PathLike,
    *,
    seed: int = 0,
    cache_dir: str | os.PathLike | None = ".cache/datasets",
    small: bool = False,
    states: Sequence[str] = PAPER_STATES,
    progress: bool = True,
    datasets: Sequence[str | os.PathLike | xr.Dataset] = DATASETS,
    dynamic_lags: Sequence[float] = DYNAMIC_LAGS,
) -> dict[str, Any]:
    """Run the paper's experiments and write ``report.md``, figures and ``results.json``.

    Parameters
    ----------
    out_dir
        Output folder (created if needed).
    seed
        Seed of the simulations and of the models; the same seed gives the same numbers.
    cache_dir
        Folder of cached simulated datasets (``None``: always simulate).
    small
        Small campaigns for tests, notebooks and CI: :data:`SMALL_RUNS_PER_STATE` runs per
        state (20 train, 4 test) of :data:`SMALL_DURATION` s; the numbers are then rougher
        than with the paper's sizes.
    states
        States of the paper protocol (default the paper's ten).
    progress
        Show progress on stderr.
    datasets
        Campaigns to run: names or TOML paths (simulated or cached), or datasets already in
        the project's format (named by their ``campaign`` attribute).
    dynamic_lags
        Beyond the paper: run the whole pipeline a second time with dynamic normal models,
        ``CV(t - L)`` for these lags (s) as extra inputs (default :data:`DYNAMIC_LAGS`);
        ``()`` skips it.

    Returns
    -------
    dict
        The content of ``results.json``: ``bayes_fdi_version``, ``seed``, ``small``,
        ``states``, ``datasets`` (name -> :func:`evaluate_dataset` results plus ``campaign``
        info) and ``seconds`` (total wall-clock).
    """
    from bayes_fdi import __version__
    from bayes_fdi.paper.report import render_report
    from bayes_fdi.reporting import to_jsonable, write_json

    t_start = time.perf_counter()
    say = _Progress(progress)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    results: dict[str, Any] = {
        "bayes_fdi_version": __version__,
        "seed": int(seed),
        "seeds": {"simulation": int(seed), "models": int(seed)},
        "small": bool(small),
        "states": [str(s) for s in states],
        "n_train_per_state": N_TRAIN,
        "dynamic_lags": [float(v) for v in dynamic_lags],
        "datasets": {},
    }
    figures: dict[str, dict[str, str]] = {}
    for i, item in enumerate(datasets):
        ds, info = _dataset(
            i, item, seed=seed, cache_dir=cache_dir, small=small, progress=progress, say=say
        )
        key = info["campaign"]
        res, art = _evaluate(
            ds, info, out, seed=seed, states=states, dynamic_lags=dynamic_lags, say=say
        )
        results["datasets"][key] = res
        say(f"{key}: figures")
        figures[key] = _figures(key, res, art, out)
    results["seconds"] = time.perf_counter() - t_start
    results["figures"] = figures
    results = to_jsonable(results)
    write_text(out / "report.md", render_report(results))
    write_json(results, out / "results.json")
    say(f"done in {results['seconds']:.0f} s: {out / 'report.md'}")
    return results


def _dataset(
    i: int,
    item: str | os.PathLike | xr.Dataset,
    *,
    seed: int,
    cache_dir: str | os.PathLike | None,
    small: bool,
    progress: bool,
    say: _Progress,
) -> tuple[xr.Dataset, dict[str, Any]]:
    """The ``i``-th dataset to evaluate (given, cached or simulated) and where it came from."""
    if isinstance(item, xr.Dataset):
        ds = validate_dataset(item, require=("CV", "P1", "P2", "T1", "X", "F"))
        name = str(ds.attrs.get("campaign") or f"dataset-{i + 1}")
        info = {"campaign": name, "campaign_file": None, "cached": False}
    else:
        name = os.fspath(item)
        say(f"{name}: loading or simulating the campaign")
        ds, info = load_or_simulate(
            item, seed=seed, cache_dir=cache_dir, small=small, progress=progress
        )
    if "simulate_seconds" in info:
        how = "cached" if info["cached"] else f"simulated in {info['simulate_seconds']:.0f} s"
    else:
        how = "given"
    say(f"{name}: {ds.sizes['run']} runs x {ds.sizes['time']} s ({how})")
    return ds, info


def _evaluate(
    ds: xr.Dataset,
    info: dict[str, Any],
    out: Path,
    *,
    seed: int,
    states: Sequence[str],
    dynamic_lags: Sequence[float],
    say: _Progress,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """One dataset's results: the paper's protocol, its calibration report and, with
    ``dynamic_lags``, the same with dynamic normal models (under ``"dynamic"``)."""
    key = info["campaign"]
    res, art = evaluate_dataset(
        ds, states=states, seed=seed, progress=lambda m, k=key: say(f"{k}: {m}")
    )
    res["campaign"] = info
    say(f"{key}: calibration report")
    real = None
    if str(ds.attrs.get("source", "")) == "lublin-example":
        from bayes_fdi.datasets import load_lublin_example

        real = load_lublin_example()

    def calibrate(artifacts: dict[str, Any], suffix: str, what: str) -> Any:
        return calibration_headlines(
            artifacts["diagnoser"],
            artifacts["test_runs"],
            out / f"{key}{suffix}-calibration",
            seed=seed,
            real_record=real,
            title=f"{key}: calibration of the {what} on its test runs",
        )

    res["calibration"] = calibrate(art, "", "RVM pipeline")
    if len(dynamic_lags):
        lags = tuple(float(v) for v in dynamic_lags)
        say(f"{key}: beyond the paper: dynamic normal models with CV lagged {lags} s")
        dyn, dyn_art = evaluate_dataset(
            ds,
            states=states,
            seed=seed,
            input_lags=lags,
            progress=lambda m, k=key: say(f"{k} (dynamic): {m}"),
        )
        dyn["calibration"] = calibrate(dyn_art, "-dynamic", "dynamic RVM pipeline")
        res["dynamic"] = {k: v for k, v in dyn.items() if k != "strength"}
    return res, art


def _figures(key: str, res: dict[str, Any], art: dict[str, Any], out: Path) -> dict[str, str]:
    """Draw one dataset's figures into ``out``; their file names by role."""
    from bayes_fdi.paper.report_figures import plot_features, plot_residuals

    figs = {
        "residuals": plot_residuals(
            art["residuals"], out / f"{key}-residuals.png", title=f"{key}: residuals"
        ).name,
        "features": plot_features(
            art["features"],
            art["labels"],
            out / f"{key}-features.png",
            predict=art["rvm_predict"],
            title=f"{key}: test-run features and the RVM tree's decisions",
        ).name,
    }
    if "all_states" in res:
        figs["all_features"] = plot_features(
            art["train_features"],
            art["train_labels"],
            out / f"{key}-all-states.png",
            title=f"{key}: training-run features of every state",
        ).name
    return figs

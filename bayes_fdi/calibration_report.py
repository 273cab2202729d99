"""Calibration report of a fitted diagnoser on a test dataset (``bayes-fdi calibration-report``).

:func:`write_calibration_report` diagnoses the test runs and writes into ``out_dir``:

- ``report.md``: the whole tree's calibration (top-label ECE with equal-width and equal-mass
  bins and bootstrap intervals, classwise ECE, MCE, log loss, Brier score, accuracy)
  before and after temperature scaling; the binary calibration of every tree node; the
  normal models' central-interval coverage (50/80/90/95 %), mean widths, CRPS and PIT
  histograms on the fault-free test runs;
- ``figures/*.png``: reliability diagrams before/after recalibration, PIT histograms;
- ``calibration.json``: every number of the report.

It only uses the diagnoser's public contract: ``diagnose(runs)`` returning the Dataset of
``CONTRACTS.md`` (``proba (run, class)``, ``features (run, feature)``, ``X_hat``,
``X_hat_std``, ``F_hat``, ``F_hat_std``) and, for the per-node table,
``diagnoser.classifier_.nodes_`` (nodes with ``.left``, ``.right``, ``.estimator``).

The temperature is fitted on held-out data: on ``calibration_runs`` when given, otherwise
by two-fold cross-fitting on the test runs (runs split in two seeded halves; each half is
recalibrated with the temperature fitted on the other), so no run is scored with a
temperature fitted on itself.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.calibration import (
    DEFAULT_LEVELS,
    ECEResult,
    TemperatureScaler,
    brier,
    crps_gaussian,
    expected_calibration_error,
    interval_coverage,
    log_loss,
    node_calibration,
    pit_histogram,
    pit_values,
    plot_pit_histogram,
    reliability_diagram,
)

__all__ = [
    "classification_summary",
    "configure_parser",
    "normal_model_summary",
    "run_from_cli",
    "split_in_time",
    "time_split_summary",
    "write_calibration_report",
]


# --------------------------------------------------------------------------------------
# numbers
# --------------------------------------------------------------------------------------
def _ece_dict(res: ECEResult) -> dict[str, Any]:
    return {
        "value": res.value,
        "ci_low": res.ci_low,
        "ci_high": res.ci_high,
        "mce": res.mce,
        "debiased": res.debiased,
        "noise_floor": res.noise_floor,
        "strategy": res.strategy,
        "classwise": res.classwise,
        "bin_edges": np.asarray(res.bin_edges).tolist(),
        "bin_counts": np.asarray(res.bin_counts).tolist(),
        "bin_confidence": np.asarray(res.bin_confidence).tolist(),
        "bin_accuracy": np.asarray(res.bin_accuracy).tolist(),
    }


def classification_summary(
    y_true: Any,
    proba: Any,
    classes: Any,
    *,
    n_bins: int = 15,
    n_bootstrap: int = 500,
    random_state: int | None = 0,
) -> dict[str, Any]:
    """Calibration and scores of a class distribution (the numbers of one report column).

    Returns
    -------
    dict
        ``n``, ``accuracy``, ``log_loss``, ``brier`` (multi-class, [0, 2]), ``ece``
        (top-label, equal-width bins), ``ece_quantile`` (top-label, equal-mass bins),
        ``ece_classwise`` (equal-width); each ECE as a dict with bootstrap interval, MCE and bins.
    """
    y = np.asarray(y_true)
    p = np.asarray(proba, dtype=np.float64)
    cls = np.asarray(classes)
    kw = {"classes": cls, "n_bins": n_bins, "n_bootstrap": n_bootstrap}
    top = expected_calibration_error(y, p, random_state=random_state, **kw)
    n_q = min(n_bins, y.shape[0])
    quant = expected_calibration_error(
        y, p, strategy="quantile", random_state=random_state, **(kw | {"n_bins": n_q})
    )
    cw = expected_calibration_error(y, p, classwise=True, random_state=random_state, **kw)
    return {
        "n": int(y.shape[0]),
        "accuracy": float(np.mean(cls[np.argmax(p, axis=1)] == y)),
        "log_loss": log_loss(y, p, classes=cls),
        "brier": brier(y, p, classes=cls),
        "ece": _ece_dict(top),
        "ece_quantile": _ece_dict(quant),
        "ece_classwise": _ece_dict(cw),
        "_results": (top, quant, cw),
    }


def _aligned(diag: xr.Dataset, runs: xr.Dataset, name: str, hat: str) -> tuple[np.ndarray, ...]:
    """Measured ``name`` and the predictions ``hat``/``hat_std`` on the diagnosis' time grid."""
    if hat not in diag or f"{hat}_std" not in diag:
        raise ValueError(f"diagnosis lacks {hat!r} or {hat + '_std'!r}")
    mean = diag[hat].transpose("run", ...)
    std = diag[f"{hat}_std"].transpose("run", ...)
    meas = runs[name]
    if "time" in mean.dims and "time" in mean.coords:
        meas = meas.sel(time=mean["time"].values)
    y = np.asarray(meas.transpose("run", "time").values, dtype=np.float64)
    m = np.asarray(mean.values, dtype=np.float64).reshape(y.shape)
    s = np.asarray(std.values, dtype=np.float64).reshape(y.shape)
    return y, m, s


def normal_model_summary(
    diagnosis: xr.Dataset,
    runs: xr.Dataset,
    *,
    levels: tuple[float, ...] = DEFAULT_LEVELS,
    outputs: tuple[str, ...] = ("X", "F"),
) -> dict[str, Any]:
    """Coverage, mean interval width, CRPS and PIT of the normal models on ``runs``.

    ``runs`` should be fault-free (the normal models describe the fault-free actuator).
    Samples where the measurement or the prediction is not finite are excluded and counted
    (``n_excluded``).

    Returns
    -------
    dict
        Per output: ``n``, ``n_excluded``, ``coverage`` (``CoverageResult.as_dict()``),
        ``crps`` (mean), ``rmse``, ``mean_std``, ``pit_density`` and ``pit_edges`` (10 bins),
        and ``_pit`` (the PIT values, for plotting).
    """
    out: dict[str, Any] = {}
    for name in outputs:
        y, m, s = _aligned(diagnosis, runs, name, f"{name}_hat")
        ok = np.isfinite(y) & np.isfinite(m) & np.isfinite(s) & (s > 0)
        y, m, s = y[ok], m[ok], s[ok]
        if y.size == 0:
            raise ValueError(f"no finite fault-free samples of {name} to score")
        cov = interval_coverage(y, m, s, levels=levels)
        pit = pit_values(y, m, s)
        dens, edges = pit_histogram(pit, 10)
        out[name] = {
            "n": int(y.size),
            "n_excluded": int((~ok).sum()),
            "coverage": cov.as_dict(),
            "crps": float(crps_gaussian(y, m, s).mean()),
            "rmse": float(np.sqrt(np.mean((y - m) ** 2))),
            "mean_std": float(np.mean(s)),
            "pit_density": dens.tolist(),
            "pit_edges": edges.tolist(),
            "_pit": pit,
        }
    return out


def split_in_time(runs: xr.Dataset, fraction: float = 0.5) -> tuple[xr.Dataset, xr.Dataset]:
    """Split every run at ``fraction`` of its length: ``(first part, second part)``.

    Both parts keep their original ``time`` coordinate (the second part starts at the split
    time), so nothing is re-labelled.
    """
    if not 0 < fraction < 1:
        raise ValueError(f"fraction must lie in (0, 1), got {fraction}")
    n = runs.sizes["time"]
    cut = round(fraction * n)
    if cut < 1 or cut >= n:
        raise ValueError(f"cannot split {n} samples at fraction {fraction}")
    return runs.isel(time=slice(0, cut)), runs.isel(time=slice(cut, n))


def time_split_summary(
    normal_model: Any,
    runs: xr.Dataset,
    *,
    fraction: float = 0.5,
    levels: tuple[float, ...] = DEFAULT_LEVELS,
) -> dict[str, Any]:
    """Fit a normal model on the first part of fault-free runs, score it on the rest.

    This is the honest test of the normal models on a single real record (e.g. the Lublin
    hour): fit on its first half, test on its second half, which the model has not seen and
    which lies later in time.

    Parameters
    ----------
    normal_model
        An unfitted model with ``fit(runs) -> self`` and ``predict(runs) -> Dataset`` of
        ``X_hat``, ``X_hat_std``, ``F_hat``, ``F_hat_std`` (e.g.
        ``bayes_fdi.residuals.NormalModels``).
    runs
        Fault-free runs.
    fraction
        Share of each run used for fitting (default 0.5).
    levels
        Central-interval levels.

    Returns
    -------
    dict
        As :func:`normal_model_summary` (without private entries), plus ``fraction``,
        ``n_fit_samples`` and ``split_time`` (s).
    """
    first, second = split_in_time(runs, fraction)
    model = normal_model.fit(first)
    summary = normal_model_summary(model.predict(second), second, levels=levels)
    out = _strip_private(summary)
    out["fraction"] = float(fraction)
    out["n_fit_samples"] = int(first.sizes["run"] * first.sizes["time"])
    out["split_time"] = float(second["time"].values[0])
    return out


def _samples(
    diag: xr.Dataset, runs: xr.Dataset
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """True labels, class distributions and features, one row per run (or run and window).

    For windowed diagnoses a window whose last sample is at or before its run's fault
    ``onset`` is labelled ``"fn"`` (the fault is not yet present), as FaultDiagnoser labels
    its training windows.
    """
    if "state" not in runs.coords:
        raise ValueError("runs must carry the per-run coordinate 'state'")
    states = np.asarray(runs["state"].values).astype(str)
    proba_da = diag["proba"]
    feats = None
    if "window" in proba_da.dims:
        proba = np.asarray(proba_da.transpose("run", "window", "class").values, dtype=np.float64)
        last = np.asarray(diag["window_end"].values, dtype=np.float64) - 1.0
        onset = (
            np.asarray(runs["onset"].values, dtype=np.float64)
            if "onset" in runs.coords
            else np.full(states.size, -np.inf)
        )
        y = np.where(last[None, :] <= onset[:, None], "fn", states[:, None]).ravel()
        proba = proba.reshape(-1, proba.shape[-1])
        if "features" in diag:
            f = diag["features"].transpose("run", "window", ...).values
            feats = np.asarray(f, dtype=np.float64).reshape(proba.shape[0], -1)
    else:
        proba = np.asarray(proba_da.transpose("run", "class").values, dtype=np.float64)
        y = states
        if "features" in diag:
            f = diag["features"].transpose("run", ...).values
            feats = np.asarray(f, dtype=np.float64).reshape(proba.shape[0], -1)
    return y, proba, feats


def _cross_fit(
    proba: np.ndarray, y: np.ndarray, classes: np.ndarray, seed: int
) -> tuple[np.ndarray, list[float]]:
    rng = np.random.default_rng(seed)
    perm = rng.permutation(y.shape[0])
    halves = [perm[: y.shape[0] // 2], perm[y.shape[0] // 2 :]]
    out = np.empty_like(proba)
    temps = []
    for a, b in ((0, 1), (1, 0)):
        ts = TemperatureScaler(classes=classes).fit(proba[halves[a]], y[halves[a]])
        out[halves[b]] = ts.transform(proba[halves[b]])
        temps.append(ts.temperature_)
    return out, temps


def _strip_private(d: Any) -> Any:
    if isinstance(d, dict):
        return {k: _strip_private(v) for k, v in d.items() if not str(k).startswith("_")}
    if isinstance(d, list | tuple):
        return [_strip_private(v) for v in d]
    if isinstance(d, float) and not math.isfinite(d):
        return None
    if isinstance(d, np.generic):
        return _strip_private(d.item())
    return d


# --------------------------------------------------------------------------------------
# report
# --------------------------------------------------------------------------------------
def _num(v: float | None) -> str:
    return "–" if v is None or not np.isfinite(v) else f"{v:.4f}"


def _fmt_ece(e: dict[str, Any]) -> str:
    """``plug-in (bias-corrected [basic CI])``, or just the plug-in without bootstrap."""
    if e["ci_low"] is None or not np.isfinite(e["ci_low"]):
        return f"{e['value']:.4f}"
    return f"{e['value']:.4f} ({_num(e['debiased'])} [{e['ci_low']:.4f}, {e['ci_high']:.4f}])"


def write_calibration_report(
    diagnoser: Any,
    test_runs: xr.Dataset,
    out_dir: str | Path,
    *,
    calibration_runs: xr.Dataset | None = None,
    n_bins: int = 15,
    n_bootstrap: int = 500,
    seed: int = 0,
    title: str = "Calibration report",
) -> Path:
    """Diagnose ``test_runs`` and write a calibration report (Markdown + figures + JSON).

    Parameters
    ----------
    diagnoser
        A fitted diagnoser (``FaultDiagnoser`` contract: ``diagnose(runs)``; ``classifier_``
        with ``nodes_`` for the per-node table, optional).
    test_runs
        Labelled test runs (coordinate ``state``); runs whose state the diagnoser does not
        know are excluded from the classification metrics and counted in the report.
        Fault-free (``"fn"``) runs are used for the normal-model section.
    out_dir
        Output folder (created).
    calibration_runs
        Held-out labelled runs on which the temperature is fitted; default: two-fold
        cross-fitting on the test runs.
    n_bins, n_bootstrap, seed
        ECE bins, bootstrap resamples and the seed of bootstrap and cross-fitting.
    title
        First heading of the report.

    Returns
    -------
    pathlib.Path
        Path of ``report.md``.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    fig_dir = out / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    if "state" not in test_runs.coords:
        raise ValueError("test_runs must carry the per-run coordinate 'state'")

    diag = diagnoser.diagnose(test_runs)
    classes = np.asarray([str(c) for c in diag["class"].values])
    y_samples, proba, feats_all = _samples(diag, test_runs)
    known = np.isin(y_samples, classes)
    y, p = y_samples[known], proba[known]
    if y.size < 2:
        raise ValueError("fewer than two test samples have a state the diagnoser knows")
    y_all = np.asarray(test_runs["state"].values).astype(str)
    results: dict[str, Any] = {
        "title": title,
        "classes": classes.tolist(),
        "n_test_runs": int(y_all.size),
        "n_samples": int(y_samples.size),
        "windowed": bool("window" in diag["proba"].dims),
        "n_excluded_unknown_state": int((~known).sum()),
        "excluded_states": sorted(set(y_samples[~known].tolist())),
    }
    kw = {"n_bins": n_bins, "n_bootstrap": n_bootstrap, "random_state": seed}
    before = classification_summary(y, p, classes, **kw)

    # ---- temperature scaling on held-out data
    if calibration_runs is not None:
        if "state" not in calibration_runs.coords:
            raise ValueError("calibration_runs must carry the per-run coordinate 'state'")
        ycal, pcal, _ = _samples(diagnoser.diagnose(calibration_runs), calibration_runs)
        kcal = np.isin(ycal, classes)
        ts = TemperatureScaler(classes=classes).fit(pcal[kcal], ycal[kcal])
        p_after = ts.transform(p)
        recal = {
            "method": "temperature scaling fitted on the calibration runs",
            "temperature": ts.temperature_,
            "n_fit": int(kcal.sum()),
            "at_bound": ts.at_bound_,
        }
    else:
        p_after, temps = _cross_fit(p, y, classes, seed)
        recal = {
            "method": "temperature scaling, two-fold cross-fitted on the test runs",
            "temperature": temps,
            "n_fit": int(y.size),
        }
    after = classification_summary(y, p_after, classes, **kw)
    results["recalibration"] = recal
    results["whole_tree"] = {"before": before, "after": after}

    # ---- reliability diagrams
    fig, axes = plt.subplots(1, 2, figsize=(9, 4.5))
    reliability_diagram(before["_results"][0], ax=axes[0],
                        title=f"before: ECE {_fmt_ece(before['ece'])}")  # fmt: skip
    reliability_diagram(after["_results"][0], ax=axes[1],
                        title=f"after T-scaling: ECE {_fmt_ece(after['ece'])}")  # fmt: skip
    fig.suptitle("Whole tree, top-label reliability (equal-width bins)", fontsize=10)
    fig.tight_layout()
    fig.savefig(fig_dir / "reliability_whole_tree.png", dpi=120)
    plt.close(fig)

    # ---- per node
    nodes = getattr(getattr(diagnoser, "classifier_", None), "nodes_", None)
    node_rows = []
    node_note = ""
    if nodes is None:
        node_note = "The diagnoser exposes no `classifier_.nodes_`; per-node calibration skipped."
    elif feats_all is None:
        node_note = "The diagnosis has no `features`; per-node calibration skipped."
    else:
        feats = feats_all[known]
        scaler = getattr(diagnoser, "scaler_", None)
        if scaler is not None:  # the tree sees standardised features
            feats = np.asarray(scaler.transform(feats), dtype=np.float64)
        for nc in node_calibration(nodes, feats, y, n_bins=min(n_bins, 10), random_state=seed):
            node_rows.append(
                {
                    "index": nc.index,
                    "left": list(nc.left),
                    "right": list(nc.right),
                    "n": nc.n_samples,
                    "accuracy": nc.accuracy,
                    "ece": None if nc.ece is None else nc.ece.value,
                    "mce": None if nc.ece is None else nc.ece.mce,
                    "log_loss": nc.log_loss,
                    "brier": nc.brier,
                }
            )
    results["nodes"] = node_rows

    # ---- normal models on fault-free runs
    fn = np.flatnonzero(y_all == "fn")
    normal: dict[str, Any] = {}
    if fn.size:
        normal = normal_model_summary(diag.isel(run=fn), test_runs.isel(run=fn))
        fig, axes = plt.subplots(1, len(normal), figsize=(4.5 * len(normal), 3.2))
        for ax, (name, d) in zip(np.atleast_1d(axes), normal.items(), strict=True):
            plot_pit_histogram(d["_pit"], 10, ax=ax, title=f"PIT of {name} (n = {d['n']})")
        fig.tight_layout()
        fig.savefig(fig_dir / "pit_normal_models.png", dpi=120)
        plt.close(fig)
    results["normal_models"] = normal
    results["n_fault_free_runs"] = int(fn.size)

    # ---- write
    clean = _strip_private(results)
    (out / "calibration.json").write_text(json.dumps(clean, indent=2))
    report = out / "report.md"
    report.write_text(_markdown(clean, node_note))
    return report


def _markdown(r: dict[str, Any], node_note: str) -> str:
    b, a = r["whole_tree"]["before"], r["whole_tree"]["after"]
    rc = r["recalibration"]
    temp = rc["temperature"]
    temp_s = ", ".join(f"{t:.3f}" for t in temp) if isinstance(temp, list) else f"{temp:.3f}"
    lines = [
        f"# {r['title']}",
        "",
        f"Test runs: {r['n_test_runs']}"
        + (f", diagnosed in {r['n_samples']} windows" if r.get("windowed") else "")
        + f" ({r['n_excluded_unknown_state']} excluded from the "
        f"classification metrics because their state is not among the diagnoser's classes"
        + (f": {', '.join(r['excluded_states'])}" if r["excluded_states"] else "")
        + f"). Classes: {', '.join(r['classes'])}.",
        "",
        "## Whole tree",
        "",
        f"Recalibration: {rc['method']} (T = {temp_s}, fitted on {rc['n_fit']} runs).",
        "ECE cells: plug-in estimate (bias-corrected estimate [95 % basic-bootstrap interval "
        "of the population ECE]). The plug-in ECE is biased upwards, so it may lie above the "
        "interval; the bias-corrected value subtracts the bootstrap estimate of that bias. "
        "The noise floor is the ECE a perfectly calibrated model would show on this many "
        "runs: plug-in values near it are indistinguishable from sampling noise. "
        "Brier score is the multi-class one (sum over classes of squared errors, range [0, 2]).",
        "",
        "| metric | before | after |",
        "|---|---|---|",
        f"| accuracy | {b['accuracy']:.4f} | {a['accuracy']:.4f} |",
        f"| top-label ECE (equal width) | {_fmt_ece(b['ece'])} | {_fmt_ece(a['ece'])} |",
        f"| top-label ECE (equal mass) | {_fmt_ece(b['ece_quantile'])} | "
        f"{_fmt_ece(a['ece_quantile'])} |",
        f"| classwise ECE | {_fmt_ece(b['ece_classwise'])} | {_fmt_ece(a['ece_classwise'])} |",
        f"| noise floor of top-label ECE | {b['ece']['noise_floor']:.4f} | "
        f"{a['ece']['noise_floor']:.4f} |",
        f"| MCE (top-label) | {b['ece']['mce']:.4f} | {a['ece']['mce']:.4f} |",
        f"| log loss | {b['log_loss']:.4f} | {a['log_loss']:.4f} |",
        f"| Brier | {b['brier']:.4f} | {a['brier']:.4f} |",
        "",
        "![reliability](figures/reliability_whole_tree.png)",
        "",
        "## Tree nodes",
        "",
    ]
    if r["nodes"]:
        lines += [
            "Each node's binary calibration on the test runs of its classes "
            "(outcome: the run's class is on the right).",
            "",
            "| node | left | right | n | accuracy | ECE | MCE | log loss | Brier |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for n in r["nodes"]:

            def f(v):
                return "–" if v is None else f"{v:.4f}"

            lines.append(
                f"| {n['index']} | {' '.join(n['left'])} | {' '.join(n['right'])} | {n['n']} | "
                f"{f(n['accuracy'])} | {f(n['ece'])} | {f(n['mce'])} | {f(n['log_loss'])} | "
                f"{f(n['brier'])} |"
            )
    else:
        lines.append(node_note or "No nodes.")
    lines += ["", "## Normal models (fault-free test runs)", ""]
    if r["normal_models"]:
        lines += [
            f"{r['n_fault_free_runs']} fault-free runs. Central predictive intervals "
            "mean ± z·std; CRPS in normalised units (lower is better).",
            "",
            "| output | level | coverage | mean width |",
            "|---|---|---|---|",
        ]
        for name, d in r["normal_models"].items():
            for lv, c in d["coverage"].items():
                lines.append(f"| {name} | {lv} | {c['coverage']:.4f} | {c['mean_width']:.4g} |")
        lines += [
            "",
            "| output | n samples | excluded (non-finite) | CRPS | RMSE | mean std |",
            "|---|---|---|---|---|---|",
        ]
        for name, d in r["normal_models"].items():
            lines.append(
                f"| {name} | {d['n']} | {d['n_excluded']} | {d['crps']:.4g} | {d['rmse']:.4g} | "
                f"{d['mean_std']:.4g} |"
            )
        lines += ["", "![PIT](figures/pit_normal_models.png)"]
    else:
        lines.append("No fault-free test runs: normal-model calibration not assessed.")
    lines.append("")
    return "\n".join(lines)


# --------------------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------------------
def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``bayes-fdi calibration-report``."""
    parser.add_argument("--train", required=True, help="training dataset (.nc)")
    parser.add_argument("--test", required=True, help="test dataset (.nc)")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument(
        "--calibration", default=None, help="held-out dataset (.nc) to fit the temperature on"
    )
    parser.add_argument("--method", choices=("rvm", "svm"), default="rvm")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--n-bins", type=int, default=15)
    parser.add_argument("--n-bootstrap", type=int, default=500)


def _build_diagnoser(method: str, seed: int) -> Any:
    """A fresh diagnoser of the chosen method (RVM defaults or SVM nodes)."""
    try:
        from bayes_fdi.diagnosis import FaultDiagnoser
    except ImportError as err:  # pragma: no cover - until the diagnosis stream is merged
        raise RuntimeError(f"bayes_fdi.diagnosis is not available: {err}") from None
    if method == "rvm":
        return FaultDiagnoser(random_state=seed)
    from bayes_fdi.baselines import svm_fault_diagnoser

    return svm_fault_diagnoser(random_state=seed)


def run_from_cli(args: argparse.Namespace) -> int:
    """Fit a diagnoser on ``--train`` (fn runs + all labelled runs); report on ``--test``."""
    from bayes_fdi.datasets import load_dataset

    train = load_dataset(args.train)
    test = load_dataset(args.test)
    cal = load_dataset(args.calibration) if args.calibration else None
    if "state" not in train.coords:
        raise ValueError(f"{args.train} has no per-run 'state' coordinate")
    normal = train.isel(run=np.flatnonzero(train["state"].values == "fn"))
    if normal.sizes["run"] == 0:
        raise ValueError(f"{args.train} has no fault-free ('fn') runs to fit the normal models")
    diagnoser = _build_diagnoser(args.method, args.seed).fit(normal, train)
    path = write_calibration_report(
        diagnoser,
        test,
        args.out,
        calibration_runs=cal,
        n_bins=args.n_bins,
        n_bootstrap=args.n_bootstrap,
        seed=args.seed,
        title=f"Calibration report ({args.method.upper()}, test {Path(args.test).name})",
    )
    print(path)
    return 0

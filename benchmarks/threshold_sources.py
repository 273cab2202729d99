"""Which fault-free training seconds set an online diagnoser's detector threshold.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/threshold_sources.py [--model FILE] \
        [--seed 0] [--training excitation-mix] [--above 15]

The fit calibrates the threshold on the whitened out-of-fold standardised residuals of its
fault-free training runs (`bayes_fdi.diagnosis.online.training.fit_detection`), which the model
keeps as ``normal_models_.oof_z_``. This script whitens them with the model's own filters, runs
the CUSUM's mean test (two-sided, reference 0.5, uncapped) over each run and lists the runs whose
statistic peaks above ``--above``: their training file, run, the second and channel of the
peak, and where the valve stood then: the seconds of the run with the valve shut (X above 0.97)
and with the flow reading at its upper rail (F above 0.99), and the mean absolute out-of-fold
residual of F there and elsewhere. The runs are simulated again from the training's campaign
files (``--training``, ``--seed``: those the model was fitted with; the default model's are the
defaults) to read X and F; the script stops if their number or length differs from the model's.
Results go to stdout and ``benchmarks/out/threshold_sources.json``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: Where the results are written.
OUT = ROOT / "benchmarks" / "out" / "threshold_sources.json"
#: The CUSUM's reference value (innovation standard deviations).
REFERENCE = 0.5
#: The valve counts as shut above this position, and the flow reading at its rail above this.
SHUT, RAIL = 0.97, 0.99


def cusum_peak(e: np.ndarray, k: float = REFERENCE) -> tuple[float, int, int]:
    """The largest two-sided CUSUM statistic over ``e`` ``(n, channels)`` (the library's
    `~bayes_fdi.diagnosis.detection.CUSUM`, reference ``k``, in effect uncapped; NaN seconds
    are gaps), its second and its channel (``-1`` for both if it stays 0)."""
    from bayes_fdi.diagnosis.detection import CUSUM

    detector = CUSUM(k=k, threshold=1e12, cap=1e300)
    peak, at, channel = 0.0, -1, -1
    for j in range(e.shape[1]):
        stat = np.nan_to_num(np.asarray(detector.run(e[:, j])[0].statistic), nan=0.0)
        t = int(np.argmax(stat))
        if stat[t] > peak:
            peak, at, channel = float(stat[t]), t, j
    return peak, at, channel


def valve_regimes(x: np.ndarray, f: np.ndarray, z_f: np.ndarray) -> dict[str, Any]:
    """Seconds with the valve shut and with the flow at its rail, and the mean absolute
    out-of-fold residual of F there and over the other seconds (NaN where there are none)."""
    shut, rail = x > SHUT, f > RAIL
    other = ~shut & ~rail
    z = np.abs(z_f)

    def mean(mask: np.ndarray) -> float:
        return float(np.nanmean(z[mask])) if mask.any() else float("nan")

    return {
        "shut_seconds": int(shut.sum()),
        "rail_seconds": int(rail.sum()),
        "z_F_shut": mean(shut),
        "z_F_rail": mean(rail),
        "z_F_other": mean(other),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", help="a model file (default: the cached default model)")
    parser.add_argument("--seed", type=int, default=0, help="the training seed of the model")
    parser.add_argument("--training", default="excitation-mix")
    parser.add_argument("--above", type=float, default=15.0)
    args = parser.parse_args()
    from bayes_fdi.campaigns.simulation import simulate_campaign
    from bayes_fdi.default_diagnoser import simulation_plan
    from bayes_fdi.deployment.fitting import default_model, load_online_model
    from bayes_fdi.reporting import write_json

    diagnoser = load_online_model(args.model) if args.model else default_model(progress=False)
    oof = np.asarray(diagnoser.normal_models_.oof_z_, dtype=np.float64)
    normal = [
        simulate_campaign(campaign, seed=run_seed, progress=False)
        for part, campaign, run_seed in simulation_plan(seed=args.seed, training=args.training)
        if part == "normal"
    ]  # the fault-free runs only, as the fit simulates them
    runs = [(d.attrs.get("campaign", "?"), d.isel(run=r)) for d in normal
            for r in range(d.sizes["run"])]  # fmt: skip
    if len(runs) != oof.shape[0] or any(d.sizes["time"] != oof.shape[1] for _, d in runs):
        raise SystemExit(
            f"the model's out-of-fold residuals ({oof.shape[0]} runs x {oof.shape[1]} s) are not "
            "those of this training: give the --seed and --training it was fitted with"
        )
    whiteners = [diagnoser.whiteners_[c] for c in ("X", "F")]
    rows = []
    for i, (campaign, run) in enumerate(runs):
        e = np.stack([w.run(oof[i, :, j])[0] for j, w in enumerate(whiteners)], axis=1)
        peak, at, channel = cusum_peak(e)
        if peak <= args.above:
            continue
        x, f = np.asarray(run["X"].values), np.asarray(run["F"].values)
        row = {
            "campaign": campaign,
            "run": int(i),
            "peak": peak,
            "second": at,
            "channel": "XF"[channel],
            **valve_regimes(x, f, oof[i, :, 1]),
        }
        rows.append(row)
        print(
            f"{campaign} (run {i}): CUSUM peak {peak:.1f} at {at} s on {row['channel']}; shut "
            f"{row['shut_seconds']} s (|z_F| {row['z_F_shut']:.1f}), F at its rail "
            f"{row['rail_seconds']} s (|z_F| {row['z_F_rail']:.1f}), elsewhere |z_F| "
            f"{row['z_F_other']:.2f}",
            flush=True,
        )
    print(f"threshold {diagnoser.threshold_:.2f}; {len(rows)} of {len(runs)} runs peak above "
          f"{args.above:g}")  # fmt: skip
    OUT.parent.mkdir(parents=True, exist_ok=True)
    write_json({"threshold": diagnoser.threshold_, "above": args.above, "runs": rows}, OUT)


if __name__ == "__main__":
    main()

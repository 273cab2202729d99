"""How far beyond its commissioning data does a commissioned valve's normal model hold?

A commissioned diagnoser's normal models are fitted on one healthy recording, and its input
envelope is that recording's range of CV, P1, P2, T1 widened on each side by ``input_margin``
(a share of the span, default 0.1) or at least 0.02 of full scale. This script measures the
standardised residuals ``(y - y_hat) / y_hat_std`` of X and F as the inputs leave the
commissioning range, on perturbed plants that no benchmark scores (default: plants 5 and 6 of
`bayes_fdi.benchmark.plants`, drawn as the commissioning benchmark's five).

Each plant is commissioned on its healthy hour (`bayes_fdi.commissioning.commission`, seed 0),
then diagnoses ``--runs`` healthy half hours of its level loop, each with an input and noise
seed of its own (``SEED + 100 plant + j``, apart from every seed the project's fits and
benchmarks use); the loop's demand varies run by run, so some runs leave the commissioning
range. Every second is binned by how far its inputs lie beyond that range: the largest over
CV, P1, P2, T1 of the distance beyond the range's nearer end, as a share of that channel's span.
Per run: its command's range, its alarms and the share of the alarm seconds answered
``mismatch``. Per bin: the seconds, the RMS and mean of each standardised residual, the share of
seconds with the alarm (DD) on, and the share the envelope flags (``novel_inputs``).

Run: ``OMP_NUM_THREADS=1 PYTHONPATH=. python benchmarks/commissioned_envelope.py [--plants 5,6]
[--runs 8]`` (about 3 CPU min per plant).

``--scenarios`` asks instead how often the commissioning benchmark's own runs leave their plant's
commissioning range, without commissioning anything: for each big abrupt Step-I scenario and
benchmark seed (``--seeds``, default 2) of each plant, the fault-free version of the run (the
same inputs: the loop is open at the fault) is compared with the range of the plant's healthy
hour as a commissioned diagnoser's input envelope is fitted on it (`INPUT_MARGIN`, the 0.02
floor; `onset_outside`): whether the command leaves it
within ``CHANGE_LOOKBACK`` s after the onset or an input's mean over the minute before the onset
lies outside it (a proxy of the onset check, which would answer a detection there
``mismatch``), and the share of the faulty seconds with an input outside. About 10 CPU s per
plant.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

#: Input and noise seeds of the runs: apart from the training campaigns (< 1000), the DAMADICS
#: benchmark (10 000 +), its fault-free hours (20 000 +) and the plants' seeds (30 000 - 59 999).
SEED = 90_000
#: Upper edges of the distance bins (share of the channel's span beyond its range).
EDGES = (0.0, 0.02, 0.05, 0.1, 0.2, 0.4)
ENVELOPE = ("CV", "P1", "P2", "T1")


def _run(plant, seconds: int, seed: int):
    from bayes_fdi.actuator import simulate
    from bayes_fdi.actuator.excitation import level_loop_inputs

    inputs = level_loop_inputs(1, seconds, seed=seed, loop=plant.loop, operating=plant.operating)
    return simulate(inputs.drop_vars("level"), [None], seed=seed, parameters=plant.parameters)


def distance_beyond_range(run, low, high) -> np.ndarray:
    """Per second, the largest share of a channel's span its input lies beyond its range."""
    out = np.zeros(run.sizes["time"])
    for c in ENVELOPE:
        v = np.asarray(run[c].values, dtype=np.float64).ravel()
        span = max(high[c] - low[c], 1e-12)
        out = np.maximum(out, np.maximum(v - high[c], low[c] - v).clip(min=0.0) / span)
    return out


def healthy_range(healthy) -> tuple[dict[str, float], dict[str, float]]:
    """The lowest and highest value of each input over the healthy recording."""
    return ({c: float(healthy[c].min()) for c in ENVELOPE},
            {c: float(healthy[c].max()) for c in ENVELOPE})  # fmt: skip


def onset_outside(run, envelope, onset: int, lookback: int) -> tuple[bool, float]:
    """Whether the command lies outside ``envelope`` (a fitted `InputEnvelope`) in a second of
    ``[onset, onset + lookback]`` or the inputs' mean over the 60 s before ``onset`` does, and
    the share of the seconds from ``onset`` on with an input outside (its levels only)."""
    x = np.column_stack([np.asarray(run[c].values, dtype=np.float64).ravel() for c in ENVELOPE])
    cv = x[onset : onset + lookback + 1, 0]
    near = bool(np.any((cv < envelope.low_[0]) | (cv > envelope.high_[0])))
    before = bool(envelope.outside(x[max(onset - 60, 0) : onset].mean(axis=0, keepdims=True))[0])
    return near or before, float(envelope.outside(x[onset:]).mean())


def scenario_ranges(plants, seeds: int) -> None:
    """Print, per plant, how many big abrupt runs leave the commissioning envelope at their
    onset (`onset_outside`) and the mean share of faulty seconds with an input outside it."""
    from bayes_fdi.benchmark.plant_runs import POSITION
    from bayes_fdi.benchmark.plants import draw_plant, healthy_run, scenario_run
    from bayes_fdi.benchmark.scenarios import SCENARIOS
    from bayes_fdi.commissioning import INPUT_MARGIN
    from bayes_fdi.diagnosis.online import InputEnvelope
    from bayes_fdi.diagnosis.online.envelope import CHANGE_LOOKBACK

    big = [s for s in SCENARIOS if s.mode == "abrupt" and s.size == "big"]
    for p in plants:
        plant = draw_plant(p)
        envelope = InputEnvelope(margin=INPUT_MARGIN).fit(healthy_run(plant, 3600))
        flags, shares = [], []
        for k in range(seeds):
            for scenario in big:
                run = scenario_run(plant, scenario, k, POSITION[scenario.name], faulty=False)
                flag, share = onset_outside(run, envelope, round(scenario.t_from), CHANGE_LOOKBACK)
                flags.append(flag)
                shares.append(share)
        print(f"plant {p}: {sum(flags)} of {len(flags)} big abrupt runs leave the commissioning "
              f"range at their onset; faulty seconds with an input outside it: "
              f"{100 * np.mean(shares):.1f} %", flush=True)  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plants", default="5,6")
    ap.add_argument("--runs", type=int, default=8)
    ap.add_argument("--seconds", type=int, default=1800)
    ap.add_argument("--scenarios", action="store_true", help="the benchmark's runs' ranges")
    ap.add_argument("--seeds", type=int, default=2, help="benchmark seeds (--scenarios)")
    args = ap.parse_args(argv)
    if args.scenarios:
        scenario_ranges([int(v) for v in args.plants.split(",")], args.seeds)
        return 0
    from bayes_fdi.benchmark.plants import draw_plant, healthy_run
    from bayes_fdi.commissioning import commission
    from bayes_fdi.datasets import CHANNELS

    rows = []
    for p in (int(v) for v in args.plants.split(",")):
        plant = draw_plant(p)
        healthy = healthy_run(plant, 3600)
        low, high = healthy_range(healthy)
        diagnoser = commission(healthy, seed=0, progress=False).diagnoser
        print(f"plant {p}: commissioned on CV {low['CV']:.3f}-{high['CV']:.3f}", flush=True)
        for j in range(args.runs):
            run = _run(plant, args.seconds, SEED + 100 * p + j)[list(CHANNELS)]
            one = diagnoser.run(run).isel(run=0)
            z = {
                c: (np.asarray(run[c].values).ravel() - one[f"{c}_hat"].values)
                / one[f"{c}_hat_std"].values
                for c in ("X", "F")
            }
            d = distance_beyond_range(run, low, high)
            cv = np.asarray(run["CV"].values).ravel()
            dd = np.asarray(one["DD"].values, dtype=bool)
            alarms = int(np.sum(np.diff(np.concatenate(([0], dd.astype(int)))) == 1))
            state = np.asarray(one["state"].values).astype(str)
            mismatch = float(np.mean(state[dd] == "mismatch")) if dd.any() else 0.0
            print(f"  run {j}: CV {cv.min():.3f}-{cv.max():.3f}, beyond {np.mean(d > 0):.0%} "
                  f"of the seconds, DD {dd.mean():.0%}, {alarms} alarm(s), "
                  f"{mismatch:.0%} of the alarm seconds mismatch", flush=True)  # fmt: skip
            rows.append((p, d, z["X"], z["F"], np.asarray(one["DD"].values, bool),
                         np.asarray(one["novel_inputs"].values, bool)))  # fmt: skip
    for name, sel in [("all plants", None)] + [
        (f"plant {p}", p) for p in sorted({r[0] for r in rows})
    ]:
        use = [r for r in rows if sel is None or r[0] == sel]
        d, zx, zf, dd, nov = (np.concatenate([r[k] for r in use]) for k in range(1, 6))
        print(f"\n{name}: | beyond the range (share of span) | seconds | RMS z_X | mean z_X | "
              "RMS z_F | mean z_F | DD on | flagged |")  # fmt: skip
        bins = np.digitize(d, EDGES, right=True)
        for b in range(len(EDGES) + 1):
            m = bins == b
            if not m.any():
                continue
            label = "inside" if b == 0 else (
                f"({EDGES[b - 1]:g}, {EDGES[b]:g}]" if b < len(EDGES) else f"> {EDGES[-1]:g}"
            )  # fmt: skip
            print(f"| {label} | {m.sum()} | {np.sqrt(np.mean(zx[m] ** 2)):.2f} | "
                  f"{zx[m].mean():+.2f} | {np.sqrt(np.mean(zf[m] ** 2)):.2f} | "
                  f"{zf[m].mean():+.2f} | {dd[m].mean():.1%} | {nov[m].mean():.1%} |")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())

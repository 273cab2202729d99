"""How visible a fault stays after its onset under the shift benchmark's excitation families.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/shift_visibility.py [--model FILE] \
        [--fault f11] [--size big] [--seeds 6000,6001,6002] [--window 100]

The shift benchmark asks that DD stay on after its first detection; a fault whose effect the
positioner compensates (a weaker spring, f11) shows at its onset and then mostly in how the
stem answers the command. For each excitation family of the shift benchmark
(`bayes_fdi.benchmark.shift`) and each seed, the abrupt Step-I scenario of the fault and size
given is simulated with and without the fault (inputs drawn from the family with that seed,
the noise from it too) and both runs go through the diagnoser (``--model``, or the default
model). Window by window of the faulty part (``--window`` s), the difference of the two
streams' whitened innovations is the fault's effect alone, in units of the innovations'
standard deviation before the fault (`bayes_fdi.benchmark.cases.innovation_noise`):

- *separation*: ``sqrt(sum_t sum_c (d_c(t) / sigma_c)^2)`` over the window, what a matched filter
  that knew the effect exactly would reach there (`~bayes_fdi.benchmark.cases.innovation_effect`'s
  deflection, window by window);
- *RMS faulty / healthy*: the innovations' RMS over the window in each run (X and F): what a
  test of their spread sees;
- *DD*: the share of the window's seconds with the alarm on, in the faulty run.

The seeds must lie in [1000, 10 000), apart from training (< 1000) and from the benchmark's inputs
and noise (10 000 and up).
Results go to stdout and ``benchmarks/out/shift_visibility.json``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: Where the results are written.
OUT = ROOT / "benchmarks" / "out" / "shift_visibility.json"
#: The inputs an excitation family draws.
ENVELOPE_INPUTS = ("CV", "P1", "P2", "T1")
#: The whitened innovations compared.
INNOVATIONS = ("r_X", "r_F")


def window_figures(
    faulty: Any, healthy: Any, *, t_from: float, t_hor: float, window: int, noise: dict
) -> list[dict[str, float]]:
    """Per window of ``window`` s from ``t_from`` to ``t_hor``: ``start`` (s after ``t_from``),
    ``separation`` (`~bayes_fdi.benchmark.cases.innovation_effect`'s deflection over the
    window), ``rms_faulty`` and ``rms_healthy`` (the innovations' RMS, ``{"X": ..., "F": ...}``)
    and ``dd`` (the share of the window with DD on, NaN read as off), from two streams (one run
    each) of the same run with and without the fault."""
    from bayes_fdi.benchmark.cases import innovation_effect
    from bayes_fdi.scoring.decision_signals import decision_high

    t = np.asarray(faulty["time"].values, dtype=np.float64)
    dd = decision_high(np.asarray(faulty["DD"].values, dtype=np.float64))

    def rms(stream: Any, c: str, keep: np.ndarray) -> float:
        values = np.nan_to_num(np.asarray(stream[c].values, dtype=np.float64)[keep])
        return float(np.sqrt(np.mean(values**2)))

    rows = []
    for start in np.arange(t_from, t_hor, window):
        keep = (t >= start) & (t < min(start + window, t_hor))
        effect = innovation_effect(
            faulty.isel(time=keep), healthy.isel(time=keep), t_from=float(start), noise=noise
        )
        rows.append(
            {
                "start": float(start - t_from),
                "separation": effect["deflection"],
                "rms_faulty": {c[-1]: rms(faulty, c, keep) for c in INNOVATIONS},
                "rms_healthy": {c[-1]: rms(healthy, c, keep) for c in INNOVATIONS},
                "dd": float(np.mean(dd[keep])),
            }
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", help="a model file (default: the cached default model)")
    parser.add_argument("--fault", default="f11")
    parser.add_argument("--size", default="big", choices=("small", "medium", "big"))
    parser.add_argument("--seeds", default="6000,6001,6002")
    parser.add_argument("--window", type=int, default=100)
    args = parser.parse_args()
    from bayes_fdi.actuator.simulate import simulate_replicas
    from bayes_fdi.benchmark.cases import innovation_noise, zeroed
    from bayes_fdi.benchmark.scenarios import SCENARIOS
    from bayes_fdi.benchmark.shift import shift_families
    from bayes_fdi.campaigns.excitation import excitation_inputs
    from bayes_fdi.datasets import CHANNELS
    from bayes_fdi.deployment.fitting import default_model, load_online_model
    from bayes_fdi.reporting import write_json

    seeds = [int(s) for s in args.seeds.split(",")]
    if min(seeds) < 1000 or max(seeds) >= 10_000:
        raise SystemExit("--seeds: use seeds in [1000, 10000), apart from training and evaluation")
    diagnoser = load_online_model(args.model) if args.model else default_model(progress=False)
    name = f"{args.fault} abrupt {args.size}"
    by_name = {s.name: s for s in SCENARIOS}
    if name not in by_name:
        raise SystemExit(f"--fault/--size: no Step-I scenario {name!r}")
    scenario = by_name[name]
    result: dict[str, Any] = {"scenario": name, "seeds": seeds, "window": args.window}
    for family in shift_families():
        runs = []
        for seed in seeds:
            drawn = excitation_inputs(family.excitation, 1, round(scenario.t_hor), seed=seed)
            drive = drawn[list(ENVELOPE_INPUTS)]
            with_fault = simulate_replicas(drive, [scenario.fault_spec()], seeds=[seed])[0]
            without = simulate_replicas(drive, [None], seeds=[seed])[0]
            one = zeroed(diagnoser.run(with_fault[list(CHANNELS)]).isel(run=0))
            clean = zeroed(diagnoser.run(without[list(CHANNELS)]).isel(run=0))
            t = np.asarray(clean["time"].values)
            noise = innovation_noise(clean.isel(time=(t >= scenario.t_on) & (t < scenario.t_from)))
            rows = window_figures(
                one, clean, t_from=scenario.t_from, t_hor=scenario.t_hor, window=args.window,
                noise=noise,
            )  # fmt: skip
            runs.append({"seed": seed, "windows": rows})
            cells = [
                f"{r['start']:.0f}s: {r['separation']:.0f}, RMS {r['rms_faulty']['X']:.2f}/"
                f"{r['rms_faulty']['F']:.2f} vs {r['rms_healthy']['X']:.2f}/"
                f"{r['rms_healthy']['F']:.2f}, DD {r['dd']:.2f}"
                for r in rows
            ]
            print(f"{family.name} seed {seed}: " + " | ".join(cells), flush=True)
        result[family.name] = runs
    OUT.parent.mkdir(parents=True, exist_ok=True)
    write_json(result, OUT)


if __name__ == "__main__":
    main()

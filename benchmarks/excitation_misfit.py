"""Which input makes a model's normal models misfit a new excitation: fault-free cases that change
one input at a time.

For a model file (default: the cached default model, `bayes_fdi.deployment.fitting.
default_model`), fault-free runs of each case below, their inputs and noise drawn with ``--seed``
(905 by default: below 1000 but apart from every training campaign's seed, and from the shift
benchmark's, which draws its families' inputs with the seeds of `sim/shift-*.toml`):

- the shift benchmark's chirp generator with its defaults, then with P1 held still, with P1's
  sine at DGen's 0.1 Hz instead of 0.05 Hz, and at pressure drops of 0.3-0.5, 0.5-0.8 and
  0.8-1.2 MPa;
- the training's sums of sines (the settings of `sim/online-normal-sine-sum.toml`, read from
  the file) with P1 still, and as trained, P1 oscillating by 0-200 kPa, at every drop and at
  drops of 0.3-0.5 MPa;
- the DGen sines with run-to-run variation.

Per case, after each run's first ``START_UP`` seconds (`stream_figures`): the median over the
runs of the RMS of the whitened innovations of X and F (about 1 where the normal models fit),
the share of seconds with DD on, and the alarms (DD's rising edges, one counted for a run whose
DD is on from its first scored second). About 2-3 CPU min with the defaults.

Run: ``OMP_NUM_THREADS=1 PYTHONPATH=. python benchmarks/excitation_misfit.py [--model FILE]
[--runs 6] [--duration 1800] [--seed 905]``
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

import numpy as np

START_UP = 120  #: seconds of each run left out (the streams' start-up)

#: The training's fault-free sums of sines, whose excitation settings the cases take.
SINE_SUM_CAMPAIGN = "online-normal-sine-sum"


def training_sine_sum() -> dict[str, object]:
    """The ``[excitation]`` settings of the training's sums of sines (`SINE_SUM_CAMPAIGN`), as
    `~bayes_fdi.actuator.excitation.sine_sum_inputs` takes them (P1's oscillation included)."""
    from bayes_fdi.campaigns.cache import campaign_file
    from bayes_fdi.campaigns.parsing import load_campaign

    return dict(load_campaign(campaign_file(SINE_SUM_CAMPAIGN)).excitation["parameters"])


def stream_figures(r_x: np.ndarray, r_f: np.ndarray, dd: np.ndarray) -> dict[str, float]:
    """Figures of ``(runs, time)`` arrays of one case, its start-up already left out: the median
    over the runs of each run's innovation RMS (NaN seconds left out), the share of seconds with
    DD on, and the alarms (DD's rising edges, `rising_edges` of each run; NaN DD is off, as
    PICalc reads it)."""
    from bayes_fdi.scoring.decision_signals import decision_high, rising_edges

    dd = decision_high(dd)

    def rms(r: np.ndarray) -> float:
        return float(np.median(np.sqrt(np.nanmean(np.asarray(r, dtype=np.float64) ** 2, axis=1))))

    return {
        "rms_X": rms(r_x),
        "rms_F": rms(r_f),
        "dd_share": float(dd.mean()),
        "alarms": sum(rising_edges(run) for run in dd),
    }


def cases(n: int, duration: int, seed: int) -> dict[str, Callable[[], object]]:
    """The cases' inputs, each drawn when called."""
    from bayes_fdi.actuator import benchmark_inputs
    from bayes_fdi.actuator.excitation import OperatingRange, sine_sum_inputs
    from bayes_fdi.actuator.excitation_signals import chirp_inputs

    def drop(low: float, high: float) -> OperatingRange:
        return OperatingRange(dp=(low * 1e6, high * 1e6))

    def chirp(**kw):
        return lambda: chirp_inputs(n, duration, seed=seed, **kw)

    settings = training_sine_sum()

    def sines(**kw):
        return lambda: sine_sum_inputs(n, duration, seed=seed, **{**settings, **kw})

    return {
        "chirp": chirp(),
        "chirp, P1 still": chirp(p1_amplitude=(0.0, 0.0)),
        "chirp, P1 sine at 0.1 Hz": chirp(p1_frequency=0.1),
        "chirp, drop 0.3-0.5 MPa": chirp(operating=drop(0.3, 0.5)),
        "chirp, drop 0.5-0.8 MPa": chirp(operating=drop(0.5, 0.8)),
        "chirp, drop 0.8-1.2 MPa": chirp(operating=drop(0.8, 1.2)),
        "sums of sines, P1 still": sines(p1_amplitude=(0.0, 0.0)),
        "sums of sines, P1 0-200 kPa": sines(),
        "sums of sines, P1 0-200 kPa, drop 0.3-0.5 MPa": sines(operating=drop(0.3, 0.5)),
        "DGen sines": lambda: benchmark_inputs(n, duration, seed=seed, vary=True),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", help="a model file (default: the cached default model)")
    parser.add_argument("--runs", type=int, default=6)
    parser.add_argument("--duration", type=int, default=1800)
    parser.add_argument("--seed", type=int, default=905)
    args = parser.parse_args(argv)
    from bayes_fdi.actuator import simulate
    from bayes_fdi.deployment.fitting import default_model, load_online_model

    model = load_online_model(args.model) if args.model else default_model(progress=False)
    hours = args.runs * (args.duration - START_UP) / 3600
    print(
        f"detector threshold {model.threshold_:.2f}; {args.runs} runs x {args.duration} s per case"
    )
    print(f"| case | innovations' RMS X / F | DD on | alarms in {hours:.1f} h |")
    print("|---|---|---|---|")
    for name, inputs in cases(args.runs, args.duration, args.seed).items():
        out = model.run(simulate(inputs(), seed=args.seed)).isel(time=slice(START_UP, None))
        f = stream_figures(out["r_X"].values, out["r_F"].values, out["DD"].values)
        print(
            f"| {name} | {f['rms_X']:.2f} / {f['rms_F']:.2f} | {100 * f['dd_share']:.1f} % "
            f"| {f['alarms']} |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())

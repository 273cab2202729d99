"""How soon an ideal detector on an online diagnoser's whitened innovations could see each fault.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/innovation_oracle.py [--model FILE] \
        [--seeds 31000,31001,31002,31003] [--size big]

Each abrupt Step-I scenario of the size given is simulated with and without its fault (the
same DGen inputs and the same noise, `bayes_fdi.actuator.simulate.simulate_replicas`) and both
runs go through the diagnoser (``--model``, or the default model). The difference of their
whitened innovations is the fault's effect alone; in units of the innovations' standard
deviation before the fault, `bayes_fdi.benchmark.cases.innovation_effect` sums its squares
into the separation a matched filter that knew the effect exactly would reach. The *oracle
time* is the first second after the onset at which that separation reaches
`bayes_fdi.benchmark.report.DETECTABLE_DEFLECTION` (5: one false alarm in 8 h of decisions and
a detection with 84 % probability): no detector that sees the valve through these innovations
can detect the fault sooner at that false-alarm rate. Printed per scenario and seed with the
separation 10 s and 60 s after the onset. The default seeds are apart from the benchmark's.
"""

from __future__ import annotations

import argparse

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", help="a model file (default: the cached default model)")
    parser.add_argument("--seeds", default="31000,31001,31002,31003")
    parser.add_argument("--size", default="big", choices=("small", "medium", "big"))
    args = parser.parse_args()
    from bayes_fdi.actuator import benchmark_inputs
    from bayes_fdi.actuator.simulate import simulate_replicas
    from bayes_fdi.benchmark.cases import innovation_effect, innovation_noise, zeroed
    from bayes_fdi.benchmark.scenarios import SCENARIOS
    from bayes_fdi.datasets import CHANNELS
    from bayes_fdi.deployment.fitting import default_model, load_online_model

    diagnoser = load_online_model(args.model) if args.model else default_model(progress=False)
    seeds = [int(s) for s in args.seeds.split(",")]
    for position, scenario in enumerate(SCENARIOS):
        if scenario.mode != "abrupt" or scenario.size != args.size:
            continue
        inputs = benchmark_inputs(
            n_runs=1, duration=round(scenario.t_hor), vary=False, campaign="damadics-step1"
        ).assign_coords(run=[position])
        faulty = simulate_replicas(inputs, [scenario.fault_spec()], seeds=seeds)
        healthy = simulate_replicas(inputs, [None], seeds=seeds)
        times, at10, at60 = [], [], []
        for with_fault, without in zip(faulty, healthy, strict=True):
            one = zeroed(diagnoser.run(with_fault[list(CHANNELS)]).isel(run=0))
            clean = zeroed(diagnoser.run(without[list(CHANNELS)]).isel(run=0))
            t = np.asarray(clean["time"].values)
            noise = innovation_noise(clean.isel(time=(t >= scenario.t_on) & (t < scenario.t_from)))

            # innovation_effect over the whole faulty part, and over its first 10 and 60 s
            whole, first10, first60 = (
                innovation_effect(
                    one.isel(time=keep), clean.isel(time=keep), t_from=scenario.t_from,
                    noise=noise,
                )
                for keep in (t < scenario.t_from + s for s in (np.inf, 10, 60))
            )  # fmt: skip
            times.append(whole["oracle_time"])
            at10.append(f"{first10['deflection']:.1f}")
            at60.append(f"{first60['deflection']:.1f}")
        shown = ["never" if v is None else f"{v:.0f} s" for v in times]
        print(
            f"{scenario.name}: oracle time {', '.join(shown)}; separation 10 s after the onset "
            f"{', '.join(at10)}, 60 s after {', '.join(at60)}",
            flush=True,
        )


if __name__ == "__main__":
    main()

"""An online diagnoser fitted on simulations only, on the shipped real hour, without commissioning.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/default_on_real_hour.py [--model FILE] \
        [--strength 0.75] [--onset 300]

The diagnoser (``--model``, or the default model: `bayes_fdi.deployment.fitting.default_model`,
fitted and cached on first use) runs over the whole real Lublin hour as recorded (alarms, the
SEVA statuses), then over its second half with each of the DAMADICS faults below transplanted
into it (`bayes_fdi.twin.transplant` with the actuator's nominal parameters, not a twin of this
valve; strength ``--strength`` with the benchmark's direction, from ``--onset`` s into the
half). Per fault: the share of the seconds before the onset with DD on, the share after it, the
seconds to the first detection, whether DD stayed on from then to the end, the two states named
most often over the detected seconds, and the seconds after the onset that named another known
group at a probability above 0.9 (confident wrong). The faults are those of the benchmark's big
abrupt scenarios (`bayes_fdi.benchmark.scenarios.SCENARIOS`).
"""

from __future__ import annotations

import argparse
import collections

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", help="a model file (default: the cached default model)")
    parser.add_argument("--strength", type=float, default=0.75)
    parser.add_argument("--onset", type=float, default=300.0)
    args = parser.parse_args()
    from bayes_fdi.actuator import Fault
    from bayes_fdi.actuator.parameters import NOMINAL
    from bayes_fdi.benchmark.scenarios import SCENARIOS
    from bayes_fdi.campaigns.spec import FAULT_DIRECTION
    from bayes_fdi.datasets import load_lublin_example
    from bayes_fdi.deployment.fitting import default_model, load_online_model
    from bayes_fdi.twin import transplant

    diagnoser = load_online_model(args.model) if args.model else default_model(progress=False)
    hour = load_lublin_example()
    stream = diagnoser.run(hour)
    dd = stream["DD"].values[0]
    edges = int(dd[0]) + int(np.sum(dd[1:] & ~dd[:-1]))
    status = collections.Counter(str(s) for s in stream["status"].values[0])
    print(f"whole hour as recorded: {edges} alarm(s), DD on {dd.mean():.1%}; {dict(status)}")
    second = hour.isel(time=slice(1800, None))
    onset = int(args.onset)
    faults = [s.fault for s in SCENARIOS if s.mode == "abrupt" and s.size == "big"]
    groups = ["|".join(g) for g in diagnoser.groups_]
    for name in faults:
        fault = Fault(name, args.strength * FAULT_DIRECTION[name], onset=args.onset)
        stream = diagnoser.run(transplant(second, [fault], NOMINAL))
        dd = stream["DD"].values[0].astype(bool)
        after = dd[onset:]
        first = int(np.argmax(after)) if after.any() else None
        kept = bool(after[first:].all()) if first is not None else False
        state = np.asarray(stream["state"].values[0][onset:]).astype(str)
        named = collections.Counter(str(s) for s in state[after])
        # a known group other than the fault's own, at p > 0.9 (unknown, mismatch: not named)
        truth = next((g for g in groups if name in g.split("|")), None)
        wrong = np.isin(state, list(groups)) & (state != truth)
        confident = int(np.sum(wrong & (stream["probability"].values[0][onset:] > 0.9)))
        print(
            f"{name}: DD before {dd[:onset].mean():.1%}, after {after.mean():.1%}; first "
            f"detection {'none' if first is None else f'{first} s'}, kept on {kept}; named "
            f"{named.most_common(2)}; confident (p > 0.9) wrong {confident} s"
        )


if __name__ == "__main__":
    main()

"""What naming a group only when it is more likely than not would change (the default model).

A detected second whose most probable isolability group has a probability below 0.5 is more
likely wrong than right. This script measures what answering "unknown" there would change: the
default model (`bayes_fdi.deployment.fitting.default_model`, from the model cache) runs every
Step-I scenario under noise seeds 70 000 and 70 001, which no fit or evaluation uses, and for
each threshold the faulty seconds named by a group are counted as right (the scenario's fault's
group) or wrong (another group, or any group for a fault in DGN0), keeping only the seconds whose
named group's probability reaches the threshold (`tally`). Per scenario, the shares of its faulty
seconds named right and wrong at thresholds 0 (as shipped) and 0.5. About 2 CPU min.

Run: ``OMP_NUM_THREADS=1 PYTHONPATH=. python benchmarks/naming_threshold.py``
"""

from __future__ import annotations

import sys
from collections.abc import Iterable, Sequence

import numpy as np

from bayes_fdi.diagnosis.online.stream import UNNAMED_STATES

#: Noise seeds of the scenarios: apart from the training campaigns (< 1000), the DAMADICS
#: benchmark (10 000 +), its fault-free hours (20 000 +), the plants (30 000 - 59 999) and the
#: commissioned envelope's runs (90 000 +).
SEEDS = (70_000, 70_001)


def tally(
    rows: Iterable[tuple[str, str, np.ndarray, np.ndarray]], threshold: float
) -> dict[str, list[int]]:
    """Per scenario: ``[right, wrong, seconds]``, counting the seconds named by a group whose
    probability reaches ``threshold``. ``rows``: ``(scenario, true group, states,
    probabilities)`` of the faulty seconds of one run each."""
    out: dict[str, list[int]] = {}
    for name, true, states, probability in rows:
        states = np.asarray(states).astype(str)
        named = ~np.isin(states, UNNAMED_STATES) & (np.nan_to_num(probability) >= threshold)
        entry = out.setdefault(name, [0, 0, 0])
        entry[0] += int(np.sum(named & (states == true)))
        entry[1] += int(np.sum(named & (states != true)))
        entry[2] += states.size
    return out


def _rows(seeds: Sequence[int]) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
    from bayes_fdi.benchmark.scenarios import SCENARIOS, simulate_scenario
    from bayes_fdi.datasets import CHANNELS
    from bayes_fdi.deployment.fitting import default_model

    diagnoser = default_model(progress=False)
    group_of = {f: g for g in diagnoser.isolator_.group_labels_ for f in g.split("|")}
    rows = []
    for scenario in SCENARIOS:
        stream = diagnoser.run(simulate_scenario(scenario, list(seeds))[list(CHANNELS)])
        faulty = stream.time.values >= scenario.t_from
        for r in range(len(seeds)):
            one = stream.isel(run=r)
            rows.append((
                scenario.name,
                group_of.get(scenario.fault, "DGN0"),
                np.asarray(one.state.values)[faulty],
                np.asarray(one.probability.values, dtype=np.float64)[faulty],
            ))  # fmt: skip
    return rows


def main() -> int:
    rows = _rows(SEEDS)
    tallies = {t: tally(rows, t) for t in (0.0, 0.5)}
    for t, per in tallies.items():
        right = sum(v[0] for v in per.values())
        wrong = sum(v[1] for v in per.values())
        print(f"threshold {t:g}: {right} faulty seconds named right, {wrong} wrong")
    print("| scenario | right, wrong (as shipped) | right, wrong (p >= 0.5) |")
    for name, (a, b, n) in tallies[0.0].items():
        a5, b5, _ = tallies[0.5][name]
        print(f"| {name} | {a / n:.2f}, {b / n:.2f} | {a5 / n:.2f}, {b5 / n:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Why a detection drops while the fault persists: the fault's own effect at the drop.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/detection_drops.py [--model FILE] \
        [--family nominal|chirp|flow-loop|telegraph ...] [--seeds 10]

The benchmark counts a big abrupt fault's detection as *kept on* when DD stays high from its
first detection to the end of the scenario. This script runs the big abrupt Step-I scenarios
as the benchmark does (the same inputs, noise seeds and diagnoser: ``--model`` or the default
model; a shift family's inputs drawn as ``bayes-fdi benchmark --shift`` draws them), counts the
runs its permanence target counts (faults whose effect on X or F exceeds the noise, DD off at
the fault's start) and finds those whose DD fell during the fault. At each fall it measures
what the fault itself still showed: the noise-free simulations of the run's inputs with and
without the fault (`bayes_fdi.actuator.simulate` with ``noise=False``, as
`bayes_fdi.benchmark.effects` compares them) go through the diagnoser's normal models, and the
fault's *signature* is the difference of their standardised residuals ``(y - y_hat) /
y_hat_std``, the larger over X and F, in the normal models' own standard deviations: what the
detector can see of the fault without the noise. Per fall: how many seconds before it the
signature had stayed below 1 and below 3, whether that stretch was longer than the
diagnoser's ``hold`` (DD clears only ``hold`` seconds after the last exceedance), and in which
share of the remaining faulty seconds it exceeds 3 again (the same under ``"physical"`` for the
effect on X and F in measurement-noise standard deviations). A fall after the signature stayed
under 1 for longer than the hold is a fault that stopped showing: a rule that clears after
``hold`` seconds without evidence cannot keep it on. Results go to stdout and
``benchmarks/out/detection_drops.json``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: Effect levels (in measurement-noise standard deviations) whose quiet stretches are counted.
LEVELS = (1.0, 3.0)
#: Where the results are written.
OUT = ROOT / "benchmarks" / "out" / "detection_drops.json"


def quiet_before(effect: np.ndarray, end: int, level: float) -> int:
    """Seconds before index ``end`` (exclusive) during which ``effect`` ``(n,)`` stayed below
    ``level``."""
    above = np.flatnonzero(effect[:end] >= level)
    return int(end - (above[-1] + 1)) if above.size else int(end)


def falls(dd: np.ndarray, start: int) -> np.ndarray:
    """Indices at or after ``start`` at which ``dd`` falls (high the second before, low now),
    after its first high second at or after ``start``."""
    d = np.asarray(dd, dtype=bool)
    high = np.flatnonzero(d[start:])
    if not high.size:
        return np.zeros(0, dtype=np.int64)
    first = start + int(high[0])
    idx = np.flatnonzero(~d[first + 1 :] & d[first:-1]) + first + 1
    return idx.astype(np.int64)


def analyse_run(dd: np.ndarray, effect: np.ndarray, t_from: int, hold: int) -> dict | None:
    """The drops of one run: None if DD never rose in the faulty part; else its first
    detection, whether it was kept on, and each fall's quiet stretches and the effect after.

    ``effect`` ``(n,)``: the larger of the fault's noise-free effects on X and F (in noise
    standard deviations) each second; ``dd`` ``(n,)`` the stream's DD."""
    faulty_dd = np.asarray(dd[t_from:], dtype=bool)
    if not faulty_dd.any():
        return None
    out = []
    for f in falls(dd, t_from):
        rest = effect[f:]
        out.append(
            {
                "fall": int(f - t_from),
                **{f"quiet_{lvl:g}sigma": quiet_before(effect, f, lvl) for lvl in LEVELS},
                "longer_than_hold": quiet_before(effect, f, LEVELS[0]) > hold,
                "effect_above_3sigma_after": float(np.mean(rest >= 3.0)) if rest.size else 0.0,
            }
        )
    return {
        "first_detection": int(np.flatnonzero(faulty_dd)[0]),
        "kept_on": not out,
        "falls": out,
    }


def shift_inputs(family: str, seeds):
    """The shift family's inputs as `bayes-fdi benchmark --shift` draws them (as long as the
    longest of the 44 scenarios: the draw depends on its length)."""
    from bayes_fdi.benchmark.scenarios import SCENARIOS
    from bayes_fdi.benchmark.shift import ShiftInputs, shift_families

    fam = {f.name: f for f in shift_families()}[family]
    return ShiftInputs(fam, seeds, round(max(s.t_hor for s in SCENARIOS)))


def _runs(scenarios, seeds, shift):
    """``(scenario, noisy runs, inputs)`` for each scenario: under DGen's sines (``shift``
    None; one run of inputs, the same for every seed) or a shift family's `ShiftInputs`."""
    from bayes_fdi.benchmark.scenarios import scenario_inputs, simulate_scenario

    for s in scenarios:
        if shift is None:
            yield s, simulate_scenario(s, seeds), scenario_inputs(s)
        else:
            drive = shift.inputs.sel(run=list(seeds)).isel(time=slice(0, round(s.t_hor)))
            yield s, shift.simulate(s, seeds), drive


def residual_signature(diagnoser, clean, faulty) -> np.ndarray:
    """``(runs, n)``: the fault's signature in the standardised residuals, the larger over X
    and F of ``|z_faulty - z_clean|``, where ``z = (y - y_hat) / y_hat_std`` is what the
    diagnoser's normal models make of noise-free runs with and without the fault: what its
    detector can see of the fault, in the normal models' own standard deviations."""
    z = []
    for runs in (clean, faulty):
        stream = diagnoser.run(runs)
        z.append(
            np.stack(
                [
                    (runs[c].transpose("run", "time").values - stream[f"{c}_hat"].values)
                    / stream[f"{c}_hat_std"].values
                    for c in ("X", "F")
                ]
            )
        )
    return np.nan_to_num(np.max(np.abs(z[1] - z[0]), axis=0))


def above_noise(scenarios, shift) -> dict[str, bool]:
    """Whether each scenario's fault moves X or F by more than the noise (RMS > 1 sigma over
    the faulty part, `bayes_fdi.benchmark.effects.fault_effects` under the first seed's inputs
    of ``shift``, or DGen's sines for None): the faults the benchmark's detection targets
    count, as its report does."""
    from bayes_fdi.benchmark.effects import fault_effects

    effects = fault_effects(scenarios, None if shift is None else shift.effects_inputs)
    return {e["scenario"]: max(e["rms"]["X"], e["rms"]["F"]) > 1.0 for e in effects}


def measure(diagnoser, family: str, scenarios, seeds) -> list[dict]:
    """One row per run of ``scenarios`` under ``family`` with ``seeds``: `analyse_run`'s on
    the fault's signature in the standardised residuals (`residual_signature`) and, under
    ``"physical"``, on its effect on X and F in measurement-noise standard deviations."""
    from bayes_fdi.actuator import NOISE_STD, simulate
    from bayes_fdi.benchmark.scenarios import strip_truth
    from bayes_fdi.scoring.decision_signals import decision_high

    hold = int(diagnoser.decision_.hold)
    shift = None if family == "nominal" else shift_inputs(family, seeds)
    above = above_noise(scenarios, shift)
    rows = []
    for s, runs, drive in _runs(scenarios, seeds, shift):
        stream = diagnoser.run(strip_truth(runs))
        inputs = drive[["CV", "P1", "P2", "T1"]]
        n = inputs.sizes["run"]  # one run of inputs under DGen's sines, one per seed otherwise
        clean = simulate(inputs, [None] * n, noise=False)
        faulty = simulate(inputs, [s.fault_spec()] * n, noise=False)
        signature = residual_signature(diagnoser, clean, faulty)
        physical = np.max(
            [np.abs(faulty[c].values - clean[c].values) / NOISE_STD for c in ("X", "F")], axis=0
        )
        for i, seed in enumerate(seeds):
            dd = decision_high(stream["DD"].isel(run=i).values)
            res = analyse_run(dd, signature[i % n], int(s.t_from), hold)
            if res is not None:
                phys = analyse_run(dd, physical[i % n], int(s.t_from), hold)
                counted = above[s.name] and not dd[int(s.t_from) - 1]
                rows.append(
                    {"scenario": s.name, "seed": int(seed), "counted": bool(counted), **res,
                     "physical": phys}
                )  # fmt: skip
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default=None)
    parser.add_argument(
        "--family", nargs="+", default=["nominal", "chirp", "flow-loop", "telegraph"]
    )
    parser.add_argument("--seeds", type=int, default=10)
    args = parser.parse_args()
    from bayes_fdi.benchmark.scenarios import SCENARIOS, benchmark_seeds
    from bayes_fdi.deployment.fitting import default_model, load_online_model
    from bayes_fdi.reporting import write_json

    diagnoser = load_online_model(args.model) if args.model else default_model(progress=True)
    seeds = benchmark_seeds(args.seeds)
    big = [s for s in SCENARIOS if s.mode == "abrupt" and s.size == "big"]
    result = {"hold": int(diagnoser.decision_.hold), "families": {}}
    t0 = time.process_time()
    for family in args.family:
        rows = measure(diagnoser, family, big, seeds)
        counted = [r for r in rows if r["counted"]]
        dropped = [r for r in counted if not r["kept_on"]]
        gone = [r for r in dropped if r["falls"][0]["longer_than_hold"]]
        kept = len(counted) - len(dropped)
        summary = {
            "counted_runs": len(counted),
            "kept_on": kept,
            "dropped": len(dropped),
            "dropped_after_the_signature_faded": len(gone),
            "at_most_kept_by_a_rule_that_needs_evidence": len(counted) - len(gone),
        }
        result["families"][family] = {"summary": summary, "runs": rows}
        print(
            f"{family}: {len(counted)} counted runs (big abrupt faults above the noise, DD off "
            f"before the fault), {kept} kept on, {len(dropped)} dropped; in {len(gone)} of those "
            f"the fault's signature had stayed under 1 sigma for longer than the hold "
            f"({result['hold']} s) before DD fell, so at most {len(counted) - len(gone)} "
            f"({(len(counted) - len(gone)) / max(len(counted), 1):.1%}) can be kept on by a "
            "rule that needs evidence"
        )
        for r in dropped:
            f = r["falls"][0]
            print(
                f"  {r['scenario']} seed {r['seed']}: detected at {r['first_detection']} s, fell "
                f"at {f['fall']} s ({len(r['falls'])} falls); signature < 1 sigma for "
                f"{f['quiet_1sigma']} s, < 3 sigma for {f['quiet_3sigma']} s before it; "
                f"> 3 sigma in {f['effect_above_3sigma_after']:.0%} of the seconds after"
            )
    print(f"{time.process_time() - t0:.0f} CPU s")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    write_json(result, OUT)


if __name__ == "__main__":
    main()

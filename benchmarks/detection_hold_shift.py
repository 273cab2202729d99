"""The detection decision's hold under a shifted excitation: hold 0 against `CLEAR_HOLD`.

The default online diagnoser (the quick one unless a second argument is given; the first names
the JSON written) is fitted on its training campaigns (control value: a 0.01 Hz sine) and run
on the actuator driven by a control value sine of 0.005, 0.01 and 0.02 Hz: faults f13, f18,
f19 (abrupt, strengths 0.5 and 0.75, the benchmark's directions) from 900 s to 1500 s, six
runs each (simulation seed 30 000: neither a training nor a benchmark seed), and 2 fault-free
hours per frequency (seed 30 001). Per hold: PICalc's t_dt (last rising edge), the first
detection, the runs whose DD stayed on, and the fault-free hours' alarms and share of time
with DD on.

Usage (repository root)::

    export OMP_NUM_THREADS=1 PYTHONPATH=$PWD
    .venv/bin/python benchmarks/detection_hold_shift.py quick.json
    .venv/bin/python benchmarks/detection_hold_shift.py default.json full
"""

import json
import sys

import numpy as np

from bayes_fdi.actuator import Fault, benchmark_inputs, simulate
from bayes_fdi.datasets import CHANNELS
from bayes_fdi.default_diagnoser import fit_online_diagnoser
from bayes_fdi.diagnosis.detection.decision import CLEAR_HOLD, DetectionDecision
from bayes_fdi.scoring.decision_signals import decision_high, rising_edges
from bayes_fdi.scoring.picalc import first_detection, picalc

diag = fit_online_diagnoser(seed=0, small=len(sys.argv) < 3, progress=False)
base = diag.decision_
SEEDS = 6
faults = [("f13", 1, 0.5), ("f13", 1, 0.75), ("f18", 1, 0.5), ("f18", 1, 0.75),
          ("f19", -1, 0.5), ("f19", -1, 0.75)]  # fmt: skip
out = {}
for freq in (0.005, 0.01, 0.02):
    specs = [Fault(f, d * s, 900.0) for f, d, s in faults for _ in range(SEEDS)]
    inputs = benchmark_inputs(len(specs), 1500, seed=7, vary=False, cv_frequency=freq)
    runs = simulate(inputs, specs, seed=30_000)
    normal = simulate(benchmark_inputs(1, 7500, seed=8, vary=False, cv_frequency=freq), seed=30_001)
    for hold in (0, CLEAR_HOLD):
        diag.decision_ = DetectionDecision(base.threshold, base.clear, 2, hold)
        diag.reset()
        stream = diag.run(runs[list(CHANNELS)].reset_coords(drop=True))
        t = stream["time"].values
        rows = {}
        for r, spec in enumerate(specs):
            dd = decision_high(stream["DD"].values[r])
            z = np.zeros_like(t)
            last = picalc(t, dd, dd, z, t_on=300, t_from=900, t_hor=1500)["t_dt"]
            first = first_detection(t, dd, t_on=300, t_from=900, t_hor=1500)
            rows.setdefault(f"{spec.name} {abs(spec.strength)}", []).append(
                (last, first["t_dt_first"], first["dd_permanent"])
            )
        ff = diag.run(normal[list(CHANNELS)].reset_coords(drop=True)).isel(run=0)
        dd = decision_high(ff["DD"].values)[ff["time"].values >= 300]
        out[f"{freq} {hold}"] = {
            "fault_free_2h": {"alarms": rising_edges(dd), "dd_on": float(dd.mean())},
            "faults": {
                k: {
                    "t_dt_last": [x[0] for x in v],
                    "t_dt_first": [x[1] for x in v],
                    "kept": int(sum(x[2] == 1.0 for x in v)),
                    "detected": int(sum(x[1] != -1.0 for x in v)),
                }
                for k, v in rows.items()
            },
        }
        o = out[f"{freq} {hold}"]
        print(f"CV {freq} Hz, hold {hold}: fault-free 2 h {o['fault_free_2h']}")
        for k, v in o["faults"].items():
            print(
                f"   {k:10s} kept {v['kept']}/{v['detected']} t_dt median "
                f"{np.median(v['t_dt_last']):.0f} {v['t_dt_last']} first median "
                f"{np.median(v['t_dt_first']):.0f}"
            )
        sys.stdout.flush()
json.dump(out, open(sys.argv[1], "w"), indent=1)

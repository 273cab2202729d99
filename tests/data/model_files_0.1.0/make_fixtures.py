"""Writes the model files of this folder with bayes_fdi 0.1.0 (run once, at that release).

Each fixture is a model file as 0.1.0 saved it, beside the output it gave on a fixed recording
(``*.expected.nc``): the loading test checks that today's bayes_fdi reads the file and gives
the same output. Run from the repository root:
``python tests/data/model_files_0.1.0/make_fixtures.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bayes_fdi.actuator import Fault, benchmark_inputs, simulate
from bayes_fdi.datasets import make_dataset

HERE = Path(__file__).parent


def online_recording():
    specs = [None, Fault("f1", 0.6, 100.0), Fault("f18", 0.7, 120.0)]
    return simulate(benchmark_inputs(3, 240, seed=3, vary=True), specs, seed=3)


def offline_runs(rng, states, n_per, T=80):
    sts = [s for s in states for _ in range(n_per)]
    n = len(sts)
    t = np.arange(T)
    phase = rng.uniform(0, 2 * np.pi, (n, 1))
    cv = 0.5 + 0.3 * np.sin(2 * np.pi * t / 40 + phase)
    p1 = 0.8 + 0.01 * rng.standard_normal((n, T))
    p2 = 0.6 + 0.01 * rng.standard_normal((n, T))
    t1 = 0.3 + 0.001 * rng.standard_normal((n, T))
    x = 0.9 * cv + 0.005 * rng.standard_normal((n, T))
    f = 0.7 * (1 - 0.8 * x) * np.sqrt(p1 - p2) + 0.005 * rng.standard_normal((n, T))
    offsets = {"fn": (0, 0), "f1": (0.04, 0), "f2": (0, -0.04), "f3": (0.03, 0.03)}
    for i, s in enumerate(sts):
        x[i] += offsets[s][0]
        f[i] += offsets[s][1]
    return make_dataset(dict(CV=cv, P1=p1, P2=p2, T1=t1, X=x, F=f), state=sts, campaign="fixture")


def main() -> None:
    # the module paths of bayes_fdi 0.1.0
    from bayes_fdi.diagnosis.diagnoser import FaultDiagnoser
    from bayes_fdi.diagnosis.dynamic_models import DynamicNormalModels

    from bayes_fdi.calibration import TemperatureScaler
    from bayes_fdi.diagnosis import OnlineDiagnoser, svm_fault_diagnoser
    from bayes_fdi.rvm import RVR

    # the online diagnoser, with isolation and a temperature calibrator, mid-stream
    normal = simulate(benchmark_inputs(3, 300, seed=1, vary=True), seed=1)
    specs = [Fault(f, s, 80.0) for f in ("f1", "f18") for s in (0.5, 0.7, 0.9, 1.0, 0.6)]
    faults = simulate(benchmark_inputs(len(specs), 240, seed=2, vary=True), specs, seed=2)
    models = DynamicNormalModels(
        x_widths=(8.0,),
        f_widths=(0.1,),
        evidence_max_samples=150,
        max_train_samples=200,
        calibration_folds=2,
        random_state=0,
    )
    diag = OnlineDiagnoser(models, calibrator=TemperatureScaler(), max_signatures_per_fault=12)
    diag.fit(normal, faults)
    rec = online_recording()
    for t in range(30):  # a stream in progress: the file carries its state
        diag.update({c: float(rec[c].values[1, t]) for c in ("CV", "P1", "P2", "T1", "X", "F")})
    diag.save(HERE / "online.npz")
    diag.run(rec).to_netcdf(HERE / "online.expected.nc")

    rng = np.random.default_rng(7)
    normal_runs = offline_runs(rng, ["fn"], 3)
    labelled = offline_runs(rng, ["fn", "f1", "f2", "f3"], 5)
    test = offline_runs(rng, ["fn", "f1", "f2", "f3"], 2)
    test.to_netcdf(HERE / "offline.recording.nc")
    rvm = FaultDiagnoser(RVR(kernel="rbf", width=0.3), max_train_samples=120, input_lags=(2.0,))
    rvm.fit(normal_runs, labelled)
    rvm.save(HERE / "offline-rvm.npz")
    rvm.diagnose(test).to_netcdf(HERE / "offline-rvm.expected.nc")
    svm = svm_fault_diagnoser(max_train_samples=120).fit(normal_runs, labelled)
    svm.save(HERE / "offline-svm.npz")
    svm.diagnose(test).to_netcdf(HERE / "offline-svm.expected.nc")


if __name__ == "__main__":
    main()

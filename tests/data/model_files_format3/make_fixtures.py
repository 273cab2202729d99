"""Writes the model file of this folder with a bayes_fdi of model-file format 3 (run once).

The fixture is an online diagnoser saved mid-stream in format 3 (before the input envelope
checked the inputs' rates), beside the stream it gave on a fixed recording
(``online.expected.nc``, the decisions and predictions): the loading test checks that today's
bayes_fdi reads the file and gives the same stream. Run from the repository root:
``python tests/data/model_files_format3/make_fixtures.py``.
"""

from __future__ import annotations

from pathlib import Path

from bayes_fdi.actuator import Fault, benchmark_inputs, simulate

HERE = Path(__file__).parent
#: The stream's variables kept in the expected output.
KEPT = ("DD", "state", "status", "probability", "X_hat", "F_hat", "X_hat_std", "F_hat_std")


def online_recording():
    specs = [None, Fault("f1", 0.6, 100.0), Fault("f18", 0.7, 120.0)]
    return simulate(benchmark_inputs(3, 240, seed=3, vary=True), specs, seed=3)


def main() -> None:
    from bayes_fdi import model_files
    from bayes_fdi.calibration import TemperatureScaler
    from bayes_fdi.diagnosis import OnlineDiagnoser
    from bayes_fdi.diagnosis.normal_models.dynamic import DynamicNormalModels

    assert model_files.FORMAT_VERSION == 3
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
    stream = diag.run(rec)[list(KEPT)]
    stream.attrs = {}
    stream.to_netcdf(HERE / "online.expected.nc")


if __name__ == "__main__":
    main()

"""Coverage of the normal models' predictive intervals with and without interval calibration.

Usage (repository root, after ``bayes-fdi reproduce`` has cached the campaigns)::

    OMP_NUM_THREADS=1 PYTHONPATH=$PWD python benchmarks/normal_model_coverage.py paper-simulated
    OMP_NUM_THREADS=1 PYTHONPATH=$PWD python benchmarks/normal_model_coverage.py paper-lublin
    OMP_NUM_THREADS=1 PYTHONPATH=$PWD python benchmarks/normal_model_coverage.py hour

``paper-*``: the paper protocol's fault-free runs (first 20 fit, the rest scored), from the
netCDF cache (``--cache-dir``, default ``.cache/datasets``); ``hour``: the real Lublin hour,
fitted on its first half and scored on its second. ``--width reproduce`` uses the width of
:func:`bayes_fdi.paper.setup.select_regression_width` instead of ``NormalModels``'
default search.
Prints coverage at 50/80/90/95 % and mean widths for raw RVR stds, one calibration factor and
the default (five ``|dCV/dt|`` bins).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from bayes_fdi.calibration.summaries import normal_model_summary, split_in_time
from bayes_fdi.campaigns.cache import split_train_test
from bayes_fdi.datasets import load_dataset, load_lublin_example
from bayes_fdi.diagnosis import NormalModels
from bayes_fdi.paper.setup import N_TRAIN, PAPER_STATES, select_regression_width
from bayes_fdi.rvm import RVR

CONFIGS = {
    "raw": {"interval_calibration": None},
    "one factor": {"calibration_bins": 1},
    "default": {},
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", choices=("paper-simulated", "paper-lublin", "hour"))
    parser.add_argument("--width", choices=("default", "reproduce"), default="default")
    parser.add_argument("--cache-dir", default=".cache/datasets")
    args = parser.parse_args()
    if args.data == "hour":
        fit_runs, test_runs = split_in_time(load_lublin_example(), 0.5)
    else:
        files = sorted(Path(args.cache_dir).glob(f"{args.data}-*.nc"))
        if not files:
            raise SystemExit(f"no cached {args.data} in {args.cache_dir}: run bayes-fdi reproduce")
        train, test = split_train_test(load_dataset(files[0]), n_train=N_TRAIN, states=PAPER_STATES)
        fit_runs = train.isel(run=np.flatnonzero(train["state"].values.astype(str) == "fn"))
        test_runs = test.isel(run=np.flatnonzero(test["state"].values.astype(str) == "fn"))
    regressor = None
    if args.width == "reproduce":
        width, _ = select_regression_width(fit_runs, seed=0)
        regressor = RVR(kernel="rbf", width=width)
    print(
        f"{args.data}, width {args.width}: fit {dict(fit_runs.sizes)}, test {dict(test_runs.sizes)}"
    )
    for label, kw in CONFIGS.items():
        t0 = time.perf_counter()
        model = NormalModels(regressor, random_state=0, **kw).fit(fit_runs)
        seconds = time.perf_counter() - t0
        summary = normal_model_summary(model.predict(test_runs), test_runs)
        for name in ("X", "F"):
            cov = summary[name]["coverage"]
            levels = sorted(cov, key=lambda k: cov[k]["nominal"])
            pct = " ".join(f"{100 * cov[k]['coverage']:5.1f}" for k in levels)
            width = " ".join(f"{cov[k]['mean_width']:.4f}" for k in levels)
            print(f"{label:10s} {name} coverage 50/80/90/95 % {pct} | mean width {width}")
        widths = model.widths_ or getattr(regressor, "width", None)
        print(f"{'':10s} fit {seconds:.1f} s; widths {widths}")


if __name__ == "__main__":
    main()

"""The twin on the real Lublin hour (slow): fit on the first half, check on the second; the same
numbers on other BLAS code paths and thread counts; a diagnoser trained on transplanted faults."""

from __future__ import annotations

import numpy as np
import pytest
from blas_paths import EVERYTHING_ELSE, REFERENCE, run_python

from bayes_fdi.datasets import load_lublin_example
from bayes_fdi.twin import ActuatorTwin, transplant_library

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def hour():
    return load_lublin_example()


@pytest.fixture(scope="module")
def twin(hour):
    return ActuatorTwin().fit(hour.isel(time=slice(0, 1800)))


def test_the_held_out_half_hour_is_covered_and_fitted_better_than_nominal(twin, hour):
    check = twin.check(hour.isel(time=slice(1800, 3600)), n_draws=200, seed=0)
    for channel in ("X", "F"):
        assert 0.90 <= check.coverage[channel] <= 0.98, check
        assert check.rms[channel] <= check.rms_nominal[channel], check
    assert twin.laplace_.converged


_SCRIPT = """
import hashlib
import numpy as np
from bayes_fdi.datasets import load_lublin_example
from bayes_fdi.twin import ActuatorTwin
hour = load_lublin_example().isel(time=slice(0, 900))
twin = ActuatorTwin(window=450, n_draws=50).fit(hour)
post = twin.inference_data_.posterior
draws = np.stack([post[v].values.ravel() for v in post.data_vars])
print(hashlib.sha256(draws.tobytes()).hexdigest(), twin.laplace_.iterations)
"""


def test_the_same_seed_gives_the_same_posterior_on_other_blas_paths_and_threads():
    outputs = [run_python(_SCRIPT, env).split() for env in (REFERENCE, EVERYTHING_ELSE)]
    assert outputs[0] == outputs[1]


def test_an_online_diagnoser_trains_on_a_transplanted_library(twin, hour):
    from bayes_fdi.diagnosis import OnlineDiagnoser

    library = transplant_library(hour.isel(time=slice(1800, 3600)), twin, duration=600, seed=0)
    diagnoser = OnlineDiagnoser().fit(hour.isel(time=slice(0, 1800)), fault_runs=library)
    assert "bias_X" in diagnoser.detection_rates_
    assert diagnoser.detection_rates_["f1"] == 1.0
    groups = {f for group in diagnoser.groups_ for f in group}
    assert {"f18", "bias_P1"} <= groups
    assert np.isfinite(diagnoser.threshold_)

"""Property-based tests of the recording readers (`bayes_fdi.datasets.readers`).

Arbitrary finite values (with NaN gaps) written to a CSV file at 1 Hz come back exactly, in
the project's format, whatever their magnitude (read with ``check_units=False``: values
implausible in their declared units are refused otherwise, see ``test_bad_inputs_readers.py``).
A short profile in the default run and a seeded long one under the ``fuzz`` marker (also ``slow``).
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, seed, settings
from hypothesis import strategies as st

from bayes_fdi.datasets import CHANNELS
from bayes_fdi.datasets.readers import read_csv

HEALTH = [HealthCheck.too_slow, HealthCheck.function_scoped_fixture]


@st.composite
def recordings(draw: st.DrawFn) -> tuple[int, np.ndarray]:
    start = draw(st.integers(0, 10**6))
    n = draw(st.integers(1, 40))
    value = st.one_of(
        st.floats(-1e300, 1e300, allow_nan=False, allow_subnormal=False), st.just(float("nan"))
    )
    values = np.array(draw(st.lists(value, min_size=n * 6, max_size=n * 6))).reshape(n, 6)
    return start, values


def csv_round_trip(case: tuple, tmp_path_factory: Any) -> None:
    start, values = case
    header = ",".join(["time", *CHANNELS])
    rows = [
        ",".join([str(start + i), *("NaN" if np.isnan(v) else repr(float(v)) for v in row)])
        for i, row in enumerate(values)
    ]
    path = tmp_path_factory.mktemp("csv") / "rec.csv"
    path.write_text("\n".join([header, *rows]) + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # gap warnings are expected
        ds = read_csv(path, check_units=False)
    assert ds.sizes["run"] == 1 and ds.sizes["time"] == len(rows)
    np.testing.assert_array_equal(ds["time"].values, start + np.arange(len(rows)))
    for j, name in enumerate(CHANNELS):
        np.testing.assert_array_equal(ds[name].values[0], values[:, j])  # nothing changed
    assert "state" not in ds.coords  # an unlabelled recording claims no state


def _make(n: int, fuzz: bool):
    @settings(max_examples=n, deadline=None, derandomize=not fuzz, database=None,
              suppress_health_check=HEALTH)  # fmt: skip
    @given(case=recordings())
    def run(case, tmp_path_factory):
        csv_round_trip(case, tmp_path_factory)

    return seed(20261124)(run) if fuzz else run


_default, _fuzz = _make(20, False), _make(1000, True)


def test_csv_round_trip(tmp_path_factory):
    _default(tmp_path_factory=tmp_path_factory)


@pytest.mark.fuzz
@pytest.mark.slow
def test_csv_round_trip_fuzz(tmp_path_factory):
    _fuzz(tmp_path_factory=tmp_path_factory)

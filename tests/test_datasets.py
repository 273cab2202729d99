"""The dataset format: construction, validation and netCDF round trip."""

import numpy as np
import pytest
import xarray as xr

from bayes_fdi.datasets import load_dataset, make_dataset, save_dataset, validate_dataset


def _example(rng):
    shape = (3, 50)
    channels = {c: rng.uniform(0, 1, shape) for c in ("CV", "P1", "P2", "T1", "X", "F")}
    return make_dataset(
        channels,
        state=["fn", "f1", "f17"],
        strength=[0.0, 0.5, -0.75],
        onset=[0.0, 10.0, 20.0],
        profile=["abrupt", "abrupt", "incipient"],
        ramp=[0.0, 0.0, 30.0],
        campaign="unit",
        seed=7,
    )


def test_make_dataset_shapes_and_labels(rng):
    ds = _example(rng)
    assert ds.sizes == {"run": 3, "time": 50}
    assert list(ds["state"].values) == ["fn", "f1", "f17"]
    assert ds.attrs["campaign"] == "unit" and ds.attrs["seed"] == 7
    np.testing.assert_array_equal(ds["time"].values, np.arange(50.0))


def test_netcdf_round_trip_is_exact(rng, tmp_path):
    ds = _example(rng)
    save_dataset(ds, tmp_path / "d.nc")
    back = load_dataset(tmp_path / "d.nc")
    xr.testing.assert_identical(ds, back)


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda ds: ds.assign(X=ds["X"].where(ds["X"] > 0.5)), "NaN"),
        (lambda ds: ds.rename({"X": "Y"}), "unknown channel"),
        (lambda ds: ds.drop_vars("CV"), "lacks channel"),
        (lambda ds: ds.assign_coords(state=("run", ["fn", "f1", "f42"])), "unknown state"),
    ],
)
def test_validation_names_the_problem(rng, mutate, message):
    with pytest.raises(ValueError, match=message):
        validate_dataset(mutate(_example(rng)))


def test_make_dataset_rejects_mismatched_shapes(rng):
    with pytest.raises(ValueError, match="different shapes"):
        make_dataset({"CV": rng.uniform(size=(2, 5)), "P1": rng.uniform(size=(2, 6))})


def test_load_corrupt_file(tmp_path):
    bad = tmp_path / "bad.nc"
    bad.write_bytes(b"not a netcdf file")
    with pytest.raises(ValueError, match="cannot read dataset"):
        load_dataset(bad)

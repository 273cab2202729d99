"""Catalogue of bad inputs to the Python API: each gets a clear error naming the problem.

Every entry states the call, the error class it must raise and a pattern its message must match
(the problem named in the user's terms). The command line's catalogue is in
``test_bad_inputs_cli.py``; SEVA statuses for bad windows are at the end of this file.
"""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pytest
import torch
import xarray as xr
from sklearn.exceptions import NotFittedError

from bayes_fdi.actuator import Fault, benchmark_inputs, inject_faults, simulate
from bayes_fdi.calibration import intervals, nodes
from bayes_fdi.campaigns.parsing import load_campaign, parse_campaign
from bayes_fdi.campaigns.simulation import simulate_campaign
from bayes_fdi.campaigns.spec import CampaignError
from bayes_fdi.datasets import load_dataset, make_dataset, save_dataset, validate_dataset
from bayes_fdi.datasets.plotting import plot_runs, select_runs
from bayes_fdi.memory import InsufficientMemoryError
from bayes_fdi.rvm import RVC, RVR, load

RNG = np.random.default_rng(20261124)
ONES = np.ones((2, 10))
INPUTS = benchmark_inputs(n_runs=2, duration=20)
CAMPAIGN = {
    "campaign": {
        "name": "c",
        "seed": 1,
        "duration": 60,
        "source": "benchmark-inputs",
        "runs_per_state": 1,
        "states": ["fn", "f1"],
    }
}


class Case(NamedTuple):
    call: Callable[[Path], Any]
    error: type[BaseException]
    match: str


def _inputs_with(**changes: Any) -> xr.Dataset:
    ds = INPUTS.copy(deep=True)
    for name, values in changes.items():
        ds[name] = (("run", "time"), values)
    return ds


def _campaign(**changes: Any) -> dict:
    table = json.loads(json.dumps(CAMPAIGN))
    table["campaign"].update(changes)
    return table


def _fitted_rvr() -> RVR:
    X = np.linspace(-3, 3, 30)[:, None]
    return RVR(width=1.0).fit(X, np.sin(X[:, 0]))


FITTED = _fitted_rvr()


def _saved(tmp: Path, **changes: Any) -> Path:
    """A valid model file with some arrays or metadata fields replaced (``meta_*``)."""
    good = tmp / "good.npz"
    FITTED.save(good)
    with np.load(good, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    meta = json.loads(str(arrays["metadata"]))
    for key, value in changes.items():
        if key.startswith("meta_"):
            meta[key[5:]] = value
        elif key.startswith("model_"):
            meta["models"][0][key[6:]] = value
        else:
            arrays[key] = value
    arrays["metadata"] = np.array(json.dumps(meta))
    out = tmp / "bad.npz"
    np.savez(out, **arrays)
    return out


def _zip_bomb(tmp: Path) -> Path:
    """32 MB of zeros in a deflated archive of 32 kB (read with a 10 MB limit below)."""
    path = tmp / "bomb.npz"
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": "<f8", "fortran_order": False, "shape": (1 << 22,)}
    )
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as z:
        z.writestr("X_fit.npy", header.getvalue() + bytes(1 << 25))
    assert path.stat().st_size < 100_000
    return path


def _object_array_file(tmp: Path) -> Path:
    path = tmp / "obj.npz"
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        buf, {"descr": "|O", "fortran_order": False, "shape": (1,)}
    )
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("metadata.npy", buf.getvalue() + b"\x80\x04N.")
    return path


def _lying_header_file(tmp: Path) -> Path:
    path = tmp / "lie.npz"
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        buf, {"descr": "<f8", "fortran_order": False, "shape": (10**9,)}
    )
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("X_fit.npy", buf.getvalue() + bytes(80))
    return path


def _file(tmp: Path, name: str, content: bytes) -> Path:
    path = tmp / name
    path.write_bytes(content)
    return path


CASES: dict[str, Case] = {
    # ---------------------------------------------------------------- datasets
    "make_dataset: no channel": Case(
        lambda t: make_dataset({}), ValueError, "at least one channel"
    ),
    "make_dataset: unknown channel": Case(
        lambda t: make_dataset({"Q": ONES}), ValueError, r"unknown channel\(s\) \['Q'\]"
    ),
    "make_dataset: complex channel": Case(
        lambda t: make_dataset({"X": ONES * (1 + 1j)}), ValueError, "'X' is complex"
    ),
    "make_dataset: text channel": Case(
        lambda t: make_dataset({"X": np.full((2, 3), "a")}), ValueError, "'X' must hold numbers"
    ),
    "make_dataset: boolean channel": Case(
        lambda t: make_dataset({"X": ONES > 0}), ValueError, "'X' must hold numbers"
    ),
    "make_dataset: 3-D channel": Case(
        lambda t: make_dataset({"X": np.ones((2, 2, 2))}), ValueError, "1-D or 2-D"
    ),
    "make_dataset: shapes differ": Case(
        lambda t: make_dataset({"X": ONES, "F": np.ones((2, 9))}), ValueError, "different shapes"
    ),
    "make_dataset: NaN": Case(
        lambda t: make_dataset({"X": np.full((1, 3), np.nan)}), ValueError, "3 NaN value"
    ),
    "make_dataset: inf": Case(
        lambda t: make_dataset({"X": np.array([[0.0, np.inf]])}), ValueError, "'X' contains inf"
    ),
    "make_dataset: unknown state": Case(
        lambda t: make_dataset({"X": ONES}, state="f42"), ValueError, r"unknown state.*f42"
    ),
    "make_dataset: state not text": Case(
        lambda t: make_dataset({"X": ONES}, state=[1, 2]), ValueError, "state must be text"
    ),
    "make_dataset: strength per run": Case(
        lambda t: make_dataset({"X": ONES}, strength=[0.1, 0.2, 0.3]),
        ValueError,
        r"one entry per run \(2\)",
    ),
    "make_dataset: onset NaN": Case(
        lambda t: make_dataset({"X": ONES}, onset=np.nan), ValueError, "onset must be finite"
    ),
    "make_dataset: onset negative": Case(
        lambda t: make_dataset({"X": ONES}, onset=-1.0), ValueError, "onset must be >= 0"
    ),
    "make_dataset: onset after the run": Case(
        lambda t: make_dataset({"X": ONES}, state="f1", onset=10.0),
        ValueError,
        "onset 10 s is at or after the run's end",
    ),
    "make_dataset: unknown profile": Case(
        lambda t: make_dataset({"X": ONES}, profile="sudden"), ValueError, "unknown profile"
    ),
    "validate_dataset: not a dataset": Case(
        lambda t: validate_dataset(ONES), ValueError, "expected an xarray.Dataset, got ndarray"
    ),
    "validate_dataset: complex channel": Case(
        lambda t: validate_dataset(xr.Dataset({"X": (("run", "time"), ONES * 1j)}), require=()),
        ValueError,
        "'X' is complex",
    ),
    "validate_dataset: missing channel": Case(
        lambda t: validate_dataset(make_dataset({"X": ONES})), ValueError, "lacks channel"
    ),
    "save_dataset: .csv name": Case(
        lambda t: save_dataset(INPUTS, t / "x.csv"), ValueError, r"must end in \.nc"
    ),
    "save_dataset: path is a folder": Case(
        lambda t: save_dataset(INPUTS, t), ValueError, "is a folder"
    ),
    "save_dataset: missing folder": Case(
        lambda t: save_dataset(INPUTS, t / "no" / "x.nc"), ValueError, "does not exist"
    ),
    "load_dataset: missing file": Case(
        lambda t: load_dataset(t / "none.nc"), FileNotFoundError, "does not exist"
    ),
    "load_dataset: folder": Case(lambda t: load_dataset(t), IsADirectoryError, "is a folder"),
    "load_dataset: not netCDF": Case(
        lambda t: load_dataset(_file(t, "g.nc", b"garbage" * 100)),
        ValueError,
        "cannot read dataset",
    ),
    "load_dataset: truncated netCDF": Case(
        lambda t: load_dataset(_file(t, "t.nc", b"\x89HDF\r\n\x1a\n" + bytes(200))),
        ValueError,
        "cannot read dataset",
    ),
    # ---------------------------------------------------------------- actuator
    "simulate: negative seed": Case(
        lambda t: simulate(INPUTS, seed=-1), ValueError, "seed must be an integer >= 0"
    ),
    "simulate: onset after the run": Case(
        lambda t: simulate(INPUTS, Fault("f1", 0.5, onset=25.0)),
        ValueError,
        r"f1 onset 25 s is at or after the run's end \(20 s\)",
    ),
    "simulate: P1 < P2": Case(
        lambda t: simulate(_inputs_with(P1=np.full((2, 20), 0.1))), ValueError, "P1 < P2"
    ),
    "simulate: CV not normalised": Case(
        lambda t: simulate(_inputs_with(CV=np.full((2, 20), 2.0))),
        ValueError,
        "CV must be normalised",
    ),
    "simulate: complex input": Case(
        lambda t: simulate(_inputs_with(CV=np.full((2, 20), 0.5 + 0j))), ValueError, "complex"
    ),
    "simulate: time not 1 Hz": Case(
        lambda t: simulate(INPUTS.assign_coords(time=np.arange(20) * 2.0)), ValueError, "1 Hz"
    ),
    "simulate: one fault for two runs": Case(
        lambda t: simulate(INPUTS, [None]), ValueError, "got 1 faults for 2 runs"
    ),
    "simulate: fault of the wrong type": Case(
        lambda t: simulate(INPUTS, [None, "f1"]), ValueError, r"faults\[1\] must be a Fault"
    ),
    "simulate: unknown integrator": Case(
        lambda t: simulate(INPUTS, integrator="euler"), ValueError, "integrator must be"
    ),
    "simulate: unknown hold": Case(
        lambda t: simulate(INPUTS, hold="cubic"), ValueError, "hold must be"
    ),
    "simulate: negative warmup": Case(
        lambda t: simulate(INPUTS, warmup=-5), ValueError, "warmup must be"
    ),
    "Fault: strength out of range": Case(
        lambda t: Fault("f1", 1.5).validated(), ValueError, r"strength of f1 must lie in \[0, 1\]"
    ),
    "Fault: unknown name": Case(
        lambda t: Fault("f20", 0.5).validated(), ValueError, "name must be one of f1..f19"
    ),
    "Fault: incipient without ramp": Case(
        lambda t: Fault("f1", 0.5, profile="incipient").validated(), ValueError, "ramp must be > 0"
    ),
    "Fault: abrupt with a ramp": Case(
        lambda t: Fault("f1", 0.5, ramp=3.0).validated(), ValueError, "ramp must be 0"
    ),
    "Fault: onset NaN": Case(
        lambda t: Fault("f1", 0.5, onset=float("nan")).validated(), ValueError, "must be finite"
    ),
    "benchmark_inputs: zero runs": Case(
        lambda t: benchmark_inputs(n_runs=0), ValueError, "n_runs must be an integer >= 1"
    ),
    "benchmark_inputs: float duration": Case(
        lambda t: benchmark_inputs(duration=1e8), ValueError, "duration must be an integer"
    ),
    "benchmark_inputs: memory": Case(
        lambda t: benchmark_inputs(n_runs=200, duration=10**11),
        InsufficientMemoryError,
        r"200 run\(s\) x 100000000000 s needs about .* of memory, more than",
    ),
    "benchmark_inputs: jitter": Case(
        lambda t: benchmark_inputs(amplitude_jitter=1.5), ValueError, "amplitude_jitter"
    ),
    "inject_faults: no recorded X": Case(
        lambda t: inject_faults(INPUTS, None), ValueError, r"lacks channel\(s\) \['X', 'F'\]"
    ),
    # ---------------------------------------------------------------- campaigns
    "parse_campaign: no [campaign]": Case(
        lambda t: parse_campaign({}), CampaignError, "campaign is missing"
    ),
    "parse_campaign: negative duration": Case(
        lambda t: parse_campaign(_campaign(duration=-5)),
        CampaignError,
        "campaign.duration must be > 0",
    ),
    "parse_campaign: unknown fault": Case(
        lambda t: parse_campaign({**CAMPAIGN, "faults": {"f42": {}}}),
        CampaignError,
        "faults.f42: unknown fault",
    ),
    "parse_campaign: onset beyond duration": Case(
        lambda t: parse_campaign({**CAMPAIGN, "faults": {"onset": 90.0}}),
        CampaignError,
        r"faults.onset must lie in \[0, campaign.duration=60\)",
    ),
    "load_campaign: not UTF-8": Case(
        lambda t: load_campaign(_file(t, "c.toml", b"\xff\xfe\x00bad")),
        CampaignError,
        "not valid TOML: not UTF-8",
    ),
    "load_campaign: folder": Case(lambda t: load_campaign(t), CampaignError, "is a folder"),
    "load_campaign: missing": Case(
        lambda t: load_campaign(t / "none.toml"), FileNotFoundError, "none.toml"
    ),
    "simulate_campaign: memory": Case(
        lambda t: simulate_campaign(
            parse_campaign(_campaign(duration=10**11, runs_per_state=100)), progress=False
        ),
        InsufficientMemoryError,
        r"campaign c: 200 run\(s\) x 100000000000 s needs about",
    ),
    # ---------------------------------------------------------------- RVM
    "RVR.fit: NaN in X": Case(
        lambda t: RVR().fit(np.array([[0.0], [np.nan]]), [0.0, 1.0]), ValueError, "NaN"
    ),
    "RVR.fit: inf in y": Case(
        lambda t: RVR().fit(np.zeros((2, 1)), [0.0, np.inf]), ValueError, "y.*(NaN|inf)"
    ),
    "RVR.fit: one sample": Case(
        lambda t: RVR().fit(np.zeros((1, 1)), [0.0]), ValueError, "minimum of 2"
    ),
    "RVR.fit: X and y lengths differ": Case(
        lambda t: RVR().fit(np.zeros((3, 1)), [0.0, 1.0]), ValueError, "inconsistent numbers"
    ),
    "RVR.fit: complex torch X": Case(
        lambda t: RVR().fit(torch.zeros(3, 1, dtype=torch.complex128), [0.0, 1.0, 2.0]),
        ValueError,
        "Complex data not supported",
    ),
    "RVR: negative width": Case(
        lambda t: RVR(width=-1.0).fit(np.zeros((2, 1)), [0, 1]), ValueError, "width must be"
    ),
    "RVR: width text": Case(
        lambda t: RVR(width="foo").fit(np.zeros((2, 1)), [0, 1]), ValueError, "'foo'"
    ),
    "RVR: unknown method": Case(
        lambda t: RVR(method="svi").fit(np.zeros((2, 1)), [0, 1]), ValueError, "method must be"
    ),
    "RVR: unknown dtype": Case(
        lambda t: RVR(dtype="float16").fit(np.zeros((2, 1)), [0, 1]), ValueError, "dtype must be"
    ),
    "RVR: tol 0": Case(
        lambda t: RVR(tol=0).fit(np.zeros((2, 1)), [0, 1]), ValueError, "tol must be"
    ),
    "RVR: max_iter 0": Case(
        lambda t: RVR(max_iter=0).fit(np.zeros((2, 1)), [0, 1]), ValueError, "max_iter must be"
    ),
    "RVR: auto width with a linear kernel": Case(
        lambda t: RVR(kernel="linear", width="auto").fit(np.zeros((2, 1)), [0, 1]),
        ValueError,
        "width='auto' needs kernel='rbf'",
    ),
    "RVR: float32 overflow": Case(
        lambda t: RVR(dtype="float32").fit(np.array([[0.0], [1e300]]), [0.0, 1.0]),
        ValueError,
        "X does not fit in float32",
    ),
    "RVR.predict: wrong feature count": Case(
        lambda t: FITTED.predict(np.zeros((2, 3))), ValueError, "3 features.*expecting 1"
    ),
    "RVR.predict: before fit": Case(
        lambda t: RVR().predict(np.zeros((2, 1))), NotFittedError, "not fitted"
    ),
    "RVC.fit: one class": Case(
        lambda t: RVC().fit(np.zeros((3, 1)), ["f1"] * 3), ValueError, "only one class: 'f1'$"
    ),
    "RVC.fit: continuous labels": Case(
        lambda t: RVC().fit(np.zeros((3, 1)), [0.1, 0.2, 0.3]), ValueError, "Unknown label type"
    ),
    "RVC: moderated not bool": Case(
        lambda t: RVC(moderated="yes").fit(np.zeros((2, 1)), [0, 1]), ValueError, "moderated"
    ),
    "rvm save: path is a folder": Case(lambda t: FITTED.save(t), ValueError, "is a folder"),
    "rvm save: callable kernel": Case(
        lambda t: RVR(kernel=lambda a, b: a @ b.T).fit(np.eye(3), [0.0, 1.0, 2.0]).save(t / "m"),
        ValueError,
        "callable kernel cannot be saved",
    ),
    "rvm.load: missing file": Case(
        lambda t: load(t / "none.npz"), FileNotFoundError, "does not exist"
    ),
    "rvm.load: not a zip": Case(
        lambda t: load(_file(t, "g.npz", b"garbage")), ValueError, "not a readable RVM file"
    ),
    "rvm.load: zip bomb": Case(
        lambda t: load(_zip_bomb(t), max_bytes=10_000_000),
        ValueError,
        "would decompress to 33554560 bytes, more than the limit max_bytes=10000000",
    ),
    "rvm.load: object array": Case(
        lambda t: load(_object_array_file(t)), ValueError, "holds Python objects"
    ),
    "rvm.load: header larger than data": Case(
        lambda t: load(_lying_header_file(t)), ValueError, r"declares shape \(1000000000,\)"
    ),
    "rvm.load: NaN weights": Case(
        lambda t: load(_saved(t, m0_mean=np.full_like(FITTED.mean_, np.nan))),
        ValueError,
        "weights of model 0 contains NaN or infinity",
    ),
    "rvm.load: infinite covariance": Case(
        lambda t: load(
            _saved(t, m0_covariance=np.full_like(np.atleast_2d(FITTED.covariance_), np.inf))
        ),
        ValueError,
        "covariance of model 0 contains NaN",
    ),
    "rvm.load: negative noise precision": Case(
        lambda t: load(_saved(t, model_beta=-3.0)), ValueError, r"noise precision \(beta\).*> 0"
    ),
    "rvm.load: zero precision": Case(
        lambda t: load(_saved(t, m0_alpha=np.zeros_like(FITTED.alpha_))),
        ValueError,
        r"precisions \(alpha\) of model 0 must be > 0",
    ),
    "rvm.load: deeply nested metadata": Case(
        lambda t: load(_saved_metadata(t, "[" * 100_000 + "]" * 100_000)),
        ValueError,
        "corrupt metadata",
    ),
    "rvm.load: unknown parameter": Case(
        lambda t: load(_saved(t, meta_params={"kernel": "rbf", "speed": 3})),
        ValueError,
        "invalid estimator parameters",
    ),
    "rvm.load: bad parameter value": Case(
        lambda t: load(_saved(t, meta_params={"method": "magic"})),
        ValueError,
        "invalid estimator parameters.*method",
    ),
    "rvm.load: n_iter text": Case(
        lambda t: load(_saved(t, model_n_iter="ten")), ValueError, "n_iter of model 0"
    ),
    "rvm.load: non-positive x_scale": Case(
        lambda t: load(_saved(t, meta_x_scale=-2.0)), ValueError, "x_scale must be > 0"
    ),
    "rvm.load: integer X_fit": Case(
        lambda t: load(_saved(t, X_fit=np.zeros((30, 1), dtype=np.int64))),
        ValueError,
        "X_fit must hold floats",
    ),
    # ---------------------------------------------------------------- calibration
    "interval_coverage: zero std": Case(
        lambda t: intervals.interval_coverage([0.0, 1.0], [0.0, 1.0], [1.0, 0.0]),
        ValueError,
        "std must be strictly positive",
    ),
    "interval_coverage: level 1": Case(
        lambda t: intervals.interval_coverage([0.0], [0.0], [1.0], levels=(0.5, 1.0)),
        ValueError,
        r"levels must lie in \(0, 1\)",
    ),
    "pit_histogram: value above 1": Case(
        lambda t: intervals.pit_histogram([0.2, 1.5]), ValueError, r"lie in \[0, 1\]"
    ),
    "pit_histogram: zero bins": Case(
        lambda t: intervals.pit_histogram([0.2], n_bins=0), ValueError, "n_bins"
    ),
    "node_calibration: NaN features": Case(
        lambda t: nodes.node_calibration([], np.array([[np.nan]]), ["fn"]),
        ValueError,
        "X contains NaN",
    ),
    "node_calibration: lengths differ": Case(
        lambda t: nodes.node_calibration([], np.zeros((3, 1)), ["fn"]),
        ValueError,
        r"n = len\(y_true\) = 1",
    ),
    # ---------------------------------------------------------------- plotting
    "plot_runs: unknown channel": Case(
        lambda t: plot_runs(INPUTS, channels=["X"]), ValueError, r"\['X'\] not in the dataset"
    ),
    "select_runs: run out of range": Case(
        lambda t: select_runs(INPUTS, runs=[5]), ValueError, "run 5 out of range"
    ),
    "select_runs: unknown state": Case(
        lambda t: select_runs(INPUTS, states=["f3"]), ValueError, "no run with state 'f3'"
    ),
}


def _saved_metadata(tmp: Path, text: str) -> Path:
    path = tmp / "meta.npz"
    np.savez(path, metadata=np.array(text), X_fit=np.zeros((2, 1)))
    return path


def test_the_catalogue_is_large():
    assert len(CASES) >= 60


@pytest.mark.parametrize("name", list(CASES))
def test_bad_input(name, tmp_path):
    case = CASES[name]
    with pytest.raises(case.error, match=case.match) as info:
        case.call(tmp_path)
    message = str(info.value)
    assert "np.str_" not in message and "np.float64" not in message  # plain values in messages


def test_no_partial_files_left_by_failed_saves(tmp_path):
    for name, case in CASES.items():
        if "save" in name:
            with pytest.raises(case.error):
                case.call(tmp_path)
    assert not [p for p in tmp_path.rglob("*") if p.name.endswith(".tmp")]


def test_outputs_share_no_memory_with_inputs():
    rng = np.random.default_rng(5)
    x = rng.random((2, 30))
    ds = make_dataset({"X": x, "F": x.copy()})
    assert not np.shares_memory(ds["X"].values, x)
    inputs = benchmark_inputs(n_runs=2, duration=30)
    out = simulate(inputs, seed=1)
    for name in inputs.data_vars:
        assert not np.shares_memory(out[name].values, inputs[name].values)
    real = out.copy(deep=True)
    faulty = inject_faults(real, [None, Fault("f1", 0.5, 5.0)])
    for name in real.data_vars:
        assert not np.shares_memory(faulty[name].values, real[name].values)
    faulty["CV"].values[:] = 0.0  # writing the output leaves the input unchanged
    np.testing.assert_array_equal(real["CV"].values, out["CV"].values)


@pytest.mark.parametrize("cls", [RVR, RVC])
def test_estimators_keep_no_reference_to_the_callers_tensor(cls, tmp_path):
    X = torch.linspace(-2, 2, 20, dtype=torch.float64)[:, None]
    y = (X[:, 0] > 0).double() if cls is RVC else torch.sin(X[:, 0])
    model = cls(width=1.0).fit(X, y)
    before = model.predict(X.clone())
    model.save(tmp_path / "a.npz")
    X.mul_(100.0)  # an in-place change by the caller after fit
    model.save(tmp_path / "b.npz")
    torch.testing.assert_close(model.predict(X / 100.0), before)
    with np.load(tmp_path / "a.npz") as a, np.load(tmp_path / "b.npz") as b:
        np.testing.assert_array_equal(a["X_fit"], b["X_fit"])

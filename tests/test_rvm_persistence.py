"""Save/load round trips (exact) and clear errors for corrupt or mismatched files."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from bayes_fdi.rvm import RBF, RVC, RVR, load
from bayes_fdi.rvm.persistence import FORMAT_VERSION


@pytest.fixture(scope="module")
def regression_data():
    rng = np.random.default_rng(21)
    X = rng.uniform(-5, 5, (150, 2))
    y = np.sin(X[:, 0]) + 0.1 * X[:, 1] ** 2 + 0.1 * rng.standard_normal(150)
    return X, y, rng.uniform(-6, 6, (40, 2))


@pytest.mark.parametrize("dtype", ["float64", "float32"])
@pytest.mark.parametrize("kernel", ["rbf", RBF(1.5) + 0.5 * RBF(4.0)])
def test_rvr_round_trip_exact(tmp_path, regression_data, dtype, kernel):
    X, y, X_new = regression_data
    model = RVR(kernel=kernel, width=1.5, dtype=dtype).fit(X.astype(dtype), y)
    path = tmp_path / "model.npz"
    model.save(path)
    back = load(path)
    assert isinstance(back, RVR)
    assert back.get_params()["dtype"] == dtype
    m0, s0 = model.predict(X_new, return_std=True)
    m1, s1 = back.predict(X_new, return_std=True)
    np.testing.assert_array_equal(m1, m0)
    np.testing.assert_array_equal(s1, s0)
    for name in ("relevance_indices_", "relevance_vectors_", "alpha_", "mean_", "covariance_"):
        np.testing.assert_array_equal(getattr(back, name), getattr(model, name))
    assert back.beta_ == model.beta_ and back.log_evidence_ == model.log_evidence_
    assert back.width_ == model.width_ and back.n_iter_ == model.n_iter_
    np.testing.assert_array_equal(back.evidence_trace_, model.evidence_trace_)
    torch.testing.assert_close(
        back.design_matrix(X_new, basis="all"), model.design_matrix(X_new, basis="all")
    )


def test_rvc_round_trip_binary_and_multiclass(tmp_path):
    rng = np.random.default_rng(4)
    centres = np.array([[0.0, 2.0], [-2.0, -1.0], [2.0, -1.0]])
    y = np.repeat([0, 1, 2], 40)
    X = centres[y] + rng.standard_normal((120, 2))
    labels = np.array(["fn", "f1", "f2"])[y]
    for yy in (labels, (y > 0).astype(int)):
        model = RVC(width=1.0, moderated=True).fit(X, yy)
        model.save(tmp_path / "c.npz")
        back = load(tmp_path / "c.npz")
        np.testing.assert_array_equal(back.classes_, model.classes_)
        np.testing.assert_array_equal(back.predict_proba(X), model.predict_proba(X))
        np.testing.assert_array_equal(back.decision_function(X), model.decision_function(X))
        np.testing.assert_array_equal(back.predict(X), model.predict(X))
        np.testing.assert_array_equal(back.relevance_indices_, model.relevance_indices_)


def test_precomputed_round_trip(tmp_path):
    rng = np.random.default_rng(8)
    F = rng.standard_normal((60, 5))
    y = F @ np.array([1.0, 0, 0, -2.0, 0]) + 0.1 * rng.standard_normal(60)
    model = RVR(kernel="precomputed", bias=False).fit(F, y)
    model.save(tmp_path / "p.npz")
    np.testing.assert_array_equal(load(tmp_path / "p.npz").predict(F), model.predict(F))


@pytest.fixture
def saved(tmp_path, regression_data):
    X, y, _ = regression_data
    path = tmp_path / "ok.npz"
    RVR(width=1.5).fit(X, y).save(path)
    return path


def _rewrite(path, out, **changes):
    with np.load(path, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    meta = json.loads(str(arrays["metadata"]))
    for key, value in changes.items():
        if key.startswith("meta_"):
            meta[key[5:]] = value
        elif value is None:
            arrays.pop(key)
        else:
            arrays[key] = value
    arrays["metadata"] = np.array(json.dumps(meta))
    np.savez(out, **arrays)
    return out


def test_corrupt_files(tmp_path, saved):
    truncated = tmp_path / "trunc.npz"
    truncated.write_bytes(saved.read_bytes()[:200])
    with pytest.raises(ValueError, match="not a readable RVM file"):
        load(truncated)
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"definitely not a zip archive")
    with pytest.raises(ValueError, match="not a readable RVM file"):
        load(garbage)
    no_meta = tmp_path / "nometa.npz"
    np.savez(no_meta, a=np.zeros(3))
    with pytest.raises(ValueError, match="no RVM metadata"):
        load(no_meta)
    with np.load(saved, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    arrays["metadata"] = np.array('{"format": "bayes_fdi.rvm", "format_ver')
    bad_json = tmp_path / "badjson.npz"
    np.savez(bad_json, **arrays)
    with pytest.raises(ValueError, match="corrupt metadata"):
        load(bad_json)
    with pytest.raises(FileNotFoundError):
        load(tmp_path / "missing.npz")


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"meta_format": "something.else"}, "not a bayes_fdi.rvm file"),
        ({"meta_format_version": FORMAT_VERSION + 1}, "format version"),
        ({"meta_estimator": "SVM"}, "invalid metadata"),
        ({"meta_n_features_in": 3}, "do not match"),
        ({"m0_mean": np.zeros(1)}, "inconsistent"),
        ({"m0_active": np.array([10_000])}, "inconsistent"),
        ({"m0_alpha": None}, "missing model 0"),
        ({"X_fit": None}, "invalid metadata"),
    ],
)
def test_mismatched_metadata(tmp_path, saved, changes, match):
    bad = _rewrite(saved, tmp_path / "bad.npz", **changes)
    with pytest.raises(ValueError, match=match):
        load(bad)


def test_unsaveable_models(tmp_path, regression_data):
    X, y, _ = regression_data
    model = RVR(kernel=lambda a, b: a @ b.T).fit(X, y)
    with pytest.raises(ValueError, match="callable kernel"):
        model.save(tmp_path / "f.npz")

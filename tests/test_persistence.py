"""Saving and loading fitted diagnosers: exact round trips, and clear errors for bad files."""

from __future__ import annotations

import json
import os
import zipfile

import numpy as np
import pytest
import xarray as xr
from conftest import sine_inputs

from bayes_fdi import model_files
from bayes_fdi.calibration import DirichletScaler, TemperatureScaler
from bayes_fdi.datasets import make_dataset
from bayes_fdi.diagnosis import (
    FaultDiagnoser,
    HierarchicalClassifier,
    KernelRidgeRegressor,
    NormalModels,
    svm_classifier,
    svm_fault_diagnoser,
)
from bayes_fdi.diagnosis.seva.record import to_frame
from bayes_fdi.rvm import RBF, RVC, RVR

OFFSETS = {"fn": (0, 0), "f1": (0.04, 0), "f2": (0, -0.04), "f3": (0.03, 0.03)}


def campaign(states, n_per, rng, T=80):
    sts = [s for s in states for _ in range(n_per)]
    n = len(sts)
    ch = sine_inputs(n, rng, T)
    X = 0.9 * ch["CV"] + 0.005 * rng.standard_normal((n, T))
    F = 0.7 * (1 - 0.8 * X) * np.sqrt(ch["P1"] - ch["P2"]) + 0.005 * rng.standard_normal((n, T))
    for i, s in enumerate(sts):
        X[i] += OFFSETS[s][0]
        F[i] += OFFSETS[s][1]
    return make_dataset(dict(ch, X=X, F=F), state=sts, campaign="persistence-test")


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(7)
    return (
        campaign(["fn"], 3, rng),
        campaign(list(OFFSETS), 6, rng),
        campaign(list(OFFSETS), 3, rng),
    )


@pytest.fixture(scope="module")
def rvm_diagnoser(data):
    normal, labelled, _ = data
    # a fixed width: the default evidence-grid search is slow and not what is tested here
    regressor = RVR(kernel="rbf", width=0.3)
    return FaultDiagnoser(regressor, max_train_samples=150, input_lags=(2.0,)).fit(normal, labelled)


@pytest.fixture(scope="module")
def svm_diagnoser(data):
    normal, labelled, _ = data
    return svm_fault_diagnoser(max_train_samples=150).fit(normal, labelled)


def _assert_same_diagnosis(a: FaultDiagnoser, b: FaultDiagnoser, runs: xr.Dataset) -> None:
    xr.testing.assert_identical(b.diagnose(runs), a.diagnose(runs))
    feats = a.training_features_
    np.testing.assert_array_equal(b.predict_features(feats), a.predict_features(feats))
    frame_a, frame_b = to_frame(a.seva(runs)), to_frame(b.seva(runs))
    assert frame_a.equals(frame_b)


@pytest.mark.parametrize("which", ["rvm_diagnoser", "svm_diagnoser"])
def test_fault_diagnoser_round_trip_is_exact(which, data, tmp_path, request):
    model = request.getfixturevalue(which)
    path = tmp_path / "model.npz"
    assert model.save(path) == os.fspath(path)
    back = FaultDiagnoser.load(path)
    assert type(back) is FaultDiagnoser
    _assert_same_diagnosis(model, back, data[2])
    assert back.get_params().keys() == model.get_params().keys()
    assert back.classifier_.export_text() == model.classifier_.export_text()
    np.testing.assert_array_equal(back.classes_, model.classes_)
    assert back.classes_.dtype == model.classes_.dtype
    # the normal models' fitted attributes come back as they were
    nm0, nm1 = model.normal_models_, back.normal_models_
    for name in ("X", "F"):
        np.testing.assert_array_equal(nm1.std_scale_[name], nm0.std_scale_[name])
    assert nm1.input_lags_ == nm0.input_lags_ and nm1.widths_ == nm0.widths_
    assert nm1.width_log_evidence_ == nm0.width_log_evidence_


def test_shared_objects_stay_shared(svm_diagnoser, tmp_path):
    """The SVM node's ``svc_`` is the calibrated classifier's estimator: one object, also after."""
    path = tmp_path / "svm.npz"
    svm_diagnoser.save(path)
    back = FaultDiagnoser.load(path)
    node = back.classifier_.nodes_[0].estimator
    assert node.svc_ is node.calibrated_.calibrated_classifiers_[0].estimator
    assert node.support_vectors_ is node.svc_.support_vectors_


def test_components_and_recalibrators_round_trip(data, rvm_diagnoser, tmp_path):
    _, labelled, test = data
    nm = rvm_diagnoser.normal_models_
    model_files.save(nm, tmp_path / "nm.npz")
    back = model_files.load(tmp_path / "nm.npz", expected=NormalModels)
    xr.testing.assert_identical(back.residuals(test), nm.residuals(test))

    proba = rvm_diagnoser.diagnose(labelled)["proba"].values
    y = labelled["state"].values
    for scaler in (TemperatureScaler(), DirichletScaler(reg_lambda=1e-2, reg_mu=1e-2)):
        scaler.fit(proba, y)
        path = tmp_path / f"{type(scaler).__name__}.npz"
        model_files.save(scaler, path)
        again = model_files.load(path, expected=type(scaler))
        np.testing.assert_array_equal(again.transform(proba), scaler.transform(proba))


def test_rvm_with_composite_kernel_and_float32(tmp_path, rng):
    X = rng.uniform(-3, 3, (60, 2))
    y = np.sin(X[:, 0]) + 0.05 * rng.standard_normal(60)
    kernel = RBF(1.0) + 0.5 * RBF(3.0)
    model = RVR(kernel=kernel, dtype="float32").fit(X.astype(np.float32), y)
    tree = HierarchicalClassifier(RVC(width=2.0)).fit(X, np.where(y > 0.3, "a", "b"))
    for obj, check in (
        (model, lambda m: m.predict(X, return_std=True)),
        (tree, lambda m: m.predict_proba(X)),
    ):
        path = tmp_path / "m.npz"
        model_files.save(obj, path)
        back = model_files.load(path)
        for u, v in zip(np.atleast_1d(check(back)), np.atleast_1d(check(obj)), strict=True):
            np.testing.assert_array_equal(u, v)


def test_file_is_plain_npz_without_pickle(rvm_diagnoser, tmp_path):
    path = tmp_path / "m.npz"
    rvm_diagnoser.save(path)
    with np.load(path, allow_pickle=False) as z:  # readable with numpy alone, no pickle
        meta = json.loads(str(z["metadata"]))
        assert meta["format"] == model_files.FORMAT_NAME
        assert meta["format_version"] == model_files.FORMAT_VERSION
        assert meta["root_class"] == "FaultDiagnoser"
        assert set(z.files) == {"metadata", *meta["arrays"]}
        for key, spec in meta["arrays"].items():
            assert z[key].dtype.str == spec["dtype"] and list(z[key].shape) == spec["shape"]
    assert model_files.read_metadata(path)["root_class"] == meta["root_class"]


def test_atomic_write_leaves_no_partial_file(rvm_diagnoser, tmp_path, monkeypatch):
    path = tmp_path / "m.npz"
    path.write_bytes(b"previous content")

    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez_compressed", broken)
    with pytest.raises(OSError, match="disk full"):
        rvm_diagnoser.save(path)
    assert path.read_bytes() == b"previous content"
    assert os.listdir(tmp_path) == ["m.npz"]  # no temporary file left


def test_unsaveable_contents_are_named(data, tmp_path):
    normal, labelled, _ = data
    diag = FaultDiagnoser(
        KernelRidgeRegressor(width=0.3), HierarchicalClassifier(svm_classifier())
    ).fit(normal, labelled)
    diag.classifier_.random_state = np.random.default_rng(0)
    with pytest.raises(ValueError, match=r"classifier_\.random_state.*Generator"):
        diag.save(tmp_path / "x.npz")
    assert not (tmp_path / "x.npz").exists()
    with pytest.raises(ValueError, match="not fitted"):
        FaultDiagnoser().save(tmp_path / "y.npz")


# ------------------------------------------------------------------------------ bad files
@pytest.fixture(scope="module")
def saved(rvm_diagnoser, tmp_path_factory):
    path = tmp_path_factory.mktemp("saved") / "model.npz"
    rvm_diagnoser.save(path)
    return path


def _rewrite(src, dst, change):
    """Copy a model file, letting ``change(name, bytes) -> bytes | None`` edit members."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for info in zin.infolist():
            out = change(info.filename, zin.read(info.filename))
            if out is not None:
                zout.writestr(info.filename, out)


def _metadata_member(meta: dict) -> bytes:
    import io

    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.array(json.dumps(meta)), allow_pickle=False)
    return buf.getvalue()


def _meta(path) -> dict:
    with np.load(path, allow_pickle=False) as z:
        return json.loads(str(z["metadata"]))


def test_truncated_and_garbage_files(saved, tmp_path):
    data = saved.read_bytes()
    cut = tmp_path / "cut.npz"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="not a bayes_fdi model file"):
        FaultDiagnoser.load(cut)
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"\x00" * 100)
    with pytest.raises(ValueError, match="not a zip archive"):
        FaultDiagnoser.load(junk)
    with pytest.raises(FileNotFoundError):
        FaultDiagnoser.load(tmp_path / "missing.npz")


def test_flipped_bytes_are_caught_by_the_crc(saved, tmp_path):
    meta = _meta(saved)
    biggest = max(meta["arrays"], key=lambda k: np.prod(meta["arrays"][k]["shape"]))
    bad = tmp_path / "bad.npz"
    with zipfile.ZipFile(saved) as zin, zipfile.ZipFile(bad, "w", zipfile.ZIP_STORED) as zout:
        for info in zin.infolist():
            zout.writestr(info.filename, zin.read(info.filename))
    raw = bytearray(bad.read_bytes())
    with zipfile.ZipFile(bad) as z:
        info = z.getinfo(f"{biggest}.npy")
        # the member's data start after its local header (30 bytes + name + extra)
        start = info.header_offset + 30 + len(info.filename) + len(info.extra)
    raw[start + info.file_size - 3] ^= 0xFF
    bad.write_bytes(bytes(raw))
    with pytest.raises(ValueError, match="corrupt"):
        FaultDiagnoser.load(bad)


def test_foreign_newer_and_mismatched_files(saved, tmp_path, rng):
    rvm_file = tmp_path / "rvm.npz"
    X = rng.normal(size=(30, 2))
    RVR(width=1.0).fit(X, X[:, 0]).save(rvm_file)
    with pytest.raises(ValueError, match=r"format 'bayes_fdi.rvm'.*bayes_fdi.rvm.load"):
        FaultDiagnoser.load(rvm_file)

    plain = tmp_path / "plain.npz"
    np.savez(plain, x=np.arange(3))
    with pytest.raises(ValueError, match="no metadata"):
        FaultDiagnoser.load(plain)

    meta = _meta(saved)
    newer = tmp_path / "newer.npz"
    meta_newer = dict(meta, format_version=model_files.FORMAT_VERSION + 1)
    _rewrite(
        saved,
        newer,
        lambda n, b: _metadata_member(meta_newer) if n == "metadata.npy" else b,
    )
    with pytest.raises(ValueError, match="newer than this bayes_fdi"):
        FaultDiagnoser.load(newer)

    with pytest.raises(ValueError, match="holds a FaultDiagnoser, not a NormalModels"):
        model_files.load(saved, expected=NormalModels)


def test_missing_array_and_forbidden_class(saved, tmp_path):
    meta = _meta(saved)
    missing = tmp_path / "missing.npz"
    _rewrite(saved, missing, lambda n, b: None if n == "a0.npy" else b)
    with pytest.raises(ValueError, match="members do not match"):
        FaultDiagnoser.load(missing)

    evil = dict(meta, root={"__object__": "os:system", "state": {}}, root_class="os:system")
    path = tmp_path / "evil.npz"
    _rewrite(saved, path, lambda n, b: _metadata_member(evil) if n == "metadata.npy" else b)
    with pytest.raises(ValueError, match="'os:system' is not allowed"):
        model_files.load(path)

    inner = json.loads(json.dumps(meta).replace('"rvm.RBF"', '"os:system"'))
    sneaky = dict(meta, root={"__object__": meta["root_class"], "state": {"x": {
        "__object__": "subprocess:Popen", "state": {}}}})  # fmt: skip
    for variant in (inner, sneaky):
        _rewrite(
            saved, path, lambda n, b, v=variant: _metadata_member(v) if n == "metadata.npy" else b
        )
        with pytest.raises(ValueError, match="is not allowed"):
            model_files.load(path)


def test_size_limit_is_checked_before_decompressing(saved, tmp_path):
    with zipfile.ZipFile(saved) as z:
        total = sum(i.file_size for i in z.infolist())
    with pytest.raises(ValueError, match="exceed the limit"):
        FaultDiagnoser.load(saved, max_bytes=total - 1)
    # a zip bomb: a small file claiming a huge member is refused from the directory alone
    bomb = tmp_path / "bomb.npz"
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("metadata.npy", _metadata_member(_meta(saved)))
        with z.open("a0.npy", "w", force_zip64=True) as handle:
            block = b"\x00" * 2**20
            for _ in range(64):
                handle.write(block)
    assert bomb.stat().st_size < 2**20
    with pytest.raises(ValueError, match="exceed the limit"):
        FaultDiagnoser.load(bomb, max_bytes=2**25)


def test_enums_tuples_sets_and_odd_dict_keys(tmp_path):
    """Every JSON encoding of the format, through a generic object of the model layers."""
    from bayes_fdi.diagnosis import SevaStatus
    from bayes_fdi.diagnosis.normal_models.std_scaler import StdScaler

    obj = StdScaler()
    obj.extra_ = {
        "status": SevaStatus.BLURRED,
        "tuple": (1, 2.5, "x"),
        "set": {3, 1, 2},
        "frozen": frozenset({"a"}),
        "float keys": {0.05: -1.5, 0.1: float("nan")},
        "inf": float("-inf"),
        "scalar": np.float32(0.1),
        "objects": np.array(["fn", None, 3], dtype=object),
        "empty": np.zeros((0, 3)),
        "fortran": np.asfortranarray(np.arange(6.0).reshape(2, 3)),
    }
    obj.extra_["same"] = obj.extra_["fortran"]  # one array, referenced twice
    model_files.save(obj, tmp_path / "x.npz")
    back = model_files.load(tmp_path / "x.npz", expected=StdScaler).extra_
    assert back["status"] is SevaStatus.BLURRED
    assert back["tuple"] == (1, 2.5, "x") and back["set"] == {1, 2, 3}
    assert back["frozen"] == frozenset({"a"}) and isinstance(back["frozen"], frozenset)
    assert back["float keys"][0.05] == -1.5 and np.isnan(back["float keys"][0.1])
    assert back["inf"] == float("-inf")
    assert back["scalar"].dtype == np.float32 and back["scalar"] == np.float32(0.1)
    assert back["objects"].dtype == object and back["objects"].tolist() == ["fn", None, 3]
    assert back["empty"].shape == (0, 3)
    np.testing.assert_array_equal(back["fortran"], np.arange(6.0).reshape(2, 3))
    assert back["same"] is back["fortran"]

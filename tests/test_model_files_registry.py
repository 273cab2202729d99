"""Model files across releases and the registry of persisted classes (bayes_fdi.model_files).

The files under ``tests/data/model_files_0.1.0`` were written by bayes_fdi 0.1.0, before its
modules moved (``make_fixtures.py`` beside them made them): they must load and give the outputs
0.1.0 gave. Loading imports nothing a file names: a file naming a module outside the registry
is refused before any import.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from bayes_fdi import model_files
from bayes_fdi.diagnosis import FaultDiagnoser, OnlineDiagnoser
from bayes_fdi.model_files.registry import LEGACY_NAMES, PERSISTED, resolve_class, stable_name

FIXTURES = Path(__file__).parent / "data" / "model_files_0.1.0"
CHANNELS = ("CV", "P1", "P2", "T1", "X", "F")


def _fixture_module():
    spec = importlib.util.spec_from_file_location("make_fixtures", FIXTURES / "make_fixtures.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_0_1_0_files_name_classes_by_their_old_modules():
    meta = model_files.read_metadata(FIXTURES / "online.npz")
    assert meta["format_version"] == 1 and meta["bayes_fdi_version"] == "0.1.0"
    assert meta["root_class"] == "bayes_fdi.diagnosis.online:OnlineDiagnoser"


@pytest.mark.parametrize("kind", ["rvm", "svm"])
def test_offline_diagnosers_saved_by_0_1_0_give_the_same_diagnosis(kind):
    """The same diagnosis as 0.1.0: every label, coordinate and attribute identical, every
    number equal to rounding. The numbers pass through float64 kernel sums and products whose
    rounding follows the CPU's and the libraries' builds (up to a few 1e-15 relative in the
    predictions, 1e-11 in the residuals, which are small differences of them); ``rtol`` 1e-9
    bounds that with room, while any change of a fitted value, a kernel width or a scaling
    moves them by more than 1e-6."""
    model = FaultDiagnoser.load(FIXTURES / f"offline-{kind}.npz")
    runs = xr.load_dataset(FIXTURES / "offline.recording.nc")
    expected = xr.load_dataset(FIXTURES / f"offline-{kind}.expected.nc")
    got = model.diagnose(runs)
    assert got.attrs == expected.attrs
    numbers = [v for v in expected.data_vars if expected[v].dtype.kind == "f"]
    assert numbers and set(got.data_vars) == set(expected.data_vars)
    xr.testing.assert_identical(got.drop_vars(numbers), expected.drop_vars(numbers))
    xr.testing.assert_allclose(got[numbers], expected[numbers], rtol=1e-9, atol=0.0)


def test_online_diagnoser_saved_by_0_1_0_gives_the_same_stream_and_continues_it():
    model = OnlineDiagnoser.load(FIXTURES / "online.npz")
    recording = _fixture_module().online_recording()
    expected = xr.load_dataset(FIXTURES / "online.expected.nc")
    stream = model.run(recording)
    # every variable 0.1.0 gave is given identically; variables added since come on top
    added = {"evidence", "novel_inputs", "novel_signature", "novel_onset", "unproven_onset"}
    assert set(stream.data_vars) - set(expected.data_vars) == added
    added_attrs = {"p_fault", "novelty_ratio", "fit_proof_seconds"}
    assert set(stream.attrs) - set(expected.attrs) == added_attrs
    same = stream[list(expected.data_vars)]
    same.attrs = {k: v for k, v in same.attrs.items() if k in expected.attrs}
    xr.testing.assert_identical(same, expected)
    # the file was saved after 30 seconds of run 1 through `update`: the next seconds continue
    # that stream, i.e. equal the stream of run 1 at those seconds
    loaded = OnlineDiagnoser.load(FIXTURES / "online.npz")
    for t in range(30, 60):
        sample = {c: float(recording[c].values[1, t]) for c in CHANNELS}
        record = loaded.update(sample)
        assert record.status.value == str(expected["status"].values[1, t])
        assert loaded.last_["DD"] == bool(expected["DD"].values[1, t])
        np.testing.assert_array_equal(loaded.last_["stat_X"], expected["stat_X"].values[1, t])
        np.testing.assert_array_equal(record.x_vmv, expected["VMV_X"].values[1, t])


def test_the_registry_table_is_consistent():
    for name, location in PERSISTED.items():
        cls = resolve_class(name, "table")
        assert isinstance(cls, type), location
        assert stable_name(cls) == name
    assert len({resolve_class(n, "table") for n in PERSISTED}) == len(PERSISTED)
    for old, new in LEGACY_NAMES.items():
        assert new in PERSISTED, old
        assert resolve_class(old, "legacy") is resolve_class(new, "table")


def test_a_file_naming_an_unregistered_module_is_refused_without_importing_it(tmp_path):
    """The loader of 0.1.0 imported any bayes_fdi module a file named: one naming
    ``bayes_fdi.__main__`` ran the command line inside the caller and exited it."""
    saved = FIXTURES / "offline-svm.npz"
    with np.load(saved, allow_pickle=False) as z:
        meta = json.loads(str(z["metadata"]))
    evil = tmp_path / "evil.npz"
    for name in ("bayes_fdi.__main__:main", "bayes_fdi.cli:main", "Unregistered"):
        bad = dict(meta, root_class=name, root={"__object__": name, "state": {}})
        with zipfile.ZipFile(saved) as src, zipfile.ZipFile(evil, "w") as dst:
            for info in src.infolist():
                data = src.read(info)
                if info.filename == "metadata.npy":
                    import io

                    buf = io.BytesIO()
                    np.lib.format.write_array(buf, np.array(json.dumps(bad)))
                    data = buf.getvalue()
                dst.writestr(info.filename, data)
        code = (
            "import sys\nfrom bayes_fdi import model_files\n"
            f"try:\n    model_files.load({str(evil)!r})\n"
            "except ValueError as e:\n    print('refused:', e)\n"
            "print('imported __main__:', 'bayes_fdi.__main__' in sys.modules)\n"
            "print('imported cli:', 'bayes_fdi.cli' in sys.modules)\n"
        )
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             timeout=120, check=True).stdout  # fmt: skip
        assert f"refused: {evil}: class {name!r} is not allowed" in out
        assert "imported __main__: False" in out and "imported cli: False" in out


def test_metadata_nested_beyond_reason_is_refused_naming_the_file(tmp_path):
    saved = FIXTURES / "offline-svm.npz"
    deep = tmp_path / "deep.npz"
    for depth in (100_000, 500):
        text = '{"format":"bayes_fdi.model","format_version":3,"arrays":{},"root_class":' \
            '"FaultDiagnoser","root":' + '{"__tuple__":[' * depth + "]}" * depth + "}"  # fmt: skip
        with zipfile.ZipFile(deep, "w") as dst:
            import io

            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.array(text))
            dst.writestr("metadata.npy", buf.getvalue())
        with pytest.raises(ValueError, match=rf"{deep}.*nested"):
            model_files.load(deep)
    assert saved.exists()

"""Bad model files of the online diagnoser: a damaged or tampered file fails when it is loaded,
with an error naming the file and the value, never later while it diagnoses."""

from __future__ import annotations

import io
import re
import zipfile
from pathlib import Path

import numpy as np
import pytest

from bayes_fdi.datasets import load_lublin_example
from bayes_fdi.diagnosis import OnlineDiagnoser


@pytest.fixture(scope="module")
def saved(tmp_path_factory) -> Path:
    hour = load_lublin_example()
    path = tmp_path_factory.mktemp("model") / "valve.npz"
    OnlineDiagnoser(random_state=0).fit(hour.isel(time=slice(0, 900))).save(path)
    return path


def _tampered(source: Path, target: Path, pattern: str, replacement: str) -> Path:
    """A copy of ``source`` whose metadata JSON has ``pattern`` (first match) replaced."""
    with zipfile.ZipFile(source) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    text = str(np.load(io.BytesIO(members["metadata.npy"]), allow_pickle=False))
    changed, n = re.subn(pattern, replacement, text, count=1)
    assert n == 1, pattern
    buffer = io.BytesIO()
    np.save(buffer, np.array(changed), allow_pickle=False)
    members["metadata.npy"] = buffer.getvalue()
    with zipfile.ZipFile(target, "w") as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    return target


NAN = '{"__float__":"nan"}'
THRESHOLD, CLEAR = r'"threshold_":[0-9.e+-]+', r'"clear_level_":[0-9.e+-]+'
CASES = {
    "threshold NaN": (THRESHOLD, f'"threshold_":{NAN}', "threshold_ must be finite"),
    "threshold -1": (THRESHOLD, '"threshold_":-1.0', "threshold_ must be finite and > 0"),
    "clear level above the threshold": (
        CLEAR,
        '"clear_level_":1e9',
        "clear_level_ must be finite, >= 0 and below",
    ),
    "clear level NaN": (CLEAR, f'"clear_level_":{NAN}', "clear_level_"),
}


@pytest.mark.parametrize("name", list(CASES))
def test_a_tampered_fitted_value_fails_at_load_naming_the_file(saved, tmp_path, name):
    pattern, replacement, message = CASES[name]
    bad = _tampered(saved, tmp_path / "bad.npz", pattern, replacement)
    with pytest.raises(ValueError, match=re.escape(str(bad)) + ".*" + message):
        OnlineDiagnoser.load(bad)


def test_the_untampered_file_loads_and_an_identity_edit_too(saved, tmp_path):
    assert isinstance(OnlineDiagnoser.load(saved), OnlineDiagnoser)
    same = _tampered(saved, tmp_path / "same.npz", r'"clear_level_":', '"clear_level_":')
    assert OnlineDiagnoser.load(same).threshold_ == OnlineDiagnoser.load(saved).threshold_


def test_deeply_nested_metadata_names_the_file(saved, tmp_path):
    deep = "[" * 100_000 + "]" * 100_000
    bad = _tampered(
        saved, tmp_path / "deep.npz", r'"clear_level_":[0-9.e+-]+', f'"clear_level_":{deep}'
    )
    with pytest.raises(ValueError, match=re.escape(str(bad))):
        OnlineDiagnoser.load(bad)

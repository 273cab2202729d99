"""Atomic writes: a file appears whole or not at all, and a signal mid-write never hangs.

The signal tests run a real subprocess that writes a large netCDF dataset (tens of MB, about a
second of zlib compression), wait until its temporary file exists in the destination folder and
then send SIGINT or SIGTERM. Before `bayes_fdi.atomic`, SIGINT there deadlocked in xarray's
file-manager lock and left a partial file at the destination.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from bayes_fdi.atomic import atomic_path, check_output_path
from bayes_fdi.datasets import load_dataset, make_dataset, save_dataset
from bayes_fdi.rvm import RVR, load

WRITER = textwrap.dedent(
    """
    import sys
    import numpy as np
    from bayes_fdi.datasets import make_dataset, save_dataset

    rng = np.random.default_rng(0)
    # 6 channels x 40 runs x 20000 s of random values: ~38 MB that zlib compresses slowly
    ds = make_dataset({c: rng.random((40, 20000)) for c in ("CV", "P1", "P2", "T1", "X", "F")})
    print("writing", flush=True)
    save_dataset(ds, sys.argv[1])
    print("written", flush=True)
    """
)


def _temporaries(folder: Path, name: str) -> list[Path]:
    return sorted(folder.glob(f".{name}.*.tmp"))


def _default_signals() -> None:
    """In the child: SIGINT and SIGTERM at their defaults, whatever the test runner inherited
    (a background job or ``nohup`` starts with SIGINT ignored, and the child would inherit it)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _interrupt_while_writing(
    tmp_path: Path, sig: int, *, ignore: bool = False
) -> tuple[subprocess.Popen, float, str]:
    script = tmp_path / "writer.py"
    script.write_text(WRITER)
    target = tmp_path / "out.nc"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}

    def preexec() -> None:
        _default_signals()
        if ignore:
            signal.signal(sig, signal.SIG_IGN)

    proc = subprocess.Popen(
        [sys.executable, str(script), str(target)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        preexec_fn=preexec,
    )
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "writing"
    deadline = time.monotonic() + 60
    while not _temporaries(tmp_path, "out.nc"):  # the write has started
        assert proc.poll() is None, "the writer ended before its temporary file appeared"
        assert time.monotonic() < deadline
        time.sleep(0.005)
    # the temporary file must still be there when the signal is sent, i.e. mid-write
    proc.send_signal(sig)
    sent = time.monotonic()
    try:
        out, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:  # the reported deadlock
        proc.kill()
        proc.communicate()
        pytest.fail("the writer hung after the signal (deadlock)")
    return proc, time.monotonic() - sent, out + err


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_during_netcdf_write_leaves_nothing_and_exits(tmp_path, sig):
    proc, seconds, output = _interrupt_while_writing(tmp_path, sig)
    # the write was abandoned: no file at the destination, no temporary file left
    assert not (tmp_path / "out.nc").exists()
    assert _temporaries(tmp_path, "out.nc") == []
    assert "written" not in output
    if sig == signal.SIGINT:  # KeyboardInterrupt re-raised after the write's clean-up
        assert "KeyboardInterrupt" in output
        assert proc.returncode != 0
    else:  # the default SIGTERM disposition, re-delivered after the clean-up
        assert proc.returncode == -signal.SIGTERM
    # bounded by the write itself (the writer finishes it before acting on the signal); the
    # 60 s communicate() timeout above is the hang detector, this only documents the order
    assert seconds < 60


def test_ignored_signal_during_write_does_not_drop_the_file(tmp_path):
    """A process that ignores SIGINT (a background job, ``nohup``) finishes the write: the
    signal is not recorded, so the data are not silently abandoned."""
    proc, _, output = _interrupt_while_writing(tmp_path, signal.SIGINT, ignore=True)
    assert proc.returncode == 0
    assert "written" in output
    assert load_dataset(tmp_path / "out.nc").sizes["run"] == 40
    assert _temporaries(tmp_path, "out.nc") == []


def test_interrupted_cli_simulate_exits_130_without_output(tmp_path):
    """``bayes-fdi simulate`` interrupted during its netCDF write: exit 130, one line, no file."""
    campaign = tmp_path / "c.toml"
    campaign.write_text(
        textwrap.dedent(
            """
            [campaign]
            name = "big"
            seed = 1
            duration = 3000
            source = "benchmark-inputs"
            runs_per_state = 40
            states = ["fn", "f1"]
            """
        )
    )
    target = tmp_path / "sim.nc"
    proc = subprocess.Popen(
        [sys.executable, "-m", "bayes_fdi", "simulate", str(campaign), "--out", str(target),
         "--no-progress"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_default_signals,
    )  # fmt: skip
    deadline = time.monotonic() + 300
    while not _temporaries(tmp_path, "sim.nc"):
        if proc.poll() is not None:
            out, err = proc.communicate()
            pytest.fail(f"simulate ended before writing: {out}{err}")
        assert time.monotonic() < deadline
        time.sleep(0.002)
    proc.send_signal(signal.SIGINT)
    try:
        out, err = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        pytest.fail("bayes-fdi simulate hung after SIGINT")
    if target.exists():  # the write had already finished: the file must then be whole
        assert load_dataset(target).sizes["run"] == 80
    else:
        assert proc.returncode == 130
        assert err.strip().splitlines() == ["bayes-fdi simulate: interrupted"]
        assert "Traceback" not in err
    assert _temporaries(tmp_path, "sim.nc") == []


def test_failed_write_keeps_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "kept.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError, match="writer failed"), atomic_path(target) as tmp:
        Path(tmp).write_text("half")
        raise RuntimeError("writer failed")
    assert target.read_text() == "old"
    assert _temporaries(tmp_path, "kept.txt") == []


def test_atomic_file_gets_the_permissions_of_a_new_file(tmp_path):
    umask = os.umask(0o022)
    os.umask(umask)
    with atomic_path(tmp_path / "f.bin") as tmp:
        Path(tmp).write_bytes(b"x")
    assert (tmp_path / "f.bin").stat().st_mode & 0o777 == 0o666 & ~umask


def test_save_dataset_and_rvm_save_are_atomic_and_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    ds = make_dataset({"X": rng.random((2, 30)), "F": rng.random((2, 30))})
    save_dataset(ds, tmp_path / "d.nc")
    back = load_dataset(tmp_path / "d.nc")
    np.testing.assert_array_equal(back["X"].values, ds["X"].values)
    X = rng.uniform(-3, 3, (40, 1))
    model = RVR().fit(X, np.sin(X[:, 0]))
    model.save(tmp_path / "m.npz")
    np.testing.assert_array_equal(load(tmp_path / "m.npz").predict(X), model.predict(X))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.nc", "m.npz"]


def test_check_output_path_probes_the_folder(tmp_path):
    assert check_output_path(tmp_path / "a.nc", suffixes=(".nc",)) == str(tmp_path / "a.nc")
    with pytest.raises(ValueError, match=r"must end in \.nc"):
        check_output_path(tmp_path / "a.csv", suffixes=(".nc",))
    with pytest.raises(ValueError, match="is a folder"):
        check_output_path(tmp_path, suffixes=(".nc",))
    with pytest.raises(ValueError, match="does not exist"):
        check_output_path(tmp_path / "missing" / "a.nc")
    assert list(tmp_path.iterdir()) == []  # the probe left nothing

"""Catalogue of bad command lines: exit 2 for usage errors, 1 for runtime errors, one line.

Every entry gives the arguments (built in a temporary folder), the exit status and a pattern the
error line must match. Usage errors found by argparse print the usage and then one error line;
every other error is exactly one line, ``bayes-fdi COMMAND: error: MESSAGE``, with no traceback
(``--debug`` shows it). Every check happens before any long work: no case here simulates or fits.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest

from bayes_fdi.cli import main
from bayes_fdi.cli_arguments import UsageError
from bayes_fdi.datasets import make_dataset, save_dataset

SIM = Path(__file__).resolve().parents[1] / "sim"
CAMPAIGN = textwrap.dedent(
    """
    [campaign]
    name = "tiny"
    seed = 1
    duration = 30
    source = "benchmark-inputs"
    runs_per_state = 1
    states = ["fn", "f1"]
    """
)


def _unwritable_folder(tmp: Path) -> Path:
    """A folder where creating a file fails, also for root (sysfs refuses regular files)."""
    if os.geteuid() == 0:
        return Path("/sys")
    folder = tmp / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    return folder


def _campaign(tmp: Path, text: str = CAMPAIGN) -> str:
    path = tmp / "c.toml"
    path.write_text(text)
    return str(path)


def _dataset(tmp: Path) -> str:
    path = tmp / "d.nc"
    save_dataset(make_dataset({"X": np.full((2, 5), 0.5)}, state=["fn", "f1"]), path)
    return str(path)


def _garbage(tmp: Path, name: str) -> str:
    path = tmp / name
    path.write_bytes(b"\x00\xffgarbage" * 50)
    return str(path)


def _healthy_csv(tmp: Path, seconds: int = 1200, stuck_x: bool = False) -> str:
    """A fault-free recording of the shipped hour (normalised), its stem frozen if asked."""
    from bayes_fdi.datasets import load_lublin_example

    run = load_lublin_example().isel(run=0, time=slice(0, seconds))
    columns = {"time": run["time"].values, **{c: run[c].values for c in
               ("CV", "P1", "P2", "T1", "X", "F")}}  # fmt: skip
    if stuck_x:
        columns["X"] = np.full(seconds, 0.6)
    path = tmp / ("stuck.csv" if stuck_x else "healthy.csv")
    header = ",".join(columns)
    np.savetxt(path, np.column_stack(list(columns.values())), delimiter=",", header=header,
               comments="", fmt="%.6g")  # fmt: skip
    return str(path)


class CliCase(NamedTuple):
    argv: Callable[[Path], list[str]]
    status: int
    match: str


CLI_CASES: dict[str, CliCase] = {
    "unknown command": CliCase(lambda t: ["fly"], 2, "invalid choice: 'fly'"),
    "unknown option": CliCase(lambda t: ["rvm-demo", "--speed", "3"], 2, "unrecognized argum"),
    "simulate: missing campaign file": CliCase(
        lambda t: ["simulate", str(t / "none.toml"), "--out", str(t / "x.nc")],
        2,
        r"campaign: input file .*none.toml' does not exist",
    ),
    "simulate: campaign is a folder": CliCase(
        lambda t: ["simulate", str(t), "--out", str(t / "x.nc")], 2, "is a folder, not a file"
    ),
    "simulate: campaign not TOML": CliCase(
        lambda t: ["simulate", _garbage(t, "g.toml"), "--out", str(t / "x.nc")],
        2,
        "not valid TOML",
    ),
    "simulate: --out x.csv": CliCase(
        lambda t: ["simulate", _campaign(t), "--out", str(t / "x.csv")],
        2,
        r"--out: output file .*x.csv' must end in \.nc",
    ),
    "simulate: --out is a folder": CliCase(
        lambda t: ["simulate", _campaign(t), "--out", str(t)], 2, "is a folder, not a file"
    ),
    "simulate: --out in a missing folder": CliCase(
        lambda t: ["simulate", _campaign(t), "--out", str(t / "no" / "x.nc")],
        2,
        "does not exist",
    ),
    "simulate: --out in a read-only folder": CliCase(
        lambda t: ["simulate", _campaign(t), "--out", str(_unwritable_folder(t) / "x.nc")],
        2,
        "is not writable",
    ),
    "simulate: --seed -1": CliCase(
        lambda t: ["simulate", _campaign(t), "--out", str(t / "x.nc"), "--seed", "-1"],
        2,
        "--seed: must be an integer >= 0",
    ),
    "simulate: --seed text": CliCase(
        lambda t: ["simulate", _campaign(t), "--out", str(t / "x.nc"), "--seed", "abc"],
        2,
        "--seed: must be an integer >= 0, got 'abc'",
    ),
    "simulate: --set without =": CliCase(
        lambda t: ["simulate", _campaign(t), "--out", str(t / "x.nc"), "--set", "duration"],
        2,
        "--set expects KEY=VALUE",
    ),
    "simulate: --set duration=-5": CliCase(
        lambda t: ["simulate", _campaign(t), "--out", str(t / "x.nc"), "--set", "duration=-5"],
        2,
        "campaign.duration must be > 0, got -5",
    ),
    "simulate: unknown state": CliCase(
        lambda t: [
            "simulate",
            _campaign(t, CAMPAIGN.replace('"f1"', '"f42"')),
            "--out",
            str(t / "x.nc"),
        ],
        2,
        "campaign.states: unknown state 'f42'",
    ),
    "simulate: more memory than available": CliCase(
        lambda t: [
            "simulate",
            _campaign(t),
            "--out",
            str(t / "x.nc"),
            "--set",
            "duration=100000000000",
            "--set",
            "runs_per_state=1000",
        ],
        1,
        r"campaign tiny: 2000 run\(s\) x 100000000000 s needs about .* of memory",
    ),
    "plot: missing dataset": CliCase(
        lambda t: ["plot", str(t / "none.nc")], 2, "input file .*none.nc' does not exist"
    ),
    "plot: dataset not netCDF": CliCase(
        lambda t: ["plot", _garbage(t, "g.nc")], 1, "cannot read dataset"
    ),
    "plot: run out of range": CliCase(
        lambda t: ["plot", _dataset(t), "--runs", "9"], 2, "run 9 out of range"
    ),
    "plot: state not in the dataset": CliCase(
        lambda t: ["plot", _dataset(t), "--states", "f7"], 2, "no run with state 'f7'"
    ),
    "plot: channel not in the dataset": CliCase(
        lambda t: ["plot", _dataset(t), "--channels", "CV"], 2, r"\['CV'\] not in"
    ),
    "plot: unknown channel": CliCase(
        lambda t: ["plot", _dataset(t), "--channels", "Q"], 2, "invalid choice: 'Q'"
    ),
    "plot: --out .txt": CliCase(
        lambda t: ["plot", _dataset(t), "--out", str(t / "f.txt")], 2, r"must end in \.png"
    ),
    "plot: --out in a missing folder": CliCase(
        lambda t: ["plot", _dataset(t), "--out", str(t / "no" / "f.png")], 2, "does not exist"
    ),
    "plot: --dpi 0": CliCase(
        lambda t: ["plot", _dataset(t), "--dpi", "0"], 2, "--dpi: must be >= 1"
    ),
    "rvm-demo: --width foo": CliCase(
        lambda t: ["rvm-demo", "--width", "foo"], 2, "--width: must be a number > 0 or 'auto'"
    ),
    "rvm-demo: --width -1": CliCase(lambda t: ["rvm-demo", "--width", "-1"], 2, "got '-1'"),
    "rvm-demo: --width nan": CliCase(lambda t: ["rvm-demo", "--width", "nan"], 2, "got 'nan'"),
    "rvm-demo: --n 1": CliCase(lambda t: ["rvm-demo", "--n", "1"], 2, "--n: must be at least 2"),
    "rvm-demo: --n huge": CliCase(lambda t: ["rvm-demo", "--n", "10000000"], 2, "at most 100000"),
    "rvm-demo: --noise -0.1": CliCase(
        lambda t: ["rvm-demo", "--noise", "-0.1"], 2, "--noise: must be a finite number >= 0"
    ),
    "rvm-demo: --method": CliCase(
        lambda t: ["rvm-demo", "--method", "gibbs"], 2, "invalid choice: 'gibbs'"
    ),
    "rvm-demo: --seed -3": CliCase(lambda t: ["rvm-demo", "--seed", "-3"], 2, "must be >= 0"),
    "reproduce: unknown campaign": CliCase(
        lambda t: [
            "reproduce",
            "--out",
            str(t / "o"),
            "--campaign",
            "nonexistent",
            "--no-progress",
        ],
        2,
        "--campaign: campaign 'nonexistent' not found",
    ),
    "reproduce: unknown state": CliCase(
        lambda t: ["reproduce", "--out", str(t / "o"), "--states", "fn,f42"],
        2,
        r"unknown state\(s\) \['f42'\]",
    ),
    "fit --normal: a stuck stem": CliCase(
        lambda t: ["fit", "--normal", _healthy_csv(t, stuck_x=True), "--out", str(t / "m.npz")],
        1,
        r"X hardly moves in the healthy data \(standard deviation \S+ of full scale.*stuck stem",
    ),
    "fit --normal: too short": CliCase(
        lambda t: ["fit", "--normal", _healthy_csv(t, seconds=300), "--out", str(t / "m.npz")],
        1,
        r"only 300 complete seconds of healthy data.*at least 900 s",
    ),
    "calibration-report: missing dataset": CliCase(
        lambda t: [
            "calibration-report",
            "--train",
            str(t / "none.nc"),
            "--test",
            str(t / "none.nc"),
            "--out",
            str(t / "o"),
        ],
        1,
        "dataset file does not exist",
    ),
}


def test_the_cli_catalogue_is_large():
    assert len(CLI_CASES) >= 30


@pytest.mark.parametrize("name", list(CLI_CASES))
def test_bad_command_line(name, tmp_path, capsys):
    case = CLI_CASES[name]
    status = main(case.argv(tmp_path))
    err = capsys.readouterr().err
    assert status == case.status, err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.strip()]
    if not lines[0].startswith("usage:"):  # not an argparse error: exactly one line
        assert len(lines) == 1, err
    assert lines[-1].startswith("bayes-fdi") and ": error: " in lines[-1], err
    assert re.search(case.match, lines[-1]), lines[-1]
    assert "np.str_" not in err
    assert not list(tmp_path.rglob("*.tmp")), "a temporary file was left behind"


def test_debug_shows_the_traceback(tmp_path):
    argv = ["simulate", _campaign(tmp_path), "--out", str(tmp_path / "x.nc"), "--set",
            "duration=-5"]  # fmt: skip
    with pytest.raises(UsageError, match=r"campaign\.duration"):
        main(["--debug", *argv])
    with pytest.raises(UsageError, match=r"campaign\.duration"):
        main([*argv, "--debug"])


def test_the_installed_command_prints_one_line_and_no_traceback(tmp_path):
    """The real entry point (a subprocess): exit status and stderr as a user sees them."""
    cmd = [sys.executable, "-m", "bayes_fdi", "simulate", _campaign(tmp_path), "--out",
           str(tmp_path / "x.nc"), "--set", "duration=-5"]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        f"bayes-fdi simulate: error: {tmp_path / 'c.toml'}: campaign.duration must be > 0, got -5"
    ]
    debug = subprocess.run([*cmd, "--debug"], capture_output=True, text=True, timeout=120)
    assert debug.returncode == 1 and "Traceback" in debug.stderr
    assert "UsageError" in debug.stderr


def test_output_errors_come_before_the_simulation(tmp_path, capsys, monkeypatch):
    """A bad --out is found while parsing: the (3800-run) simulation is never started."""
    from bayes_fdi.campaigns import simulation as campaigns

    def must_not_run(*args, **kwargs):
        raise AssertionError("simulate_campaign was called before the output path was checked")

    monkeypatch.setattr(campaigns, "simulate_campaign", must_not_run)
    status = main(["simulate", str(SIM / "paper-simulated.toml"), "--out", str(tmp_path)])
    assert status == 2
    assert "is a folder" in capsys.readouterr().err
    status = main(["simulate", str(SIM / "paper-simulated.toml"), "--out", str(tmp_path / "a.csv")])
    assert status == 2
    assert "must end in .nc" in capsys.readouterr().err

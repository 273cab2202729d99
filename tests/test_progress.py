"""Progress on stderr (bayes_fdi.progress): refreshed frames on a terminal, plain lines in a log."""

from __future__ import annotations

import subprocess
import sys
import time

from bayes_fdi.progress import PlainProgress, busy, progress_bar


def test_plain_lines_when_stderr_is_a_file(capsys):
    bar = progress_bar(8, "simulating", unit="run")
    assert isinstance(bar, PlainProgress)  # pytest's captured stderr is not a terminal
    for _ in range(8):
        bar.update(1)
    bar.close()
    with busy("fitting"):
        time.sleep(0.01)
    err = capsys.readouterr().err
    assert "\r" not in err
    lines = err.splitlines()
    assert lines[0] == "simulating: 0 of 8 run"
    assert [line.split(":")[1].split(" in ")[0].strip() for line in lines[1:4]] == [
        "2 of 8 run",
        "4 of 8 run",
        "6 of 8 run",
    ]
    assert "left" in lines[1] and lines[4].startswith("simulating: 8 run in ")
    assert lines[5] == "fitting ..." and lines[6].startswith("fitting: done in ")


def test_a_long_step_says_it_is_still_running(capsys):
    """In a log, a step longer than the heartbeat writes a line each heartbeat, never a frame."""
    with busy("fitting", heartbeat=0.05):
        time.sleep(0.28)
    lines = capsys.readouterr().err.splitlines()
    assert lines[0] == "fitting ..." and lines[-1].startswith("fitting: done in ")
    beats = lines[1:-1]
    # 0.28 s at one line per 0.05 s: at most 5 beats; a loaded machine may delay some
    assert 1 <= len(beats) <= 5
    assert all(line.startswith("fitting: still running, ") for line in beats)


def test_a_command_logs_plain_lines_to_a_file(tmp_path):
    """``bayes-fdi simulate`` with stderr redirected to a file writes no carriage return."""
    campaign = tmp_path / "c.toml"
    campaign.write_text(
        '[campaign]\nname = "t"\nseed = 1\nduration = 20\nsource = "benchmark-inputs"\n'
        'runs_per_state = 2\nstates = ["fn"]\n'
    )
    log = tmp_path / "log.txt"
    with open(log, "w") as err:
        subprocess.run(
            [
                sys.executable,
                "-m",
                "bayes_fdi",
                "simulate",
                str(campaign),
                "--out",
                str(tmp_path / "c.nc"),
            ],
            stderr=err,
            check=True,
            timeout=300,
        )
    text = log.read_text()
    assert "simulating" in text and "\r" not in text

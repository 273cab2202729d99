"""The ``rvm-demo`` command: runs fast and reports a sparse, accurate fit."""

from __future__ import annotations

import re

from bayes_fdi.cli import main


def test_rvm_demo_cli(capsys):
    assert main(["rvm-demo", "--n", "200", "--seed", "1"]) == 0
    out = capsys.readouterr().out
    n_rv = int(re.search(r"relevance vectors : (\d+) of 200", out).group(1))
    rmse = float(re.search(r"RMSE vs sinc\s+: ([0-9.]+)", out).group(1))
    noise = float(re.search(r"noise sd estimate : ([0-9.]+)", out).group(1))
    seconds = float(re.search(r"fit time\s+: ([0-9.]+) s", out).group(1))
    assert 2 <= n_rv <= 20
    assert rmse < 0.05  # noise sd 0.1, 200 points
    assert 0.08 < noise < 0.12
    assert seconds > 0.0
    assert re.search(r"log evidence\s+: -?[0-9.]+", out)

"""The command line wiring."""

from bayes_fdi import __version__
from bayes_fdi.cli import COMMANDS, main


def test_version(capsys):
    assert main(["--version"]) == 0
    assert __version__ in capsys.readouterr().out


def test_no_command_prints_help(capsys):
    assert main([]) == 2
    out = capsys.readouterr().out
    for name in COMMANDS:
        assert name in out


_HELP_AND_LIST_MODULES = """
import json, sys
from bayes_fdi.cli import main
try:
    status = main([sys.argv[1], "--help"])
except SystemExit as exc:
    status = exc.code
print(json.dumps({"status": status, "modules": sorted(sys.modules)}))
"""


def test_help_of_every_command_loads_neither_torch_nor_numba():
    """``bayes-fdi COMMAND --help`` answers without importing the numerical stack: torch and
    numba take seconds to import, and help and usage errors should not wait for them."""
    import json
    import subprocess
    import sys

    slow = {}
    for name in COMMANDS:
        proc = subprocess.run(
            [sys.executable, "-c", _HELP_AND_LIST_MODULES, name],
            capture_output=True,
            text=True,
            check=True,
        )
        result = json.loads(proc.stdout.splitlines()[-1])
        assert result["status"] == 0, name
        heavy = sorted({m.split(".")[0] for m in result["modules"]} & {"torch", "numba", "pyro"})
        if heavy:
            slow[name] = heavy
    assert slow == {}


def test_benchmark_help_states_the_commissioning_benchmark_settings():
    from bayes_fdi.benchmark.commissioning import FULL, SMALL
    from bayes_fdi.commands.benchmark import PLANTS_FULL, PLANTS_SMALL

    assert (PLANTS_FULL, PLANTS_SMALL) == (FULL["plants"], SMALL["plants"])

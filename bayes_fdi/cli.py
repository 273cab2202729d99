"""The ``bayes-fdi`` command line.

Each sub-command lives in the module that owns its concept; this file only
wires them together. A command module provides two functions::

    configure_parser(parser: argparse.ArgumentParser) -> None
    run_from_cli(args: argparse.Namespace) -> int

and is imported only when its command runs (``--help`` of the top level stays fast).
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

#: command name -> (module path, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "simulate": (
        "bayes_fdi.experiments.campaigns",
        "simulate a campaign TOML file into a netCDF dataset",
    ),
    "plot": ("bayes_fdi.datasets.plotting", "plot the signals of chosen runs of a dataset"),
    "reproduce": ("bayes_fdi.experiments.reproduce", "reproduce the paper's tables (the main job)"),
    "calibration-report": (
        "bayes_fdi.calibration.report",
        "write a calibration report for a diagnoser on a test dataset",
    ),
    "benchmark": (
        "bayes_fdi.experiments.benchmark",
        "score the online diagnoser on the DAMADICS benchmark's 44 scenarios (PICalc indices)",
    ),
    "rvm-demo": ("bayes_fdi.rvm.demo", "fit an RVM on a small sinc problem and print it"),
}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """Build the parser; the sub-parser of ``command`` (if given) is fully configured."""
    from bayes_fdi import __version__

    parser = argparse.ArgumentParser(
        prog="bayes-fdi",
        description="Bayesian fault detection and isolation for SEVA pneumatic actuators.",
    )
    parser.add_argument("--version", action="version", version=f"bayes_fdi {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module_path, help_text) in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        if name == command:
            module = importlib.import_module(module_path)
            module.configure_parser(p)
            p.set_defaults(_module=module)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``bayes-fdi``."""
    argv = list(sys.argv[1:] if argv is None else argv)
    command = next((a for a in argv if a in COMMANDS), None)
    parser = build_parser(command)
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    return int(args._module.run_from_cli(args) or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

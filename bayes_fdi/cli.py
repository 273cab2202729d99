"""The ``bayes-fdi`` command line.

Each sub-command lives in the module that owns its concept; this file only
wires them together. A command module provides two functions::

    configure_parser(parser: argparse.ArgumentParser) -> None
    run_from_cli(args: argparse.Namespace) -> int

and is imported only when its command runs (``--help`` of the top level stays fast).

Error conventions (every command): exit status 2 for a bad command line (an argparse error, or a
:class:`~bayes_fdi.cli_arguments.UsageError` raised by the command), 1 for an error while the
command runs, 130 when interrupted (Ctrl-C); the error is one line on stderr,
``bayes-fdi COMMAND: error: MESSAGE``, with no traceback unless ``--debug`` is given (before or
after the command name).
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from bayes_fdi.cli_arguments import UsageError

#: command name -> (module path, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "simulate": (
        "bayes_fdi.campaigns.simulation",
        "simulate a campaign TOML file into a netCDF dataset",
    ),
    "plot": ("bayes_fdi.datasets.plotting", "plot the signals of chosen runs of a dataset"),
    "reproduce": ("bayes_fdi.commands.reproduce", "reproduce the paper's tables (the main job)"),
    "calibration-report": (
        "bayes_fdi.commands.calibration_report",
        "write a calibration report for a diagnoser on a test dataset",
    ),
    "benchmark": (
        "bayes_fdi.commands.benchmark",
        "score the online diagnoser on the DAMADICS benchmark's 44 scenarios (PICalc indices); "
        "--commissioning: commissioned diagnosers on the real hour and perturbed plants",
    ),
    "rvm-demo": ("bayes_fdi.commands.rvm_demo", "fit an RVM on a small sinc problem and print it"),
    "fit": ("bayes_fdi.deployment.fitting", "fit an online diagnoser and save it to a file"),
    "commission": (
        "bayes_fdi.deployment.commission",
        "learn a valve from its healthy recordings: normal models, digital twin, fault library",
    ),
    "diagnose": ("bayes_fdi.deployment.diagnose", "diagnose recordings, 1 s at a time"),
    "serve": (
        "bayes_fdi.deployment.serve.service",
        "diagnose valves live over OPC UA: read the plant, publish SEVA records, log, live page",
    ),
    "simulate-plant": (
        "bayes_fdi.deployment.serve.plant_simulator",
        "run the actuator model as an OPC UA plant server (1 Hz or faster, scheduled faults)",
    ),
}


_DEBUG_HELP = "on an error, show the full traceback instead of a one-line message"


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """Build the parser; the sub-parser of ``command`` (if given) is fully configured."""
    from bayes_fdi import __version__

    parser = argparse.ArgumentParser(
        prog="bayes-fdi",
        description="Bayesian fault detection and isolation for SEVA pneumatic actuators.",
    )
    parser.add_argument("--version", action="version", version=f"bayes_fdi {__version__}")
    parser.add_argument("--debug", action="store_true", help=_DEBUG_HELP)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module_path, help_text) in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help=_DEBUG_HELP)
        if name == command:
            module = importlib.import_module(module_path)
            module.configure_parser(p)
            p.set_defaults(_module=module)
    return parser


def _one_line(exc: BaseException) -> str:
    """The message of ``exc`` on one line (an OSError as 'reason: path')."""
    if isinstance(exc, OSError) and exc.strerror:
        text = exc.strerror + (f": {exc.filename!r}" if exc.filename else "")
    else:
        text = str(exc) or type(exc).__name__
        if isinstance(exc, KeyError):  # str(KeyError) is the repr of the key
            text = f"missing key {text}"
    return " ".join(text.split())


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``bayes-fdi``; returns the exit status (see the module docstring)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    command = next((a for a in argv if a in COMMANDS), None)
    parser = build_parser(command)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help/--version (0) or a usage error (2)
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    if args.command is None:
        parser.print_help()
        return 2
    prefix = f"bayes-fdi {args.command}"
    try:
        return int(args._module.run_from_cli(args) or 0)
    except KeyboardInterrupt:
        if args.debug:
            raise
        print(f"{prefix}: interrupted", file=sys.stderr)
        return 130
    except SystemExit as exc:
        if isinstance(exc.code, int | None) or args.debug:
            raise
        print(f"{prefix}: error: {' '.join(str(exc.code).split())}", file=sys.stderr)
        return 2
    except UsageError as exc:
        if args.debug:
            raise
        print(f"{prefix}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except Exception as exc:
        if args.debug:
            raise
        print(f"{prefix}: error: {_one_line(exc)} (--debug shows the traceback)", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

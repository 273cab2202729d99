"""The command line's argument contract, shared by the command modules of every layer.

- :class:`UsageError`: raised by a command's ``run_from_cli`` for a bad command line found after
  parsing (a value that needs more than its own text to check); ``bayes-fdi`` exits with status 2
  and a one-line message. Any other error of a running command exits with status 1.
- argparse ``type=`` functions that check an argument *while parsing*, before any work:
  :func:`input_file`, :func:`output_file` (e.g. ``output_file(".nc")``), :func:`output_folder`,
  :func:`positive_int`, :func:`non_negative_int`, :func:`non_negative_float`. A bad value is an
  argparse error: usage line, one-line message, exit status 2.
- `ISOLATION_CHOICES`: the choices of every ``--isolation`` option.
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable

from bayes_fdi.atomic import check_output_path

__all__ = [
    "ISOLATION_CHOICES",
    "UsageError",
    "input_file",
    "non_negative_float",
    "non_negative_int",
    "output_file",
    "output_folder",
    "positive_int",
]


#: The isolation classifiers a command can commission with: the names of
#: `bayes_fdi.commissioning.commission.ISOLATION_CLASSIFIERS`, written here so that parsing a
#: command line imports no model code (the tests hold the two equal).
ISOLATION_CHOICES: tuple[str, ...] = ("tree", "forest")


class UsageError(ValueError):
    """A bad command line (exit status 2); the message names the argument and the problem."""


def input_file(text: str) -> str:
    """An existing, readable file (not a folder)."""
    if not text:
        raise argparse.ArgumentTypeError("the input path is empty")
    if not os.path.exists(text):
        raise argparse.ArgumentTypeError(f"input file {text!r} does not exist")
    if os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"input {text!r} is a folder, not a file")
    if not os.access(text, os.R_OK):
        raise argparse.ArgumentTypeError(f"input file {text!r} is not readable")
    return text


def output_file(*suffixes: str) -> Callable[[str], str]:
    """An argparse type: a writable file path ending in one of ``suffixes`` (any if none)."""

    def check(text: str) -> str:
        try:
            return check_output_path(text, suffixes=suffixes)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    check.__name__ = "output file"
    return check


def output_folder(text: str) -> str:
    """A folder that exists and is writable, or that can be created (its parent is writable)."""
    if not text:
        raise argparse.ArgumentTypeError("the output folder path is empty")
    path = os.path.abspath(text)
    if os.path.exists(path) and not os.path.isdir(path):
        raise argparse.ArgumentTypeError(f"output folder {text!r} is a file")
    existing = path
    while not os.path.exists(existing):
        existing = os.path.dirname(existing)
    if not os.path.isdir(existing):
        raise argparse.ArgumentTypeError(f"output folder {text!r}: {existing!r} is a file")
    try:
        check_output_path(os.path.join(existing, "probe"), what="output folder")
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"output folder {text!r}: {existing!r} is not writable"
        ) from None
    return text


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None


def positive_int(text: str) -> int:
    """An integer >= 1."""
    value = _integer(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def non_negative_int(text: str) -> int:
    """An integer >= 0."""
    value = _integer(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def non_negative_float(text: str) -> float:
    """A finite number >= 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text!r}")
    return value

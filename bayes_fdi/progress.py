"""Progress shown on stderr for steps that report none of their own.

Loops with a known length use :func:`progress_bar`: a ``tqdm`` bar on a terminal, plain lines
elsewhere (at the start, every quarter and at the end, each with the time so far and the
estimated time left). :func:`busy` is for one long call that cannot
report its progress (an RVM fit, a report being written): a tqdm line with the step's name and
the elapsed time, refreshed by a background thread until the call returns, then closed with the
time it took. When stderr is not a terminal (a log file, a pipe) it writes plain lines instead
of refreshed frames: one when the step starts, one when it ends with the time it took.
``enabled=False`` (the commands' ``--quiet``) shows nothing.

Written by hand: tqdm has no "elapsed time of one call" display; this is a tqdm bar refreshed
from a thread (a dozen lines).
"""

from __future__ import annotations

import contextlib
import sys
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

__all__ = ["PlainProgress", "busy", "progress_bar"]


def _terminal() -> bool:
    """Whether stderr is a terminal (where refreshed frames read well)."""
    return bool(getattr(sys.stderr, "isatty", lambda: False)())


@contextlib.contextmanager
def busy(
    desc: str, *, enabled: bool = True, interval: float = 0.5, heartbeat: float = 20.0
) -> Iterator[None]:
    """Show ``desc`` and the elapsed time on stderr while the block runs.

    Parameters
    ----------
    desc
        What is running, e.g. ``"fitting the diagnoser"``.
    enabled
        ``False``: show nothing.
    interval
        Seconds between refreshes.
    heartbeat
        When stderr is not a terminal (a log file, a pipe): seconds between the plain lines
        that say the step is still running (no ``\\r`` frames).
    """
    if not enabled:
        yield
        return
    if not _terminal():
        yield from _plain_busy(desc, heartbeat)
        return
    from tqdm.auto import tqdm

    bar = tqdm(total=None, desc=desc, bar_format="{desc}: {elapsed}", leave=True)
    try:
        with _every(interval, bar.refresh):
            yield
    finally:
        bar.close()


def _plain_busy(desc: str, heartbeat: float) -> Iterator[None]:
    """`busy` for a log file: a line at the start, one every ``heartbeat`` s, one at the end."""
    start = time.perf_counter()
    print(f"{desc} ...", file=sys.stderr, flush=True)

    def beat() -> None:
        elapsed = time.perf_counter() - start
        print(f"{desc}: still running, {elapsed:.0f} s", file=sys.stderr, flush=True)

    with _every(heartbeat, beat):
        yield
    print(f"{desc}: done in {time.perf_counter() - start:.1f} s", file=sys.stderr, flush=True)


@contextlib.contextmanager
def _every(seconds: float, action: Callable[[], None]) -> Iterator[None]:
    """Call ``action`` every ``seconds`` from a background thread while the block runs."""
    stop = threading.Event()

    def loop() -> None:
        while not stop.wait(seconds):
            action()

    ticker = threading.Thread(target=loop, name="bayes_fdi-busy", daemon=True)
    ticker.start()
    try:
        yield
    finally:
        stop.set()
        ticker.join()


class PlainProgress:
    """A progress report in plain lines, for stderr that is not a terminal: the tqdm calls
    ``update`` and ``close`` print a line at the start, at every quarter and at the end."""

    def __init__(self, total: float, desc: str, unit: str) -> None:
        self.total, self.desc, self.unit = float(total), desc, unit
        self.done, self.quarter = 0.0, 0
        self.start = time.perf_counter()
        print(f"{desc}: 0 of {total:g} {unit}", file=sys.stderr, flush=True)

    def update(self, n: float = 1) -> None:
        """Count ``n`` more; print a line when a further quarter is done."""
        self.done += n
        quarter = int(4 * self.done / self.total) if self.total else 4
        if 0 < quarter < 4 and quarter > self.quarter:
            self.quarter = quarter
            elapsed = time.perf_counter() - self.start
            left = elapsed * (self.total - self.done) / self.done
            print(
                f"{self.desc}: {self.done:g} of {self.total:g} {self.unit} in {elapsed:.0f} s, "
                f"about {left:.0f} s left",
                file=sys.stderr,
                flush=True,
            )

    def close(self) -> None:
        """Print the closing line."""
        elapsed = time.perf_counter() - self.start
        print(
            f"{self.desc}: {self.done:g} {self.unit} in {elapsed:.1f} s",
            file=sys.stderr,
            flush=True,
        )


def progress_bar(total: float, desc: str, *, unit: str = "it", leave: bool = True) -> Any:
    """A progress bar over ``total`` steps: tqdm on a terminal, `PlainProgress` elsewhere."""
    if not _terminal():
        return PlainProgress(total, desc, unit)
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit=unit, leave=leave)

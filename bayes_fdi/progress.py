"""Progress shown on stderr for steps that report none of their own.

Loops with a known length use ``tqdm`` directly. :func:`busy` is for one long call that cannot
report its progress (an RVM fit, a report being written): a tqdm line with the step's name and
the elapsed time, refreshed by a background thread until the call returns, then closed with the
time it took. ``enabled=False`` (the commands' ``--quiet``) shows nothing.

Written by hand: tqdm has no "elapsed time of one call" display; this is a tqdm bar refreshed
from a thread (a dozen lines).
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator

__all__ = ["busy"]


@contextlib.contextmanager
def busy(desc: str, *, enabled: bool = True, interval: float = 0.5) -> Iterator[None]:
    """Show ``desc`` and the elapsed time on stderr while the block runs.

    Parameters
    ----------
    desc
        What is running, e.g. ``"fitting the diagnoser"``.
    enabled
        ``False``: show nothing.
    interval
        Seconds between refreshes.
    """
    if not enabled:
        yield
        return
    from tqdm.auto import tqdm

    bar = tqdm(total=None, desc=desc, bar_format="{desc}: {elapsed}", leave=True)
    stop = threading.Event()

    def refresh() -> None:
        while not stop.wait(interval):
            bar.refresh()

    ticker = threading.Thread(target=refresh, name="bayes_fdi-busy", daemon=True)
    ticker.start()
    try:
        yield
    finally:
        stop.set()
        ticker.join()
        bar.close()

"""Atomic file output: every file the library writes appears whole or not at all.

:func:`atomic_path` hands a writer a temporary path in the destination's folder; when the writer
returns, the temporary file is flushed to disk (``fsync``), given the permissions a new file would
get (``0o666`` less the umask) and renamed over the destination (``os.replace``, atomic on POSIX
and Windows within one file system), and the folder is synced. If the writer raises, the temporary
file is removed and the destination is left as it was.

``SIGINT`` (Ctrl-C) and ``SIGTERM`` are *deferred* while the writer runs (main thread only): a
signal arriving mid-write is recorded, the write finishes and its files are closed, the temporary
file is removed (the write is abandoned: an interrupted command leaves no output), and the signal
is then re-delivered with the handler that was in place before (``KeyboardInterrupt`` for
``SIGINT``, process termination for a default ``SIGTERM``). Raising ``KeyboardInterrupt`` inside a
netCDF write instead leaves xarray's file-manager lock held and the process deadlocks in its
clean-up, which is why the write is never interrupted half-way.

:func:`atomic_folder` does the same for a folder of files written together (a diagnosed
recording's outputs): they are written into a hidden folder beside the destination, which then
replaces the destination as a whole, so an interruption leaves the old folder or the new one,
never a mix.

:func:`write_text` and :func:`save_figure` are the two writes most modules need.

:func:`check_output_path` validates a destination before any long work (the command line calls it
before simulating or fitting).

Written by hand: the standard library has the pieces (``tempfile``, ``os.replace``, ``signal``)
but no atomic-replace helper; no dependency provides one.
"""

from __future__ import annotations

import contextlib
import os
import signal
import tempfile
import threading
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

__all__ = [
    "atomic_folder",
    "atomic_path",
    "check_output_path",
    "deferred_signals",
    "save_figure",
    "write_text",
]

#: Signals deferred during a write.
DEFERRED_SIGNALS: tuple[int, ...] = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def deferred_signals(signals: Sequence[int] = DEFERRED_SIGNALS) -> Iterator[list[int]]:
    """Record ``signals`` instead of acting on them inside the block; re-deliver them after.

    Yields the list of signals received so far (the caller may look at it). On exit the previous
    handlers are restored and every recorded signal is raised again, once, in arrival order. Off
    the main thread (where Python cannot install handlers) the block runs unchanged. A signal the
    process ignores (``SIG_IGN``, e.g. SIGINT of a background job or under ``nohup``) stays
    ignored: recording it would make the caller abandon work that nothing will stop.
    """
    if threading.current_thread() is not threading.main_thread():
        yield []
        return
    received: list[int] = []

    def record(signum: int, frame: object) -> None:
        if signum not in received:
            received.append(signum)

    previous = {}
    for sig in signals:
        handler = signal.getsignal(sig)
        if handler is signal.SIG_IGN:
            continue
        previous[sig] = handler
        signal.signal(sig, record)
    try:
        yield received
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)
        for sig in received:
            signal.raise_signal(sig)


def _new_file_mode() -> int:
    umask = os.umask(0o022)
    os.umask(umask)
    return 0o666 & ~umask


def _fsync_dir(folder: str) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # e.g. Windows: folders cannot be opened
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[str]:
    """Yield a temporary path next to ``path``; move it over ``path`` if the block succeeds.

    Parameters
    ----------
    path
        The destination file. Its folder must exist and be writable.

    Yields
    ------
    str
        A fresh, empty temporary file in the same folder (hidden name ``.NAME.XXXX.tmp``) for
        the writer to overwrite.

    Raises
    ------
    OSError
        If the temporary file cannot be created (the folder is missing or read-only), or the
        write or the rename fails. The destination is then unchanged and no temporary file is
        left behind.
    """
    final = os.path.abspath(os.fspath(path))
    folder, name = os.path.split(final)
    with deferred_signals() as received:
        fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=folder)
        os.close(fd)
        committed = False
        try:
            yield tmp
            if not received:
                fd = os.open(tmp, os.O_RDONLY)
                try:
                    os.fsync(fd)
                finally:
                    os.close(fd)
                os.chmod(tmp, _new_file_mode())
                os.replace(tmp, final)
                committed = True
                _fsync_dir(folder)
        finally:
            if not committed:
                with contextlib.suppress(FileNotFoundError):
                    os.remove(tmp)


@contextlib.contextmanager
def atomic_folder(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Write a folder as a whole: yields a hidden empty folder beside ``path`` to fill.

    When the block returns, the new folder replaces ``path`` (an older folder there is moved
    aside and removed; the swap runs with ``SIGINT``/``SIGTERM`` deferred and the parent folder
    synced); if the block raises, the new folder is removed and ``path`` is left as it was.
    """
    import shutil

    destination = Path(path)
    parent = destination.parent
    parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{destination.name}.", suffix=".partial", dir=parent))
    try:
        yield staging
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    old = None
    with deferred_signals():
        if destination.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{destination.name}.", suffix=".old", dir=parent))
            os.replace(destination, old / destination.name)
        os.replace(staging, destination)
        _fsync_dir(os.fspath(parent))
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; return the path."""
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as handle:
        handle.write(text)
    return Path(path)


def save_figure(fig: Any, path: str | os.PathLike[str], **savefig_kwargs: Any) -> Path:
    """Write a matplotlib figure to ``path`` atomically and close it; return the path.

    The format follows the file name's suffix (``.png``, ``.svg``, ``.pdf``); ``savefig_kwargs``
    go to :meth:`matplotlib.figure.Figure.savefig` (e.g. ``dpi``).
    """
    import matplotlib.pyplot as plt

    suffix = Path(path).suffix.lstrip(".").lower() or None
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format=suffix, **savefig_kwargs)
    finally:
        plt.close(fig)
    return Path(path)


def check_output_path(
    path: str | os.PathLike[str], *, suffixes: Sequence[str] = (), what: str = "output file"
) -> str:
    """Check, before any long work, that a file can be written at ``path``.

    Parameters
    ----------
    path
        The destination.
    suffixes
        Allowed file-name endings (e.g. ``(".nc",)``); empty: any.
    what
        How the message names the file.

    Returns
    -------
    str
        ``path`` as a string.

    Raises
    ------
    ValueError
        If the name does not end in one of ``suffixes``, ``path`` is a folder, its folder does
        not exist or is not a folder, or the folder (or an existing file at ``path``) is not
        writable.
    """
    text = os.fspath(path)
    if not text:
        raise ValueError(f"{what}: the path is empty")
    if os.path.isdir(text):
        raise ValueError(f"{what} {text!r} is a folder, not a file")
    if suffixes and not text.lower().endswith(tuple(s.lower() for s in suffixes)):
        raise ValueError(
            f"{what} {text!r} must end in {' or '.join(suffixes)} "
            f"(the format is chosen by the file name)"
        )
    folder = os.path.dirname(os.path.abspath(text))
    if not os.path.exists(folder):
        raise ValueError(f"{what} {text!r}: folder {folder!r} does not exist")
    if not os.path.isdir(folder):
        raise ValueError(f"{what} {text!r}: {folder!r} is not a folder")
    try:  # a probe: permission bits do not tell for root, ACLs or read-only file systems
        fd, probe = tempfile.mkstemp(prefix=".write-probe.", suffix=".tmp", dir=folder)
    except OSError as exc:
        raise ValueError(
            f"{what} {text!r}: folder {folder!r} is not writable ({exc.strerror})"
        ) from None
    os.close(fd)
    os.remove(probe)
    if os.path.exists(text) and not os.access(text, os.W_OK):
        raise ValueError(f"{what} {text!r} exists and is read-only")
    return text

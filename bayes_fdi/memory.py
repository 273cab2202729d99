"""Memory checked before large allocations: a clear error up front, not a late ``MemoryError``.

:func:`check_memory` compares an estimate of the bytes a step will allocate with the memory
available now (Linux: ``MemAvailable`` of ``/proc/meminfo`` and the cgroup limit; elsewhere the
physical memory) and raises :class:`InsufficientMemoryError` naming both. Where the available
memory cannot be read, nothing is checked.

Written by hand: reading ``/proc/meminfo`` and the cgroup limit is a few lines; the dependencies
offer no portable "available memory" (psutil is not one of them).
"""

from __future__ import annotations

import os

__all__ = ["InsufficientMemoryError", "available_memory", "check_memory", "format_bytes"]


class InsufficientMemoryError(MemoryError):
    """The estimated memory of a step exceeds the memory available; the message states both."""


def _meminfo_available() -> int | None:
    try:
        with open("/proc/meminfo", encoding="ascii") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _cgroup_limit() -> int | None:
    for path, usage_path in (
        ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
        (
            "/sys/fs/cgroup/memory/memory.limit_in_bytes",
            "/sys/fs/cgroup/memory/memory.usage_in_bytes",
        ),
    ):
        try:
            with open(path, encoding="ascii") as handle:
                text = handle.read().strip()
            if text == "max":
                return None
            limit = int(text)
            if limit >= 1 << 60:  # cgroup v1 "unlimited"
                return None
            try:
                with open(usage_path, encoding="ascii") as handle:
                    used = int(handle.read().strip())
            except (OSError, ValueError):
                used = 0
            return max(limit - used, 0)
        except (OSError, ValueError):
            continue
    return None


def available_memory() -> int | None:
    """Bytes of memory available to this process now, or ``None`` where it cannot be told."""
    candidates = [v for v in (_meminfo_available(), _cgroup_limit()) if v is not None]
    if not candidates:
        try:
            candidates = [os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")]
        except (ValueError, OSError, AttributeError):
            return None
    return min(candidates)


def format_bytes(n: float) -> str:
    """``n`` bytes in the largest unit that keeps the number >= 1 (``"3.2 GB"``)."""
    value = float(n)
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if abs(value) < 1000.0 or unit == "PB":
            return f"{value:.3g} {unit}"
        value /= 1000.0
    return f"{value:.3g} PB"  # pragma: no cover


def check_memory(n_bytes: float, what: str) -> None:
    """Raise :class:`InsufficientMemoryError` if ``n_bytes`` exceed the memory available.

    Parameters
    ----------
    n_bytes
        Estimated peak allocation of the step (bytes).
    what
        The step, for the message (e.g. ``"simulate: 200 runs x 100000000 s"``).
    """
    available = available_memory()
    if available is not None and n_bytes > available:
        raise InsufficientMemoryError(
            f"{what} needs about {format_bytes(n_bytes)} of memory, more than the "
            f"{format_bytes(available)} available; use fewer or shorter runs"
        )

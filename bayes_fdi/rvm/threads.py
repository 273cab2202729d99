"""Thread limits inside the fits: small dense linear algebra runs fastest on one thread.

The RVM solvers work on matrices of a few hundred columns at most and spend their time in many
small products and rank-one updates; on those, a second BLAS thread costs more in
synchronisation than it gains (the README's five-line example: 15 s with the default two threads,
5.4 s with one, on a 2-core machine). :func:`fit_threads` runs a block with torch's intra-op
pool and every BLAS/OpenMP pool that threadpoolctl can reach (OpenBLAS behind numpy and scipy)
limited to :func:`get_fit_threads` threads, and restores the caller's settings afterwards;
:func:`limit_fit_threads` applies it to a ``fit`` method. Thread counts also fix the order of
summation in a product, so the same seed gives the same fit however many threads the caller's
process uses.

The limits are set in the thread that fits, and restored there when the fit ends.

Imports torch and threadpoolctl only.
"""

from __future__ import annotations

import contextlib
import functools
import sys
import threading
from collections.abc import Callable, Iterator
from typing import Any, TypeVar

__all__ = ["fit_threads", "get_fit_threads", "limit_fit_threads", "set_fit_threads"]

_F = TypeVar("_F", bound=Callable[..., Any])

#: Threads of torch and of the BLAS libraries inside a fit (``None``: leave them as they are).
_fit_threads: int | None = 1
#: Per-thread nesting depth of :func:`fit_threads` (the outermost block sets and restores).
_local = threading.local()
#: (number of imported modules, threadpoolctl controller) of the last scan.
_cached: tuple[int, Any] | None = None


def get_fit_threads() -> int | None:
    """Threads used inside fits (``None``: the caller's settings are left as they are)."""
    return _fit_threads


def set_fit_threads(n: int | None) -> None:
    """Set the threads used inside fits (default 1; ``None`` leaves the caller's settings).

    Parameters
    ----------
    n
        A positive thread count, or ``None`` to fit with whatever torch and the BLAS libraries
        are set to (e.g. for very large fits on a many-core machine).
    """
    global _fit_threads
    if n is not None and (isinstance(n, bool) or int(n) != n or n < 1):
        raise ValueError(f"fit threads must be a positive integer or None, got {n!r}")
    _fit_threads = None if n is None else int(n)


@contextlib.contextmanager
def fit_threads(n: int | None = None) -> Iterator[None]:
    """Limit torch and the BLAS/OpenMP pools to ``n`` threads inside the block; then restore.

    Parameters
    ----------
    n
        Threads inside the block; default :func:`get_fit_threads`. ``None`` there: no limit.

    Notes
    -----
    Each thread's outermost block sets the limits and restores what that thread saw before;
    nested blocks keep the outer block's limit. torch keeps a thread count per thread, so a fit
    in a worker thread runs torch on ``n`` threads too; OpenBLAS (0.3) takes thread-count
    changes from the thread that started it only, so there its pool stays as it is.
    """
    limit = get_fit_threads() if n is None else n
    depth = getattr(_local, "depth", 0)
    if limit is None or depth > 0:
        _local.depth = depth + 1
        try:
            yield
        finally:
            _local.depth = depth
        return
    import torch

    torch_before = torch.get_num_threads()
    # threadpoolctl reaches the pools of the libraries loaded so far (numpy's and scipy's
    # OpenBLAS, OpenMP runtimes); torch's own pool (MKL, OpenMP) is set through torch.
    pools = _controller().limit(limits=limit)
    _local.depth = 1
    try:
        if torch_before != limit:
            torch.set_num_threads(limit)
        yield
    finally:
        _local.depth = 0
        if torch.get_num_threads() != torch_before:
            torch.set_num_threads(torch_before)
        pools.restore_original_limits()


def _controller() -> Any:
    """threadpoolctl's view of the loaded libraries, rebuilt when modules were imported since.

    Building it scans every loaded shared library (milliseconds); a new native library is
    only loaded by an import, so the count of imported modules tells when to scan again.
    """
    global _cached
    from threadpoolctl import ThreadpoolController

    if _cached is None or _cached[0] != len(sys.modules):
        _cached = (len(sys.modules), ThreadpoolController())
    return _cached[1]


def limit_fit_threads(method: _F) -> _F:
    """Decorator: run ``method`` (an estimator's ``fit``) inside :func:`fit_threads`."""

    @functools.wraps(method)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        with fit_threads():
            return method(*args, **kwargs)

    return wrapper  # type: ignore[return-value]

"""Independent tasks run serially or on a dask.distributed cluster, with the same results.

`run_tasks` maps a function over tasks (one recording, or one batch of simulated runs, per
task) and returns the results in task order. Without ``workers`` and ``scheduler`` it runs them
one after the other in this process; with ``workers=N`` it starts a local cluster of ``N``
worker processes with one thread each; with ``scheduler=ADDRESS`` it submits to an existing
cluster (``tcp://host:8786``). Inside every worker the numerical libraries use one thread
(``OMP_NUM_THREADS``, ``OPENBLAS_NUM_THREADS``, ``MKL_NUM_THREADS``, ``NUMBA_NUM_THREADS`` set to
1 for a local cluster, ``torch.set_num_threads(1)`` before every task), so a task computes
exactly what it computes serially.

Dask is an optional dependency (``pip install bayes_fdi[distributed]``), imported only here and
only when a cluster is asked for. Tasks and results travel between processes through dask's
own serialisation; nothing is written to disk.

Written by hand: the cluster set-up and ordered gathering are a few calls of dask.distributed;
the single-thread settings and the serial fallback are the project's.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Iterator, Sequence
from typing import Any

__all__ = ["SINGLE_THREAD_ENV", "add_cluster_arguments", "cluster_client", "run_tasks"]

#: Environment of the worker processes of a local cluster: one thread for every library.
SINGLE_THREAD_ENV: dict[str, str] = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
}


def _dask_distributed() -> Any:
    try:
        import dask.distributed
    except ImportError:
        raise ImportError(
            "running on several workers needs dask.distributed: "
            "pip install 'bayes_fdi[distributed]'"
        ) from None
    return dask.distributed


def _check_cluster_arguments(workers: int | None, scheduler: str | None) -> None:
    if workers is not None and scheduler is not None:
        raise ValueError("give workers (a local cluster) or scheduler (an existing one), not both")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)):
        raise ValueError(f"workers must be a positive integer, got {workers!r}")
    if workers is not None and workers < 1:
        raise ValueError(f"workers must be a positive integer, got {workers}")
    if scheduler is not None and not str(scheduler).strip():
        raise ValueError("scheduler must be an address such as tcp://host:8786")


@contextlib.contextmanager
def cluster_client(workers: int | None = None, scheduler: str | None = None) -> Iterator[Any]:
    """A ``dask.distributed.Client`` of a new local cluster (``workers``) or of ``scheduler``.

    The local cluster has ``workers`` processes with one thread each (:data:`SINGLE_THREAD_ENV`)
    and its HTTP server on a free port; it is shut down when the block ends.
    """
    _check_cluster_arguments(workers, scheduler)
    if workers is None and scheduler is None:
        raise ValueError("cluster_client needs workers or scheduler")
    distributed = _dask_distributed()
    if scheduler is not None:
        with distributed.Client(scheduler) as client:
            yield client
        return
    with (
        distributed.LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",  # the scheduler's HTTP server on a free port
            silence_logs=logging.ERROR,
            env=dict(SINGLE_THREAD_ENV),
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        yield client


def _single_threaded(fn: Callable[[Any], Any], task: Any) -> Any:
    """Run ``fn(task)`` with torch on one thread (inside a worker), and the dask collections it
    computes (a lazily read recording's chunks) in its own thread: inside a worker dask would
    otherwise hand them to the worker's other threads, where netCDF reads them while the task
    writes its own netCDF file, and the HDF5 library is not thread-safe ("NetCDF: HDF error")."""
    import dask
    import torch

    if torch.get_num_threads() != 1:
        torch.set_num_threads(1)
    with dask.config.set(scheduler="synchronous"):
        return fn(task)


def run_tasks(
    fn: Callable[[Any], Any],
    tasks: Sequence[Any],
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: bool = True,
    desc: str = "",
    unit: str = "task",
    sizes: Sequence[int] | None = None,
) -> list[Any]:
    """``[fn(task) for task in tasks]``, serially or on a cluster; results in task order.

    Parameters
    ----------
    fn
        A module-level function of one task (it is sent to the workers by reference).
    tasks
        The tasks (each sent to one worker).
    workers
        Number of worker processes of a local cluster (one thread each).
    scheduler
        Address of an existing cluster's scheduler (``tcp://host:8786``).
    progress
        Show a progress bar (tqdm, on stderr).
    desc, unit
        Label and unit of the progress bar.
    sizes
        Progress units per task (e.g. runs per batch); default one per task.

    Returns
    -------
    list
        ``fn(task)`` for every task, in the order of ``tasks``. A task's exception is raised
        here (the cluster is shut down first).
    """
    _check_cluster_arguments(workers, scheduler)
    tasks = list(tasks)
    sizes = [1] * len(tasks) if sizes is None else [int(s) for s in sizes]
    if len(sizes) != len(tasks):
        raise ValueError("sizes must have one entry per task")
    bar = None
    if progress:
        from bayes_fdi.progress import progress_bar

        bar = progress_bar(sum(sizes), desc or "tasks", unit=unit)
    try:
        if workers is None and scheduler is None:
            results = []
            for task, size in zip(tasks, sizes, strict=True):
                results.append(fn(task))
                if bar is not None:
                    bar.update(size)
            return results
        distributed = _dask_distributed()
        with cluster_client(workers, scheduler) as client:
            futures = client.map(_single_threaded, [fn] * len(tasks), tasks, pure=False)
            position = {f.key: i for i, f in enumerate(futures)}
            for future in distributed.as_completed(futures):
                if future.status == "error":
                    future.result()  # raises the task's exception here
                if bar is not None:
                    bar.update(sizes[position[future.key]])
            return client.gather(futures)
    finally:
        if bar is not None:
            bar.close()


def add_cluster_arguments(parser: Any) -> None:
    """Add ``--workers N`` and ``--scheduler ADDRESS`` to a command's parser."""
    from bayes_fdi.cli_arguments import positive_int

    group = parser.add_mutually_exclusive_group()
    group.add_argument(
        "--workers",
        type=positive_int,
        default=None,
        metavar="N",
        help="run on a local dask cluster of N worker processes, one thread each "
        "(needs pip install 'bayes_fdi[distributed]')",
    )
    group.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="run on an existing dask cluster, e.g. tcp://host:8786",
    )

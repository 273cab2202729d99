"""``bayes-fdi serve``: many valves diagnosed live from the plant's OPC UA server, in one process.

`Service` wires the parts of `bayes_fdi.deployment.serve` into one asyncio loop:

1. at start: the TOML is checked (`~bayes_fdi.deployment.serve.config.load_config`), each model
   file loaded once, the log recovered
   (`~bayes_fdi.deployment.serve.durable_log.DurableLog.recover`), and the valves grouped by
   model file (`~bayes_fdi.deployment.serve.valve_group.ValveGroup`), each valve's stream resumed
   from its last checkpoint;
2. one `~bayes_fdi.deployment.serve.opcua_client.PlantReader` per plant endpoint feeds samples
   to the valves' groups; the valves whose second is complete are diagnosed at once, those of
   one group in one call, and every ``tick`` the deadlines are checked (a second without its
   samples becomes BLIND);
3. the records of a wake-up are published together
   (`~bayes_fdi.deployment.serve.opcua_server.SevaPublisher.publish_many`), handed to the live
   page (`~bayes_fdi.deployment.serve.live_page.LiveHub`) and queued for the log; every
   ``commit_seconds`` the queued rows and each valve's checkpoint are committed (one journal
   part; the checkpoints' texts and the part are made in a writer thread); after a restart the
   live page's history is read back from the log meanwhile;
4. SIGTERM or Ctrl-C: the readers stop, the last rows are committed and the journal flushed into
   the valves' files.

The node checks of the first connection are fatal (a `PlantConfigError` ends ``serve`` with
exit status 1); a lost connection is not (the reader reconnects, the seconds become BLIND).
"""

from __future__ import annotations

import argparse
import asyncio
import concurrent.futures
import contextlib
import gc
import hashlib
import logging
import os
import signal
import sys
import time
from collections.abc import Mapping
from typing import Any

__all__ = ["Service", "configure_parser", "run_from_cli"]

_log = logging.getLogger("bayes_fdi.serve")

STOP_SECONDS = 10.0
"""Seconds `Service.stop` gives the running tasks, and then the OPC UA endpoint, to end."""


def model_fingerprint(path: str) -> str:
    """The first 16 hex digits of the model file's SHA-256."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()[:16]


class Service:
    """The whole ``serve`` process (see the module docstring).

    Parameters
    ----------
    config
        The checked TOML (`ServeConfig`).
    default_model
        Model file of the valves without their own ``model`` (``--model``).
    http
        ``(host, port)`` of the live page, or None.
    tick
        Wall-clock seconds between two deadline checks.
    """

    def __init__(
        self,
        config: Any,
        default_model: str | None = None,
        http: tuple[str, int] | None = None,
        tick: float = 0.05,
    ) -> None:
        self.config = config
        self.default_model = default_model
        self.http = http
        self.tick = float(tick)
        self.stopped = asyncio.Event()
        self.groups: list[Any] = []
        self.group_of: dict[str, Any] = {}
        self.pending: dict[str, list[dict[str, Any]]] = {}
        self.ready: set[str] = set()
        self.wake = asyncio.Event()
        self.records = 0
        self.writer = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="seva-log")
        self.error: BaseException | None = None

    # ------------------------------------------------------------------ start
    def _models(self) -> dict[str, tuple[Any, dict[str, Any]]]:
        """Model file (absolute path) -> (its diagnoser, its valves' units), in TOML order."""
        from bayes_fdi.cli_arguments import UsageError
        from bayes_fdi.diagnosis import OnlineDiagnoser

        by_model: dict[str, dict[str, Any]] = {}
        for valve in self.config.valves:
            path = valve.model or self.default_model
            if path is None:
                raise UsageError(
                    f"valve {valve.name} has no model: give --model or [valves.{valve.name}] model"
                )
            by_model.setdefault(os.path.abspath(path), {})[valve.name] = valve.units
        return {path: (OnlineDiagnoser.load(path), valves) for path, valves in by_model.items()}

    async def start(self) -> None:
        """Load, recover, open the endpoint and the page, start reading."""
        from bayes_fdi.deployment.serve.durable_log import DurableLog
        from bayes_fdi.deployment.serve.live_page import LiveHub
        from bayes_fdi.deployment.serve.opcua_server import SevaPublisher
        from bayes_fdi.deployment.serve.records import group_labels
        from bayes_fdi.deployment.serve.valve_group import ValveGroup

        cfg = self.config
        models = self._models()
        labels = {v: group_labels(m) for m, valves in models.values() for v in valves}
        self.log = DurableLog(cfg.log.folder, labels, cfg.log.segment_seconds)
        loop = asyncio.get_running_loop()
        checkpoints = await loop.run_in_executor(self.writer, self.log.recover)
        for path, (diagnoser, valves) in models.items():
            group = ValveGroup(
                diagnoser,
                model_fingerprint(path),
                valves,
                {v: checkpoints[v] for v in valves if v in checkpoints},
                speed=cfg.plant.speed,
                max_delay=cfg.plant.max_delay,
                clock_tolerance=cfg.plant.clock_tolerance,
                resume_max_gap=cfg.log.resume_max_gap,
            )
            self.groups.append(group)
        self.group_of = {v: g for g in self.groups for v in g.names}
        self.pending = {v.name: [] for v in cfg.valves}
        units = {v.name: v.units for v in cfg.valves}
        self.publisher = SevaPublisher(cfg.server, units)
        await self.publisher.start()
        self.hub = LiveHub(units, cfg.http.history_seconds, cfg.http.panels)
        self.tasks = [
            asyncio.create_task(self._process_loop(), name="process"),
            asyncio.create_task(self._commit_loop(), name="commit"),
            asyncio.create_task(self.hub.broadcast(), name="page-feed"),
            asyncio.create_task(self._page_history([v for v in units if v in checkpoints])),
        ]
        if self.http is not None:
            from bayes_fdi.deployment.serve.live_page import serve_page

            page = serve_page(self.hub, *self.http, self.stopped)
            self.tasks.append(asyncio.create_task(page, name="page"))
        self.readers = self._readers()
        for reader in self.readers:
            task = asyncio.create_task(reader.run(), name=f"read {reader.endpoint}")
            task.add_done_callback(self._reader_done)
            self.tasks.append(task)

    async def _page_history(self, valves: list[str]) -> None:
        """The live page's history from the log (a restart), one valve at a time in the log's
        writer thread (between commits, never beside a flush), while the valves run."""
        from bayes_fdi.deployment.serve.durable_log import read_recent

        loop = asyncio.get_running_loop()
        folder, seconds = self.log.folder, self.config.http.history_seconds
        for valve in valves:
            recent = await loop.run_in_executor(self.writer, read_recent, folder, valve, seconds)
            if recent is not None:
                self.hub.load(valve, recent)

    def _readers(self) -> list[Any]:
        from bayes_fdi.deployment.serve.opcua_client import PlantReader

        by_endpoint: dict[str, dict[str, tuple[str, str, str]]] = {}
        for valve in self.config.valves:
            nodes = by_endpoint.setdefault(valve.endpoint, {})
            for channel, node in valve.nodes.items():
                nodes[node] = (valve.name, channel, valve.units[channel])
        readers = []
        for endpoint, nodes in by_endpoint.items():
            valves = sorted({v for v, _, _ in nodes.values()})
            readers.append(
                PlantReader(
                    endpoint, self.config.plant, nodes, self._sample, self._notifier(valves)
                )
            )
        return readers

    def _notifier(self, valves: list[str]) -> Any:
        def notify(text: str) -> None:
            for v in valves:
                self.group_of[v].note(v, text)

        return notify

    def _reader_done(self, task: asyncio.Task) -> None:
        if task.cancelled() or self.stopped.is_set():
            return
        self.error = task.exception() or RuntimeError(f"{task.get_name()} ended")
        self.stopped.set()

    # ------------------------------------------------------------------ running
    def _sample(self, valve: str, channel: str, value: float, stamp: float, wall: float) -> None:
        group = self.group_of[valve]
        group.offer(valve, channel, value, stamp, wall)
        if group.ready(valve):
            self.ready.add(valve)
            self.wake.set()

    async def _process_loop(self) -> None:
        last_sweep = 0.0
        while True:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self.wake.wait(), self.tick)
            self.wake.clear()
            mono = time.monotonic()
            sweep = mono - last_sweep >= self.tick  # every valve's deadlines, once a tick
            if sweep:
                last_sweep = mono
            ready, self.ready = self.ready, set()
            to_unix = time.time() - mono
            rows = []
            for group in self.groups:
                valves = None if sweep else [v for v in group.names if v in ready]
                if valves != []:
                    rows += group.step(mono, to_unix, valves)
            if rows:
                await self._publish(rows)

    async def _publish(self, rows: list[tuple[str, dict[str, Any]]]) -> None:
        """Publish a batch of records (one write of the OPC UA server's values), then log and
        show them."""
        await self.publisher.publish_many(rows)
        published = time.time()
        for valve, row in rows:
            row["published"] = published
            self.pending[valve].append(row)
            self.hub.add(valve, row)
            if row["note"]:
                _log.info("%s %s: %s", valve, row["time"], row["note"])
        self.records += len(rows)

    async def _commit_loop(self) -> None:
        while True:
            await asyncio.sleep(self.config.log.commit_seconds)
            await self.commit()

    async def commit(self) -> None:
        """Commit the queued rows and their checkpoints (one journal part)."""
        rows = {v: r for v, r in self.pending.items() if r}
        if not rows:
            return
        snapshots = [g.checkpoints([v for v in g.names if v in rows]) for g in self.groups]
        for v in rows:
            self.pending[v] = []

        def write() -> None:  # in the writer thread: the checkpoints' texts, then the part
            checkpoints = {}
            for snapshot in snapshots:
                checkpoints.update(snapshot())
            self.log.commit(rows, checkpoints)

        loop = asyncio.get_running_loop()
        await loop.run_in_executor(self.writer, write)

    async def stop(self) -> None:
        """Stop reading, commit what is left, flush the journal, close the endpoint.

        The tasks and the endpoint get `STOP_SECONDS` each: one still running then is logged as
        a warning with where it waits, and left behind. The commit and the flush are not
        bounded, so that no record is lost.
        """
        self.stopped.set()
        for task in self.tasks:
            if not task.done() and task.get_name() != "page":
                task.cancel()
        if self.tasks:
            done, pending = await asyncio.wait(self.tasks, timeout=STOP_SECONDS)
            for task in done:  # retrieved, as awaiting them would (a reader's error is kept)
                if not task.cancelled():
                    task.exception()
            for task in pending:
                where = "".join(f"\n  {frame}" for frame in task.get_stack(limit=5))
                _log.warning(
                    "stop: task %r still running after %.0f s; left behind. It waits in:%s",
                    task.get_name(),
                    STOP_SECONDS,
                    where,
                )
        await self.commit()
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(self.writer, self.log.flush)
        self.writer.shutdown()
        try:
            await asyncio.wait_for(self.publisher.stop(), STOP_SECONDS)
        except TimeoutError:
            _log.warning("stop: the OPC UA endpoint did not close within %.0f s", STOP_SECONDS)

    def status(self) -> Mapping[str, Any]:
        """Counts for the log line: records, and per valve the aligner's event counts."""
        return {
            "records": self.records,
            "events": {v: dict(g.aligners[v].counts) for g in self.groups for v in g.names},
        }


# ----------------------------------------------------------------------------------------------
# command line
# ----------------------------------------------------------------------------------------------
def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``bayes-fdi serve``."""
    from bayes_fdi.cli_arguments import input_file

    parser.add_argument(
        "--config",
        required=True,
        type=input_file,
        help="the TOML file: plant endpoint, published endpoint, log, valves",
    )
    parser.add_argument(
        "--model",
        type=input_file,
        default=None,
        help="model file (bayes-fdi fit) of the valves without their own model",
    )
    parser.add_argument(
        "--http",
        default=None,
        metavar="[HOST:]PORT",
        help="serve the live page there (host 127.0.0.1 unless given; default: "
        "[http] address, else no page)",
    )
    parser.add_argument(
        "--verbose",
        action="store_true",
        help="log every reported event (duplicates, late samples, ...)",
    )


def _http_address(text: str) -> tuple[str, int]:
    from bayes_fdi.cli_arguments import UsageError
    from bayes_fdi.deployment.serve.config import ConfigError, parse_address

    if text.isdigit():
        text = f"127.0.0.1:{text}"
    try:
        return parse_address(text, what="--http")
    except ConfigError as exc:
        raise UsageError(str(exc)) from None


async def _main(args: argparse.Namespace) -> int:
    from bayes_fdi.cli_arguments import UsageError
    from bayes_fdi.deployment.serve.config import ConfigError, load_config

    try:
        config = load_config(args.config)
    except ConfigError as exc:
        raise UsageError(str(exc)) from None
    address = args.http if args.http is not None else config.http.address
    http = _http_address(address) if address else None
    service = Service(config, args.model, http)
    await service.start()
    # the models and the OPC UA address space live as long as the process: out of the cyclic
    # garbage collector's full collections, which scanned them for about half a second every
    # 15 s with 200 valves (every record late by that much); and young collections rare enough
    # that a second's short-lived objects (the published values) are freed before one comes
    gc.freeze()
    gc.set_threshold(100_000, 10, 10)
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, service.stopped.set)
    page = f"; live page on http://{http[0]}:{http[1]}/" if http else ""
    print(
        f"serve: {len(config.valves)} valve(s) from {len(service.readers)} plant endpoint(s); "
        f"publishing on {config.server.endpoint}{page}",
        flush=True,
    )
    await service.stopped.wait()
    await service.stop()
    print(f"serve: stopped after {service.records} record(s)", flush=True)
    if service.error is not None:
        raise service.error
    return 0


def run_from_cli(args: argparse.Namespace) -> int:
    """Run ``bayes-fdi serve``."""
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        stream=sys.stderr,
        format="%(asctime)s %(name)s %(levelname)s: %(message)s",
    )
    logging.getLogger("asyncua").setLevel(logging.CRITICAL)
    return asyncio.run(_main(args))

"""``bayes-fdi serve``: many valves diagnosed live from the plant's OPC UA server, in one process.

`Service` wires the parts of `bayes_fdi.deployment.serve` into one asyncio loop:

1. at start: the TOML is checked (`~bayes_fdi.deployment.serve.config.load_config`), each valve's
   model loaded, the log recovered (`~bayes_fdi.deployment.serve.durable_log.DurableLog.recover`)
   and each valve's stream resumed from its last checkpoint;
2. one `~bayes_fdi.deployment.serve.opcua_client.PlantReader` per plant endpoint feeds samples
   to the valves' runners; a valve whose second is complete is diagnosed at once, and every
   ``tick`` the deadlines are checked (a second without its samples becomes BLIND);
3. each record is published (`~bayes_fdi.deployment.serve.opcua_server.SevaPublisher`), handed to
   the live page (`~bayes_fdi.deployment.serve.live_page.LiveHub`) and queued for the log; every
   ``commit_seconds`` the queued rows and each valve's checkpoint are committed (one journal
   part, in a writer thread);
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
import hashlib
import logging
import signal
import sys
import time
from collections.abc import Mapping
from typing import Any

__all__ = ["Service", "configure_parser", "run_from_cli"]

_log = logging.getLogger("bayes_fdi.serve")


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
        self.runners: dict[str, Any] = {}
        self.pending: dict[str, list[dict[str, Any]]] = {}
        self.ready: set[str] = set()
        self.wake = asyncio.Event()
        self.records = 0
        self.writer = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="seva-log")
        self.error: BaseException | None = None

    # ------------------------------------------------------------------ start
    def _models(self) -> dict[str, tuple[Any, str]]:
        from bayes_fdi.cli_arguments import UsageError
        from bayes_fdi.diagnosis import OnlineDiagnoser

        out = {}
        fingerprints: dict[str, str] = {}
        for valve in self.config.valves:
            path = valve.model or self.default_model
            if path is None:
                raise UsageError(
                    f"valve {valve.name} has no model: give --model or [valves.{valve.name}] model"
                )
            if path not in fingerprints:
                fingerprints[path] = model_fingerprint(path)
            out[valve.name] = (OnlineDiagnoser.load(path), fingerprints[path])
        return out

    async def start(self) -> None:
        """Load, recover, open the endpoint and the page, start reading."""
        from bayes_fdi.deployment.serve.durable_log import DurableLog
        from bayes_fdi.deployment.serve.live_page import LiveHub
        from bayes_fdi.deployment.serve.opcua_server import SevaPublisher
        from bayes_fdi.deployment.serve.records import group_labels
        from bayes_fdi.deployment.serve.valve_runner import ValveRunner

        cfg = self.config
        models = self._models()
        groups = {v: group_labels(m) for v, (m, _) in models.items()}
        self.log = DurableLog(cfg.log.folder, groups, cfg.log.segment_seconds)
        loop = asyncio.get_running_loop()
        checkpoints = await loop.run_in_executor(self.writer, self.log.recover)
        for valve in cfg.valves:
            diagnoser, fingerprint = models[valve.name]
            self.runners[valve.name] = ValveRunner(
                valve.name,
                diagnoser,
                valve.units,
                fingerprint,
                checkpoints.get(valve.name),
                speed=cfg.plant.speed,
                max_delay=cfg.plant.max_delay,
                clock_tolerance=cfg.plant.clock_tolerance,
                resume_max_gap=cfg.log.resume_max_gap,
            )
            self.pending[valve.name] = []
        units = {v.name: v.units for v in cfg.valves}
        self.publisher = SevaPublisher(cfg.server, units)
        await self.publisher.start()
        self.hub = LiveHub(units, cfg.http.history_seconds, cfg.http.panels)
        self.tasks = [
            asyncio.create_task(self._process_loop(), name="process"),
            asyncio.create_task(self._commit_loop(), name="commit"),
            asyncio.create_task(self.hub.broadcast(), name="page-feed"),
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
                self.runners[v].note(text)

        return notify

    def _reader_done(self, task: asyncio.Task) -> None:
        if task.cancelled() or self.stopped.is_set():
            return
        self.error = task.exception() or RuntimeError(f"{task.get_name()} ended")
        self.stopped.set()

    # ------------------------------------------------------------------ running
    def _sample(self, valve: str, channel: str, value: float, stamp: float, wall: float) -> None:
        runner = self.runners[valve]
        runner.offer(channel, value, stamp, wall)
        if runner.aligner.ready():
            self.ready.add(valve)
            self.wake.set()

    async def _process_loop(self) -> None:
        last_sweep = 0.0
        while True:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self.wake.wait(), self.tick)
            self.wake.clear()
            mono = time.monotonic()
            if mono - last_sweep >= self.tick:
                valves, last_sweep = list(self.runners), mono
            else:
                valves = list(self.ready)
            self.ready.clear()
            to_unix = time.time() - mono
            for valve in valves:
                for row in self.runners[valve].step(mono, to_unix):
                    await self._publish(valve, row)

    async def _publish(self, valve: str, row: dict[str, Any]) -> None:
        await self.publisher.publish(valve, row)
        row["published"] = time.time()
        self.pending[valve].append(row)
        self.hub.add(valve, row)
        self.records += 1
        if row["note"]:
            _log.info("%s %s: %s", valve, row["time"], row["note"])

    async def _commit_loop(self) -> None:
        while True:
            await asyncio.sleep(self.config.log.commit_seconds)
            await self.commit()

    async def commit(self) -> None:
        """Commit the queued rows and their checkpoints (one journal part)."""
        rows = {v: r for v, r in self.pending.items() if r}
        if not rows:
            return
        checkpoints = {v: self.runners[v].checkpoint() for v in rows}
        for v in rows:
            self.pending[v] = []
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(self.writer, self.log.commit, rows, checkpoints)

    async def stop(self) -> None:
        """Stop reading, commit what is left, flush the journal, close the endpoint."""
        self.stopped.set()
        for task in self.tasks:
            if not task.done() and task.get_name() != "page":
                task.cancel()
        for task in self.tasks:
            with contextlib.suppress(BaseException):
                await task
        await self.commit()
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(self.writer, self.log.flush)
        self.writer.shutdown()
        await self.publisher.stop()

    def status(self) -> Mapping[str, Any]:
        """Counts for the log line: records, and per valve the aligner's event counts."""
        return {
            "records": self.records,
            "events": {v: dict(r.aligner.counts) for v, r in self.runners.items()},
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

"""``Service.stop`` is bounded: a task that ignores its cancellation is left behind with a warning
that names it and where it waits, and the journal is still flushed and the OPC UA endpoint
closed. In process, with the real asyncua endpoint on 127.0.0.1 (no plant server: the reader
keeps retrying)."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import time

from serve_helpers import fit_tiny_model, free_ports, write_toml

from bayes_fdi.deployment.serve import service as service_module
from bayes_fdi.deployment.serve.config import load_config


def _accepts(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(2.0)
        return s.connect_ex(("127.0.0.1", port)) == 0


def test_stop_leaves_behind_a_task_that_ignores_its_cancellation_and_still_closes(
    tmp_path, monkeypatch, caplog
):
    model = fit_tiny_model(tmp_path / "tiny.npz")
    plant_port, seva_port = free_ports(2)
    toml = write_toml(
        tmp_path / "valve.toml",
        plant_port=plant_port,
        seva_port=seva_port,
        valves={"V1": ""},
        speed=1.0,
    )
    bound = 0.5
    monkeypatch.setattr(service_module, "STOP_SECONDS", bound)
    release, running = asyncio.Event(), asyncio.Event()
    flushed = []

    async def stubborn() -> None:
        running.set()
        while not release.is_set():
            try:
                await asyncio.sleep(3600)
            except asyncio.CancelledError:  # ignored, as a misbehaving library task might
                pass

    async def scenario() -> tuple[float, bool, bool]:
        service = service_module.Service(load_config(str(toml)), str(model))
        await service.start()
        open_before = _accepts(seva_port)
        flush = service.log.flush

        def counted_flush() -> None:
            flushed.append(True)
            flush()

        service.log.flush = counted_flush
        task = asyncio.create_task(stubborn(), name="stubborn")
        service.tasks.append(task)
        await running.wait()
        started = time.monotonic()
        await service.stop()
        elapsed = time.monotonic() - started
        open_after = _accepts(seva_port)
        release.set()
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
        return elapsed, open_before, open_after

    with caplog.at_level(logging.WARNING, logger="bayes_fdi.serve"):
        elapsed, open_before, open_after = asyncio.run(scenario())
    # it waited the bound for the stubborn task, then went on: the rest (the reader's and the
    # loops' cancellation, an empty commit, the flush, closing the endpoint) takes well under
    # a second on loopback; 10 s is the margin of a loaded 2-core machine
    assert bound <= elapsed < bound + 10.0
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    left = [w for w in warnings if "'stubborn'" in w]
    assert len(left) == 1 and "left behind" in left[0] and "stubborn" in left[0].split("in:")[1]
    assert not any("still running" in w and "'stubborn'" not in w for w in warnings)
    assert flushed == [True]
    assert open_before and not open_after

"""``bayes-fdi simulate-plant``: the DAMADICS actuator model behind an OPC UA server.

The plant is simulated whole at start (`bayes_fdi.actuator.simulate` over DGen-like inputs,
`bayes_fdi.actuator.benchmark_inputs` with ``vary``; valve ``i`` of the TOML is run ``i``; its
``fault`` table schedules its fault), then played out second by second: second ``k`` is written
at wall-clock time ``t0 + k / speed`` with the plant time ``start + k`` (Unix s) as source
timestamp, each channel in its engineering unit (``[valves.NAME] units``), on the node ids of
the TOML. Each node is a Double variable with the ``EngineeringUnits`` property.

``[simulation]`` also schedules the plant's troubles: ``outages`` (the server stops for that many
seconds: the samples of those seconds are never served), ``clock_jumps`` (from that second on the
timestamps are shifted), ``duplicates`` (the samples of that second are written twice, the
second time 1 % of full scale off) and ``late`` (the X sample of that second is written 3 s
late, with its own timestamp). ``--write-times FILE`` records, per second, the Unix time its
samples were written (for latency measurements). The plant is served without security
(anonymous, no encryption): it is a test bench for loopback use.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import datetime as dt
import math
import signal
import sys
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["PlantSimulator", "configure_parser", "plant_recording", "run_from_cli"]

_DUPLICATE_OFFSET = 0.01  #: full scale added to a duplicate sample
_LATE_SECONDS = 3


def plant_recording(config: Any, duration: int | None = None) -> Any:
    """The simulated recording (normalised, ``run`` = valve index) of the TOML's valves."""
    from bayes_fdi.actuator import benchmark_inputs, simulate

    sim = config.simulation
    n = len(config.valves)
    duration = sim.duration if duration is None else duration
    inputs = benchmark_inputs(n, duration, seed=sim.seed, vary=True)
    faults = [v.fault for v in config.valves]
    return simulate(inputs, faults, seed=sim.seed)


class PlantSimulator:
    """The simulated plant's OPC UA server(s) and playback (see the module docstring)."""

    def __init__(self, config: Any, recording: Any, *, speed: float, start: float | None = None):
        from bayes_fdi.datasets import CHANNELS
        from bayes_fdi.datasets.units import to_physical

        self.config = config
        self.speed = float(speed)
        self.duration = int(recording.sizes["time"])
        self.start = float(math.ceil(time.time()) if start is None else start)
        self.values: dict[tuple[str, str], np.ndarray] = {}
        self.full_scale: dict[tuple[str, str], float] = {}
        for i, valve in enumerate(config.valves):
            for c in CHANNELS:
                normalised = np.asarray(recording[c].values[i], dtype=np.float64)
                unit = valve.units[c]
                self.values[(valve.name, c)] = np.asarray(to_physical(normalised, c, unit))
                self.full_scale[(valve.name, c)] = float(
                    to_physical(1.0, c, unit) - to_physical(0.0, c, unit)
                )
        self.servers: dict[str, Any] = {}
        self.node_ids: dict[tuple[str, str], Any] = {}
        self.write_times = np.full(self.duration, np.nan)

    async def _build(self, endpoint: str, valves: Sequence[Any]) -> Any:
        from asyncua import Server, ua

        server = Server()
        await server.init()
        server.set_endpoint(endpoint)
        server.set_server_name("bayes-fdi simulated plant")
        server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
        server.disable_clock()
        idx = await server.register_namespace("urn:bayes-fdi:simulated-plant")
        for valve in valves:
            obj = await server.nodes.objects.add_object(idx, valve.name)
            for channel, node in valve.nodes.items():
                nid = ua.NodeId.from_string(node)
                if nid.NamespaceIndex != idx:
                    raise ValueError(
                        f"valve {valve.name}, channel {channel}: node {node} must be in namespace "
                        f"{idx} (the simulated plant's)"
                    )
                var = await obj.add_variable(
                    nid, ua.QualifiedName(channel, idx), 0.0, varianttype=ua.VariantType.Double
                )
                eu = ua.EUInformation(DisplayName=ua.LocalizedText(valve.units[channel]), UnitId=-1)
                await var.add_property(
                    ua.NodeId(f"{node}.EngineeringUnits", idx),
                    ua.QualifiedName("EngineeringUnits", 0),
                    eu,
                )
                self.node_ids[(valve.name, channel)] = nid
        return server

    async def start_servers(self) -> None:
        """Build and open one server per endpoint of the TOML."""
        by_endpoint: dict[str, list[Any]] = {}
        for valve in self.config.valves:
            by_endpoint.setdefault(valve.endpoint, []).append(valve)
        for endpoint, valves in by_endpoint.items():
            server = await self._build(endpoint, valves)
            await server.start()
            self.servers[endpoint] = server

    async def _write(
        self, second: int, k: int, offset: float = 0.0, channels: Sequence[str] | None = None
    ) -> None:
        from asyncua import ua

        stamp = dt.datetime.fromtimestamp(second, dt.UTC)
        for valve in self.config.valves:
            server = self.servers[valve.endpoint]
            for c in channels or valve.nodes:
                value = float(self.values[(valve.name, c)][k])
                value += offset * self.full_scale[(valve.name, c)]
                dv = ua.DataValue(
                    ua.Variant(value, ua.VariantType.Double),
                    SourceTimestamp=stamp,
                    ServerTimestamp=stamp,
                )
                await server.write_attribute_value(self.node_ids[(valve.name, c)], dv)

    async def play(self, progress: bool = True) -> None:
        """Write second after second; the outages stop the servers meanwhile."""
        sim = self.config.simulation
        down = {s for first, n in sim.outages for s in range(first, first + n)}
        jumps = dict(sim.clock_jumps)
        late: dict[int, list[tuple[int, int]]] = {}
        # second 0 is written at the plant time `start` when that is now or soon (real time)
        lead = self.start - time.time()
        t0 = time.monotonic() + (lead if 0.0 <= lead < 5.0 else 0.0)
        offset = 0
        for k in range(self.duration):
            await asyncio.sleep(max(0.0, t0 + k / self.speed - time.monotonic()))
            offset += jumps.get(k, 0)
            second = int(self.start) + k + offset
            if k in down:
                if k - 1 not in down:
                    print(f"outage: servers down at second {k}", flush=True)
                    for server in self.servers.values():
                        await server.stop()
                continue
            if k - 1 in down:
                for endpoint in list(self.servers):
                    self.servers[endpoint] = await self._restart(endpoint)
                print(f"outage over at second {k}", flush=True)
            channels = None
            if k in sim.late:
                late.setdefault(k + _LATE_SECONDS, []).append((second, k))
                channels = ("CV", "P1", "P2", "T1", "F")
            for old_second, old_k in late.pop(k, []):
                await self._write(old_second, old_k, channels=("X",))
            await self._write(second, k, channels=channels)
            if k in sim.duplicates:
                await self._write(second, k, offset=_DUPLICATE_OFFSET, channels=channels)
            self.write_times[k] = time.time()
            if progress and k % 60 == 0:
                print(f"second {k} of {self.duration}", flush=True)

    async def _restart(self, endpoint: str) -> Any:
        server = self.servers[endpoint]
        for _ in range(100):  # the port may linger for a moment after stop()
            try:
                await server.start()
                return server
            except OSError:
                await asyncio.sleep(0.02)
        raise RuntimeError(f"cannot reopen {endpoint} after the outage")

    async def stop(self) -> None:
        """Close every server."""
        for server in self.servers.values():
            with contextlib.suppress(Exception):
                await server.stop()


def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``bayes-fdi simulate-plant``."""
    from bayes_fdi.cli_arguments import input_file, non_negative_int

    parser.add_argument("--config", required=True, type=input_file, help="the TOML file")
    parser.add_argument(
        "--speed",
        type=float,
        default=None,
        help="plant seconds per wall-clock second (default: [plant] speed)",
    )
    parser.add_argument(
        "--duration",
        type=non_negative_int,
        default=None,
        help="seconds to simulate (default: [simulation] duration)",
    )
    parser.add_argument(
        "--start",
        type=float,
        default=None,
        help="plant time (Unix s) of the first sample (default: [simulation] "
        "start, else the next whole second)",
    )
    parser.add_argument(
        "--write-times",
        default=None,
        metavar="CSV",
        help="write the Unix time each second's samples were written",
    )
    parser.add_argument(
        "--hold",
        action="store_true",
        help="keep the servers open after the last second until stopped",
    )


async def _main(args: argparse.Namespace) -> int:
    from bayes_fdi.cli_arguments import UsageError
    from bayes_fdi.deployment.serve.config import ConfigError, load_config

    try:
        config = load_config(args.config, publishing=False)
    except ConfigError as exc:
        raise UsageError(str(exc)) from None
    speed = config.plant.speed if args.speed is None else args.speed
    if not speed > 0:
        raise UsageError(f"--speed must be > 0, got {speed}")
    recording = plant_recording(config, args.duration)
    start = config.simulation.start if args.start is None else args.start
    plant = PlantSimulator(config, recording, speed=speed, start=start)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    await plant.start_servers()
    endpoints = ", ".join(plant.servers)
    print(
        f"simulated plant: {len(config.valves)} valve(s) on {endpoints}, {plant.duration} s "
        f"at {speed:g}x from plant time {plant.start:.0f}",
        flush=True,
    )
    playing = asyncio.create_task(plant.play())
    stopping = asyncio.create_task(stop.wait())
    await asyncio.wait({playing, stopping}, return_when=asyncio.FIRST_COMPLETED)
    if playing.done():
        playing.result()
        print("simulated plant: all seconds written", flush=True)
        if args.hold:
            await stopping
    playing.cancel()
    stopping.cancel()
    await plant.stop()
    if args.write_times:
        _write_times(args.write_times, plant)
    return 0


def _write_times(path: str, plant: PlantSimulator) -> None:
    from bayes_fdi.atomic import write_text

    lines = ["k,written"]
    lines += [f"{k},{t:.6f}" for k, t in enumerate(plant.write_times) if np.isfinite(t)]
    write_text(path, "\n".join(lines) + "\n")


def run_from_cli(args: argparse.Namespace) -> int:
    """Run ``bayes-fdi simulate-plant``."""
    import logging

    logging.basicConfig(level=logging.WARNING, stream=sys.stderr)
    logging.getLogger("asyncua").setLevel(logging.ERROR)
    return asyncio.run(_main(args))

"""The plant reader: the valves' measurements read from a plant OPC UA server, reconnecting.

`PlantReader` holds one connection to one plant endpoint and reads every node of the valves
served there, either by **subscription** (one subscription, a monitored item per node with the
``StatusValueTimestamp`` trigger so that every new sample is reported even when its value
repeats, a queue so that none is dropped between two publishes) or by **polling** (one read of
all nodes every plant period). Each sample goes to ``sink(valve, channel, value, timestamp,
wall)``: the value as a float (NaN when the plant gives a bad status), the plant's timestamp
(source or server, ``[plant] timestamps``) in Unix seconds, and the monotonic wall clock.

On every connection the nodes are checked (`check_nodes`): a node that does not exist, is not a
variable of a numeric type, or whose ``EngineeringUnits`` differ from the unit configured for
its channel is a `PlantConfigError` naming the valve, channel, node and problem; ``serve`` stops
with it. A lost connection (or a failed connect) is reported to the valves (``notify``) and
retried with exponential back-off from ``reconnect_min`` to ``reconnect_max`` seconds; the
seconds without data become BLIND in the valves' aligners meanwhile.
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime as dt
import logging
import math
import time
from collections.abc import Callable, Mapping
from typing import Any

from asyncua import Client, ua

from bayes_fdi.datasets.units import PHYSICAL_UNITS, parse_units
from bayes_fdi.deployment.serve.config import PlantConfig

__all__ = ["NUMERIC_TYPES", "PlantConfigError", "PlantReader", "check_nodes", "secure_client"]

_log = logging.getLogger("bayes_fdi.serve")

#: OPC UA data types accepted for a measurement.
NUMERIC_TYPES = frozenset(
    ua.NodeId(getattr(ua.ObjectIds, name))
    for name in (
        "Double",
        "Float",
        "Int16",
        "Int32",
        "Int64",
        "UInt16",
        "UInt32",
        "UInt64",
        "Byte",
        "SByte",
        "Number",
        "Decimal",
    )
)


class PlantConfigError(ValueError):
    """A node of the configuration does not fit the plant server (fatal at start)."""


async def secure_client(endpoint: str, plant: PlantConfig) -> Client:
    """An unconnected client of ``endpoint`` with the ``[plant]`` security settings."""
    client = Client(endpoint, timeout=plant.timeout, watchdog_intervall=1.0)
    client.name = client.description = "bayes-fdi serve"
    client.application_uri = "urn:bayes-fdi:serve:client"
    if plant.security != "None":
        policy, mode = plant.security.split("_", 1)
        parts = [policy, mode, plant.certificate, plant.private_key]
        if plant.server_certificate:
            parts.append(plant.server_certificate)
        await client.set_security_string(",".join(parts))
    return client


def _unit_text(value: Any) -> str | None:
    if isinstance(value, ua.EUInformation):
        return value.DisplayName.Text
    return None


async def check_nodes(client: Client, nodes: Mapping[str, tuple[str, str, str]]) -> list[str]:
    """Check the nodes (node id -> (valve, channel, unit)); returns warnings, raises on errors.

    Raises
    ------
    PlantConfigError
        Listing every node that does not exist, is not a numeric variable, or has other
        engineering units than configured.
    """
    ids = list(nodes)
    node_objs = [client.get_node(n) for n in ids]
    classes = await client.read_attributes(node_objs, ua.AttributeIds.NodeClass)
    types = await client.read_attributes(node_objs, ua.AttributeIds.DataType)
    errors, warnings = [], []
    for i, nid in enumerate(ids):
        valve, channel, unit = nodes[nid]
        where = f"valve {valve}, channel {channel}, node {nid}"
        code = classes[i].StatusCode
        if code is not None and not code.is_good():
            errors.append(f"{where}: no such node on the plant server ({code.name})")
            continue
        if classes[i].Value.Value != ua.NodeClass.Variable:
            errors.append(f"{where}: not a variable (node class {classes[i].Value.Value!r})")
            continue
        dtype = types[i].Value.Value
        if dtype not in NUMERIC_TYPES:
            errors.append(f"{where}: data type {dtype.to_string()} is not numeric")
            continue
        eu = await _engineering_units(node_objs[i])
        if eu is None:
            warnings.append(f"{where}: no EngineeringUnits property; unit {unit!r} assumed")
            continue
        try:
            plant_unit = parse_units({**PHYSICAL_UNITS, channel: eu})[channel]
        except ValueError:
            errors.append(f"{where}: the plant's unit {eu!r} is not one bayes_fdi knows")
            continue
        if plant_unit != unit:
            errors.append(f"{where}: unit mismatch: the plant says {eu!r}, the TOML {unit!r}")
    if errors:
        raise PlantConfigError("; ".join(errors))
    return warnings


async def _engineering_units(node: Any) -> str | None:
    try:
        prop = await node.get_child("0:EngineeringUnits")
    except ua.UaError:
        return None
    try:
        return _unit_text(await prop.read_value())
    except ua.UaError:
        return None


def _unix(stamp: dt.datetime | None) -> float:
    if stamp is None:
        return math.nan
    if stamp.tzinfo is None:
        stamp = stamp.replace(tzinfo=dt.UTC)
    return stamp.timestamp()


class PlantReader:
    """One plant endpoint's connection (see the module docstring).

    Parameters
    ----------
    endpoint
        The plant server's address.
    plant
        The ``[plant]`` section.
    nodes
        Node id -> (valve, channel, unit) of every node read here.
    sink
        ``sink(valve, channel, value, timestamp, wall)`` for every sample.
    notify
        ``notify(text)``: an event every valve of this endpoint reports (connection lost...).
    """

    def __init__(
        self,
        endpoint: str,
        plant: PlantConfig,
        nodes: Mapping[str, tuple[str, str, str]],
        sink: Callable[[str, str, float, float, float], None],
        notify: Callable[[str], None],
    ) -> None:
        self.endpoint = endpoint
        self.plant = plant
        self.nodes = dict(nodes)
        self.sink = sink
        self.notify = notify
        self.connected = asyncio.Event()
        self.checked = asyncio.Event()
        self.connections = 0
        self._lost = asyncio.Event()
        self._by_nodeid = {ua.NodeId.from_string(n): v for n, v in self.nodes.items()}
        self._last_stamp: dict[ua.NodeId, float] = {}
        self._failing = False

    async def run(self) -> None:
        """Connect, read, and reconnect with back-off, until cancelled."""
        delay = self.plant.reconnect_min
        while True:
            client = await secure_client(self.endpoint, self.plant)
            try:
                await client.connect()
            except (TimeoutError, OSError, ua.UaError) as exc:
                self._failed(f"cannot connect to the plant server {self.endpoint} ({exc!r})", delay)
                await asyncio.sleep(delay)
                delay = min(2 * delay, self.plant.reconnect_max)
                continue
            try:
                await self._serve_connection(client)
                delay = self.plant.reconnect_min
            except PlantConfigError:
                raise
            except (TimeoutError, OSError, ua.UaError, ConnectionError) as exc:
                self._failed(f"connection to {self.endpoint} lost ({exc!r})", delay)
            finally:
                self.connected.clear()
                with contextlib.suppress(Exception):
                    await asyncio.wait_for(client.disconnect(), 2.0)
            await asyncio.sleep(delay)
            delay = min(2 * delay, self.plant.reconnect_max)

    def _failed(self, text: str, delay: float) -> None:
        _log.warning("%s; retrying in %.1f s", text, delay)
        if not self._failing:  # the valves' records say it once per outage
            self.notify(f"{text}; retrying with back-off")
        self._failing = True

    async def _serve_connection(self, client: Client) -> None:
        self._lost.clear()

        async def lost(exc: Exception) -> None:
            self._lost.set()

        client.connection_lost_callback = lost
        warnings = await check_nodes(client, self.nodes)
        if not self.checked.is_set():
            for w in warnings:
                _log.warning(w)
            self.checked.set()
        self.connections += 1
        self._failing = False
        if self.connections > 1:
            _log.info("reconnected to %s", self.endpoint)
            self.notify(f"reconnected to the plant server {self.endpoint}")
        self.connected.set()
        if self.plant.mode == "subscribe":
            await self._subscribe(client)
            await self._lost.wait()
            raise ConnectionError("the server closed the connection")
        await self._poll(client)

    async def _subscribe(self, client: Client) -> None:
        period_ms = 1000.0 * self.plant.publishing_interval
        sub = await client.create_subscription(period_ms, self)
        requests = []
        # client handles far above asyncua's own counter (this subscription has no other items)
        for handle, nodeid in enumerate(self._by_nodeid, start=1_000_000):
            rv = ua.ReadValueId(NodeId=nodeid, AttributeId=ua.AttributeIds.Value)
            params = ua.MonitoringParameters(
                ClientHandle=handle,
                SamplingInterval=0.0,
                QueueSize=16,
                DiscardOldest=True,
                Filter=ua.DataChangeFilter(Trigger=ua.DataChangeTrigger.StatusValueTimestamp),
            )
            requests.append(
                ua.MonitoredItemCreateRequest(
                    ItemToMonitor=rv,
                    MonitoringMode=ua.MonitoringMode.Reporting,
                    RequestedParameters=params,
                )
            )
        results = await sub.create_monitored_items(requests)
        bad = [str(r) for r in results if isinstance(r, ua.StatusCode)]
        if bad:
            raise PlantConfigError(f"the plant server refused to monitor nodes: {bad}")

    def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
        """asyncua's subscription callback: one sample."""
        self._deliver(node.nodeid, data.monitored_item.Value, time.monotonic())

    def status_change_notification(self, status: Any) -> None:
        """asyncua's subscription callback: the subscription's status changed (e.g. lost)."""
        self._lost.set()

    def _deliver(self, nodeid: ua.NodeId, dv: ua.DataValue, wall: float) -> None:
        target = self._by_nodeid.get(nodeid)
        if target is None:
            return
        valve, channel, _ = target
        stamp = dv.SourceTimestamp if self.plant.timestamps == "source" else dv.ServerTimestamp
        code = dv.StatusCode
        value = dv.Value.Value if dv.Value is not None else None
        if (code is not None and not code.is_good()) or not isinstance(value, int | float):
            value = math.nan
        self.sink(valve, channel, float(value), _unix(stamp), wall)

    async def _poll(self, client: Client) -> None:
        nodes = [client.get_node(n) for n in self._by_nodeid]
        period = self.plant.period / self.plant.speed
        next_read = time.monotonic()
        while not self._lost.is_set():
            dvs = await client.read_attributes(nodes, ua.AttributeIds.Value)
            wall = time.monotonic()
            for node, dv in zip(nodes, dvs, strict=True):
                stamp = _unix(
                    dv.SourceTimestamp if self.plant.timestamps == "source" else dv.ServerTimestamp
                )
                if self._last_stamp.get(node.nodeid) == stamp:
                    continue  # the same sample read again: not a duplicate of the plant's
                self._last_stamp[node.nodeid] = stamp
                self._deliver(node.nodeid, dv, wall)
            next_read += period
            await asyncio.sleep(max(0.0, next_read - time.monotonic()))
        raise ConnectionError("the server closed the connection")

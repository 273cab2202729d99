"""The TOML file of ``bayes-fdi serve`` and ``bayes-fdi simulate-plant``: schema and validation.

One file describes the plant's OPC UA server (``[plant]``), the endpoint ``serve`` publishes on
(``[server]``), the durable log (``[log]``), the live page (``[http]``), the simulated plant
(``[simulation]``, read by ``simulate-plant`` only) and one section per valve
(``[valves.NAME]``). `load_config` reads it into frozen dataclasses; every mistake is a
`ConfigError` naming the file, the section and the key (unknown keys included: a misspelt key is
an error, not a default). The schema with its defaults is in ``docs/plant.md``.

Paths (models, certificates, the log folder) are relative to the TOML file's folder.
"""

from __future__ import annotations

import math
import os
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from bayes_fdi.actuator import Fault
from bayes_fdi.datasets import CHANNELS
from bayes_fdi.datasets.units import PHYSICAL_UNITS, parse_units

__all__ = [
    "SECURITY_POLICIES",
    "ConfigError",
    "HttpConfig",
    "LogConfig",
    "PlantConfig",
    "ServeConfig",
    "ServerConfig",
    "SimulationConfig",
    "ValveConfig",
    "load_config",
    "parse_address",
    "parse_config",
]

#: The OPC UA security policies (policy_mode) the endpoints accept.
SECURITY_POLICIES: tuple[str, ...] = (
    "None",
    "Basic256Sha256_Sign",
    "Basic256Sha256_SignAndEncrypt",
)
_VALVE_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}$")


class ConfigError(ValueError):
    """A mistake in the TOML file (the message names the file, section and key)."""


@dataclass(frozen=True)
class PlantConfig:
    """``[plant]``: the OPC UA server the valves' measurements are read from."""

    endpoint: str = "opc.tcp://127.0.0.1:4840/plant"
    mode: str = "subscribe"  #: "subscribe" or "poll"
    period: float = 1.0  #: sampling period of the plant, s (plant time)
    publishing_interval: float = 0.1  #: subscription publishing interval, s
    timestamps: str = "source"  #: "source" or "server": the timestamp that places a sample
    max_delay: float = 1.5  #: wall-clock s a second waits for its samples before it is BLIND
    clock_tolerance: float = 5.0  #: s of plant time beyond which a sample is a clock jump
    speed: float = 1.0  #: plant seconds per wall-clock second (1 on a real plant)
    reconnect_min: float = 0.5  #: first reconnection delay, s (doubled at each failure)
    reconnect_max: float = 10.0  #: longest reconnection delay, s
    timeout: float = 4.0  #: OPC UA request timeout, s
    security: str = "None"
    certificate: str | None = None
    private_key: str | None = None
    server_certificate: str | None = None
    node_pattern: str = "ns=2;s={valve}.{channel}"


@dataclass(frozen=True)
class ServerConfig:
    """``[server]``: the OPC UA endpoint ``serve`` publishes the SEVA records on."""

    endpoint: str = "opc.tcp://127.0.0.1:4841/seva"
    namespace: str = "urn:bayes-fdi:seva"
    security: tuple[str, ...] = ("Basic256Sha256_SignAndEncrypt",)
    certificate: str | None = None
    private_key: str | None = None
    trusted_clients: tuple[str, ...] = ()
    allow_anonymous: bool = False


@dataclass(frozen=True)
class LogConfig:
    """``[log]``: the durable log."""

    folder: str = "seva-log"
    commit_seconds: float = 1.0  #: wall-clock s between journal commits
    segment_seconds: int = 600  #: plant s per netCDF segment of a valve
    resume_max_gap: int = 86_400  #: a longer gap at restart starts a fresh stream


@dataclass(frozen=True)
class HttpConfig:
    """``[http]``: the live page (``address`` ``""``, the default: no page; ``--http`` opens it)."""

    address: str = ""
    history_seconds: int = 3600
    panels: int = 8  #: valves drawn on the overview page (all are listed)


@dataclass(frozen=True)
class SimulationConfig:
    """``[simulation]``: the simulated plant of ``bayes-fdi simulate-plant``."""

    duration: int = 3600
    seed: int = 0  #: seed of the simulated inputs and measurement noise
    start: float | None = None  #: plant time (Unix s) of the first sample; None: now
    outages: tuple[tuple[int, int], ...] = ()  #: (first second, seconds) the server is down
    clock_jumps: tuple[tuple[int, int], ...] = ()  #: (second, jump s) of the plant clock
    duplicates: tuple[int, ...] = ()  #: seconds whose samples are written twice
    late: tuple[int, ...] = ()  #: seconds whose X sample arrives 3 s late


@dataclass(frozen=True)
class ValveConfig:
    """``[valves.NAME]``: one valve, its model, its nodes and units."""

    name: str
    model: str | None
    endpoint: str
    nodes: Mapping[str, str]
    units: Mapping[str, str]
    fault: Fault | None = None  #: simulation only: the scheduled fault


@dataclass(frozen=True)
class ServeConfig:
    """The whole file."""

    path: str
    plant: PlantConfig
    server: ServerConfig
    log: LogConfig
    http: HttpConfig
    simulation: SimulationConfig
    valves: tuple[ValveConfig, ...] = field(default_factory=tuple)


class _Section:
    """Typed reads from one TOML table; every error names the file and the section."""

    def __init__(self, source: str, name: str, table: Any) -> None:
        if not isinstance(table, dict):
            raise ConfigError(f"{source}: [{name}] must be a table")
        self.source, self.name, self.table = source, name, table
        self.used: set[str] = set()

    def error(self, key: str, message: str) -> ConfigError:
        return ConfigError(f"{self.source}: [{self.name}] {key}: {message}")

    def get(self, key: str, kind: type | tuple[type, ...], default: Any) -> Any:
        self.used.add(key)
        if key not in self.table:
            return default
        value = self.table[key]
        kinds = kind if isinstance(kind, tuple) else (kind,)
        if float in kinds and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if isinstance(value, bool) and bool not in kinds:
            raise self.error(key, f"expected {_kind_names(kinds)}, got {value!r}")
        if not isinstance(value, kinds):
            raise self.error(key, f"expected {_kind_names(kinds)}, got {value!r}")
        return value

    def number(self, key: str, default: float, *, low: float = 0.0, strict: bool = True) -> float:
        value = self.get(key, float, default)
        if not math.isfinite(value) or value < low or (strict and value == low):
            raise self.error(key, f"must be a number {'>' if strict else '>='} {low}, got {value}")
        return value

    def choice(self, key: str, default: str, allowed: tuple[str, ...]) -> str:
        value = self.get(key, str, default)
        if value not in allowed:
            raise self.error(key, f"must be one of {list(allowed)}, got {value!r}")
        return value

    def path(self, key: str, base: str, *, must_exist: bool = True) -> str | None:
        value = self.get(key, str, None)
        if value in (None, ""):
            return None
        full = os.path.normpath(os.path.join(base, os.path.expanduser(value)))
        if must_exist and not os.path.isfile(full):
            raise self.error(key, f"file {full!r} does not exist")
        return full

    def finish(self) -> None:
        unknown = sorted(set(self.table) - self.used)
        if unknown:
            raise ConfigError(
                f"{self.source}: [{self.name}]: unknown key(s) {unknown}; known keys are "
                f"{sorted(self.used)}"
            )


def _kind_names(kinds: tuple[type, ...]) -> str:
    names = {
        str: "a string",
        float: "a number",
        int: "an integer",
        bool: "true or false",
        list: "a list",
        dict: "a table",
    }
    return " or ".join(names.get(k, k.__name__) for k in kinds)


def _endpoint(section: _Section, key: str, default: str) -> str:
    value = section.get(key, str, default)
    if not re.match(r"^opc\.tcp://[^/:]+(:\d+)?(/.*)?$", value):
        raise section.error(key, f"must be an opc.tcp://HOST:PORT/PATH address, got {value!r}")
    return value


def _plant(source: str, table: Any, base: str) -> PlantConfig:
    s = _Section(source, "plant", table)
    d = PlantConfig()
    plant = PlantConfig(
        endpoint=_endpoint(s, "endpoint", d.endpoint),
        mode=s.choice("mode", d.mode, ("subscribe", "poll")),
        period=s.number("period", d.period),
        publishing_interval=s.number("publishing_interval", d.publishing_interval),
        timestamps=s.choice("timestamps", d.timestamps, ("source", "server")),
        max_delay=s.number("max_delay", d.max_delay),
        clock_tolerance=s.number("clock_tolerance", d.clock_tolerance),
        speed=s.number("speed", d.speed),
        reconnect_min=s.number("reconnect_min", d.reconnect_min),
        reconnect_max=s.number("reconnect_max", d.reconnect_max),
        timeout=s.number("timeout", d.timeout),
        security=s.choice("security", d.security, SECURITY_POLICIES),
        certificate=s.path("certificate", base),
        private_key=s.path("private_key", base),
        server_certificate=s.path("server_certificate", base),
        node_pattern=s.get("node_pattern", str, d.node_pattern),
    )
    s.finish()
    if plant.period != 1.0:
        raise s.error("period", "the diagnoser runs at 1 Hz: the plant period must be 1 s")
    if plant.reconnect_max < plant.reconnect_min:
        raise s.error("reconnect_max", "must be >= reconnect_min")
    if plant.clock_tolerance <= plant.max_delay * plant.speed:
        raise s.error("clock_tolerance", "must exceed max_delay x speed (plant seconds)")
    if plant.security != "None" and not (plant.certificate and plant.private_key):
        raise s.error("security", f"{plant.security} needs certificate and private_key")
    return plant


def _server(source: str, table: Any, base: str, *, check: bool) -> ServerConfig:
    s = _Section(source, "server", table)
    d = ServerConfig()
    security = s.get("security", (list, str), list(d.security))
    security = (security,) if isinstance(security, str) else tuple(security)
    for policy in security:
        if policy not in SECURITY_POLICIES:
            raise s.error("security", f"unknown policy {policy!r}; use {list(SECURITY_POLICIES)}")
    if not security:
        raise s.error("security", "give at least one policy")
    trusted = s.get("trusted_clients", list, [])
    paths = []
    for i, item in enumerate(trusted):
        if not isinstance(item, str):
            raise s.error("trusted_clients", f"item {i} must be a file name, got {item!r}")
        full = os.path.normpath(os.path.join(base, os.path.expanduser(item)))
        if not os.path.isfile(full):
            raise s.error("trusted_clients", f"file {full!r} does not exist")
        paths.append(full)
    server = ServerConfig(
        endpoint=_endpoint(s, "endpoint", d.endpoint),
        namespace=s.get("namespace", str, d.namespace),
        security=security,
        certificate=s.path("certificate", base),
        private_key=s.path("private_key", base),
        trusted_clients=tuple(paths),
        allow_anonymous=s.get("allow_anonymous", bool, d.allow_anonymous),
    )
    s.finish()
    secure = [p for p in security if p != "None"]
    if not check:
        return server
    if secure and not (server.certificate and server.private_key):
        raise s.error("security", f"{secure} need the server's certificate and private_key")
    if not server.allow_anonymous and not server.trusted_clients:
        raise s.error(
            "allow_anonymous",
            "anonymous access is off and no trusted_clients are given: no client could read the "
            "published values (list the clients' certificates, or set allow_anonymous = true)",
        )
    if not server.allow_anonymous and not secure:
        raise s.error("security", "client certificates need a secure policy (Basic256Sha256_*)")
    return server


def _log(source: str, table: Any, base: str) -> LogConfig:
    s = _Section(source, "log", table)
    d = LogConfig()
    folder = s.get("folder", str, d.folder)
    log = LogConfig(
        folder=os.path.normpath(os.path.join(base, os.path.expanduser(folder))),
        commit_seconds=s.number("commit_seconds", d.commit_seconds),
        segment_seconds=int(s.number("segment_seconds", d.segment_seconds)),
        resume_max_gap=int(s.number("resume_max_gap", d.resume_max_gap, strict=False)),
    )
    s.finish()
    if log.segment_seconds < 2:
        raise s.error("segment_seconds", "must be >= 2")
    return log


def _http(source: str, table: Any) -> HttpConfig:
    s = _Section(source, "http", table)
    d = HttpConfig()
    http = HttpConfig(
        address=s.get("address", str, d.address),
        history_seconds=int(s.number("history_seconds", d.history_seconds)),
        panels=int(s.number("panels", d.panels, strict=False)),
    )
    s.finish()
    if http.address:
        parse_address(http.address, what=f"{source}: [http] address")
    return http


def parse_address(text: str, *, what: str = "address") -> tuple[str, int]:
    """``HOST:PORT`` as (host, port); a `ConfigError` names ``what`` otherwise."""
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 <= int(port) < 65536:
        raise ConfigError(f"{what}: expected HOST:PORT (e.g. 127.0.0.1:8080), got {text!r}")
    return host.strip("[]"), int(port)


def _pairs(s: _Section, key: str, names: tuple[str, str]) -> tuple[tuple[int, int], ...]:
    out = []
    for i, item in enumerate(s.get(key, list, [])):
        if not isinstance(item, dict) or set(item) != set(names):
            raise s.error(key, f"item {i} must be a table with keys {list(names)}, got {item!r}")
        values = [item[n] for n in names]
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in values):
            raise s.error(key, f"item {i}: {names} must be integers (s)")
        if values[0] < 0 or (key == "outages" and values[1] <= 0):
            raise s.error(key, f"item {i}: {names[0]} must be >= 0 and the length > 0")
        out.append((int(values[0]), int(values[1])))
    return tuple(out)


def _simulation(source: str, table: Any) -> SimulationConfig:
    s = _Section(source, "simulation", table)
    d = SimulationConfig()
    start = s.get("start", (float, str), None)
    if isinstance(start, str):
        import datetime as dt

        try:
            start = dt.datetime.fromisoformat(start.replace("Z", "+00:00")).timestamp()
        except ValueError:
            raise s.error("start", f"expected an ISO date-time, got {start!r}") from None
    seconds = s.get("duplicates", list, []), s.get("late", list, [])
    for key, values in zip(("duplicates", "late"), seconds, strict=True):
        if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in values):
            raise s.error(key, "must be a list of seconds (integers >= 0)")
    sim = SimulationConfig(
        duration=int(s.number("duration", d.duration)),
        seed=int(s.get("seed", int, d.seed)),
        start=None if start is None else float(start),
        outages=_pairs(s, "outages", ("start", "seconds")),
        clock_jumps=_pairs(s, "clock_jumps", ("at", "seconds")),
        duplicates=tuple(seconds[0]),
        late=tuple(seconds[1]),
    )
    s.finish()
    return sim


def _valve(source: str, name: str, table: Any, plant: PlantConfig, base: str) -> ValveConfig:
    if not _VALVE_NAME.match(name):
        raise ConfigError(
            f"{source}: [valves.{name}]: a valve name is letters, digits, '_', '.' or '-' "
            "(at most 64), starting with a letter, digit or '_'"
        )
    s = _Section(source, f"valves.{name}", table)
    nodes_table = s.get("nodes", dict, {})
    unknown = sorted(set(nodes_table) - set(CHANNELS))
    if unknown:
        raise s.error("nodes", f"unknown channel(s) {unknown}; channels are {list(CHANNELS)}")
    nodes = {}
    for channel in CHANNELS:
        node = nodes_table.get(channel, plant.node_pattern.format(valve=name, channel=channel))
        if not isinstance(node, str):
            raise s.error("nodes", f"{channel} must be a node id string, got {node!r}")
        nodes[channel] = _check_node_id(s, channel, node)
    units_table = s.get("units", dict, {})
    try:
        units = parse_units({**PHYSICAL_UNITS, **units_table})
    except ValueError as exc:
        raise s.error("units", str(exc)) from None
    fault = s.get("fault", dict, None)
    valve = ValveConfig(
        name=name,
        model=s.path("model", base),
        endpoint=_endpoint(s, "endpoint", plant.endpoint),
        nodes=nodes,
        units=units,
        fault=None if fault is None else _fault(s, fault),
    )
    s.finish()
    return valve


def _check_node_id(s: _Section, channel: str, node: str) -> str:
    from asyncua import ua

    try:
        ua.NodeId.from_string(node)
    except Exception as exc:  # asyncua raises several types for a malformed id
        raise s.error("nodes", f"{channel}: {node!r} is not an OPC UA node id ({exc})") from None
    return node


def _fault(s: _Section, table: dict) -> Fault:
    known = {"name", "strength", "onset", "profile", "ramp"}
    if set(table) - known or "name" not in table:
        raise s.error("fault", f"a table with name and strength, onset, profile, ramp; got {table}")
    try:
        return Fault(
            table["name"],
            table.get("strength", 1.0),
            table.get("onset", 0.0),
            table.get("profile", "abrupt"),
            table.get("ramp", 0.0),
        ).validated()
    except ValueError as exc:
        raise s.error("fault", str(exc)) from None


def parse_config(
    text: str, *, source: str = "<config>", base: str = ".", publishing: bool = True
) -> ServeConfig:
    """Read the TOML ``text`` (paths relative to ``base``); a `ConfigError` names any mistake.

    ``publishing``: check the ``[server]`` section's security (``serve``); the simulated plant
    reads the same file without it.
    """
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: not valid TOML: {exc}") from None
    known = {"plant", "server", "log", "http", "simulation", "valves"}
    unknown = sorted(set(doc) - known)
    if unknown:
        raise ConfigError(f"{source}: unknown section(s) {unknown}; sections are {sorted(known)}")
    plant = _plant(source, doc.get("plant", {}), base)
    valves_table = doc.get("valves", {})
    if not isinstance(valves_table, dict) or not valves_table:
        raise ConfigError(f"{source}: no [valves.NAME] section: give at least one valve")
    valves = tuple(_valve(source, n, t, plant, base) for n, t in valves_table.items())
    seen: dict[tuple[str, str], str] = {}
    for v in valves:
        for channel, node in v.nodes.items():
            key = (v.endpoint, node)
            if key in seen:
                raise ConfigError(
                    f"{source}: [valves.{v.name}] nodes: {channel} = {node!r} is also {seen[key]}"
                )
            seen[key] = f"{v.name}.{channel}"
    return ServeConfig(
        path=source,
        plant=plant,
        server=_server(source, doc.get("server", {}), base, check=publishing),
        log=_log(source, doc.get("log", {}), base),
        http=_http(source, doc.get("http", {})),
        simulation=_simulation(source, doc.get("simulation", {})),
        valves=valves,
    )


def load_config(path: str | os.PathLike[str], *, publishing: bool = True) -> ServeConfig:
    """Read and check a TOML file (see the module docstring and `parse_config`)."""
    path = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as handle:
            text = handle.read()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot be read ({exc.strerror})") from None
    base = os.path.dirname(os.path.abspath(path))
    return parse_config(text, source=path, base=base, publishing=publishing)

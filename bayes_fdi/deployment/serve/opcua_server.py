"""The SEVA publisher: ``serve``'s own OPC UA server, one object per valve, read-only.

Address space (namespace ``[server] namespace``; node ids ``ns=<i>;s=<valve>.<variable>``)::

    Objects/Valves/<valve>/
        Time         DateTime   the plant second of the record
        Status       String     CLEAR, BLURRED, DAZZLED or BLIND
        Fault        String     the diagnosed fault or isolability group ("fn": none; "unknown")
        Probability  Double     its probability (NaN when none)
        DD           Boolean    the detection decision
        X, F         Double     measured stem position and flow (engineering units)
        X_VMV, X_VU  Double     validated measurement value and uncertainty of X (its unit)
        F_VMV, F_VU  Double     the same of F
        r_X, r_F     Double     whitened residuals (innovations, in standard deviations)
        Reason       String     why the status

Every analog variable has the ``EngineeringUnits`` (EUInformation) property. The measurement
variables (X, F, the VMVs and VUs, the residuals) carry the SEVA status as OPC UA quality: Good
(CLEAR), Uncertain (BLURRED, DAZZLED), Bad (BLIND; the value is then null); the status variables
are Good once the first record is in (BadWaitingForInitialData before). Values carry the record's
plant second as source timestamp.

Security (`bayes_fdi.deployment.serve.config.ServerConfig`): the endpoints' policies (default
Basic256Sha256 Sign & Encrypt only) with the server's certificate and key; client application
certificates must be in ``trusted_clients`` (checked when a session is created); the user is the
client's X509 certificate from the same list; anonymous users only with ``allow_anonymous``.
Clients may read, browse and subscribe; writes, method calls and node management are refused
(a permission rule set, and every variable is read-only).
"""

from __future__ import annotations

import datetime
import math
from collections.abc import Mapping, Sequence
from typing import Any

from asyncua import Server, ua
from asyncua.crypto.permission_rules import PermissionRuleset, User, UserRole

from bayes_fdi.datasets.units import to_physical
from bayes_fdi.deployment.serve.config import ServerConfig

__all__ = ["QUALITY", "SevaPublisher"]

#: SEVA status -> OPC UA status code of the measurement variables.
QUALITY: dict[str, int] = {
    "CLEAR": ua.StatusCodes.Good,
    "BLURRED": ua.StatusCodes.Uncertain,
    "DAZZLED": ua.StatusCodes.Uncertain,
    "BLIND": ua.StatusCodes.Bad,
}
_CODES = {status: ua.StatusCode(code) for status, code in QUALITY.items()}
_POLICY = {
    "None": ua.SecurityPolicyType.NoSecurity,
    "Basic256Sha256_Sign": ua.SecurityPolicyType.Basic256Sha256_Sign,
    "Basic256Sha256_SignAndEncrypt": ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt,
}
#: The requests a client may make (no Write, Call, AddNodes, DeleteNodes, ...).
_READ_ONLY_REQUESTS = frozenset(
    ua.NodeId(getattr(ua.ObjectIds, f"{name}Request_Encoding_DefaultBinary"))
    for name in (
        "CreateSession",
        "CloseSession",
        "ActivateSession",
        "Read",
        "Browse",
        "BrowseNext",
        "GetEndpoints",
        "FindServers",
        "TranslateBrowsePathsToNodeIds",
        "CreateSubscription",
        "ModifySubscription",
        "DeleteSubscriptions",
        "TransferSubscriptions",
        "CreateMonitoredItems",
        "ModifyMonitoredItems",
        "DeleteMonitoredItems",
        "Publish",
        "Republish",
        "CloseSecureChannel",
        "SetMonitoringMode",
        "SetPublishingMode",
        "RegisterNodes",
        "UnregisterNodes",
    )
)
#: (browse name, data type, channel whose unit it has or None, takes the SEVA quality)
_VARIABLES: tuple[tuple[str, int, str | None, bool], ...] = (
    ("Time", ua.ObjectIds.DateTime, None, False),
    ("Status", ua.ObjectIds.String, None, False),
    ("Fault", ua.ObjectIds.String, None, False),
    ("Probability", ua.ObjectIds.Double, "1", False),
    ("DD", ua.ObjectIds.Boolean, None, False),
    ("X", ua.ObjectIds.Double, "X", True),
    ("F", ua.ObjectIds.Double, "F", True),
    ("X_VMV", ua.ObjectIds.Double, "X", True),
    ("X_VU", ua.ObjectIds.Double, "X", True),
    ("F_VMV", ua.ObjectIds.Double, "F", True),
    ("F_VU", ua.ObjectIds.Double, "F", True),
    ("r_X", ua.ObjectIds.Double, "1", True),
    ("r_F", ua.ObjectIds.Double, "1", True),
    ("Reason", ua.ObjectIds.String, None, False),
)
_VARIANT = {
    ua.ObjectIds.DateTime: ua.VariantType.DateTime,
    ua.ObjectIds.String: ua.VariantType.String,
    ua.ObjectIds.Double: ua.VariantType.Double,
    ua.ObjectIds.Boolean: ua.VariantType.Boolean,
}


_INITIAL = {
    ua.ObjectIds.DateTime: datetime.datetime(1970, 1, 1, tzinfo=datetime.UTC),
    ua.ObjectIds.String: "",
    ua.ObjectIds.Double: math.nan,
    ua.ObjectIds.Boolean: False,
}


class ReadOnlyRules(PermissionRuleset):
    """Users may read, browse and subscribe; nothing else."""

    def check_validity(self, user: User, action_type_id: ua.NodeId, body: Any) -> bool:
        return (
            user is not None
            and user.role in (UserRole.User, UserRole.Admin)
            and (action_type_id in _READ_ONLY_REQUESTS)
        )


class TrustedClients:
    """User manager: a trusted client certificate is a (read-only) user; anonymous if allowed."""

    def __init__(self, certificates: Mapping[bytes, str], allow_anonymous: bool) -> None:
        self.certificates = dict(certificates)
        self.allow_anonymous = allow_anonymous

    def get_user(
        self,
        iserver: Any,
        username: str | None = None,
        password: str | None = None,
        certificate: Any = None,
    ) -> User | None:
        if username is not None:
            return None  # user names and passwords are not accepted
        der = _der(certificate)
        if der is not None and der in self.certificates:
            return User(role=UserRole.User, name=self.certificates[der])
        return User(role=UserRole.User, name="anonymous") if self.allow_anonymous else None

    async def validate_application(self, certificate: Any, description: Any) -> None:
        """Session creation: the client's application certificate must be trusted."""
        if _der(certificate) not in self.certificates:
            raise ua.uaerrors.BadCertificateUntrusted


def _der(certificate: Any) -> bytes | None:
    if certificate is None:
        return None
    if isinstance(certificate, bytes | bytearray):
        return bytes(certificate)
    from cryptography.hazmat.primitives.serialization import Encoding

    return certificate.public_bytes(Encoding.DER)


def _eu(unit: str) -> ua.EUInformation:
    info = ua.EUInformation()
    info.NamespaceUri = "http://www.opcfoundation.org/UA/units/un/cefact"
    info.UnitId = -1  # no UNECE code is claimed; the display name is the unit
    info.DisplayName = ua.LocalizedText(unit)
    info.Description = ua.LocalizedText(unit)
    return info


class SevaPublisher:
    """The OPC UA server ``serve`` publishes the valves' records on.

    Parameters
    ----------
    config
        The ``[server]`` section.
    valves
        Valve -> channel units (the X and F variables are published in those units).
    """

    def __init__(self, config: ServerConfig, valves: Mapping[str, Mapping[str, str]]) -> None:
        self.config = config
        self.valves = {v: dict(u) for v, u in valves.items()}
        self.server: Server | None = None
        self.nodes: dict[str, dict[str, ua.NodeId]] = {}
        self.namespace_index: int | None = None

    async def start(self) -> None:
        """Create the address space and open the endpoint."""
        from asyncua.crypto import uacrypto

        c = self.config
        trusted = {}
        for path in c.trusted_clients:
            cert = await uacrypto.load_certificate(path)
            trusted[_der(cert)] = path
        users = TrustedClients(trusted, c.allow_anonymous)
        server = Server(user_manager=users)
        await server.init()
        server.set_endpoint(c.endpoint)
        server.set_server_name("bayes-fdi serve (SEVA)")
        server.disable_clock()
        server.set_security_policy(
            [_POLICY[p] for p in c.security], permission_ruleset=ReadOnlyRules()
        )
        if c.certificate and c.private_key:
            await server.load_certificate(c.certificate)
            await server.load_private_key(c.private_key)
        tokens: list[type] = [ua.X509IdentityToken] if trusted else []
        if c.allow_anonymous:
            tokens.append(ua.AnonymousIdentityToken)
        server.set_identity_tokens(tokens)
        if trusted and any(p != "None" for p in c.security):
            server.set_certificate_validator(users.validate_application)
        idx = await server.register_namespace(c.namespace)
        self.namespace_index = idx
        root = await server.nodes.objects.add_folder(
            ua.NodeId("Valves", idx), ua.QualifiedName("Valves", idx)
        )
        for valve, units in self.valves.items():
            await self._add_valve(root, idx, valve, units)
        await server.start()
        self.server = server

    async def _add_valve(self, root: Any, idx: int, valve: str, units: Mapping[str, str]) -> None:
        obj = await root.add_object(ua.NodeId(valve, idx), ua.QualifiedName(valve, idx))
        nodes = {}
        waiting = ua.StatusCode(ua.StatusCodes.BadWaitingForInitialData)
        for name, dtype, unit_of, _ in _VARIABLES:
            nid = ua.NodeId(f"{valve}.{name}", idx)
            var = await obj.add_variable(
                nid,
                ua.QualifiedName(name, idx),
                _INITIAL[dtype],
                varianttype=_VARIANT[dtype],
                datatype=dtype,
            )
            if unit_of is not None:
                unit = unit_of if unit_of == "1" else units[unit_of]
                await var.add_property(
                    ua.NodeId(f"{valve}.{name}.EngineeringUnits", idx),
                    ua.QualifiedName("EngineeringUnits", 0),
                    _eu(unit),
                )
            await var.write_value(ua.DataValue(StatusCode=waiting))
            nodes[name] = nid
        self.nodes[valve] = nodes

    async def publish(self, valve: str, row: Mapping[str, Any]) -> None:
        """Write one record (a row of `bayes_fdi.deployment.serve.records`)."""
        import datetime as dt

        units = self.valves[valve]
        quality = _CODES[str(row["status"])]
        good = _CODES["CLEAR"]
        stamp = dt.datetime.fromtimestamp(int(row["time"]), dt.UTC)
        now = dt.datetime.now(dt.UTC)  # one server timestamp for the whole record
        values = _published_values(row, units)
        write = self.server.write_attribute_value
        nodes = self.nodes[valve]
        for name, dtype, _, takes_quality in _VARIABLES:
            variant = ua.Variant(values[name], _VARIANT[dtype])
            dv = ua.DataValue(
                variant,
                StatusCode=quality if takes_quality else good,
                SourceTimestamp=stamp,
                ServerTimestamp=now,
            )
            await write(nodes[name], dv)

    async def stop(self) -> None:
        """Close the endpoint."""
        if self.server is not None:
            await self.server.stop()
            self.server = None

    def endpoint_node_ids(self, valve: str) -> dict[str, str]:
        """Variable name -> node id string of a valve (for clients and tests)."""
        return {k: v.to_string() for k, v in self.nodes[valve].items()}


def _published_values(row: Mapping[str, Any], units: Mapping[str, str]) -> dict[str, Any]:
    """The variables' values: X and F quantities in their engineering units."""
    import datetime as dt

    def phys(channel: str, value: float) -> float:
        return float(to_physical(value, channel, units[channel]))

    def width(channel: str, centre: float, half: float) -> float:
        return phys(channel, centre + half) - phys(channel, centre)

    out: dict[str, Any] = {
        "Time": dt.datetime.fromtimestamp(int(row["time"]), dt.UTC),
        "Status": str(row["status"]),
        "Fault": str(row["state"]),
        "Probability": float(row["probability"]),
        "DD": bool(row["DD"]),
        "Reason": str(row["reason"]),
        "r_X": float(row["r_X"]),
        "r_F": float(row["r_F"]),
    }
    for c in ("X", "F"):
        out[c] = phys(c, row[c])
        out[f"{c}_VMV"] = phys(c, row[f"VMV_{c}"])
        out[f"{c}_VU"] = width(c, row[f"VMV_{c}"], row[f"VU_{c}"])
    return {
        k: (float("nan") if isinstance(v, float) and math.isnan(v) else v) for k, v in out.items()
    }


def status_of_quality(code: ua.StatusCode) -> str:
    """Good, Uncertain or Bad (the severity of an OPC UA status code)."""
    if code.is_good():
        return "Good"
    return "Uncertain" if code.is_uncertain() else "Bad"


def published_names() -> Sequence[str]:
    """The variables every valve object has."""
    return tuple(v[0] for v in _VARIABLES)

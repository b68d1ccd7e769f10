"""`prc3cfg status serve`: the configuration status on OPC UA (asyncua, the optional extra `opcua`),
read-only.

Address space, DI-shaped (OPC UA for Devices, namespace `DI`): asyncua ships no DI nodeset and none is
fetched, so the nodes carry DI's browse names in the DI namespace without DI's types (docs/status.md):

    Objects/DeviceSet/
        LINE/                           one object per line (bus), DeviceHealth: its modules' worst
            MODULE/                     one object per module
                RevisionCounter         Int32: verified applies and restores that changed it
                SoftwareRevision        String: "" (no PRC 3 message names its firmware)
                DeviceHealth            Int32: DeviceHealthEnumeration (NORMAL 0 … MAINTENANCE_REQUIRED 4)
                Configuration/          PlantFile, Commit, PlantHash, LastVerifiedTime, LastVerifiedBy,
                                        DriftFound, PendingTravel, HealthReason

Node ids are strings, `LINE`, `LINE/ADDRESS`, `LINE/ADDRESS/NAME`, in prc3cfg's namespace. No node is
writable (AccessLevel CurrentRead). Every `POLL` s the records' files are looked at (size and time of
change, `prc3cfg.shell.status.fingerprint`); when they changed the status is gathered again and published —
never a frame on the bus.

Security: Basic256Sha256 SignAndEncrypt only; the server's certificate given, or made once into the
user's state folder; a client's application certificate must be in the `--trust` folder (else its
channel is refused), and it is identified by that certificate (X509 identity) unless `--allow-anonymous`.
`--no-security`: the None endpoint alone, anonymous (the CLI warns).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass
from hashlib import sha256
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from asyncua import Node, Server, ua
from asyncua.crypto import cert_gen
from asyncua.crypto.permission_rules import SimpleRoleRuleset
from asyncua.crypto.truststore import TrustStore
from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions
from asyncua.server.user_managers import CertificateUserManager
from cryptography.x509.oid import ExtendedKeyUsageOID

from prc3cfg.core.status import ModuleFacts, health, worst
from prc3cfg.errors import UserError
from prc3cfg.plant import Plant
from prc3cfg.shell import machine_folder, platform
from prc3cfg.shell.cancel import Cancellation
from prc3cfg.shell.plant_files import load_plant, plant_bytes
from prc3cfg.shell.status import fingerprint, gather, identities

DI = "http://opcfoundation.org/UA/DI/"
NAMESPACE = "urn:prc3cfg:status"
APPLICATION_URI = "urn:prc3cfg:status-server"
#: Seconds between looks at the records' files.
POLL = 1.0
#: The Configuration group's variables: browse name → (value from a module's facts, variant type).
CONFIGURATION: dict[str, tuple[Callable[[ModuleFacts], Any], ua.VariantType]] = {
    "PlantFile": (lambda f: (f.last_verified and f.last_verified.plant_file) or "", ua.VariantType.String),
    "Commit": (lambda f: (f.last_verified and f.last_verified.commit) or "", ua.VariantType.String),
    "PlantHash": (lambda f: (f.last_verified and f.last_verified.plant_sha256) or "", ua.VariantType.String),
    "LastVerifiedTime": (lambda f: f.last_verified.time if f.last_verified else "", ua.VariantType.String),
    "LastVerifiedBy": (lambda f: (f.last_verified and f.last_verified.by) or "", ua.VariantType.String),
    "DriftFound": (lambda f: f.drift_seen, ua.VariantType.Boolean),
    "PendingTravel": (lambda f: f.travel_pending, ua.VariantType.Boolean),
    "HealthReason": (lambda f: health(f)[1], ua.VariantType.String),
}


@dataclass(frozen=True)
class ServerSettings:
    listen: str
    certificate: Path | None
    private_key: Path | None
    trust: Path | None
    allow_anonymous: bool
    no_security: bool


def _values(facts: ModuleFacts) -> dict[str, tuple[Any, ua.VariantType]]:
    """Every variable of a module by its path below the module's object."""
    values = {"RevisionCounter": (facts.revision, ua.VariantType.Int32),
              "SoftwareRevision": (facts.firmware, ua.VariantType.String),
              "DeviceHealth": (int(health(facts)[0]), ua.VariantType.Int32)}
    values |= {f"Configuration/{name}": (get(facts), kind) for name, (get, kind) in CONFIGURATION.items()}
    return values


def _endpoint(listen: str) -> str:
    parts = urlsplit(listen)
    if parts.scheme != "opc.tcp" or not parts.hostname or parts.port is None:
        raise UserError(f"--listen {listen}: not opc.tcp://HOST:PORT — e.g. --listen opc.tcp://0.0.0.0:4840")
    return listen


async def _server_certificate(settings: ServerSettings) -> tuple[Path, Path]:
    """The server's certificate and key: those given, else the ones made on the first start in this user's own
    state folder (`PRC3CFG_STATE_DIR` where set; never the machine's, which other users read) — the key
    readable by this user alone."""
    if settings.certificate is not None and settings.private_key is not None:
        return settings.certificate, settings.private_key
    folder = machine_folder.state_dirs()[-1] / "opcua"
    folder.mkdir(parents=True, exist_ok=True)
    cert, key = folder / "server-certificate.der", folder / "server-key.pem"
    await cert_gen.setup_self_signed_certificate(key, cert, APPLICATION_URI, socket.gethostname(),
                                                 [ExtendedKeyUsageOID.SERVER_AUTH],
                                                 {"commonName": "prc3cfg status",
                                                  "organizationName": "prc3cfg"})
    with key.open("rb") as handle:
        platform.set_mode(handle.fileno(), 0o600)
    return cert, key


async def _trusted(settings: ServerSettings) -> TrustStore | None:
    """The client certificates allowed in (None without security), read before the server is built — a
    wrong `--trust` is said before asyncua's own start and before a server key is made."""
    if settings.no_security:
        return None
    assert settings.trust is not None  # the CLI asks for it
    if not settings.trust.is_dir():
        raise UserError(f"--trust {settings.trust}: no such folder — give the folder of client certificates "
                        "(DER or PEM) allowed to connect")
    store = TrustStore([settings.trust], [])
    try:
        await store.load()
    # asyncua: "can't create an empty store", or a file there that is no certificate
    except ValueError as error:
        empty = not any(p.is_file() for p in settings.trust.iterdir())
        found = "holds no client certificate" if empty else f"cannot be read as certificates ({error})"
        raise UserError(f"--trust {settings.trust}: {found} — put there the DER or PEM certificates of the "
                        "clients allowed to connect") from None
    return store


async def _secured(server: Server, settings: ServerSettings, store: TrustStore | None) -> None:
    if store is None:
        server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
        server.set_identity_tokens([ua.AnonymousIdentityToken])
        return
    cert, key = await _server_certificate(settings)
    try:
        await server.load_certificate(str(cert))
        await server.load_private_key(str(key))
    except (OSError, ValueError) as error:
        raise UserError(f"{cert}, {key}: not a certificate and its private key ({error}) — give a DER "
                        "or PEM pair") from None
    server.set_security_policy([ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt],
                               permission_ruleset=SimpleRoleRuleset())
    options = CertificateValidatorOptions.TRUSTED_VALIDATION | CertificateValidatorOptions.PEER_CLIENT
    validator = CertificateValidator(options, store)
    server.set_certificate_validator(validator)
    server.set_identity_tokens([ua.X509IdentityToken,
                                *([ua.AnonymousIdentityToken] if settings.allow_anonymous else [])])


def _id(text: str, index: int) -> ua.NodeId:
    return ua.NodeId(ua.String(text), ua.Int16(index))


def _path(bus: str, *parts: object) -> str:
    """The string of a node id under a line, "LINE/ADDRESS/…" (docs/status.md): a "/" and a "%" in the line's
    name percent-encoded (a line named "a/1" is not module 1 of line "a": one id twice was BadNodeIdExists,
    and the server ended)."""
    return "/".join([bus.replace("%", "%25").replace("/", "%2F"), *map(str, parts)])


async def _variable(parent: Node, index: int, node_id: str, name: str, value: Any, kind: ua.VariantType,
                    di: int) -> Node:
    node = await parent.add_variable(_id(node_id, index), ua.QualifiedName(name, di), ua.Variant(value, kind))
    await node.write_attribute(ua.AttributeIds.AccessLevel,
                               ua.DataValue(ua.Variant(ua.AccessLevel.CurrentRead.mask, ua.VariantType.Byte)))
    await node.write_attribute(ua.AttributeIds.UserAccessLevel,
                               ua.DataValue(ua.Variant(ua.AccessLevel.CurrentRead.mask, ua.VariantType.Byte)))
    return node


async def _run(plant: Plant, settings: ServerSettings, stop: threading.Event) -> None:
    endpoint, store = _endpoint(settings.listen), await _trusted(settings)
    users = None if settings.no_security else CertificateUserManager()
    server = Server(user_manager=users)  # type: ignore[arg-type]  # asyncua's own manager, typed apart from its protocol
    await server.init()
    server.set_endpoint(endpoint)
    server.set_server_name("prc3cfg status")
    await server.set_application_uri(APPLICATION_URI)
    await _secured(server, settings, store)
    if users is not None and settings.trust is not None:
        for file in sorted(settings.trust.iterdir()):
            with contextlib.suppress(Exception):  # what is no certificate is no user
                await users.add_user(file, name=file.name)
    index = await server.register_namespace(NAMESPACE)
    di = await server.register_namespace(DI)
    space = _Space(server, await server.nodes.objects.add_folder(_id("DeviceSet", index),
                                                                 ua.QualifiedName("DeviceSet", di)), index,
                   di)
    keys = identities(plant)
    facts, _ = gather(plant, keys)
    await space.follow(facts)
    async with server:
        await _publish(server, space.variables, facts)
        print(f"listening on {settings.listen}", flush=True)
        # None: the first look checks again — what changed between the start's reads and this line, said to
        # the client already, would otherwise pass unseen; nor is `seen` taken again after a reload (a write
        # just after it would be missed): new keys only cost one more look
        seen: tuple[tuple[str, int, int], ...] | None = None
        while not await asyncio.to_thread(stop.wait, POLL):  # the polling period, cut short by a stop
            if (now := fingerprint(plant, keys)) == seen:
                continue
            seen = now
            if (changed := _reloaded(plant)) is not None:
                plant, keys = changed, identities(changed)
            facts = gather(plant, keys)[0]
            if changed is not None:
                added, removed = await space.follow(facts)
                print(f"{plant.path}: changed — publishing {len(facts)} modules (added "
                      f"{', '.join(added) or 'none'}, "
                      f"removed {', '.join(removed) or 'none'})", flush=True)
            await _publish(server, space.variables, facts)


def _reloaded(plant: Plant) -> Plant | None:
    """The plant file again where its bytes changed; None where they did not, or where it is no longer valid
    (said in one line: the server goes on publishing the plant it last read whole)."""
    try:
        if sha256(plant_bytes(plant.path)).hexdigest() == plant.sha256:
            return None
        return load_plant(plant.path)
    except UserError as error:
        problem = str(error).splitlines()[0]
        print(f"{problem if problem.startswith(str(plant.path)) else f'{plant.path}: {problem}'} — still "
              "publishing its last valid "
              f"version", flush=True)
        return None


class _Space:
    """The DeviceSet's nodes: a line object per bus, a module object per module with its variables. `follow`
    makes them what the plant file holds now: the nodes of a module added to it are added, those of one taken
    out deleted."""

    def __init__(self, server: Server, device_set: Node, index: int, di: int) -> None:
        self.server, self.device_set, self.index, self.di = server, device_set, index, di
        self.variables: dict[str, Node] = {}
        self.lines: dict[str, Node] = {}
        self.modules: dict[str, tuple[str, Node]] = {}  # "LINE/ADDRESS" → (module name, its object)

    async def follow(self, facts: list[ModuleFacts]) -> tuple[list[str], list[str]]:
        """Add the nodes of modules not published yet, delete those of modules gone: their names, added and
        removed."""
        wanted = {_path(f.bus, f.address): f for f in facts}
        removed = [name for key, (name, _) in self.modules.items() if key not in wanted
                   or wanted[key].name != name]
        for key in [key for key, (name, _) in self.modules.items() if name in removed]:
            await self.server.delete_nodes([self.modules.pop(key)[1]], recursive=True)
            self.variables = {path: n for path, n in self.variables.items() if not path.startswith(f"{key}/")}
        for bus in [bus for bus in self.lines if not any(f.bus == bus for f in facts)]:
            await self.server.delete_nodes([self.lines.pop(bus)], recursive=True)
            del self.variables[_path(bus, "DeviceHealth")]
        added = [f.name for key, f in wanted.items() if key not in self.modules]
        for key, f in wanted.items():
            if key not in self.modules:
                self.modules[key] = (f.name, await self._module(f))
        return added, removed

    async def _module(self, f: ModuleFacts) -> Node:
        index, di = self.index, self.di
        if f.bus not in self.lines:
            line = await self.device_set.add_object(_id(_path(f.bus), index), ua.QualifiedName(f.bus, index))
            self.lines[f.bus] = line
            health = _path(f.bus, "DeviceHealth")
            self.variables[health] = await _variable(line, index, health, "DeviceHealth", 0,
                                                     ua.VariantType.Int32, di)
        module = await self.lines[f.bus].add_object(_id(_path(f.bus, f.address), index),
                                                    ua.QualifiedName(f.name, index))
        group = await module.add_object(_id(_path(f.bus, f.address, "Configuration"), index),
                                        ua.QualifiedName("Configuration", di))
        for path, (value, kind) in _values(f).items():
            configured = path.startswith("Configuration/")
            parent, name = (group, path.partition("/")[2]) if configured else (module, path)
            node_id = _path(f.bus, f.address, path)
            self.variables[node_id] = await _variable(parent, index, node_id, name, value, kind, di)
        return module


async def _publish(server: Server, variables: dict[str, Node], facts: list[ModuleFacts]) -> None:
    """Write the values of `facts` into the nodes (server side: clients cannot)."""
    by_line: dict[str, list[ModuleFacts]] = {}
    for f in facts:
        by_line.setdefault(f.bus, []).append(f)
        for path, (value, kind) in _values(f).items():
            if (node := variables.get(_path(f.bus, f.address, path))) is not None:
                await server.write_attribute_value(node.nodeid, ua.DataValue(ua.Variant(value, kind)))
    for bus, found in by_line.items():
        value = int(worst([health(f)[0] for f in found]))
        await server.write_attribute_value(variables[_path(bus, "DeviceHealth")].nodeid,
                                           ua.DataValue(ua.Variant(value, ua.VariantType.Int32)))


def serve(plant: Plant, settings: ServerSettings, cancel: Cancellation) -> None:
    """Serve until SIGINT or SIGTERM (`cancel`, handling them): the signal only sets its event, which ends the
    server's wait for its next look at the records — an exception raised by the signal inside asyncua's own
    callbacks (a client's handshake) was caught there, and the server went on serving."""
    # its warnings are for its developers; refusals are its clients' to see
    logging.getLogger("asyncua").setLevel(logging.ERROR)
    try:
        with cancel.deferred():
            asyncio.run(_run(plant, settings, cancel.event))
    except OSError as error:
        raise UserError(f"--listen {settings.listen}: cannot listen there ({error.strerror or error}) — "
                        "choose another port") from None
    print("stopped", file=sys.stderr)

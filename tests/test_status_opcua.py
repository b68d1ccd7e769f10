"""`prc3cfg status serve` (issue 44, item 2): a real server process started by the CLI, read with asyncua's
own client — every node, RevisionCounter and DeviceHealth around an apply on the emulator, a client without a
trusted certificate refused, every write refused. Synchronised on the "listening on" line and on node values
(polled, bounded), never on a sleep. Skipped, naming the install command, where asyncua is missing."""

from __future__ import annotations

import asyncio
import os
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

asyncua = pytest.importorskip("asyncua", reason="asyncua is not installed: pip install -e '.[opcua]'")

from asyncua import Client, ua  # noqa: E402
from asyncua.crypto import cert_gen  # noqa: E402
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256  # noqa: E402
from cryptography.x509.oid import ExtendedKeyUsageOID  # noqa: E402
from emulated import emulated_plant, run_cli  # noqa: E402

from prc3cfg.shell.locks import line_lock  # noqa: E402
from prc3cfg.shell.sessions import bus_line_keys  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CLIENT_URI = "urn:prc3cfg:test-client"
#: The longest a published value may take to follow the records: the server looks every second.
WAIT = 30.0
VARIABLES = ("RevisionCounter", "SoftwareRevision", "DeviceHealth", "Configuration/PlantFile",
             "Configuration/Commit",
             "Configuration/PlantHash", "Configuration/LastVerifiedTime", "Configuration/LastVerifiedBy",
             "Configuration/DriftFound", "Configuration/PendingTravel",
             "Configuration/HealthReason")


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def certificate(folder: Path, name: str) -> tuple[Path, Path]:
    folder.mkdir(parents=True, exist_ok=True)
    cert, key = folder / f"{name}.der", folder / f"{name}-key.pem"
    asyncio.run(cert_gen.setup_self_signed_certificate(key, cert, CLIENT_URI, "localhost",
                                                       [ExtendedKeyUsageOID.CLIENT_AUTH],
                                                       {"commonName": name}))
    return cert, key


class Served:
    def __init__(self, process: subprocess.Popen, url: str, plant) -> None:
        self.process, self.url, self.plant = process, url, plant


@pytest.fixture
def served(tmp_path):
    """The emulated demo plant, a trusted client certificate, and `status serve` on it as a real process."""
    trusted, key = certificate(tmp_path / "client", "trusted")
    (tmp_path / "trust").mkdir()
    (tmp_path / "trust" / "trusted.der").write_bytes(trusted.read_bytes())
    with emulated_plant(tmp_path) as plant:
        url = f"opc.tcp://127.0.0.1:{free_port()}"
        process = subprocess.Popen([sys.executable, "-m", "prc3cfg", "status", "serve", str(plant.path),
                                    "--listen", url,
                                    "--trust", str(tmp_path / "trust")], stdout=subprocess.PIPE,
                                   stderr=subprocess.PIPE, text=True,
                                   env=os.environ | {"PYTHONPATH": str(ROOT)})
        try:
            line = process.stdout.readline()
            assert line.strip() == f"listening on {url}", (line, process.stderr.read()
                                                           if process.poll() is not None else "")
            yield Served(process, url, plant), (trusted, key)
        finally:
            process.terminate()
            # drained: a server blocked on a full pipe would not see the signal
            _, stderr = process.communicate(timeout=30)
    # SIGTERM stops it between two looks at its cancel event — also after a client's refused handshake, where
    # a signal raised inside asyncua's own callback was caught there and the server served on (a 30 s hang)
    if sys.platform != "win32":
        assert process.returncode == 0, (process.returncode, stderr)
        assert stderr.strip().splitlines()[-1:] == ["stopped"], (process.returncode, stderr)


async def connected(url: str, cert: Path, key: Path, *, identified: bool = True) -> Client:
    """asyncua's client on the secure channel with `cert`; `identified`: the user is that certificate (else
    anonymous)."""
    client = Client(url)
    client.application_uri = CLIENT_URI
    await client.set_security(SecurityPolicyBasic256Sha256, str(cert), str(key),
                              mode=ua.MessageSecurityMode.SignAndEncrypt)
    if identified:
        await client.load_client_certificate(str(cert))
        await client.load_private_key(str(key))
    await client.connect()
    return client


async def node(client: Client, path: str):
    index = await client.get_namespace_index("urn:prc3cfg:status")
    return client.get_node(ua.NodeId(path, index))


async def wait_for(client: Client, path: str, wanted) -> None:
    """Poll the node until it holds `wanted`, bounded by WAIT."""
    target = await node(client, path)
    deadline = time.monotonic() + WAIT
    while (value := await target.read_value()) != wanted:
        assert time.monotonic() < deadline, f"{path} stayed {value!r}, never {wanted!r}"
        await asyncio.sleep(0.1)


def test_a_trusted_client_reads_every_node_and_sees_an_apply(served, capsys):
    server, (cert, key) = served
    plant = server.plant

    async def check() -> None:
        client = await connected(server.url, cert, key)
        try:
            di = await client.get_namespace_index("http://opcfoundation.org/UA/DI/")
            device_set = await client.nodes.objects.get_child(ua.QualifiedName("DeviceSet", di))
            lines = await device_set.get_children()
            assert len(lines) == 2  # booth-a, booth-b
            for path in ("booth-a/DeviceHealth", *(f"booth-a/1/{v}" for v in VARIABLES)):
                await (await node(client, path)).read_value()  # each is there and readable
            assert await (await node(client, "booth-a/1/RevisionCounter")).read_value() == 0
            bus = next(b for b in plant.plant.buses if b.name == "booth-a")
            with line_lock(bus_line_keys(plant.plant, bus), "test: an apply holds the line"):
                await wait_for(client, "booth-a/1/DeviceHealth", 2)  # CHECK_FUNCTION
            result = run_cli(capsys, "apply", plant.path, "--auto-approve", "--allow-axis-release")
            assert result.code == 0, result.err
            await wait_for(client, "booth-a/1/RevisionCounter", 1)
            await wait_for(client, "booth-a/1/DeviceHealth", 0)  # NORMAL
            assert (await (await node(client, "booth-a/1/Configuration/PlantHash")).read_value())
            target = await node(client, "booth-a/1/RevisionCounter")
            with pytest.raises(ua.UaStatusCodeError) as refused:
                await target.write_value(ua.DataValue(ua.Variant(7, ua.VariantType.Int32)))
            assert type(refused.value).__name__ in ("BadUserAccessDenied", "BadNotWritable")
            assert await target.read_value() == 1
        finally:
            await client.disconnect()

    asyncio.run(check())


def test_a_client_without_a_trusted_certificate_is_refused(served, tmp_path):
    server, _ = served
    stranger, key = certificate(tmp_path / "stranger", "stranger")

    async def check() -> None:
        with pytest.raises(ua.UaStatusCodeError) as refused:
            client = await connected(server.url, stranger, key)
            await client.disconnect()
        assert type(refused.value).__name__ == "BadCertificateUntrusted", repr(refused.value)

    asyncio.run(check())


def test_a_trusted_client_without_a_user_is_refused_unless_anonymous_is_allowed(served):
    server, (cert, key) = served

    async def check() -> None:
        with pytest.raises(ua.UaStatusCodeError) as refused:
            client = await connected(server.url, cert, key, identified=False)
            await client.disconnect()
        assert type(refused.value).__name__.startswith("BadIdentityToken"), repr(refused.value)

    asyncio.run(check())


@pytest.mark.parametrize("content", [None, b"not a certificate"], ids=["empty", "no certificate"])
def test_a_trust_folder_without_certificates_is_one_line(tmp_path, content):
    """An empty folder, or one holding no certificate, ended in asyncua's traceback ("can't create an empty
    store"). It is said before the server is built: no server key is made for a start that is refused."""
    state = tmp_path / "state"
    (tmp_path / "trust").mkdir()
    if content is not None:
        (tmp_path / "trust" / "client.der").write_bytes(content)
    with emulated_plant(tmp_path) as plant:
        done = subprocess.run([sys.executable, "-m", "prc3cfg", "status", "serve", str(plant.path),
                               "--listen", f"opc.tcp://127.0.0.1:{free_port()}",
                               "--trust", str(tmp_path / "trust")], capture_output=True, text=True,
                              timeout=60,
                              env=os.environ | {"PYTHONPATH": str(ROOT), "PRC3CFG_STATE_DIR": str(state)})
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    (line,) = done.stderr.strip().splitlines()
    assert (line.startswith(f"error: --trust {tmp_path / 'trust'}: ")
            and "certificates of the clients allowed to connect" in line), line
    assert not (state / "opcua").exists(), sorted(state.rglob("*"))


def test_the_server_s_own_key_is_kept_in_this_user_s_state_folder_for_this_user_alone(served, tmp_path):
    """Made on the first start where no --certificate is given: in PRC3CFG_STATE_DIR (the tests' own), mode
    0600."""
    key = Path(os.environ["PRC3CFG_STATE_DIR"]) / "opcua" / "server-key.pem"
    assert key.is_file()
    if sys.platform != "win32":
        assert key.stat().st_mode & 0o777 == 0o600


def edited(server: Served, old: str, new: str) -> str:
    """The served plant file with its first `old` made `new` (which changes it), and the line the server says
    of it."""
    text = server.plant.path.read_text()
    changed = text.replace(old, new, 1)
    assert changed != text
    server.plant.path.write_text(changed)
    return _said(server.process, f"{server.plant.path}:")


def _said(process: subprocess.Popen, start: str) -> str:
    """The next line the server prints on stdout that starts with `start` (it prints one each time the plant
    file it serves changes), read by a thread so that a server that never says it fails the test within WAIT,
    not hangs it."""
    lines: queue.Queue[str] = queue.Queue()

    def read() -> None:
        while (line := process.stdout.readline()) and not line.startswith(start):
            pass
        lines.put(line.strip())

    threading.Thread(target=read, daemon=True).start()
    try:
        return lines.get(timeout=WAIT)
    except queue.Empty:
        raise AssertionError(f"the server did not say {start!r} within {WAIT} s") from None


def test_a_module_added_to_the_plant_file_is_published_without_a_restart_and_a_broken_file_keeps_the_last(
    served,
):
    server, (cert, key) = served
    path = server.plant.path
    text = path.read_text()
    said = edited(server, "    name: booth-a-left\n", "    name: booth-a-left\n    bogus: 1\n")
    assert "unknown key 'bogus'" in said and said.endswith("still publishing its last valid version"), said
    grown = text.replace("  - address: 5\n",
                         "  - address: 7\n    name: booth-a-new\n    profiles: reciprocator\n  - "
                         "address: 5\n", 1)
    assert grown != text
    path.write_text(grown)
    assert _said(server.process,
                 f"{path}:") == f"{path}: changed — publishing 7 modules (added booth-a-new, removed none)"

    async def check() -> None:
        client = await connected(server.url, cert, key)
        try:
            for v in VARIABLES:
                await (await node(client, f"booth-a/7/{v}")).read_value()  # each is there and readable
        finally:
            await client.disconnect()

    asyncio.run(check())
    path.write_text(text)
    assert _said(server.process,
                 f"{path}:") == f"{path}: changed — publishing 6 modules (added none, removed booth-a-new)"

    async def gone() -> None:
        client = await connected(server.url, cert, key)
        try:
            with pytest.raises(ua.UaStatusCodeError) as unknown:
                await (await node(client, "booth-a/7/RevisionCounter")).read_value()
            assert type(unknown.value).__name__ == "BadNodeIdUnknown"
            # the others stay
            assert await (await node(client, "booth-a/1/RevisionCounter")).read_value() == 0
        finally:
            await client.disconnect()

    asyncio.run(gone())


def test_a_line_named_like_another_line_s_module_has_nodes_of_its_own(served):
    """Node ids are "LINE/ADDRESS/…": a line named "booth-a/1" (booth-b renamed, the file reloaded) took the
    id of booth-a's module 1, and the server ended (BadNodeIdExists). A "/" (and a "%") in a line's name is
    percent-encoded in its ids: its nodes are its own, and booth-a's module 1 keeps its own."""
    server, (cert, key) = served
    said = edited(server, "- name: booth-b\n", "- name: booth-a/1\n")
    assert said.startswith(f"{server.plant.path}: changed — publishing 6 modules"), said

    async def check() -> None:
        client = await connected(server.url, cert, key)
        try:
            di = await client.get_namespace_index("http://opcfoundation.org/UA/DI/")
            device_set = await client.nodes.objects.get_child(ua.QualifiedName("DeviceSet", di))
            names = {(await line.read_browse_name()).Name for line in await device_set.get_children()}
            assert names == {"booth-a", "booth-a/1"}
            for path_ in ("booth-a%2F1/DeviceHealth", *(f"booth-a%2F1/{a}/{v}" for a in (1, 3, 4)
                                                         for v in VARIABLES)):
                await (await node(client, path_)).read_value()  # each is there and readable
            module = await node(client, "booth-a/1")
            assert (await module.read_browse_name()).Name == "booth-a-left"
            module = await node(client, "booth-a%2F1/1")
            assert (await module.read_browse_name()).Name == "booth-b-left"
        finally:
            await client.disconnect()

    asyncio.run(check())

"""An OPC UA client over loopback, an encrypted session, a controller on the mock loom."""

from __future__ import annotations

import asyncio
import socket
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from asyncua import Client, ua
from asyncua.crypto import cert_gen
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from cryptography import x509
from cryptography.hazmat.primitives.serialization import Encoding
from cryptography.x509.oid import ExtendedKeyUsageOID

from bwsd.controller.facade import Controller
from bwsd.fieldbus import open_bus
from bwsd.journal import Journal
from bwsd.opcua.server import OpcUaServer
from bwsd.opcua.space import NAMESPACE, ROOT
from bwsd.tokens import TokenStore
from tests.support.fieldbus import client_config, mock, slow_mock

__all__ = ["mock", "slow_mock"]

CYCLE = "ROW 1:+1 2:-1\nCOL 1:+1 2:-1\nROW 1:-1 2:+1\nCOL 1:-1 2:+1\nTAKEUP 2\n"
TEXT = f"YARN diameter=1\nFILL row=1 col=0\n.XX.\n.XX.\nEND\nREPEAT 3\n{CYCLE}END\n"  # 15


def run(scenario: Any) -> Any:
    return asyncio.run(asyncio.wait_for(scenario, 90))


@dataclass(frozen=True)
class ClientCert:
    """A client application's certificate and key files, and its application URI."""

    cert: Path
    key: Path
    uri: str


def client_cert(folder: Path, name: str = "line-plc") -> ClientCert:
    """A self-signed OPC UA client certificate (what a PLC's OPC UA client makes)."""
    folder.mkdir(parents=True, exist_ok=True)
    uri = f"urn:{socket.gethostname()}:{name}"
    key = cert_gen.generate_private_key()
    names = [x509.UniformResourceIdentifier(uri), x509.DNSName(socket.gethostname())]
    cert = cert_gen.generate_self_signed_app_certificate(
        key, name, {}, names, [ExtendedKeyUsageOID.CLIENT_AUTH]
    )
    made = ClientCert(folder / f"{name}.der", folder / f"{name}.pem", uri)
    made.cert.write_bytes(cert.public_bytes(Encoding.DER))
    made.key.write_bytes(cert_gen.dump_private_key_as_pem(key))
    return made


def trust(server_folder: Path, cert: ClientCert) -> None:
    """What an integrator does: copy the client's certificate into trusted/."""
    trusted = server_folder / "trusted"
    trusted.mkdir(parents=True, exist_ok=True)
    (trusted / cert.cert.name).write_bytes(cert.cert.read_bytes())


@asynccontextmanager
async def session(
    url: str, cert: ClientCert | None, user: str | None = None, password: str | None = None
) -> AsyncIterator[Client]:
    """A connected client: Basic256Sha256 Sign & Encrypt with ``cert`` (None: no security)."""
    client = Client(url, timeout=10)
    if cert is not None:
        client.application_uri = cert.uri
        await client.set_security(
            SecurityPolicyBasic256Sha256,
            str(cert.cert),
            str(cert.key),
            mode=ua.MessageSecurityMode.SignAndEncrypt,
        )
    if user is not None:
        client.set_user(user)
        client.set_password(password or "")
    await client.connect()
    try:
        yield client
    finally:
        await client.disconnect()


async def loom(client: Client) -> Any:
    """The PackML object, found by browsing from Objects."""
    idx = await client.get_namespace_index(NAMESPACE)
    return await client.nodes.objects.get_child(f"{idx}:{ROOT}")


async def var(client: Client, path: str) -> Any:
    idx = await client.get_namespace_index(NAMESPACE)
    node = await loom(client)
    return await node.get_child([f"{idx}:{part}" for part in path.split("/")])


@dataclass
class Rig:
    controller: Controller
    journal: Journal
    server: OpcUaServer
    tokens: TokenStore
    folder: Path
    cert: ClientCert
    users: dict[str, str]  # name -> token (the password)

    def session(self, name: str = "operator", cert: ClientCert | None = None) -> Any:
        return session(self.server.url, cert or self.cert, name, self.users[name])


@asynccontextmanager
async def rig(
    mock: Any, tmp_path: Path, *, trusted: bool = True, **settings: Any
) -> AsyncIterator[Rig]:
    """A controller on the mock loom, its OPC UA server, three users and a client (trusted
    unless ``trusted`` is false: then the state folder is as a fresh install leaves it)."""
    config = client_config("modbus", mock.ports)
    bus = open_bus(config)
    await bus.connect()
    journal = Journal.open(tmp_path / "journal.db")
    ctl = Controller(config.machine, bus, journal)
    tokens = TokenStore.load(tmp_path / "tokens.json")
    users = {role: tokens.add(role, role) for role in ("viewer", "operator", "admin")}
    folder = tmp_path / "opcua"
    cert = client_cert(tmp_path / "client")
    if trusted:
        trust(folder, cert)
    server = OpcUaServer(ctl, tokens, folder, {"port": 0, **settings})
    try:
        await server.start()
        yield Rig(ctl, journal, server, tokens, folder, cert, users)
    finally:
        await server.stop()
        await ctl.wait()
        await bus.close()
        journal.close()

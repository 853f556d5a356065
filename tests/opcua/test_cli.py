"""`bwsd opcua cert`, and a server that cannot start says where and why."""

from __future__ import annotations

import hashlib
import re
import socket
import subprocess
import sys

import pytest
from asyncua import Client

from bwsd.cli import main
from bwsd.opcua.security import OpcUaError
from tests.opcua.conftest import rig, run
from tests.support.fieldbus import MACHINE, toml

pytestmark = pytest.mark.slow  # every test here is in the slow tier


def thumbprint(out: str) -> str:
    found = re.search(r"thumbprint \(SHA-1\) ([0-9A-F:]{59})", out)
    assert found, out
    return found[1]


def test_cert_is_made_once_shown_and_renewed(tmp_path, capsys, mock):
    config = tmp_path / "bwsd.toml"
    config.write_text(toml({"machine": MACHINE}))
    where = ["--config", str(config), "--state-dir", str(tmp_path)]
    assert main(["opcua", "cert", *where]) == 0
    first = thumbprint(capsys.readouterr().out)
    assert main(["opcua", "cert", *where]) == 0
    assert thumbprint(capsys.readouterr().out) == first  # shown, not made again
    assert oct((tmp_path / "opcua" / "server-key.pem").stat().st_mode & 0o777) == "0o600"
    assert main(["opcua", "cert", *where, "--renew"]) == 0
    renewed = thumbprint(capsys.readouterr().out)
    assert renewed != first

    async def served() -> str:  # the daemon serves the certificate the command showed
        async with rig(mock, tmp_path) as r:
            client = Client(r.server.url, timeout=5)
            endpoints = await client.connect_and_get_server_endpoints()
            der = endpoints[0].ServerCertificate
            digest = hashlib.sha1(der, usedforsecurity=False).hexdigest().upper()
            return ":".join(digest[i : i + 2] for i in range(0, 40, 2))

    assert run(served()) == renewed


@pytest.mark.slow
def test_a_port_in_use_is_an_error_naming_the_table(mock, tmp_path):
    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        port = held.getsockname()[1]

        async def scenario() -> None:
            async with rig(mock, tmp_path, port=port):
                pass

        with pytest.raises(OpcUaError, match=rf"\[opcua\] cannot listen on 127.0.0.1:{port}"):
            run(scenario())


@pytest.mark.slow
def test_serve_stops_with_the_error_when_the_opcua_port_is_taken(tmp_path):
    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        port = held.getsockname()[1]
        config = tmp_path / "bwsd.toml"
        config.write_text(
            toml(
                {
                    "machine": MACHINE,
                    "api": {"port": 0},
                    "plc": {"port": 0},
                    "opcua": {"enabled": True, "port": port},
                }
            )
        )
        served = subprocess.run(
            [
                sys.executable,
                "-m",
                "bwsd.cli",
                "serve",
                "--config",
                str(config),
                "--state-dir",
                str(tmp_path / "state"),
            ],
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )
    assert served.returncode == 2, served.stderr
    assert served.stdout == ""  # never ready
    assert served.stderr.endswith(
        f"bwsd: error: [opcua] cannot listen on 127.0.0.1:{port}: Address already in use\n"
    ), served.stderr[-300:]

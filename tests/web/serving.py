"""`bwsd serve` on the mock loom for the page's tests: an example's machine and a program."""

from __future__ import annotations

import tomllib
from pathlib import Path

from bwsd.api.auth import TokenStore
from tests.fieldbus.conftest import BUS, Mock, start_mock, toml
from tests.test_daemon import Served

ROOT = Path(__file__).resolve().parents[2]


def example(stem: str) -> tuple[str, dict[str, object]]:
    """The example program ``stem`` and the machine table of its config."""
    text = (ROOT / "examples" / f"{stem}.bws").read_text()
    machine = tomllib.loads((ROOT / "config" / f"{stem}.toml").read_text())["machine"]
    return text, machine


def serve(tmp: Path, machine: dict[str, object], text: str) -> tuple[Served, Mock, str]:
    """The mock loom set up for ``text`` and `bwsd serve` on it (Modbus), with an operator's
    token: the daemon, the loom and the token; the caller stops both."""
    mock = start_mock(tmp, {}, machine=machine, program=text)
    config = tmp / "bwsd.toml"
    config.write_text(toml({"machine": machine, "fieldbus": {"backend": "modbus", **BUS},
                            "fieldbus.modbus": {"port": mock.ports["modbus"]},
                            "api": {"port": 0}, "plc": {"port": 0}}))  # fmt: skip
    state = tmp / "state"
    state.mkdir()
    token = TokenStore.load(state / "tokens.json").add("tester", "operator")
    return Served(config, state, token), mock, token

"""`bwsd demo`: a port in use names the option that moves it, the mock loom's failure always
has a reason, and the demo's token ends with the demo."""

from __future__ import annotations

import json
import re
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from bwsd.api.auth import TokenStore

ROOT = Path(__file__).resolve().parents[1]
OPTIONS = ("--api-port", "--plc-port", "--modbus-port", "--socketcand-port", "--control-port")
FREE = [word for option in OPTIONS for word in (option, "0")]


def _demo(cwd: Path, *args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    bwsd = shutil.which("bwsd", path=str(Path(sys.executable).parent))
    assert bwsd, "the bwsd console script is not installed beside this Python"
    command = [bwsd, "demo", "--exit-when-done", *args]
    return subprocess.run(command, capture_output=True, text=True, timeout=timeout, cwd=cwd)


def _ports(option: str, port: int) -> list[str]:
    """Every port free but ``option``'s, which is ``port``."""
    return [word for name in OPTIONS for word in (name, str(port) if name == option else "0")]


@pytest.mark.parametrize(
    ("option", "what"),
    [
        ("--api-port", r"the REST API and the page \(\[api\] port\)"),
        ("--plc-port", r"the PLC tags \(\[plc\] port\)"),
        ("--modbus-port", r"the mock loom's Modbus server \(\[simulator\] modbus_port\)"),
        ("--control-port", r"the mock loom's control channel \(\[simulator\] control_port\)"),
    ],
)
def test_a_port_in_use_names_the_option_to_change_and_nothing_starts(tmp_path, option, what):
    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = taken.getsockname()[1]
        done = _demo(tmp_path, *_ports(option, port), timeout=120)
    assert done.returncode == 2, done.stdout + done.stderr
    assert re.fullmatch(
        rf"bwsd: error: port {port} of {what} is in use on 127\.0\.0\.1: choose another with "
        rf"{option} PORT \(0: any free port\)\n",
        done.stderr,
    ), done.stderr
    assert done.stdout == "" and list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_a_mock_loom_that_cannot_start_says_why(tmp_path):
    text = (ROOT / "config" / "loom.toml").read_text()
    config = tmp_path / "loom.toml"
    config.write_text(text.replace('state_file = ""', 'state_file = "loom.json"'))
    (tmp_path / "loom.json").write_text("not the mechanics of a loom")
    done = _demo(tmp_path, "--config", str(config), *FREE, timeout=120)
    assert done.returncode == 2
    last = done.stderr.strip().splitlines()[-1]
    wanted = (
        r"bwsd: error: the mock loom did not start: simulator_hw: error: .*loom\.json: not the "
        r"saved state of this machine .*"
    )
    assert re.fullmatch(wanted, last), last


@pytest.mark.slow
def test_the_demo_token_is_revoked_when_it_stops_and_a_stale_one_replaced(tmp_path):
    state = tmp_path / "state"
    state.mkdir()
    stale = TokenStore.load(state / "tokens.json").add("demo", "operator")  # a killed demo's
    kept = TokenStore.load(state / "tokens.json").add("alice", "viewer")
    done = _demo(tmp_path, "--state-dir", str(state), *FREE)
    assert done.returncode == 0, done.stdout + done.stderr
    said = r"^operator token: (\S+) \(revoked when the demo stops\)$"
    token = re.search(said, done.stdout, re.MULTILINE)
    assert token and token[1] != stale
    store = TokenStore.load(state / "tokens.json")
    assert [entry.name for entry in store.entries] == ["alice"]
    assert store.check(token[1]) is None and store.check(stale) is None
    assert store.check(kept) == ("alice", "viewer")
    assert json.loads((state / "tokens.json").read_text())["version"] == 1

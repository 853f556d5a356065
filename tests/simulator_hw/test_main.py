"""`bwsd mock` (python -m simulator_hw): it logs as the daemon does, one timestamped line a
record, and never the raw frames pymodbus appends to what it could not decode."""

from __future__ import annotations

import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.support.fieldbus import MACHINE, PROGRAM, toml

pytestmark = pytest.mark.slow  # every test here is in the slow tier

LINE = re.compile(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3} (DEBUG|INFO|WARNING|ERROR) [\w.]+: ")


def test_garbage_on_the_modbus_port_is_logged_in_lines_without_frames(tmp_path):
    config = tmp_path / "mock.toml"
    ports = {"modbus_port": 0, "socketcand_port": 0, "control_port": 0}
    config.write_text(toml({"machine": MACHINE, "simulator": ports}))
    program = tmp_path / "fill.bws"
    program.write_text(PROGRAM)
    bwsd = shutil.which("bwsd", path=str(Path(sys.executable).parent))
    assert bwsd
    command = [bwsd, "mock", "--config", str(config), "--program", str(program)]
    mock = subprocess.Popen(
        command,
        text=True,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
    )
    try:
        assert mock.stdout is not None
        ready = mock.stdout.readline()
        assert ready.startswith("ready modbus="), ready
        found = re.search(r"modbus=(\d+)", ready)
        assert found is not None, ready
        port = int(found[1])
        with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
            sock.sendall(bytes.fromhex("000100000006010300deadbeef0011223344556677"))
            sock.sendall(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n")
            time.sleep(0.5)  # let it read, decode and log both
    finally:
        mock.send_signal(signal.SIGTERM)
        _, err = mock.communicate(timeout=30)
    assert mock.returncode == 0, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert lines, "nothing was logged of the garbage"
    for line in lines:
        assert LINE.match(line), line
    assert ">>>>>" not in err and "0xde" not in err and "0x47" not in err

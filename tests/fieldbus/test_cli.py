"""`bwsd hw`: the commissioning commands against the mock loom, through the console script."""

from __future__ import annotations

import asyncio
import shutil
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pytest

from simulator_hw.control import request
from tests.support.fieldbus import BUS, HEARTBEAT_MS, MACHINE, Mock, start_mock, toml

pytestmark = pytest.mark.slow  # every test here is in the slow tier

BWSD = shutil.which("bwsd", path=str(Path(sys.executable).parent))


def hw_config(tmp: Path, mock: Mock, backend: str, machine: Mapping[str, Any] = MACHINE) -> Path:
    path = tmp / f"{backend}.toml"
    path.write_text(
        toml(
            {
                "machine": machine,
                "fieldbus": {"backend": backend, **BUS},
                "fieldbus.modbus": {"port": mock.ports["modbus"]},
                "fieldbus.canopen": {
                    "port": mock.ports["socketcand"] if backend == "canopen" else 1,
                    "heartbeat_ms": HEARTBEAT_MS,
                },
            }
        )
    )
    return path


def hw(config: Path, *args: str) -> subprocess.CompletedProcess[str]:
    assert BWSD, "the bwsd console script is not installed beside this Python"
    return subprocess.run(
        [BWSD, "hw", *args, "--config", str(config)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


@pytest.mark.parametrize("backend", ["modbus", "canopen"])
def test_commissioning_session(tmp_path, mock, backend):
    config = hw_config(tmp_path, mock, backend)
    status = hw(config, "status")
    assert status.returncode == 0, status.stderr
    assert ".XX.\n.XX." in status.stdout and "released" in status.stdout
    moved = hw(config, "shift", "row", "1", "1")
    assert moved.returncode == 0, moved.stderr
    assert "..XX\n.XX." in moved.stdout
    jam = hw(config, "shift", "row", "1", "1")
    assert jam.returncode == 2 and "axis row1: jam" in jam.stderr
    assert hw(config, "status").returncode == 1  # the jam is latched
    reset = hw(config, "reset")
    assert reset.returncode == 0, reset.stderr
    takeup = hw(config, "takeup", "2.5")
    assert takeup.returncode == 0 and "2500" in takeup.stdout


def test_status_fails_while_the_estop_is_pressed(tmp_path, mock):
    asyncio.run(request("127.0.0.1", mock.ports["control"], {"cmd": "estop", "pressed": True}))
    status = hw(hw_config(tmp_path, mock, "modbus"), "status")
    assert status.returncode == 1
    assert "PRESSED" in status.stdout


def test_bad_requests_and_configs_are_refused_by_name(tmp_path, mock):
    config = hw_config(tmp_path, mock, "modbus")
    done = hw(config, "shift", "row", "9", "1")
    assert done.returncode == 2 and "no axis 'row9'" in done.stderr
    assert "only advances" in hw(config, "takeup", "-1").stderr
    bad = tmp_path / "bad.toml"
    bad.write_text(config.read_text().replace("io_timeout", "io_timout"))
    done = hw(bad, "status")
    assert done.returncode == 2 and "[fieldbus.io_timout]: unknown key" in done.stderr
    closed = tmp_path / "closed.toml"
    closed.write_text(config.read_text().replace(f"port = {mock.ports['modbus']}", "port = 1"))
    done = hw(closed, "status")
    assert done.returncode == 2 and "cannot reach the bus" in done.stderr


@pytest.mark.parametrize("backend", ["modbus", "canopen"])
def test_a_segment_is_shifted_by_its_own_axis(tmp_path, backend):
    machine = {**MACHINE, "segments": ["ROW 1[0..2]"]}
    fill = "FILL row=1 col=0\nX..X\nEND\n"
    mock = start_mock(tmp_path, {}, machine=machine, program=fill, canopen=backend == "canopen")
    try:
        config = hw_config(tmp_path, mock, backend, machine)
        status = hw(config, "status")
        assert status.returncode == 0, status.stderr
        assert "row1[0..2]" in status.stdout  # listed with the other axes
        moved = hw(config, "shift", "row", "1[0..2]", "2")
        assert moved.returncode == 0, moved.stderr
        assert "....\n..XX\n...." in moved.stdout  # only (1, 0) moved; (1, 3) stayed
        jam = hw(config, "shift", "row", "1 [0..2]", "1")  # (1, 2) would leave the segment
        assert jam.returncode == 2 and "axis row1[0..2]: jam" in jam.stderr
        unknown = hw(config, "shift", "row", "1[0..1]", "1")
        assert unknown.returncode == 2 and "no axis 'row1[0..1]'" in unknown.stderr
        assert "segments: row1[0..2]" in unknown.stderr
        bad = hw(config, "shift", "row", "1[0..]", "1")
        assert bad.returncode == 2 and "'1[0..]' is not a line (3) or a segment" in bad.stderr
    finally:
        mock.stop()


def test_moves_are_refused_while_a_daemon_runs_a_program_and_status_is_not(tmp_path, mock):
    from bwsd.api.auth import TokenStore
    from tests.test_daemon import TEXT, Served, daemon_config

    state = tmp_path / "state"
    state.mkdir()
    token = TokenStore.load(state / "tokens.json").add("tester", "operator")
    daemon = daemon_config(tmp_path, mock)
    served = Served(daemon, state, token)
    config = hw_config(tmp_path, mock, "modbus")
    try:
        served.http.post("/programs", json={"name": "b.bws", "text": TEXT}).raise_for_status()
        served.command("reset")
        served.command("start")
        pid = served.proc.pid
        shift = hw(config, "shift", "row", "1", "1", "--state-dir", str(state))
        assert shift.returncode == 2, shift.stdout
        assert f"held by bwsd serve (pid {pid}, config {daemon.resolve()}" in shift.stderr
        for args in (("takeup", "1"), ("reset",)):
            refused = hw(config, *args, "--state-dir", str(state))
            assert refused.returncode == 2 and f"pid {pid}" in refused.stderr
        assert hw(config, "status", "--state-dir", str(state)).returncode in (0, 1)
        elsewhere = hw(config, "shift", "row", "1", "1", "--state-dir", str(tmp_path / "other"))
        assert elsewhere.returncode == 2  # another folder: the loom itself refuses
        assert f"the loom is held by another client: pid {pid}" in elsewhere.stderr
        final = served.wait_for({"Complete", "Held", "Aborted"})
        assert final["name"] == "Complete", final["reason"]  # nothing moved under it
    finally:
        served.stop()
    done = hw(config, "status", "--state-dir", str(state))
    assert done.returncode == 0 and "held" not in done.stderr
    moved = hw(config, "takeup", "1", "--state-dir", str(state))  # free again once it stops
    assert moved.returncode == 0, moved.stderr

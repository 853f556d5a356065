"""The mock loom as a separate process on loopback, and configs that point at it.

The ``mock`` and ``slow_mock`` fixtures are defined here; a folder's conftest.py imports
them where its tests use them."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypedDict

import pytest

from bwsd.config import Config, parse_config
from tests.support.processes import owned
from tests.timing import scaled

# The drives' heartbeat period; a drive is lost after three missed (bwsd.fieldbus.canopen).
# Longer than the daemon's default (100 ms): on a test machine shared by three test workers,
# a scheduling pause of the mock loom's process (320 ms seen) is not a lost drive.
HEARTBEAT_MS = round(scaled(0.25) * 1000)

ROOT = Path(__file__).resolve().parents[2]


class MachineTable(TypedDict):
    """A config's [machine] table as these tests write it: Machine's own first fields."""

    rows: int
    cols: int
    pitch_x: float
    pitch_y: float
    d_mat: float
    c_mat: float


MACHINE: MachineTable = {
    "rows": 4,
    "cols": 4,
    "pitch_x": 10.0,
    "pitch_y": 10.0,
    "d_mat": 100.0,
    "c_mat": 0.5,
}
PROGRAM = "FILL row=1 col=0\n.XX.\n.XX.\nEND\n"  # cases at (1, 1), (1, 2), (2, 1), (2, 2)
BUS = {
    "timeout": scaled(3.0),
    "io_timeout": scaled(0.5),
    "reconnect_delay": 0.05,
    "reconnect_delay_max": 0.2,
    "reconnect_attempts": 4,
}


def toml(data: dict[str, Any]) -> str:
    """A small TOML writer for the flat tables these tests use."""
    lines: list[str] = []
    for table, values in data.items():
        lines.append(f"[{table}]")
        for key, value in values.items():
            lines.append(f"{key} = {_toml_value(value)}")
    return "\n".join(lines) + "\n"


def _toml_value(value: Any) -> str:
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return f'"{value}"' if isinstance(value, str) else str(value).lower()


@dataclass
class Mock:
    """A running mock loom process and what it listens on."""

    proc: subprocess.Popen[str]
    ports: dict[str, int]
    config_path: Path
    program_path: Path

    def control(self, message: dict[str, Any]) -> dict[str, Any]:
        """One request on the mock loom's control channel (simulator_hw/control.py), which
        must succeed: its answer."""
        with socket.create_connection(("127.0.0.1", self.ports["control"]), timeout=10) as conn:
            conn.sendall(json.dumps(message).encode() + b"\n")
            answer: dict[str, Any] = json.loads(conn.makefile().readline())
        assert answer["ok"], answer
        return answer

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            self.proc.wait(timeout=20)
        for pipe in (self.proc.stdout, self.proc.stderr):
            if pipe is not None:
                pipe.close()


def start_mock(
    tmp: Path,
    simulator: dict[str, Any],
    ports: dict[str, int] | None = None,
    *,
    machine: Mapping[str, Any] = MACHINE,
    program: str = PROGRAM,
    tables: dict[str, dict[str, Any]] | None = None,
    canopen: bool | None = None,
) -> Mock:
    """The mock loom in its own process; ``program`` gives its FILL (the cases' places),
    ``tables`` more of its config (``{"fieldbus.modbus": {"map": 2}}``). It serves the
    CANopen drives only when ``canopen`` asks for them: their heartbeats would cost every
    other test CPU time. By default, a loom started again on the ``ports`` of one before
    serves what that one did."""
    if canopen is None:
        canopen = ports is not None and "socketcand" in ports
    ports = ports or {"modbus": 0, "socketcand": 0, "control": 0}
    sim = {
        "modbus_port": ports["modbus"],
        "socketcand_port": ports.get("socketcand", 0),
        "control_port": ports["control"],
        "heartbeat_ms": HEARTBEAT_MS,
        "canopen": "on" if canopen else "off",
        **simulator,
    }
    config_path = tmp / "mock.toml"
    config_path.write_text(toml({"machine": machine, "simulator": sim, **(tables or {})}))
    program_path = tmp / "fill.bws"
    program_path.write_text(program)
    proc = owned(
        subprocess.Popen(
            [
                sys.executable,
                "-m",
                "simulator_hw",
                "--config",
                str(config_path),
                "--program",
                str(program_path),
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            stdin=subprocess.DEVNULL,
            text=True,
            cwd=ROOT,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
    )
    assert proc.stdout is not None and proc.stderr is not None  # both are PIPE
    line = proc.stdout.readline()
    if not line.startswith("ready "):
        proc.kill()
        raise RuntimeError(f"mock loom did not start: {line!r} {proc.stderr.read()!r}")
    found = dict(part.split("=") for part in line.split()[1:])
    return Mock(proc, {k: int(v) for k, v in found.items()}, config_path, program_path)


def client_config(
    backend: str, ports: dict[str, int], *, machine: Mapping[str, Any] = MACHINE, **bus: Any
) -> Config:
    """A config for bwsd's side, pointing at the mock loom's ports."""
    if backend == "canopen":
        assert "socketcand" in ports, "this mock loom serves no CANopen: start it with canopen"
    return parse_config(
        {
            "machine": machine,
            "fieldbus": {
                "backend": backend,
                **BUS,
                **bus,
                "modbus": {"port": ports["modbus"]},
                "canopen": {
                    "interface": "socketcand",
                    "port": ports.get("socketcand", 1),  # unused but for CANopen
                    "heartbeat_ms": HEARTBEAT_MS,
                },
            },
        }
    )


def wants_canopen(request: pytest.FixtureRequest) -> bool:
    """Whether the test asking runs on the CANopen backend (its ``backend`` parameter)."""
    callspec = getattr(request.node, "callspec", None)
    return callspec is not None and callspec.params.get("backend") == "canopen"


@pytest.fixture
def mock(tmp_path: Path, request: pytest.FixtureRequest) -> Iterator[Mock]:
    running = start_mock(tmp_path, {}, canopen=wants_canopen(request))
    yield running
    running.stop()


@pytest.fixture
def slow_mock(tmp_path: Path, request: pytest.FixtureRequest) -> Iterator[Mock]:
    """Strokes take time (10 mm at 100 mm/s), so a stall or e-stop can catch one moving."""
    speeds = {"stroke_speed": 100.0, "takeup_speed": 100.0}
    running = start_mock(tmp_path, speeds, canopen=wants_canopen(request))
    yield running
    running.stop()

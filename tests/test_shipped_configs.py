"""Every shipped config loads; the loom config runs the mock loom and `bwsd hw` against it."""

from __future__ import annotations

import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from bwsd.config import load_config
from bwsd.program import load_program

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = sorted((ROOT / "config").glob("*.toml"))


@pytest.mark.parametrize("path", CONFIGS, ids=[p.stem for p in CONFIGS])
def test_shipped_config_loads(path):
    config = load_config(path)
    assert config.machine.rows >= 1


def _grid(cells: set[tuple[int, int]], rows: int, cols: int) -> str:
    return "\n".join(
        "".join("X" if (r, c) in cells else "." for c in range(cols)) for r in range(rows)
    )


def _hw(config: str, *args: str) -> subprocess.CompletedProcess[str]:
    bwsd = shutil.which("bwsd", path=str(Path(sys.executable).parent))
    assert bwsd, "the bwsd console script is not installed beside this Python"
    command = [bwsd, "hw", *args, "--config", config]
    return subprocess.run(command, capture_output=True, text=True, timeout=60, check=False)


@pytest.mark.slow
def test_the_loom_config_drives_the_mock_loom_on_both_buses(tmp_path):
    machine = load_config(ROOT / "config/loom.toml").machine
    fill = set(load_program(ROOT / "examples/braid-2x2.bws", machine).fill)
    shifted = {(r, c + 1) if r == 1 else (r, c) for r, c in fill}
    mock = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "simulator_hw",
            "--config",
            "config/loom.toml",
            "--program",
            "examples/braid-2x2.bws",
            "--modbus-port",
            "0",
            "--socketcand-port",
            "0",
            "--control-port",
            "0",
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert mock.stdout is not None
        ready = mock.stdout.readline()
        ports = dict(re.findall(r"(\w+)=(?:[\d.]+:)?(\d+)", ready))
        assert ready.startswith("ready ") and {"modbus", "socketcand"} <= set(ports), ready
        text = (ROOT / "config/loom.toml").read_text()
        text = text.replace("port = 15020", f"port = {ports['modbus']}", 1)
        text = text.replace("port = 29536", f"port = {ports['socketcand']}", 1)
        modbus, canopen = tmp_path / "modbus.toml", tmp_path / "canopen.toml"
        modbus.write_text(text)
        canopen.write_text(text.replace('backend = "modbus"', 'backend = "canopen"'))
        for config in (str(modbus), str(canopen)):
            done = _hw(config, "shift", "row", "1", "1")
            assert done.returncode == 0, done.stderr
            assert _grid(shifted, machine.rows, machine.cols) in done.stdout
            done = _hw(config, "shift", "row", "1", "-1")
            assert done.returncode == 0, done.stderr
            assert _grid(fill, machine.rows, machine.cols) in done.stdout
    finally:
        mock.send_signal(signal.SIGTERM)
        mock.wait(timeout=20)

"""The README's commands as a user runs them: `bwsd demo`, and `bwsd token add` then `serve`."""

from __future__ import annotations

import re
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from bwsd.config import load_config
from bwsd.program import load_program
from bwsd.twin import simulate

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_demo_runs_the_example_braid_on_the_mock_loom_to_complete(tmp_path):
    bwsd = shutil.which("bwsd", path=str(Path(sys.executable).parent))
    assert bwsd
    done = subprocess.run(
        [bwsd, "demo", "--exit-when-done", "--state-dir", str(tmp_path / "state"), *FREE],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert re.search(r"^api: http://127\.0\.0\.1:\d+$", done.stdout, re.MULTILINE)
    assert "operator token: " in done.stdout
    machine = load_config(ROOT / "config/loom.toml").machine
    twin = simulate(machine, load_program(ROOT / "examples/braid-2x2.bws", machine))
    assert f"Complete: 50 instructions done, {twin.contact_count} contacts" in done.stdout
    assert (tmp_path / "state" / "journal.db").is_file()


OPTIONS = ("--api-port", "--plc-port", "--modbus-port", "--socketcand-port", "--control-port")
FREE = [word for option in OPTIONS for word in (option, "0")]
PORT_KEYS = ("port", "modbus_port", "socketcand_port", "control_port")


def _config_on_taken_ports(path: Path) -> tuple[Path, list[socket.socket]]:
    """The shipped loom config at ``path`` with every port one held here (taken)."""
    held: list[socket.socket] = []

    def taken(match: re.Match[str]) -> str:
        held.append(socket.create_server(("127.0.0.1", 0)))
        return f"{match[1]} = {held[-1].getsockname()[1]}"

    text = (ROOT / "config/loom.toml").read_text()
    text = re.sub(rf"^({'|'.join(PORT_KEYS)}) = \d+", taken, text, flags=re.MULTILINE)
    path.write_text(text)
    return path, held


def _addresses(out: str) -> dict[str, int]:
    """The ports the demo printed: mock loom's by name, then api and plc."""
    found = {k: int(v) for k, v in re.findall(r"(\w+)=127\.0\.0\.1:(\d+)", out)}
    for name in ("api", "plc"):
        match = re.search(rf"^{name}: \S+://127\.0\.0\.1:(\d+)$", out, re.MULTILINE)
        if match:
            found[name] = int(match[1])
    return found


@pytest.mark.slow
def test_demos_run_at_once_on_free_ports_while_the_configs_ports_are_taken(tmp_path):
    bwsd = shutil.which("bwsd", path=str(Path(sys.executable).parent))
    assert bwsd
    config, held = _config_on_taken_ports(tmp_path / "loom.toml")
    taken = {sock.getsockname()[1] for sock in held}
    demos = []
    try:
        for name in ("a", "b"):
            (tmp_path / name).mkdir()
            demos.append(
                subprocess.Popen(
                    [bwsd, "demo", "--exit-when-done", "--config", str(config), *FREE],
                    cwd=tmp_path / name,
                    stdout=subprocess.PIPE,
                    stderr=subprocess.PIPE,
                    stdin=subprocess.DEVNULL,
                    text=True,
                )
            )
        results = [demo.communicate(timeout=300) for demo in demos]
    finally:
        for demo in demos:
            if demo.poll() is None:
                demo.kill()
                demo.communicate()
        for sock in held:
            sock.close()
    ports = []
    for demo, (out, err) in zip(demos, results, strict=True):
        assert demo.returncode == 0, out + err
        assert "Complete: 50 instructions done, 73 contacts" in out
        found = _addresses(out)
        assert set(found) == {"modbus", "socketcand", "control", "api", "plc"}, out
        assert not set(found.values()) & taken
        assert f"live preview: http://127.0.0.1:{found['api']}/#token=" in out
        ports.append(found)
    assert not set(ports[0].values()) & set(ports[1].values())
    for name in ("a", "b"):  # each in its own folder's default state folder
        assert (tmp_path / name / "out" / "demo-state" / "journal.db").is_file()


@pytest.mark.slow
def test_demo_runs_the_config_and_program_given(tmp_path):
    """The config's ports are used (0 here); its bus is pointed at the mock loom wherever that
    listens; the PLC tags are off as the config says; the program is the one given."""
    bwsd = shutil.which("bwsd", path=str(Path(sys.executable).parent))
    assert bwsd
    text = (ROOT / "config/loom.toml").read_text()
    for key in ("modbus_port", "socketcand_port", "control_port"):
        text = re.sub(rf"^{key} = \d+", f"{key} = 0", text, flags=re.MULTILINE)
    text = re.sub(r"^stroke_speed = [\d.]+", "stroke_speed = 0.0", text, flags=re.MULTILINE)
    config = tmp_path / "mine.toml"
    text = re.sub(r"^port = 8080\b", "port = 0", text, flags=re.MULTILINE)
    config.write_text(re.sub(r"^enabled = true\b", "enabled = false", text, flags=re.MULTILINE))
    program = tmp_path / "short.bws"
    program.write_text(
        (ROOT / "examples/braid-2x2.bws").read_text().replace("REPEAT 10", "REPEAT 2")
    )
    done = subprocess.run(
        [
            bwsd,
            "demo",
            "--exit-when-done",
            "--config",
            str(config),
            "--program",
            str(program),
            "--state-dir",
            str(tmp_path / "state"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    found = _addresses(done.stdout)
    assert set(found) == {"modbus", "socketcand", "control", "api"}, done.stdout
    assert "running short.bws: 10 instructions" in done.stdout
    assert "Complete: 10 instructions done" in done.stdout


@pytest.mark.slow
def test_demo_port_options_take_0_to_65535(tmp_path):
    bwsd = shutil.which("bwsd", path=str(Path(sys.executable).parent))
    assert bwsd
    shown = subprocess.run(
        [bwsd, "demo", "--help"],
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
        cwd=tmp_path,
    ).stdout
    for option in (
        "--config",
        "--program",
        "--state-dir",
        "--api-port",
        "--plc-port",
        "--modbus-port",
        "--socketcand-port",
        "--control-port",
    ):
        assert option in shown
    assert len(re.findall(r"0:\s+any\s+free\s+port", shown)) == 5
    for bad, why in (
        ("-1", "a port lies in 0..65535"),
        ("65536", "a port lies in 0..65535"),
        ("http", "not a port number"),
    ):
        run = subprocess.run(
            [bwsd, "demo", "--api-port", bad],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
            cwd=tmp_path,
        )
        assert run.returncode == 2
        assert "--api-port" in run.stderr and why in run.stderr and run.stdout == ""
    assert list(tmp_path.iterdir()) == []


def test_the_demo_points_the_daemon_at_the_mock_loom_where_it_listens():
    from bwsd.demo import demo_config

    config = load_config(ROOT / "config/loom.toml")
    mock = {"modbus": 41001, "socketcand": 41002, "control": 41003}
    mine = demo_config(config, "127.0.0.1", mock, api_port=0, plc_port=None)
    assert mine.table("fieldbus.modbus")["port"] == 41001
    assert mine.table("fieldbus.canopen")["port"] == 41002
    assert mine.table("api")["port"] == 0
    assert mine.table("plc")["port"] == config.table("plc")["port"]
    assert mine.table("fieldbus.modbus") != config.table("fieldbus.modbus")  # a copy changed
    modbus_only = demo_config(config, "127.0.0.1", {"modbus": 41001, "control": 41003}, None, None)
    assert modbus_only.table("fieldbus.canopen") == config.table("fieldbus.canopen")

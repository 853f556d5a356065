"""The README's commands as a user runs them: `bwsd demo`, and `bwsd token add` then `serve`."""

from __future__ import annotations

import os
import re
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import httpx

from bwsd.config import load_config
from bwsd.program import load_program
from bwsd.twin import simulate
from tests.fieldbus.conftest import start_mock
from tests.test_daemon import daemon_config

ROOT = Path(__file__).resolve().parents[1]


def test_demo_runs_the_example_braid_on_the_mock_loom_to_complete(tmp_path):
    bwsd = shutil.which("bwsd", path=str(Path(sys.executable).parent))
    assert bwsd
    done = subprocess.run(
        [bwsd, "demo", "--exit-when-done", "--state-dir", str(tmp_path / "state")],
        capture_output=True, text=True, timeout=300, check=False, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    assert "api: http://127.0.0.1:8080" in done.stdout
    assert "operator token: " in done.stdout
    machine = load_config(ROOT / "config/loom.toml").machine
    twin = simulate(machine, load_program(ROOT / "examples/braid-2x2.bws", machine))
    assert f"Complete: 50 instructions done, {twin.contact_count} contacts" in done.stdout
    assert (tmp_path / "state" / "journal.db").is_file()


def _readme_commands(section: str) -> list[list[str]]:
    """The README's `bwsd ...` lines (comments dropped) from its ``## section``."""
    text = (ROOT / "README.md").read_text().split(f"## {section}\n", 1)[1].split("\n## ")[0]
    return [line.split("#")[0].split() for line in text.splitlines() if line.startswith("bwsd ")]


def test_the_readme_token_steps_give_a_token_that_serve_accepts(tmp_path):
    bwsd = shutil.which("bwsd", path=str(Path(sys.executable).parent))
    assert bwsd
    commands = _readme_commands("Commands")
    serve = next(c for c in commands if c[1] == "serve")
    add = next(c for c in commands if c[1:3] == ["token", "add"])
    assert serve[serve.index("--config") + 1] == add[add.index("--config") + 1]
    assert "--state-dir" not in serve + add  # each finds the state folder on its own
    work = tmp_path / "work"  # a fresh working folder holding only the config
    config = work / add[add.index("--config") + 1]
    config.parent.mkdir(parents=True)
    mock = start_mock(tmp_path, {})
    daemon_config(tmp_path, mock, config)
    env = {k: v for k, v in os.environ.items() if k != "STATE_DIRECTORY"}
    try:
        added = subprocess.run([bwsd, *add[1:]], capture_output=True, text=True, timeout=60,
                               check=False, cwd=work, env=env)  # fmt: skip
        assert added.returncode == 0, added.stderr
        token = added.stdout.strip()
        assert re.fullmatch(r"[A-Za-z0-9_-]{40,}", token), added.stdout
        served = subprocess.Popen([bwsd, *serve[1:]], stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True,
                                  cwd=work, env=env)  # fmt: skip
        try:
            assert served.stdout is not None
            line = served.stdout.readline()
            assert line.startswith("ready "), line + served.communicate(timeout=30)[1]
            urls = dict(part.split("=", 1) for part in line.split()[1:])
            answer = httpx.get(f"{urls['api']}/api/v1/state", timeout=30,
                               headers={"Authorization": f"Bearer {token}"})  # fmt: skip
            assert answer.status_code == 200, answer.text
        finally:
            served.terminate()
            served.communicate(timeout=30)
    finally:
        mock.stop()
    assert (work / "state" / "tokens.json").is_file()
    assert sorted(p.name for p in work.iterdir()) == ["config", "state"]


FREE = ["--api-port", "0", "--plc-port", "0", "--modbus-port", "0", "--socketcand-port", "0",
        "--control-port", "0"]  # fmt: skip
DEFAULT_PORTS = (8080, 15502, 15020, 15021, 29536)  # of config/loom.toml


def _hold(port: int) -> socket.socket | None:
    """A listener on a loopback port, so that nobody else can have it (None: taken already)."""
    sock = socket.socket()
    try:
        sock.bind(("127.0.0.1", port))
        sock.listen()
    except OSError:
        sock.close()
        return None
    return sock


def _addresses(out: str) -> dict[str, int]:
    """The ports the demo printed: mock loom's by name, then api and plc."""
    found = {k: int(v) for k, v in re.findall(r"(\w+)=127\.0\.0\.1:(\d+)", out)}
    for name in ("api", "plc"):
        match = re.search(rf"^{name}: \S+://127\.0\.0\.1:(\d+)$", out, re.MULTILINE)
        if match:
            found[name] = int(match[1])
    return found


def test_demos_run_at_once_on_free_ports_while_the_default_ports_are_taken(tmp_path):
    bwsd = shutil.which("bwsd", path=str(Path(sys.executable).parent))
    assert bwsd
    held = [s for s in (_hold(p) for p in DEFAULT_PORTS) if s is not None]
    demos = []
    try:
        for name in ("a", "b"):
            (tmp_path / name).mkdir()
            demos.append(subprocess.Popen(
                [bwsd, "demo", "--exit-when-done", *FREE], cwd=tmp_path / name,
                stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL,
                text=True,
            ))  # fmt: skip
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
        assert not set(found.values()) & set(DEFAULT_PORTS)
        assert f"live preview: http://127.0.0.1:{found['api']}/#token=" in out
        ports.append(found)
    assert not set(ports[0].values()) & set(ports[1].values())
    for name in ("a", "b"):  # each in its own folder's default state folder
        assert (tmp_path / name / "out" / "demo-state" / "journal.db").is_file()


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
    config.write_text(text + "\n[api]\nport = 0\n\n[plc]\nenabled = false\n")
    program = tmp_path / "short.bws"
    program.write_text(
        (ROOT / "examples/braid-2x2.bws").read_text().replace("REPEAT 10", "REPEAT 2")
    )
    done = subprocess.run(
        [bwsd, "demo", "--exit-when-done", "--config", str(config), "--program", str(program),
         "--state-dir", str(tmp_path / "state")],
        capture_output=True, text=True, timeout=300, check=False, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    found = _addresses(done.stdout)
    assert set(found) == {"modbus", "socketcand", "control", "api"}, done.stdout
    assert not set(found.values()) & set(DEFAULT_PORTS)
    assert "running short.bws: 10 instructions" in done.stdout
    assert "Complete: 10 instructions done" in done.stdout


def test_demo_port_options_take_0_to_65535(tmp_path):
    bwsd = shutil.which("bwsd", path=str(Path(sys.executable).parent))
    assert bwsd
    shown = subprocess.run([bwsd, "demo", "--help"], capture_output=True, text=True, timeout=60,
                           check=True, cwd=tmp_path).stdout  # fmt: skip
    for option in ("--config", "--program", "--state-dir", "--api-port", "--plc-port",
                   "--modbus-port", "--socketcand-port", "--control-port"):  # fmt: skip
        assert option in shown
    assert len(re.findall(r"0:\s+any\s+free\s+port", shown)) == 5
    for bad, why in (("-1", "a port lies in 0..65535"), ("65536", "a port lies in 0..65535"),
                     ("http", "not a port number")):  # fmt: skip
        run = subprocess.run([bwsd, "demo", "--api-port", bad], capture_output=True, text=True,
                             timeout=60, check=False, cwd=tmp_path)  # fmt: skip
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
    assert config.table("fieldbus.modbus")["port"] == 15020  # the config itself is unchanged
    modbus_only = demo_config(config, "127.0.0.1", {"modbus": 41001, "control": 41003}, None, None)
    assert modbus_only.table("fieldbus.canopen") == config.table("fieldbus.canopen")

"""`bwsd serve` with OPC UA on: the API answers while asyncua loads, which happens off the
event loop (it takes seconds: the import, then the standard address space). How soon and
how fast it answers meanwhile is measured by bench/startup.py, not asserted here."""

from __future__ import annotations

import queue
import re
import shutil
import socket
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import httpx
import pytest

from bwsd.deploy.folder import init_folder

pytestmark = pytest.mark.slow  # every test here is in the slow tier

MEANWHILE = 3  # /healthz answers that come back before OPC UA listens, at the least


def _closed_port() -> int:
    """A loopback port nothing listens on (the loom is absent: never fatal to the daemon)."""
    with socket.create_server(("127.0.0.1", 0)) as sock:
        return int(sock.getsockname()[1])


def _opcua_config(tmp: Path) -> Path:
    """A loom folder's config with OPC UA on, every port it serves free, the bus on a port
    nothing listens on."""
    config = init_folder(tmp / "loom").folder / "loom.toml"
    lines, table = [], ""
    for line in config.read_text().splitlines():
        table = line.strip("[]") if line.startswith("[") else table
        key = line.split(" = ")[0]
        if key in ("port", "modbus_port", "socketcand_port", "control_port"):
            port = _closed_port() if table.startswith("fieldbus.") else 0
            line = f"{key} = {port}"
        elif table == "opcua" and key == "enabled":
            line = "enabled = true"
        lines.append(line)
    config.write_text("\n".join(lines) + "\n")
    return config


def test_asyncua_is_imported_off_the_event_loop(tmp_path):
    """The import of asyncua held the event loop for about a second (the API already
    listened and could not answer)."""
    config = _opcua_config(tmp_path)
    script = textwrap.dedent(f"""
        import asyncio, sys, threading
        where = []
        def hook(event, args):
            if event == "import" and args[0] == "asyncua":
                where.append(threading.current_thread() is threading.main_thread())
        sys.addaudithook(hook)
        from bwsd import daemon
        from bwsd.config import load_config
        from bwsd.paths import state_folder
        async def main():
            config = load_config({str(config)!r})
            running = await daemon.start(config, state_folder(config))
            assert "opcua" in running.urls, running.urls
            await daemon.stop(running)
        asyncio.run(main())
        print("main thread" if where and where[0] else "elsewhere" if where else "never")
    """)
    done = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=180,
        check=False,
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.split() == ["elsewhere"], done.stdout


def test_serve_answers_healthz_while_opcua_starts(tmp_path):
    bwsd = shutil.which("bwsd", path=str(Path(sys.executable).parent))
    assert bwsd
    config = _opcua_config(tmp_path)
    served = subprocess.Popen(
        [bwsd, "serve", "--config", str(config)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
    )
    ready = threading.Event()
    lines: list[str] = []
    logged: queue.Queue[str] = queue.Queue()

    def follow() -> None:
        assert served.stdout is not None
        for line in served.stdout:
            lines.append(line)
            if line.startswith("ready "):
                ready.set()

    def log() -> None:
        assert served.stderr is not None
        for line in served.stderr:
            logged.put(line)
        logged.put("")  # the end

    threading.Thread(target=follow, daemon=True).start()
    threading.Thread(target=log, daemon=True).start()
    try:
        while True:  # the API listens: the daemon says where
            line = logged.get(timeout=120)
            assert line, "the daemon ended before its API listened"
            found = re.search(r"REST API and the page on (\S+)", line)
            if found:
                break
        before_ready = 0  # answers back while OPC UA was still starting
        with httpx.Client(base_url=found[1], timeout=30) as client:
            while not ready.is_set():
                assert client.get("/healthz").status_code in (200, 503)
                before_ready += not ready.is_set()
                time.sleep(0.02)
        assert any("opcua=opc.tcp://127.0.0.1:" in line for line in lines), lines
        assert before_ready >= MEANWHILE, before_ready
    finally:
        served.terminate()
        served.communicate(timeout=60)
    assert served.returncode == 0

"""The whole daemon as a user runs it: `bwsd serve` against the mock loom, over HTTP.

The crash test kills the daemon with SIGKILL at random moments while a program runs,
restarts it, resumes, and checks that the final skeleton equals an uninterrupted run's and
that the journal holds every instruction exactly once.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import random
import re
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from bwsd.api.auth import TokenStore
from bwsd.config import parse_config
from bwsd.export.skeleton_json import skeleton_to_dict
from bwsd.program import parse_program
from bwsd.twin import simulate
from simulator_hw.control import request
from tests.support.fieldbus import BUS, MACHINE, Mock, start_mock, toml
from tests.support.processes import owned
from tests.timing import scaled

pytestmark = pytest.mark.slow  # every test here is in the slow tier

CYCLE = "ROW 1:+1 2:-1\nCOL 1:+1 2:-1\nROW 1:-1 2:+1\nCOL 1:-1 2:+1\nTAKEUP 2\n"
TEXT = f"YARN diameter=1\nFILL row=1 col=0\n.XX.\n.XX.\nEND\nREPEAT 4\n{CYCLE}END\n"
LONG = TEXT.replace("REPEAT 4", "REPEAT 80")  # 400 instructions: room for every kill
LONG_STEPS = 400
KILLS = int(os.environ.get("BWSD_CRASH_KILLS", "100"))
# The kills in runs of their own, so that a parallel test run spreads them over its workers:
# each run is its own daemon, journal and mock loom, with its own seed.
KILL_RUNS = 4
KILL_TEXT = TEXT.replace("REPEAT 4", "REPEAT 30")  # 150 instructions: room for a run's kills
KILL_STEPS = 150


def daemon_config(tmp: Path, mock: Mock, path: Path | None = None) -> Path:
    """A daemon config on the mock loom's Modbus port (API and PLC on any free port)."""
    path = path or tmp / "bwsd.toml"
    path.write_text(
        toml(
            {
                "machine": MACHINE,
                "fieldbus": {"backend": "modbus", **BUS},
                "fieldbus.modbus": {"port": mock.ports["modbus"]},
                "api": {"port": 0},
                "plc": {"port": 0},
            }
        )
    )
    return path


class Served:
    """`bwsd serve` in its own process, and an HTTP client with an operator token."""

    def __init__(self, config: Path, state: Path, token: str) -> None:
        self.log = state.parent / "daemon.log"  # appended to by every daemon of the test
        with self.log.open("a") as log:
            self.proc = owned(
                subprocess.Popen(
                    [
                        sys.executable,
                        "-m",
                        "bwsd.cli",
                        "serve",
                        "--config",
                        str(config),
                        "--state-dir",
                        str(state),
                    ],
                    stdout=subprocess.PIPE,
                    stderr=log,
                    stdin=subprocess.DEVNULL,
                    text=True,
                )
            )
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        if not line.startswith("ready "):
            self.proc.kill()
            raise RuntimeError(f"daemon did not start: {line!r} {self.log.read_text()[-2000:]!r}")
        self.urls = urls = dict(part.split("=", 1) for part in line.split()[1:])
        self.http = httpx.Client(
            base_url=urls["api"] + "/api/v1",
            timeout=30,
            headers={"Authorization": f"Bearer {token}"},
        )

    def state(self) -> dict[str, Any]:
        answer: dict[str, Any] = self.http.get("/state").raise_for_status().json()
        return answer

    def command(self, name: str) -> None:
        self.http.post(f"/commands/{name}", json={}).raise_for_status()

    def recovered(self, limit: float = 60) -> dict[str, Any]:
        """The state once the twin is rebuilt (commands wait while it is)."""
        deadline = time.monotonic() + scaled(limit)
        while (state := self.state())["recovering"].startswith("rebuilding"):
            assert time.monotonic() < deadline, state["recovering"]
            time.sleep(0.02)
        return state

    def wait_for(self, names: set[str], limit: float = 120) -> dict[str, Any]:
        deadline = time.monotonic() + scaled(limit)
        while (state := self.state())["name"] not in names:
            assert time.monotonic() < deadline, f"still {state['name']}: {state['reason']}"
            time.sleep(0.05)
        return state

    def kill(self) -> None:
        self.http.close()
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=scaled(20))

    def stop(self) -> None:
        self.http.close()
        self.proc.send_signal(signal.SIGTERM)
        self.proc.wait(timeout=scaled(30))


@pytest.fixture
def rig(tmp_path: Path) -> Iterator[tuple[Path, Path, str, Mock]]:
    mock = start_mock(tmp_path, {"stroke_speed": 400.0, "takeup_speed": 400.0})
    state = tmp_path / "state"
    state.mkdir()
    token = TokenStore.load(state / "tokens.json").add("tester", "operator")
    yield daemon_config(tmp_path, mock), state, token, mock
    mock.stop()


def expected_skeleton(text: str = TEXT) -> dict[str, Any]:
    machine = parse_config({"machine": MACHINE}).machine
    return skeleton_to_dict(simulate(machine, parse_program(text)).skeleton())


def same_geometry(got: dict[str, Any], want: dict[str, Any]) -> bool:
    return [y["nodes"] for y in got["yarns"]] == [y["nodes"] for y in want["yarns"]] and got[
        "contacts"
    ] == want["contacts"]


def test_a_program_runs_to_complete_over_http_and_equals_simulate(rig):
    config, state, token, _ = rig
    served = Served(config, state, token)
    try:
        loaded = served.http.post("/programs", json={"name": "braid.bws", "text": TEXT})
        assert loaded.status_code == 201, loaded.text
        served.command("reset")
        served.command("start")
        final = served.wait_for({"Complete", "Aborted", "Held"})
        assert final["name"] == "Complete", final["reason"]
        assert final["index"] == final["count"] == 20
        skeleton = served.http.get("/skeleton", params={"format": "json"}).json()
        assert same_geometry(skeleton, expected_skeleton())
    finally:
        served.stop()


def resume_run(served: Served, limit: float = 60) -> dict[str, Any]:
    """The commands an operator gives after a restart, an Abort or a Stop, until the program
    runs again (or has completed): Unhold, or Clear, Reset and Start with resume."""
    deadline = time.monotonic() + limit
    refused = ""
    while (state := served.recovered())["name"] not in ("Execute", "Complete"):
        assert time.monotonic() < deadline, f"{state['name']}: {state['reason']}; {refused}"
        step = {"Held": "unhold", "Aborted": "clear", "Stopped": "reset", "Idle": "start"}
        if state["name"] in step:
            body = {"resume": state["resumable"]} if state["name"] == "Idle" else {}
            answer = served.http.post(f"/commands/{step[state['name']]}", json=body)
            refused = answer.text if answer.status_code != 200 else ""  # 409: again
            if "report a fault: Abort" in refused:  # cut strokes left drives faulted
                served.http.post("/commands/abort", json={})
        time.sleep(0.02)
    return state


def fire(served: Served, name: str, body: dict[str, Any]) -> None:
    """Send a command without waiting for its answer (the daemon is killed meanwhile)."""

    def send() -> None:
        with contextlib.suppress(httpx.HTTPError):
            httpx.post(
                f"{served.urls['api']}/api/v1/commands/{name}",
                json=body,
                timeout=5,
                headers=served.http.headers,
            )

    threading.Thread(target=send, daemon=True).start()


@pytest.mark.slow
@pytest.mark.parametrize("run", range(KILL_RUNS))
def test_killed_anywhere_the_daemon_resumes_to_the_identical_skeleton(rig, run):
    """SIGKILL at random moments: while it runs (predicting, journaling, moving), inside an
    Abort, and inside the resume that follows one (KILLS in all, over KILL_RUNS runs)."""
    config, state, token, _ = rig
    rng = random.Random(20261127 + run)
    served = Served(config, state, token)
    served.http.post("/programs", json={"name": "long.bws", "text": KILL_TEXT}).raise_for_status()
    served.command("reset")
    served.command("start")
    try:
        kills = KILLS // KILL_RUNS + (run < KILLS % KILL_RUNS)
        served = kill_anywhere(served, config, state, token, rng, kills)
        final = served.wait_for({"Complete", "Held", "Aborted"})
        assert final["name"] == "Complete" and final["index"] == KILL_STEPS, final
        skeleton = served.http.get("/skeleton", params={"format": "json"}).json()
        assert same_geometry(skeleton, expected_skeleton(KILL_TEXT))
    finally:
        served.stop()
    journal = sqlite3.connect(state / "journal.db")
    rows = journal.execute("SELECT idx, done IS NOT NULL FROM instructions ORDER BY idx").fetchall()
    journal.close()
    assert rows == [(i, 1) for i in range(1, KILL_STEPS + 1)]  # each exactly once, all done


def kill_anywhere(
    served: Served, config: Path, state: Path, token: str, rng: random.Random, kills: int
) -> Served:
    """``kills`` kills at random moments, each followed by a restart and a resume; the
    daemon serving at the end."""
    for kill in range(kills):
        where = rng.choice(["running", "aborting", "resuming"])
        time.sleep(rng.uniform(0.0, 0.15))
        # A program that completes is no longer resumed: every kill must come before its end.
        assert served.state()["index"] < KILL_STEPS - 10, (
            f"KILL_TEXT is too short for {kills} kills"
        )
        if where == "aborting":
            fire(served, "abort", {"reason": "operator"})
        elif where == "resuming":
            served.http.post("/commands/abort", json={}).raise_for_status()
            served.command("clear")
            served.command("reset")
            fire(served, "start", {"resume": True})
        time.sleep(rng.uniform(0.0, 0.05) if where != "running" else 0)
        served.kill()
        served = Served(config, state, token)
        try:
            now = served.recovered()
            assert now["name"] in ("Held", "Aborted"), f"after kill {kill + 1} ({where}): {now}"
            assert now["reason"].startswith("restarted"), now
            resume_run(served)
        except BaseException:
            served.stop()
            raise
    return served


@pytest.mark.slow
def test_a_restart_while_the_loom_is_silent_holds_and_resumes_once_it_answers(rig):
    config, state, token, mock = rig
    served = Served(config, state, token)
    served.http.post("/programs", json={"name": "braid.bws", "text": TEXT}).raise_for_status()
    served.command("reset")
    served.command("start")
    while served.state()["index"] < 6:
        time.sleep(0.01)
    served.kill()
    control = ("127.0.0.1", mock.ports["control"])
    asyncio.run(request(*control, {"cmd": "fault", "kind": "mute"}))
    served = Served(config, state, token)  # answers although the loom does not
    try:
        now = served.recovered()
        assert now["name"] == "Held" and now["stop_cause"] == "restart", now
        refused = served.http.post("/commands/unhold", json={})
        assert refused.status_code == 409 and "cannot be read" in refused.json()["error"]
        assert served.state()["bus"]["connected"] is False
        asyncio.run(request(*control, {"cmd": "clear"}))
        deadline = time.monotonic() + scaled(30)
        while not served.state()["bus"]["connected"]:  # the watch task reads it again
            assert time.monotonic() < deadline
            time.sleep(0.05)
        served.command("unhold")
        final = served.wait_for({"Complete", "Held", "Aborted"})
        assert final["name"] == "Complete", final["reason"]
        skeleton = served.http.get("/skeleton", params={"format": "json"}).json()
        assert same_geometry(skeleton, expected_skeleton())
    finally:
        served.stop()


def test_the_log_says_who_commanded_what_and_why_in_timestamped_lines(rig):
    config, state, token, mock = rig
    served = Served(config, state, token)
    try:
        served.http.post("/programs", json={"name": "braid.bws", "text": TEXT}).raise_for_status()
        served.command("reset")
        assert served.http.post("/commands/unhold", json={}).status_code == 409
        asyncio.run(request("127.0.0.1", mock.ports["control"], {"cmd": "fault", "kind": "mute"}))
        assert served.http.post("/commands/start", json={}).status_code == 409  # bus silent
        asyncio.run(request("127.0.0.1", mock.ports["control"], {"cmd": "clear"}))
        served.command("start")
        # the link may still drop once while the loom's muted answers drain: a fault hold,
        # resumed as an operator would
        while served.wait_for({"Complete", "Held"})["name"] == "Held":
            served.recovered()
            served.command("unhold")
    finally:
        served.stop()
    lines = served.log.read_text().splitlines()
    stamp = r"^\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3} (INFO|WARNING|ERROR) "
    assert lines and all(re.match(stamp, line) for line in lines), lines[:5]
    text = "\n".join(lines)
    assert "program 1 'braid.bws' loaded by tester: 20 instructions" in text
    assert "command Reset from tester" in text and "command Start from tester" in text
    assert "state Stopped -> Resetting (Reset)" in text
    assert "command Unhold from tester refused: Unhold is not accepted in state Idle" in text
    assert re.search(
        r"command Start from tester refused: the machine cannot be read: .*no answer", text
    )
    assert "program 1 complete" in text
    assert "Traceback" not in text and ">>>>>" not in text  # no library frame dumps


def test_serve_talks_to_systemd(rig, tmp_path):
    """READY=1 once it listens, WATCHDOG=1 at half the interval, STOPPING=1 on SIGTERM."""
    import socket

    config, state, _, _ = rig
    path = str(tmp_path / "notify.sock")
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as sock:
        sock.bind(path)
        sock.settimeout(30)
        env = {**os.environ, "NOTIFY_SOCKET": path, "WATCHDOG_USEC": "400000"}
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "bwsd.cli",
                "serve",
                "--config",
                str(config),
                "--state-dir",
                str(state),
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            stdin=subprocess.DEVNULL,
            env=env,
        )
        try:
            messages = [sock.recv(4096).decode() for _ in range(3)]
            assert messages[0].startswith("READY=1\nSTATUS=Stopped, instruction 0, http://")
            assert all("WATCHDOG=1" in m for m in messages[1:])
            proc.send_signal(signal.SIGTERM)
            while "STOPPING=1" not in (last := sock.recv(4096).decode()):
                assert "WATCHDOG=1" in last
            assert proc.wait(timeout=30) == 0
        finally:
            if proc.poll() is None:
                proc.kill()


def test_a_port_in_use_is_a_clear_error_and_nothing_stays_open(rig):
    import socket

    config, state, _, _ = rig
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        config.write_text(config.read_text().replace("port = 0", f"port = {port}", 1))
        assert f"port = {port}" in config.read_text()
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "bwsd.cli",
                "serve",
                "--config",
                str(config),
                "--state-dir",
                str(state),
            ],
            capture_output=True,
            text=True,
            stdin=subprocess.DEVNULL,
            timeout=60,
        )
    assert done.returncode == 2, done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith(f"bwsd: error: [api] cannot listen on 127.0.0.1:{port}: "), last
    assert "address already in use" in last.lower() and "Traceback" not in done.stderr


def test_a_damaged_journal_stops_the_start_with_the_reason(rig):
    config, state, token, _ = rig
    served = Served(config, state, token)
    served.http.post("/programs", json={"name": "braid.bws", "text": TEXT}).raise_for_status()
    served.stop()
    journal = state / "journal.db"
    data = bytearray(journal.read_bytes())
    assert len(data) > 8192
    data[4096:8192] = bytes(range(256)) * 16  # garbage over the second page
    journal.write_bytes(bytes(data))
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "bwsd.cli",
            "serve",
            "--config",
            str(config),
            "--state-dir",
            str(state),
        ],
        capture_output=True,
        text=True,
        timeout=60,
        stdin=subprocess.DEVNULL,
    )
    assert done.returncode != 0 and done.stdout == ""  # never ready
    assert "journal.db" in done.stderr and "damaged" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr


def test_serve_speaks_tls_with_the_configured_files_relative_to_the_config(rig):
    import ssl

    import trustme

    config, state, token, _ = rig
    ca = trustme.CA()
    cert = ca.issue_cert("127.0.0.1")
    cert.private_key_and_cert_chain_pem.write_to_path(config.parent / "api.pem")
    config.write_text(config.read_text().replace("[api]\n", '[api]\ncertfile = "api.pem"\n', 1))
    served = Served(config, state, token)
    try:
        assert str(served.http.base_url).startswith("https://127.0.0.1:")
        context = ssl.create_default_context()
        ca.configure_trust(context)
        with httpx.Client(
            base_url=served.http.base_url,
            verify=context,
            timeout=10,
            headers={"Authorization": f"Bearer {token}"},
        ) as client:
            assert client.get("/state").json()["name"] == "Stopped"
    finally:
        served.stop()


def test_a_tls_file_that_cannot_serve_is_a_clear_error(rig):
    config, state, _, _ = rig
    (config.parent / "api.pem").write_text("not a certificate\n")
    config.write_text(config.read_text().replace("[api]\n", '[api]\ncertfile = "api.pem"\n', 1))
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "bwsd.cli",
            "serve",
            "--config",
            str(config),
            "--state-dir",
            str(state),
        ],
        capture_output=True,
        text=True,
        stdin=subprocess.DEVNULL,
        timeout=60,
    )
    assert done.returncode == 2 and done.stdout == "", done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("bwsd: error: [api.certfile]: cannot serve TLS with "), last
    assert "Traceback" not in done.stderr


@pytest.mark.slow
def test_a_restart_restores_the_loaded_program_with_its_cause(rig):
    config, state, token, _ = rig
    for stop in ("kill", "stop"):
        served = Served(config, state, token)
        loaded = served.http.post("/programs", json={"name": "braid.bws", "text": TEXT}).json()
        served.command("reset")
        getattr(served, stop)()
        served = Served(config, state, token)
        try:
            now = served.recovered()
            assert (now["name"], now["program_id"], now["count"]) == ("Stopped", loaded["id"], 20)
            assert now["stop_cause"] == "restart" and "is loaded" in now["reason"], now
            served.command("reset")
            served.command("start")
            assert served.wait_for({"Complete", "Held", "Aborted"})["name"] == "Complete"
        finally:
            served.stop()


@pytest.mark.slow
def test_sigterm_closes_the_bus_and_its_lock_while_the_journal_is_locked(rig):
    """Another process holds the journal's lock mid-run: the stall is on /healthz, the run
    holds; SIGTERM still ends the daemon cleanly, its bus lock free for the next one (the
    end of its session cannot be recorded: docs/journal.md says what the next start does)."""
    from bwsd.fieldbus.owner import holder

    config, state, token, _ = rig
    # Each record the run waits for (instruction 1 started, held, the session's end) gives
    # up after the busy timeout: 1.5 s instead of 5 s each, still past the stall's 0.75 s.
    config.write_text(config.read_text() + "\n[journal]\nbusy_timeout = 1.5\n")
    served = Served(config, state, token)
    served.http.post("/programs", json={"name": "long.bws", "text": LONG}).raise_for_status()
    served.command("reset")
    served.command("start")
    other = sqlite3.connect(state / "journal.db", isolation_level=None)
    other.execute("BEGIN IMMEDIATE")
    try:
        health = httpx.Client(base_url=served.urls["api"], timeout=30)
        deadline = time.monotonic() + scaled(30)
        while (answer := health.get("/healthz")).status_code == 200:
            assert time.monotonic() < deadline
            time.sleep(0.05)
        assert "journal" in answer.json()["problems"], answer.text
        assert served.wait_for({"Held"})["stop_cause"] == "journal"
        assert holder(state) is not None
        health.close()
        served.stop()
        assert served.proc.returncode == 0
        assert holder(state) is None  # the bus lock was let go
        log = served.log.read_text()
        assert "Traceback" not in log and "the journal has not finished writing" in log
    finally:
        other.execute("ROLLBACK")
        other.close()


def test_a_start_with_a_damaged_program_warns_holds_with_the_fix_and_aborts(rig):
    config, state, token, _ = rig
    served = Served(config, state, token)
    served.http.post("/programs", json={"name": "braid.bws", "text": TEXT}).raise_for_status()
    served.command("reset")
    served.command("start")
    while served.state()["index"] < 3:
        time.sleep(0.01)
    served.stop()  # held, its session closed; then the file is damaged
    journal = sqlite3.connect(state / "journal.db", isolation_level=None)
    journal.executescript(
        "BEGIN; DROP TRIGGER programs_fixed; UPDATE programs SET "
        "text = text || '# edited' WHERE id = 1; COMMIT;"
    )
    journal.close()
    served = Served(config, state, token)
    try:
        now = served.recovered()
        assert now["name"] == "Held" and "recovery failed" in now["reason"], now
        assert "restore the journal from a backup" in now["reason"]
        assert now["allowed"] == ["stop", "abort"]
        health = httpx.get(served.urls["api"] + "/healthz", timeout=30)
        assert health.status_code == 503 and "recovery" in health.json()["problems"]
        assert served.http.post("/commands/abort", json={}).json()["name"] == "Aborted"
        served.command("clear")
        assert served.state()["name"] == "Stopped"
        assert httpx.get(served.urls["api"] + "/healthz", timeout=30).status_code == 200
    finally:
        served.stop()
    assert "journal: program 1: its text does not match its sha256" in served.log.read_text()

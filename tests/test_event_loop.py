"""The event loop never waits on CPU or disk: a 24x24 job under asyncio's debug mode.

The daemon runs in this process (``bwsd.daemon.start``: journal, controller, API, PLC tags,
watch task) on a loop in debug mode with ``slow_callback_duration`` = 20 ms, against the mock
loom in its own process. A client process loads the 624-carrier braid, resets, reads once
(first-use costs are paid there: lazy imports, the debug mode's first source reads), then
starts it and reads ``/state``, ``/skeleton`` and the event WebSocket while it runs; slow
callbacks are counted from that start.
Every callback that held the loop longer than 20 ms by its own doing fails the test (see
SlowCallbacks: a callback preempted by another process on the machine is not counted).
"""

from __future__ import annotations

import asyncio
import linecache
import multiprocessing
import os
import resource
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
import pytest
from websockets.sync.client import connect

from bwsd.api.auth import TokenStore
from bwsd.config import load_config, parse_config
from bwsd.daemon import start, stop
from bwsd.program.generators import braid4
from tests.support.fieldbus import BUS, ROOT, start_mock

pytestmark = pytest.mark.slow  # every test here is in the slow tier

SLOW = 0.020  # s


class SlowCallbacks:
    """Every callback of the loop that held it longer than SLOW by its own doing.

    A callback's wall time counts when no thread of the daemon's process was preempted
    meanwhile (no involuntary context switch: the time was the callback's, computing or
    waiting on a disk), less the time the loop's thread was ready to run but waited for a
    CPU (Linux's schedstat run delay), or when its own CPU time passes SLOW. A callback the
    kernel preempted for another process (the machine is shared: a test run, the mock loom,
    the client) is the machine's doing, not the daemon's; so is one that waited for the
    interpreter lock while the thread holding it was preempted, and the time a thread woken
    (by the lock, or a disk) waits for a CPU the other processes hold. asyncio's wall-clock
    report alone cannot tell these apart.
    """

    def __init__(self) -> None:
        self.seen: list[str] = []
        self.armed = False  # from the moment the client has paid its first-use costs
        self._schedstat: dict[int, int] = {}  # thread id: its open schedstat file

    def _run_delay(self) -> float:
        """Seconds the calling thread has waited, ready to run, for a CPU."""
        fd = self._schedstat.get(threading.get_ident())
        if fd is None:
            fd = os.open("/proc/thread-self/schedstat", os.O_RDONLY)
            self._schedstat[threading.get_ident()] = fd
        return int(os.pread(fd, 128, 0).split()[1]) / 1e9  # CPU ns, run delay ns, slices

    def close(self) -> None:
        for fd in self._schedstat.values():
            os.close(fd)
        self._schedstat.clear()

    def wrap(self, run: Callable[[asyncio.Handle], None]) -> Callable[[asyncio.Handle], None]:
        def timed(handle: asyncio.Handle) -> None:
            before = resource.getrusage(resource.RUSAGE_SELF).ru_nivcsw
            delayed = self._run_delay()
            start, cpu = time.perf_counter(), time.thread_time()
            run(handle)
            wall, used = time.perf_counter() - start, time.thread_time() - cpu
            if self.armed and wall > SLOW:
                preempted = resource.getrusage(resource.RUSAGE_SELF).ru_nivcsw - before
                waited = self._run_delay() - delayed
                if used > SLOW or (not preempted and wall - waited > SLOW):
                    self.seen.append(
                        f"{handle!r} took {wall * 1000:.1f} ms ({used * 1000:.1f}"
                        f" ms of CPU, {waited * 1000:.1f} ms waiting for a CPU,"
                        f" preempted {preempted} times)"
                    )

        return timed


def machine() -> dict[str, Any]:
    m = load_config(ROOT / "config" / "braid-24x24.toml").machine
    return {
        "rows": m.rows,
        "cols": m.cols,
        "pitch_x": m.pitch_x,
        "pitch_y": m.pitch_y,
        "d_mat": m.d_mat,
        "c_mat": m.c_mat,
    }


def client(base: str, token: str, program: str, errors: Any, warm: Any) -> None:
    """What an operator's page and a PLC do at once: load, start, read, follow the events.

    Runs in its own process: a client thread in the daemon's process would take the
    interpreter lock from the event loop, and the test would measure the client.
    """
    headers = {"Authorization": f"Bearer {token}"}
    try:
        events = base.replace("http", "ws") + "/api/v1/events"
        with (
            httpx.Client(base_url=base + "/api/v1", headers=headers, timeout=60) as http,
            connect(events, additional_headers=headers) as ws,
        ):
            http.post("/programs", json={"name": "b.bws", "text": program}).raise_for_status()
            http.post("/commands/reset", json={}).raise_for_status()
            http.get("/skeleton").raise_for_status()
            http.get("/state").raise_for_status()
            warm.set()  # first-use costs (lazy imports, the debug mode's first source reads)
            http.post("/commands/start", json={}).raise_for_status()
            done = False
            while not done:
                state = http.get("/state").raise_for_status().json()
                done = state["name"] in ("Complete", "Held", "Aborted")
                if state["index"] % 3 == 1:
                    http.get("/skeleton").raise_for_status()
                while True:
                    try:
                        ws.recv(timeout=0.001)
                    except TimeoutError:
                        break
                time.sleep(0.01)
            if state["name"] != "Complete":
                errors.put(f"ended {state['name']}: {state['reason']}")
    except Exception as exc:  # reported by the test
        errors.put(repr(exc))


def test_a_24x24_job_never_holds_the_event_loop_for_20_ms(tmp_path: Path, monkeypatch) -> None:
    program = braid4(
        24, 24, cycles=2, takeup=3.0, pitch=10.0, d_mat=300.0, c_mat=0.3, diameter=1.5
    ).program
    mock = start_mock(tmp_path, {}, machine=machine(), program=program)
    ports = mock.ports
    config = parse_config(
        {
            "machine": machine(),
            "fieldbus": {
                "backend": "modbus",
                **BUS,
                "timeout": 30.0,
                "modbus": {"port": ports["modbus"]},
            },
            "api": {"port": 0},
            "plc": {"port": 0},
        }
    )
    state = tmp_path / "state"
    state.mkdir()
    token = TokenStore.load(state / "tokens.json").add("tester", "operator")
    slow = SlowCallbacks()
    monkeypatch.setattr(asyncio.events.Handle, "_run", slow.wrap(asyncio.events.Handle._run))
    spawn = multiprocessing.get_context("spawn")
    errors, warm = spawn.Queue(), spawn.Event()

    async def scenario() -> None:
        loop = asyncio.get_running_loop()
        loop.slow_callback_duration = SLOW
        daemon = await start(config, state)
        try:
            args = (daemon.urls["api"], token, program, errors, warm)
            worker = spawn.Process(target=client, args=args)
            worker.start()
            while worker.is_alive():
                slow.armed = warm.is_set()
                await asyncio.sleep(0.005)
            worker.join()
        finally:
            await stop(daemon)

    # Debug mode records where every handle and future was made; for each it re-checks every
    # source file in linecache with os.stat, and each stat gives the interpreter lock away for
    # up to a switch interval while a worker thread runs Python: the debug mode would measure
    # itself. The source lines are not read anyway (lookup_lines=False).
    monkeypatch.setattr(linecache, "checkcache", lambda filename=None: None)
    try:
        asyncio.run(scenario(), debug=True)
    finally:
        slow.close()
        mock.stop()
    found = []
    while not errors.empty():
        found.append(errors.get())
    assert found == []
    assert slow.seen == [], "\n".join(slow.seen)


def test_a_callback_computing_past_20_ms_is_counted_whatever_the_machine_does(monkeypatch):
    """SlowCallbacks discounts the machine's doing, never a callback's own CPU."""
    slow = SlowCallbacks()
    slow.armed = True
    monkeypatch.setattr(asyncio.events.Handle, "_run", slow.wrap(asyncio.events.Handle._run))

    def compute() -> None:
        end = time.thread_time() + 2 * SLOW
        while time.thread_time() < end:
            pass

    async def scenario() -> None:
        asyncio.get_running_loop().call_soon(compute)
        await asyncio.sleep(0)

    try:
        asyncio.run(scenario())
    finally:
        slow.close()
    assert [line for line in slow.seen if "compute()" in line], slow.seen

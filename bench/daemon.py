"""Benchmark of the daemon: prints the markdown table of docs/benchmarks.md.

    python bench/daemon.py [--cycles 10] [--rate 500] [--restart-cycles 1000]

`bwsd serve` and the mock loom run in their own processes on loopback, zero travel time,
with the 24x24 braid. Measured: the daemon's per-instruction overhead (an instruction's
wall time in the run loop minus the twin's predict time and the bus's time, all reported in
its event); `GET state` latency at a fixed request rate, first idle (the baseline) and then
while the program runs; WebSocket event lag (receipt time minus the event's own time
stamp); the restart of a held 1000-cycle job: seconds until the API answers and until the
twin is rebuilt, with snapshots in the journal and without (the baseline).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing
import socket
import statistics
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import websockets

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bwsd.api.auth import TokenStore  # noqa: E402
from bwsd.config import load_config, parse_config  # noqa: E402
from bwsd.paths import state_folder, tokens_file  # noqa: E402
from bwsd.program.generators import braid4  # noqa: E402
from tests.support.fieldbus import BUS, Mock, start_mock, toml  # noqa: E402
from tests.test_daemon import Served  # noqa: E402


def machine_table() -> dict[str, Any]:
    m = load_config(ROOT / "config" / "braid-24x24.toml").machine
    return {
        "rows": m.rows,
        "cols": m.cols,
        "pitch_x": m.pitch_x,
        "pitch_y": m.pitch_y,
        "d_mat": m.d_mat,
        "c_mat": m.c_mat,
    }


def loom(tmp: Path, program: str) -> Mock:
    """The mock loom with the 24x24 machine, its cases where ``program``'s FILL puts them."""
    return start_mock(tmp, {}, machine=machine_table(), program=program)


def write_config(path: Path, ports: dict[str, int], plc: bool = True) -> Path:
    """A daemon config for the 24x24 machine on the mock loom's ports (API and PLC: any)."""
    path.write_text(
        toml(
            {
                "machine": machine_table(),
                "fieldbus": {"backend": "modbus", **BUS, "timeout": 30.0},
                "fieldbus.modbus": {"port": ports["modbus"]},
                "api": {"port": 0},
                "plc": {"port": 0, "enabled": plc},
            }
        )
    )
    return path


def start(tmp: Path, program: str) -> tuple[Mock, Served]:
    mock = loom(tmp, program)
    config = write_config(tmp / "bwsd.toml", mock.ports)
    state = state_folder(load_config(config), tmp / "state")
    token = TokenStore.load(tokens_file(load_config(config), state)).add("bench", "operator")
    return mock, Served(config, state, token)


def braid_24x24(cycles: int) -> str:
    """The benchmarks' 24x24 braid program (624 carriers)."""
    return braid4(
        24, 24, cycles=cycles, takeup=8.0, pitch=10.0, d_mat=300.0, c_mat=0.3, diameter=0.5
    ).program


@contextmanager
def serving(program: str) -> Iterator[Served]:
    """The mock loom and `bwsd serve` for ``program``, stopped at the end."""
    with tempfile.TemporaryDirectory() as tmp:
        mock, served = start(Path(tmp), program)
        try:
            yield served
        finally:
            served.stop()
            mock.stop()


async def measure(
    served: Served, program: str, rate: float, idle_s: float
) -> dict[str, list[float]]:
    """GET state at ``rate`` while idle for ``idle_s``, then during the run; events' timings.

    The events are read in a process of their own, so that the load generator's work does
    not delay their receipt (and the other way round).
    """
    base = str(served.http.base_url).rstrip("/")
    token = served.http.headers["Authorization"].split()[1]
    ws_url = base.replace("http", "ws", 1) + "/events"
    out: dict[str, list[float]] = {"state": [], "idle": []}
    spawn = multiprocessing.get_context("spawn")
    results, listening = spawn.Queue(), spawn.Event()
    async with httpx.AsyncClient(base_url=base, headers=served.http.headers, timeout=30) as c:
        (await c.post("/programs", json={"name": "b.bws", "text": program})).raise_for_status()
        (await c.post("/commands/reset", json={})).raise_for_status()
        load = Requester(base, token)
        quiet = asyncio.Event()
        asyncio.get_running_loop().call_later(idle_s, quiet.set)
        await load.run(rate, out["idle"], quiet)
        reader = spawn.Process(target=read_events, args=(ws_url, token, results, listening))
        reader.start()
        while not listening.is_set():
            await asyncio.sleep(0.01)
        (await c.post("/commands/start", json={})).raise_for_status()
        done = asyncio.Event()

        async def watch() -> None:
            while reader.is_alive():
                await asyncio.sleep(0.05)
            done.set()

        watcher = asyncio.create_task(watch())
        await load.run(rate, out["state"], done)
        await watcher
    out.update(results.get(timeout=30))
    return out


def read_events(ws_url: str, token: str, results: Any, listening: Any) -> None:
    """The event reader's process: lags and the instructions' timings, until the run ends."""
    out: dict[str, list[float]] = {k: [] for k in ("lag", "overhead", "predict", "bus", "commit")}

    async def main() -> None:
        headers = {"Authorization": f"Bearer {token}"}  # never in the URL: logs print URLs
        async with websockets.connect(ws_url, additional_headers=headers, max_size=None) as ws:
            await ws.recv()  # hello
            since = time.time()
            listening.set()
            async for text in ws:
                now = time.time()
                event = json.loads(text)
                if event.get("at", 0) >= since:  # not those queued before the run
                    out["lag"].append(now - event["at"])
                if event.get("event") == "instruction" and "step_s" in event:
                    step, commit = event["step_s"], event["commit_s"]
                    out["overhead"].append(step + commit - event["predict_s"] - event["bus_s"])
                    out["predict"].append(event["predict_s"])
                    out["bus"].append(event["bus_s"])
                    out["commit"].append(commit)
                if event.get("event") == "state" and event.get("to") in (
                    "Complete",
                    "Held",
                    "Aborted",
                ):
                    return

    asyncio.run(main())
    results.put(out)


class Requester:
    """GET /api/v1/state over ``conns`` kept-alive connections, raw HTTP/1.1.

    A load generator as light as possible (one prepared request, the response read by its
    length), so that the latency measured is the daemon's, not the client's.
    """

    def __init__(self, base: str, token: str, conns: int = 8) -> None:
        host, port = base.removeprefix("http://").split("/")[0].split(":")
        self.host, self.port, self.conns = host, int(port), conns
        self.request = (
            f"GET /api/v1/state HTTP/1.1\r\nHost: {host}\r\nAuthorization: Bearer {token}\r\n\r\n"
        ).encode()

    async def run(self, rate: float, into: list[float], done: asyncio.Event) -> None:
        """Requests at ``rate`` per second in all (spread over the connections) until done."""
        period = self.conns / rate
        start = time.perf_counter()
        await asyncio.gather(
            *(self._one(start + i / rate, period, into, done) for i in range(self.conns))
        )

    async def _one(
        self, first: float, period: float, into: list[float], done: asyncio.Event
    ) -> None:
        reader, writer = await asyncio.open_connection(self.host, self.port)
        sock = writer.get_extra_info("socket")
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        due = first
        try:
            while not done.is_set():
                await asyncio.sleep(max(0.0, due - time.perf_counter()))
                sent = time.perf_counter()
                writer.write(self.request)
                head = await reader.readuntil(b"\r\n\r\n")
                if not head.startswith(b"HTTP/1.1 200"):
                    raise RuntimeError(head.decode(errors="replace"))
                length = int(head.lower().split(b"content-length:")[1].split(b"\r\n")[0])
                await reader.readexactly(length)
                into.append(time.perf_counter() - sent)
                due = max(due + period, time.perf_counter())  # late requests are not queued
        finally:
            writer.close()


# ----- restart -----
def journal_of_a_long_job(folder: Path, cycles: int, snapshot_every: int) -> tuple[Path, int]:
    """A journal as a daemon leaves it after ``cycles`` cycles of the 24x24 braid, every
    instruction done, held (snapshots every ``snapshot_every``; 0: none)."""
    from bwsd.journal import Journal
    from bwsd.program import parse_program
    from bwsd.twin import Twin

    text = braid_24x24(cycles)
    program = parse_program(text)
    machine = parse_config({"machine": machine_table()}).machine  # as the daemon's config
    twin = Twin.from_program(machine, program)
    state = folder / "state"
    state.mkdir(parents=True)
    with Journal.open(state / "journal.db") as journal:
        pid = journal.add_program("long.bws", text, len(program.instructions))
        journal.set_outcome(pid, "running")
        for i, instruction in enumerate(program.instructions, start=1):
            journal.started(pid, i, {"takeup_origin": 0})
            twin.advance(instruction)
            journal.done(pid, i, {})
            if snapshot_every and i % snapshot_every == 0:
                journal.save_snapshot(pid, i, twin.snapshot().to_bytes())
        journal.set_outcome(pid, "held", "daemon stopping")
    return state, len(program.instructions)


def restart(folder: Path, state: Path, mock_ports: dict[str, int]) -> tuple[float, float]:
    """Seconds from `bwsd serve` starting to its API answering, and to recovery's end."""
    import subprocess

    config = write_config(folder / "bwsd.toml", mock_ports, plc=False)
    store = TokenStore.load(tokens_file(load_config(config), state))
    token = store.add(f"bench-{len(store.entries) + 1}", "viewer")
    begun = time.perf_counter()
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
        stderr=subprocess.DEVNULL,
        text=True,
        cwd=ROOT,
    )
    try:
        assert proc.stdout is not None
        api = dict(p.split("=", 1) for p in proc.stdout.readline().split()[1:])["api"]
        with httpx.Client(
            base_url=api + "/api/v1", timeout=30, headers={"Authorization": f"Bearer {token}"}
        ) as http:
            while True:
                try:
                    first = http.get("/state")
                    break
                except httpx.TransportError:
                    time.sleep(0.001)
            up = time.perf_counter() - begun
            assert first.status_code == 200, first.text
            while http.get("/state").json()["recovering"].startswith("rebuilding"):
                time.sleep(0.005)
            recovered = time.perf_counter() - begun
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    return up, recovered


def restart_rows(cycles: int, repeats: int) -> list[str]:
    """Restart of a held ``cycles``-cycle job, with snapshots (every 200) and without."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        mock = loom(folder, braid_24x24(1))
        try:
            ports = mock.ports
            for every, label in ((200, "snapshot every 200"), (0, "no snapshot (baseline)")):
                job = folder / f"job-{every}"
                state, count = journal_of_a_long_job(job, cycles, every)
                ups, recs = [], []
                for _ in range(repeats):
                    up, recovered = restart(job, state, ports)
                    ups.append(up)
                    recs.append(recovered)
                rows.append(
                    f"| {label} | {count} | {statistics.median(ups):.2f} | "
                    f"{max(ups):.2f} | {statistics.median(recs):.2f} | {max(recs):.2f} |"
                )
        finally:
            mock.stop()
    return rows


def row(name: str, values: list[float]) -> str:
    if not values:
        return f"| {name} | 0 | | |"
    ms = [v * 1e3 for v in values]
    return f"| {name} | {len(ms)} | {statistics.median(ms):.2f} | {np.percentile(ms, 99):.2f} |"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--cycles", type=int, default=10)
    parser.add_argument("--rate", type=float, default=500.0)
    parser.add_argument("--idle", type=float, default=5.0, help="seconds of idle load first")
    parser.add_argument("--restart-cycles", type=int, default=1000)
    parser.add_argument("--restarts", type=int, default=3)
    args = parser.parse_args()
    program = braid_24x24(args.cycles)
    with serving(program) as served:
        result = asyncio.run(measure(served, program, args.rate, args.idle))
    print(
        f"24x24 braid (624 carriers), {args.cycles} cycles, zero travel time, GET state at "
        f"{args.rate:g} requests/s for {args.idle:g} s idle, then during the run.\n"
    )
    print("| measure | n | p50 ms | p99 ms |\n|---|---:|---:|---:|")
    print(row("twin predict (for reference)", result["predict"]))
    print(row("bus: moves, waits and read-back (for reference)", result["bus"]))
    print(row("daemon overhead per instruction (wall - predict - bus)", result["overhead"]))
    print(row("  of which the commit (a worker thread)", result["commit"]))
    print(row("GET /api/v1/state idle (baseline)", result["idle"]))
    print(row("GET /api/v1/state during the run", result["state"]))
    print(row("WebSocket event lag", result["lag"]))
    idle, busy = (np.percentile(result[k], 99) for k in ("idle", "state"))
    idle50, busy50 = (statistics.median(result[k]) for k in ("idle", "state"))
    print(
        f"\nGET state during the run over idle: {busy50 / idle50:.2f}x at p50, "
        f"{busy / idle:.2f}x at p99.\n"
    )
    print(
        f"Restart of a held {args.restart_cycles}-cycle 24x24 job, `bwsd serve` spawned "
        f"{args.restarts} times each (median, worst):\n"
    )
    print("| journal | instructions | API up s | worst | recovered s | worst |")
    print("|---|---:|---:|---:|---:|---:|")
    for line in restart_rows(args.restart_cycles, args.restarts):
        print(line)


if __name__ == "__main__":
    main()

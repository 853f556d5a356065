"""Benchmark of the daemon: prints the markdown table of docs/benchmarks.md.

    python bench/daemon.py [--cycles 2] [--rate 500]

`bwsd serve` and the mock loom run in their own processes on loopback, zero travel time,
with the 24x24 braid. Measured: the daemon's per-instruction overhead (an instruction's
wall time in the run loop minus the twin's predict time, both reported in its event);
`GET state` latency at a fixed request rate while the program runs; WebSocket event lag
(receipt time minus the event's own time stamp).
"""

from __future__ import annotations

import argparse
import asyncio
import json
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
from bwsd.config import load_config  # noqa: E402
from bwsd.paths import state_folder, tokens_file  # noqa: E402
from bwsd.program.generators import braid4  # noqa: E402
from tests.fieldbus.conftest import BUS, toml  # noqa: E402
from tests.test_daemon import Served  # noqa: E402


def machine_table() -> dict[str, Any]:
    m = load_config(ROOT / "config" / "braid-24x24.toml").machine
    return {"rows": m.rows, "cols": m.cols, "pitch_x": m.pitch_x, "pitch_y": m.pitch_y,
            "d_mat": m.d_mat, "c_mat": m.c_mat}  # fmt: skip


def start(tmp: Path, program: str) -> tuple[Any, Served]:
    import subprocess

    machine = machine_table()
    (tmp / "prog.bws").write_text(program)
    (tmp / "mock.toml").write_text(toml({"machine": machine, "simulator": {
        "modbus_port": 0, "socketcand_port": 0, "control_port": 0}}))  # fmt: skip
    mock = subprocess.Popen([sys.executable, "-m", "simulator_hw", "--config",
                             str(tmp / "mock.toml"), "--program", str(tmp / "prog.bws")],
                            stdout=subprocess.PIPE, text=True, cwd=ROOT)  # fmt: skip
    assert mock.stdout is not None
    ports = dict(p.split("=") for p in mock.stdout.readline().split()[1:])
    (tmp / "bwsd.toml").write_text(toml({
        "machine": machine, "fieldbus": {"backend": "modbus", **BUS, "timeout": 30.0},
        "fieldbus.modbus": {"port": int(ports["modbus"])},
        "api": {"port": 0}, "plc": {"port": 0},
    }))  # fmt: skip
    state = state_folder(tmp / "state")
    tokens = tokens_file(load_config(tmp / "bwsd.toml"), state)
    token = TokenStore.load(tokens).add("bench", "operator")
    return mock, Served(tmp / "bwsd.toml", state, token)


def braid_24x24(cycles: int) -> str:
    """The benchmarks' 24x24 braid program (624 carriers)."""
    return braid4(24, 24, cycles=cycles, takeup=3.0, pitch=10.0, d_mat=300.0, c_mat=0.3,
                  diameter=1.5).program  # fmt: skip


@contextmanager
def serving(program: str) -> Iterator[Served]:
    """The mock loom and `bwsd serve` for ``program``, stopped at the end."""
    with tempfile.TemporaryDirectory() as tmp:
        mock, served = start(Path(tmp), program)
        try:
            yield served
        finally:
            served.stop()
            mock.terminate()
            mock.wait(timeout=20)


async def measure(served: Served, program: str, rate: float) -> dict[str, list[float]]:
    base = str(served.http.base_url).rstrip("/")
    token = served.http.headers["Authorization"].split()[1]
    ws_url = base.replace("http", "ws", 1) + f"/events?token={token}"
    out: dict[str, list[float]] = {"lag": [], "overhead": [], "predict": [], "state": []}
    done = asyncio.Event()
    async with websockets.connect(ws_url, max_size=None) as ws:
        reader = asyncio.create_task(_events(ws, out, done))
        async with httpx.AsyncClient(base_url=base, headers=served.http.headers, timeout=30) as c:
            (await c.post("/programs", json={"name": "b.bws", "text": program})).raise_for_status()
            await c.post("/commands/reset", json={})
            await c.post("/commands/start", json={})
            await _load(c, rate, out["state"], done)
        await reader
    return out


async def _events(ws: Any, out: dict[str, list[float]], done: asyncio.Event) -> None:
    async for text in ws:
        now = time.time()
        event = json.loads(text)
        if "at" in event:
            out["lag"].append(now - event["at"])
        if event.get("event") == "instruction" and "step_s" in event:
            out["overhead"].append(event["step_s"] - event["predict_s"])
            out["predict"].append(event["predict_s"])
        if event.get("event") == "state" and event.get("to") in ("Complete", "Held", "Aborted"):
            done.set()
            return


async def _load(client: httpx.AsyncClient, rate: float, into: list[float],
                done: asyncio.Event) -> None:  # fmt: skip
    async def one() -> None:
        start = time.perf_counter()
        (await client.get("/state")).raise_for_status()
        into.append(time.perf_counter() - start)

    pending: set[asyncio.Task[None]] = set()
    next_at = time.perf_counter()
    while not done.is_set():
        task = asyncio.create_task(one())
        pending.add(task)
        task.add_done_callback(pending.discard)
        next_at += 1 / rate
        await asyncio.sleep(max(0.0, next_at - time.perf_counter()))
    await asyncio.gather(*pending)


def row(name: str, values: list[float]) -> str:
    if not values:
        return f"| {name} | 0 | | |"
    ms = [v * 1e3 for v in values]
    return f"| {name} | {len(ms)} | {statistics.median(ms):.2f} | {np.percentile(ms, 99):.2f} |"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--cycles", type=int, default=2)
    parser.add_argument("--rate", type=float, default=500.0)
    args = parser.parse_args()
    program = braid_24x24(args.cycles)
    with serving(program) as served:
        result = asyncio.run(measure(served, program, args.rate))
    print(
        f"24x24 braid (624 carriers), {args.cycles} cycles, zero travel time, "
        f"GET state at {args.rate:g} requests/s during the run.\n"
    )
    print("| measure | n | p50 ms | p99 ms |\n|---|---:|---:|---:|")
    print(row("twin predict (for reference)", result["predict"]))
    print(row("daemon overhead per instruction (wall - predict)", result["overhead"]))
    print(row("GET /api/v1/state during production", result["state"]))
    print(row("WebSocket event lag", result["lag"]))


if __name__ == "__main__":
    main()

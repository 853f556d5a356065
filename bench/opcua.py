"""Benchmark of the OPC UA door: state change to subscription notification, against the
WebSocket's event, in the same run. Prints the table of docs/benchmarks.md.

    python bench/opcua.py [--cycles 50] [--intervals 10 50 100]

`bwsd serve` (with `[opcua] enabled = true`) and the mock loom (the 4x4 test machine, no
travel time) run in their own processes on loopback. A reader process holds one WebSocket
(`/api/v1/events`) and one OPC UA session (Basic256Sha256 Sign & Encrypt, an operator's
user) with one subscription to `Status.StateCurrent` per publishing interval. The main
process runs the program ``--cycles`` times (load, Reset, Start, to Complete: six state
changes a cycle). The lag of each state change is its receipt time minus the time the
controller made it: the WebSocket event's ``at``, the OPC UA notification's source time
stamp (the same ``at``, tests/opcua/test_server.py).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import websockets

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bwsd.api.auth import TokenStore  # noqa: E402
from tests.opcua.conftest import TEXT, client_cert, session, trust, var  # noqa: E402
from tests.opcua.test_views import served_config  # noqa: E402
from tests.support.fieldbus import start_mock  # noqa: E402
from tests.test_daemon import Served  # noqa: E402

CHANGES_PER_CYCLE = 6  # Resetting, Idle, Starting, Execute, Completing, Complete


def read_changes(
    urls: dict[str, str],
    token: str,
    cert: Any,
    intervals: list[int],
    expected: int,
    results: Any,
    listening: Any,
) -> None:
    """The reader's process: every state change's lag, per channel, until ``expected``."""
    lags: dict[str, list[float]] = {
        "websocket": [],
        **{f"OPC UA, publishing every {i} ms": [] for i in intervals},
    }

    class Handler:
        def __init__(self, into: list[float]) -> None:
            self.into, self.first = into, True

        def datachange_notification(self, node: Any, value: Any, data: Any) -> None:
            now = time.time()
            if self.first:  # the value at subscription, not a change
                self.first = False
                return
            self.into.append(now - data.monitored_item.Value.SourceTimestamp.timestamp())

    async def main() -> None:
        ws_url = urls["api"].replace("http", "ws", 1) + "/api/v1/events"
        headers = {"Authorization": f"Bearer {token}"}  # never in the URL: logs print URLs
        async with (
            websockets.connect(ws_url, additional_headers=headers, max_size=None) as ws,
            session(urls["opcua"], cert, "bench", token) as client,
        ):
            await ws.recv()  # hello
            node = await var(client, "Status/StateCurrent")
            for interval in intervals:
                sub = await client.create_subscription(
                    interval, Handler(lags[f"OPC UA, publishing every {interval} ms"])
                )
                await sub.subscribe_data_change(node, queuesize=100)
            await asyncio.sleep(0.5)
            listening.set()
            while len(lags["websocket"]) < expected:
                event = json.loads(await ws.recv())
                if event.get("event") == "state":
                    lags["websocket"].append(time.time() - event["at"])
            deadline = time.monotonic() + 10
            while min(map(len, lags.values())) < expected and time.monotonic() < deadline:
                await asyncio.sleep(0.05)

    asyncio.run(main())
    results.put(lags)


async def drive(served: Served, cycles: int) -> None:
    base = str(served.http.base_url).rstrip("/")
    async with httpx.AsyncClient(base_url=base, headers=served.http.headers, timeout=30) as c:
        for _ in range(cycles):
            (await c.post("/programs", json={"name": "b.bws", "text": TEXT})).raise_for_status()
            for command in ("reset", "start"):
                (await c.post(f"/commands/{command}", json={})).raise_for_status()
            while (await c.get("/state")).json()["name"] != "Complete":
                await asyncio.sleep(0.01)
            await asyncio.sleep(0.05)  # the changes of one cycle apart from the next's


def row(name: str, lags: list[float], base: float) -> str:
    ms = np.array(lags) * 1000
    median = statistics.median(ms)
    return (
        f"| {name} | {len(ms)} | {median:.2f} | {np.percentile(ms, 99):.2f} | "
        f"{ms.max():.2f} | {median / base:.2f} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=50)
    parser.add_argument(
        "--intervals",
        type=int,
        nargs="+",
        default=[10, 50, 100],
        help="OPC UA publishing intervals (ms)",
    )
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        tmp = Path(folder)
        mock = start_mock(tmp, {})
        state = tmp / "state"
        state.mkdir()
        token = TokenStore.load(state / "tokens.json").add("bench", "operator")
        cert = client_cert(tmp / "client")
        trust(state / "opcua", cert)
        config = served_config(tmp, mock.ports["modbus"])
        served = Served(config, state, token)
        try:
            spawn = multiprocessing.get_context("spawn")
            results, listening = spawn.Queue(), spawn.Event()
            expected = args.cycles * CHANGES_PER_CYCLE
            reader = spawn.Process(
                target=read_changes,
                args=(served.urls, token, cert, args.intervals, expected, results, listening),
            )
            reader.start()
            while not listening.is_set():
                time.sleep(0.01)
            asyncio.run(drive(served, args.cycles))
            lags = results.get(timeout=60)
            reader.join(timeout=30)
        finally:
            served.stop()
            mock.stop()
    base = statistics.median(lags["websocket"]) * 1000
    print(
        f"State change to notification, {args.cycles} runs of the 15-instruction braid "
        f"({expected} state changes), lag in ms:\n"
    )
    print("| channel | changes | median | p99 | max | median / WebSocket's |")
    print("|---|---|---|---|---|---|")
    for name, values in lags.items():
        print(row(name if name != "websocket" else "WebSocket event (baseline)", values, base))


if __name__ == "__main__":
    main()

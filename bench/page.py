"""Benchmark of the live preview page: prints the markdown tables of docs/benchmarks.md.

    python bench/page.py [--cycles 40] [--speed MM_S] [--screenshot docs/preview.png]

`bwsd serve` and the mock loom run in their own processes on loopback with the 24x24
braid; Debian's chromium shows the page while the program runs. The loom's actuators
travel at ``--speed`` mm/s (a 10 mm shift goes out and back: 0.1 s at 200 mm/s), or in no
time by default, when the daemon sends instructions as fast as it predicts them. Measured:

- how long an executed instruction takes to appear: from the instruction event's own time
  stamp (taken when the instruction is done) to the page's frame that drew it, against
  the same time to a plain WebSocket client in Python (the baseline, in the same run);
- whether the page stays smooth as the preform grows: the interval between the page's
  frames while updates flow, and the page's work per frame (applying the deltas and
  drawing) on the first tenth of the run against the last tenth, with the preform's node
  count at each;
- the size of the instruction events on the wire, first tenth against last tenth.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import websockets
from playwright.sync_api import sync_playwright

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.daemon import braid_24x24, machine_table  # noqa: E402
from bwsd.api.auth import TokenStore  # noqa: E402
from bwsd.config import load_config  # noqa: E402
from bwsd.paths import state_folder, tokens_file  # noqa: E402
from tests.support.fieldbus import BUS, start_mock, toml  # noqa: E402
from tests.test_daemon import Served  # noqa: E402
from tests.web.conftest import ARGS, CHROMIUM  # noqa: E402


class Listener(threading.Thread):
    """A plain WebSocket client: when each instruction event arrives, and its size."""

    def __init__(self, url: str, token: str) -> None:
        super().__init__(daemon=True)
        self.url = url
        self.headers = {"Authorization": f"Bearer {token}"}  # never in the URL: logs print URLs
        self.lag: list[float] = []  # ms, receipt - event time
        self.sizes: list[int] = []  # bytes of each instruction event
        self.connected = threading.Event()
        self.finished = threading.Event()
        self.error: str | None = None  # why the stream ended early, if it did

    def run(self) -> None:
        try:
            asyncio.run(self._listen())
        except Exception as exc:  # the run goes on; the baseline then covers part of it
            self.error = f"{type(exc).__name__}: {exc}"
        finally:
            self.finished.set()

    async def _listen(self) -> None:
        async with websockets.connect(
            self.url, additional_headers=self.headers, max_size=None
        ) as ws:
            self.connected.set()
            async for text in ws:
                now = time.time()
                event = json.loads(text)
                if event.get("event") == "instruction":
                    self.lag.append((now - event["at"]) * 1e3)
                    self.sizes.append(len(text.encode()))
                if event.get("event") == "state" and event.get("to") in (
                    "Complete",
                    "Held",
                    "Aborted",
                ):
                    self.finished.set()
                    return


@contextmanager
def serving(program: str, speed: float) -> Iterator[Served]:
    """The mock loom (actuators at ``speed`` mm/s, 0: no travel time) and `bwsd serve`."""
    with tempfile.TemporaryDirectory() as folder:
        tmp = Path(folder)
        speeds = {"stroke_speed": speed, "takeup_speed": speed}
        mock = start_mock(tmp, speeds, machine=machine_table(), program=program)
        config = tmp / "bwsd.toml"
        config.write_text(
            toml(
                {
                    "machine": machine_table(),
                    "fieldbus": {"backend": "modbus", **BUS, "timeout": 30.0},
                    "fieldbus.modbus": {"port": mock.ports["modbus"]},
                    "api": {"port": 0},
                    "plc": {"port": 0},
                }
            )
        )
        state = state_folder(load_config(config), tmp / "state")
        token = TokenStore.load(tokens_file(load_config(config), state)).add("bench", "operator")
        served = Served(config, state, token)
        try:
            yield served
        finally:
            served.stop()
            mock.stop()


def row(name: str, ms: list[float], unit: float = 1.0) -> str:
    if not ms:
        return f"| {name} | 0 | | |"
    values = [v * unit for v in ms]
    return (
        f"| {name} | {len(values)} | {statistics.median(values):.1f} | "
        f"{np.percentile(values, 99):.1f} |"
    )


def tenths(values: list[Any]) -> tuple[list[Any], list[Any]]:
    k = max(1, len(values) // 10)
    return values[:k], values[-k:]


def run(served: Served, program: str, shot: Path | None) -> dict[str, Any]:
    base = str(served.http.base_url).rstrip("/").removesuffix("/api/v1")
    token = served.http.headers["Authorization"].split()[1]
    listener = Listener(base.replace("http", "ws", 1) + "/api/v1/events", token)
    listener.start()
    listener.connected.wait(30)
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        errors: list[str] = []
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.goto(f"{base}/#token={token}")
        page.wait_for_function("() => window.bwsd && window.bwsd.ready", timeout=60_000)
        # the load dry-runs the whole program first: minutes for a large preform
        loaded = served.http.post(
            "/programs", json={"name": "b.bws", "text": program}, timeout=3600
        )
        count = int(loaded.raise_for_status().json()["instructions"])
        served.command("reset")
        page.wait_for_function("() => window.bwsd.state === 'Idle'", timeout=60_000)
        served.command("start")
        began = time.monotonic()
        while not listener.finished.wait(5):
            done = page.evaluate("window.bwsd.done")
            print(
                f"  {done}/{count} instructions, {time.monotonic() - began:.0f} s", file=sys.stderr
            )
            if done == count:
                break
        page.wait_for_function(f"() => window.bwsd.done === {count}", timeout=120_000)
        hooks = page.evaluate("({...window.bwsd, stats: window.bwsd.view?.layers?.stats ?? null})")
        if shot is not None:
            page.screenshot(path=str(shot))
        browser.close()
    return {
        "hooks": hooks,
        "lag": listener.lag,
        "sizes": listener.sizes,
        "errors": errors,
        "count": count,
        "listener": listener.error,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--cycles", type=int, default=40)
    parser.add_argument(
        "--speed",
        type=float,
        default=0.0,
        help="the loom's actuator speed, mm/s (default 0: no travel time)",
    )
    parser.add_argument("--screenshot", type=Path, help="save the page at the end (PNG)")
    args = parser.parse_args()
    program = braid_24x24(args.cycles)
    with serving(program, args.speed) as served:
        result = run(served, program, args.screenshot)
    hooks, count = result["hooks"], result["count"]
    work = hooks.get("work", [])
    first, last = tenths(work)
    size_first, size_last = tenths(result["sizes"])
    travel = f"actuators at {args.speed:g} mm/s" if args.speed else "zero travel time"
    print(
        f"24x24 braid (624 carriers), {args.cycles} cycles ({count} instructions), {travel}; "
        f"headless chromium (software WebGL), 1280x800.\n"
    )
    print("| measure | n | p50 ms | p99 ms |\n|---|---:|---:|---:|")
    print(row("instruction event to a Python WebSocket client (baseline)", result["lag"]))
    print(row("instruction event to the page's frame that drew it", hooks["latencies"]))
    print(row("page frame interval while updates flow", hooks["frames"]))
    print(row("interval between drawings of the 3D view while updates flow", hooks["drawn"]))
    nodes0 = int(np.median([w["nodes"] for w in first])) if first else 0
    nodes1 = int(np.median([w["nodes"] for w in last])) if last else 0
    print(row(f"page work per frame, first tenth (~{nodes0:,} nodes)", [w["ms"] for w in first]))
    print(row(f"page work per frame, last tenth (~{nodes1:,} nodes)", [w["ms"] for w in last]))
    if first and last:
        ratio = statistics.median(w["ms"] for w in last) / statistics.median(w["ms"] for w in first)
        print(
            f"\nPage work per frame, last tenth over first tenth (p50): {ratio:.2f}x "
            f"for {nodes1 / max(nodes0, 1):.1f}x the nodes."
        )
    if size_first and size_last:
        print(
            f"Instruction event size, p50: {statistics.median(size_first) / 1e3:.1f} kB "
            f"(first tenth), {statistics.median(size_last) / 1e3:.1f} kB (last tenth)."
        )
    lag = statistics.median(result["lag"]) if result["lag"] else 0.0
    page = statistics.median(hooks["latencies"]) if hooks["latencies"] else 0.0
    print(
        f"Page over baseline (p50): {page / lag if lag else float('nan'):.2f}x. "
        f"Console errors: {len(result['errors'])}."
    )
    stats = hooks.get("stats")
    if stats:
        print(
            f"Settled image: drawn whole {len(stats['images'])} times, split from scratch "
            f"{stats['splits']} times, {stats['increments']} incremental draws."
        )
    if result["listener"]:
        print(
            f"The baseline client's stream ended early ({result['listener']}): its row "
            f"covers {len(result['lag'])} of {count} instructions."
        )


if __name__ == "__main__":
    main()
